#pragma once
// Drift warning (issue 19, docs/quality.md "Drift warning"): an EWMA chart of a feature's values
// against its baseline, which sees a die wearing long before its parts leave the tolerance.
#include <cstddef>
#include <span>

#include "hotgauge/core/result.hpp"

namespace hotgauge::quality {

struct DriftConfig {
    double lambda = 0.05;  // weight of the newest value
    // L: the limits are ±L·σ_EWMA around the baseline's mean. 5, not the textbook 3: the
    // baseline's σ is an estimate (MR̄/d2 of 100 values is ±8 %), and with L 4 one series of 1 000
    // drift-free parts in five warned (docs/quality.md "Drift warning").
    double limit_sigmas = 5.0;
};

enum class Drift { kNone, kUp, kDown };
const char* to_string(Drift d);

// z_i = λ·x_i + (1 − λ)·z_{i−1}, z_0 = the baseline's mean μ; a drift while
// |z_i − μ| > L·σ·√(λ/(2 − λ)·(1 − (1 − λ)^{2i})), σ the baseline's within σ (MR̄/d2).
class DriftMonitor {
  public:
    // μ and σ from a baseline of at least 20 values (the first parts of a die, say).
    static core::Result<DriftMonitor> from_baseline(std::span<const double> baseline,
                                                    const DriftConfig& config = {});
    DriftMonitor(double mean, double sigma, const DriftConfig& config);

    // The next value; a non-finite one (not measured) is skipped and changes nothing.
    Drift add(double value);
    Drift state() const { return state_; }
    double ewma() const { return z_; }
    double limit() const;  // the current half-width of the limits
    std::size_t count() const { return n_; }
    double mean() const { return mean_; }
    double sigma() const { return sigma_; }

  private:
    double mean_, sigma_;
    DriftConfig config_;
    double z_;
    std::size_t n_ = 0;
    Drift state_ = Drift::kNone;
};

}  // namespace hotgauge::quality
