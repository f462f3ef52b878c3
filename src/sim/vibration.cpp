#include "hotgauge/sim/vibration.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace hotgauge::sim {
namespace {

// Value with exact first and second time derivatives (a second-order jet).
struct Jet {
    double v = 0, d = 0, dd = 0;
};
Jet operator*(Jet a, Jet b) {
    return {a.v * b.v, a.d * b.v + a.v * b.d, a.dd * b.v + 2 * a.d * b.d + a.v * b.dd};
}
Jet operator+(Jet a, Jet b) { return {a.v + b.v, a.d + b.d, a.dd + b.dd}; }
Jet operator*(double s, Jet a) { return {s * a.v, s * a.d, s * a.dd}; }
Jet operator-(double s, Jet a) { return {s - a.v, -a.d, -a.dd}; }
// exp(k·τ), sin(w·τ + p) as jets of τ (dτ/dt = 1).
Jet exp_lin(double k, double tau) {
    const double e = std::exp(k * tau);
    return {e, k * e, k * k * e};
}
Jet sin_lin(double w, double p, double tau) {
    const double s = std::sin(w * tau + p), c = std::cos(w * tau + p);
    return {s, w * c, -w * w * s};
}

constexpr double kTwoPi = 2.0 * std::numbers::pi;
constexpr double kEnvelopeCutoff = 1e-7;  // a blow whose envelope fell below this is skipped

}  // namespace

Vibration::Vibration(const VibrationConfig& config, double t_begin_s, double t_end_s,
                     std::mt19937_64& rng)
    : config_(config) {
    if (!config_.enabled) return;
    std::uniform_real_distribution<double> jitter(-config_.blow_jitter_s, config_.blow_jitter_s);
    std::normal_distribution<double> scatter(1.0, config_.amplitude_scatter);
    std::uniform_real_distribution<double> phase0(0.0, config_.blow_period_s);
    // Start early enough that the line is already shaking when the first scan begins.
    for (double t = t_begin_s - 5.0 + phase0(rng); t < t_end_s; t += config_.blow_period_s) {
        Blow b{t + jitter(rng), {}};
        for (const auto& m : config_.modes)
            b.amplitude_mm.push_back(m.amplitude_mm * std::max(0.0, scatter(rng)));
        blows_.push_back(std::move(b));
    }
    // Past this, every mode's envelope is below the cutoff: evaluate() starts at the first blow
    // younger than it (a virtual cell serves hours; its samples must not scan every blow).
    for (const auto& m : config_.modes)
        horizon_s_ = std::max(
            horizon_s_, std::log(1.0 / kEnvelopeCutoff) / (m.damping_ratio * kTwoPi * m.freq_hz));
    // Ambient hum: sinusoids at random frequencies whose total RMS is ambient_rms_mm.
    constexpr int kHumLines = 24;
    std::uniform_real_distribution<double> f(2.0, 120.0), ph(0.0, kTwoPi);
    std::normal_distribution<double> g(0.0, 1.0);
    const double a = config_.ambient_rms_mm * std::sqrt(2.0 / kHumLines);
    for (int j = 0; j < kHumLines; ++j) {
        Eigen::Vector3d dir(g(rng), g(rng), g(rng));
        hum_.push_back({f(rng), a, ph(rng), dir.normalized()});
    }
}

template <class J>
void Vibration::evaluate(double t_s, J* out) const {
    const auto first = std::partition_point(
        blows_.begin(), blows_.end(), [&](const Blow& b) { return t_s - b.t_s > horizon_s_; });
    for (auto it = first; it != blows_.end(); ++it) {
        const Blow& b = *it;
        const double tau = t_s - b.t_s;
        if (tau <= 0.0) break;  // this blow and all later ones are still to come
        // Smooth onset: (1 - e^{-τ/τ_on})² starts with zero displacement, velocity and
        // acceleration.
        const Jet rise = 1.0 - exp_lin(-1.0 / config_.onset_s, tau);
        const Jet onset = rise * rise;
        for (std::size_t m = 0; m < config_.modes.size(); ++m) {
            const auto& mode = config_.modes[m];
            const double w = kTwoPi * mode.freq_hz;
            const double sigma = mode.damping_ratio * w;
            if (std::exp(-sigma * tau) < kEnvelopeCutoff) continue;
            const double wd = w * std::sqrt(1.0 - mode.damping_ratio * mode.damping_ratio);
            const Jet u =
                b.amplitude_mm[m] * (onset * exp_lin(-sigma, tau) * sin_lin(wd, 0.0, tau));
            for (int k = 0; k < 3; ++k)
                out[k] = out[k] + J{mode.direction_world[k] * u.v, mode.direction_world[k] * u.d,
                                    mode.direction_world[k] * u.dd};
        }
    }
    for (const auto& h : hum_) {
        const Jet u = h.amplitude_mm * sin_lin(kTwoPi * h.freq_hz, h.phase, t_s);
        for (int k = 0; k < 3; ++k)
            out[k] = out[k] + J{h.direction[k] * u.v, h.direction[k] * u.d, h.direction[k] * u.dd};
    }
}

Eigen::Vector3d Vibration::displacement_mm(double t_s) const {
    Jet j[3];
    evaluate(t_s, j);
    return {j[0].v, j[1].v, j[2].v};
}

Eigen::Vector3d Vibration::acceleration_mmps2(double t_s) const {
    Jet j[3];
    evaluate(t_s, j);
    return {j[0].dd, j[1].dd, j[2].dd};
}

}  // namespace hotgauge::sim
