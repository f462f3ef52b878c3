#include "hotgauge/quality/drift.hpp"

#include <cmath>
#include <string>

#include "hotgauge/quality/statistics.hpp"

namespace hotgauge::quality {

const char* to_string(Drift d) {
    switch (d) {
        case Drift::kUp:
            return "DRIFT_UP";
        case Drift::kDown:
            return "DRIFT_DOWN";
        case Drift::kNone:
            break;
    }
    return "NONE";
}

core::Result<DriftMonitor> DriftMonitor::from_baseline(std::span<const double> baseline,
                                                       const DriftConfig& config) {
    constexpr std::size_t kMinBaseline = 20;
    if (baseline.size() < kMinBaseline)
        return core::make_error("drift baseline: need at least " + std::to_string(kMinBaseline) +
                                " values, got " + std::to_string(baseline.size()));
    if (!(config.lambda > 0 && config.lambda <= 1) || !(config.limit_sigmas > 0))
        return core::make_error("drift: lambda must be in (0, 1] and the limit positive");
    const auto chart = individuals_chart(baseline);
    if (!chart) return core::make_error("drift baseline: " + chart.error().message);
    if (!(chart->sigma > 0))
        return core::make_error("drift baseline: the values do not change from one to the next");
    return DriftMonitor(chart->centre, chart->sigma, config);
}

DriftMonitor::DriftMonitor(double mean, double sigma, const DriftConfig& config)
    : mean_(mean), sigma_(sigma), config_(config), z_(mean) {}

double DriftMonitor::limit() const {
    const double l = config_.lambda;
    const double grow = 1.0 - std::pow(1.0 - l, 2.0 * static_cast<double>(n_));
    return config_.limit_sigmas * sigma_ * std::sqrt(l / (2.0 - l) * grow);
}

Drift DriftMonitor::add(double value) {
    if (!std::isfinite(value)) return state_;
    ++n_;
    z_ = config_.lambda * value + (1.0 - config_.lambda) * z_;
    const double off = z_ - mean_, lim = limit();
    state_ = off > lim ? Drift::kUp : off < -lim ? Drift::kDown : Drift::kNone;
    return state_;
}

}  // namespace hotgauge::quality
