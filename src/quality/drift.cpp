#include "hotgauge/quality/drift.hpp"

#include <algorithm>
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

DriftMonitor::DriftMonitor(double mean, double sigma, double z, std::size_t n,
                           const DriftConfig& config)
    : mean_(mean), sigma_(sigma), config_(config), z_(z), n_(n) {
    if (n_ == 0) return;
    const double off = z_ - mean_, lim = limit();
    state_ = off > lim ? Drift::kUp : off < -lim ? Drift::kDown : Drift::kNone;
}

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

const char* to_string(Watch w) {
    switch (w) {
        case Watch::kBaseline:
            return "BASELINE";
        case Watch::kWatching:
            return "WATCHING";
        case Watch::kUp:
            return "DRIFT_UP";
        case Watch::kDown:
            return "DRIFT_DOWN";
    }
    return "?";
}

DriftWatch::DriftWatch(DriftWatchConfig config) : config_(config) {
    config_.baseline = std::max(config_.baseline, kMinBaseline);
}

Watch DriftWatch::state_of(const Series& s) const {
    if (!s.monitor) return Watch::kBaseline;
    switch (s.monitor->state()) {
        case Drift::kUp:
            return Watch::kUp;
        case Drift::kDown:
            return Watch::kDown;
        case Drift::kNone:
            break;
    }
    return Watch::kWatching;
}

Watch DriftWatch::add(int die, const std::string& recipe, const std::string& feature,
                      std::optional<double> value) {
    Series& s = series_[{die, recipe, feature}];
    if (!value || !std::isfinite(*value)) return state_of(s);
    if (s.monitor) {
        s.monitor->add(*value);
        return state_of(s);
    }
    s.baseline.push_back(*value);
    if (s.baseline.size() < config_.baseline) return Watch::kBaseline;
    // A baseline that does not vary cannot set limits: collect a new one.
    if (auto m = DriftMonitor::from_baseline(s.baseline, config_.ewma)) s.monitor = *m;
    s.baseline.clear();
    return state_of(s);
}

std::vector<DriftWatch::Saved> DriftWatch::saved() const {
    std::vector<Saved> out;
    for (const auto& [key, s] : series_) {
        Saved v{std::get<0>(key), std::get<1>(key), std::get<2>(key), s.baseline};
        if (s.monitor) {
            v.watching = true;
            v.mean = s.monitor->mean();
            v.sigma = s.monitor->sigma();
            v.z = s.monitor->ewma();
            v.n = s.monitor->count();
        }
        out.push_back(std::move(v));
    }
    return out;
}

void DriftWatch::restore(const Saved& v) {
    Series s;
    if (v.watching) {
        if (!std::isfinite(v.mean) || !std::isfinite(v.z) || !std::isfinite(v.sigma) ||
            !(v.sigma > 0))
            return;
        s.monitor = DriftMonitor(v.mean, v.sigma, v.z, v.n, config_.ewma);
    } else {
        s.baseline = v.baseline;
    }
    series_[{v.die, v.recipe, v.feature}] = std::move(s);
}

Watch DriftWatch::state(int die, const std::string& recipe, const std::string& feature) const {
    const auto it = series_.find({die, recipe, feature});
    return it == series_.end() ? Watch::kBaseline : state_of(it->second);
}

}  // namespace hotgauge::quality
