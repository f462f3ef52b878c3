#pragma once
// Drift warning (issue 19, docs/quality.md "Drift warning"): an EWMA chart of a feature's values
// against its baseline, which sees a die wearing long before its parts leave the tolerance.
#include <cstddef>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <tuple>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::quality {

inline constexpr std::size_t kMinBaseline = 20;  // values a baseline needs at least

struct DriftConfig {
    double lambda = 0.05;  // weight of the newest value
    // L: the limits are ±L·σ_EWMA around the baseline's mean. 6, not the textbook 3: the
    // baseline's σ is an estimate (MR̄/d2 of 100 values is ±8 %); of 200 series of 1 000
    // drift-free parts after a 100-part baseline, 38 warned with L 4, 4 with L 5, none with L 6,
    // and a die wearing 5 µm per 100 parts is seen as early (docs/quality.md "Drift warning").
    double limit_sigmas = 6.0;
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
    // Where a monitor was (DriftWatch::saved): its EWMA z after n values.
    DriftMonitor(double mean, double sigma, double z, std::size_t n, const DriftConfig& config);

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

// Drift warnings of a production line: one DriftMonitor per die, recipe and feature, each on
// a baseline of its first `baseline` values (the daemon's; docs/quality.md "In the daemon").
// A new die id starts new baselines; a die seen before goes on where it was.
enum class Watch { kBaseline, kWatching, kUp, kDown };
const char* to_string(Watch w);

struct DriftWatchConfig {
    std::size_t baseline = 100;  // values per die and feature before watching; at least 20
    DriftConfig ewma{};
};

class DriftWatch {
  public:
    explicit DriftWatch(DriftWatchConfig config = {});
    // The next value of a feature (nullopt: not measured, or not to be used: skipped), and the
    // feature's state after it.
    Watch add(int die, const std::string& recipe, const std::string& feature,
              std::optional<double> value);
    Watch state(int die, const std::string& recipe, const std::string& feature) const;
    const DriftWatchConfig& config() const { return config_; }

    // What the watch knows, to be kept across a restart (docs/quality.md "In the daemon"): per
    // die, recipe and feature the baseline being collected, or the monitor's μ, σ, z and n.
    struct Saved {
        int die = 0;
        std::string recipe, feature;
        std::vector<double> baseline;
        bool watching = false;
        double mean = 0, sigma = 0, z = 0;
        std::size_t n = 0;
    };
    std::vector<Saved> saved() const;
    void restore(const Saved& s);  // a monitor's state must be finite with σ > 0, else ignored

  private:
    struct Series {
        std::vector<double> baseline;
        std::optional<DriftMonitor> monitor;
    };
    Watch state_of(const Series& s) const;
    DriftWatchConfig config_;
    std::map<std::tuple<int, std::string, std::string>, Series> series_;
};

}  // namespace hotgauge::quality
