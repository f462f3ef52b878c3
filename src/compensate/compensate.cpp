#include "hotgauge/compensate/compensate.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <opencv2/core.hpp>

namespace hotgauge::compensate {
namespace {

constexpr double kNsPerS = 1e9;

// (a − b) in seconds, exact in int64 where it fits; clocks centuries apart (a corrupt file)
// fall back to double arithmetic instead of overflowing.
double seconds_between(std::int64_t a, std::int64_t b) {
    std::int64_t d = 0;
    if (__builtin_sub_overflow(a, b, &d))
        return (static_cast<double>(a) - static_cast<double>(b)) / kNsPerS;
    return static_cast<double>(d) / kNsPerS;
}

std::string fmt_s(double s) {
    char b[32];
    std::snprintf(b, sizeof b, "%.3f s", s);
    return b;
}

}  // namespace

std::vector<double> integrate_twice(const std::vector<double>& accel, double rate_hz,
                                    const CompensationConfig& c) {
    const int n = static_cast<int>(accel.size());
    if (n < 8 || !(rate_hz > 0)) return std::vector<double>(accel.size(), 0.0);
    // Gravity and bias are constant: the mean goes. Not a linear trend: removing one from the
    // acceleration adds a ramp that integrates to a cubic (measured: 27 % error on a 47 Hz sine).
    std::vector<double> a = accel;
    double mean = 0;
    for (double v : a) mean += v;
    mean /= static_cast<double>(n);
    for (double& v : a) v -= mean;
    // Tukey taper: cosine ramps at both ends, flat in between.
    const int ramp = std::min(n / 4, static_cast<int>(c.taper_s * rate_hz));
    for (int i = 0; i < ramp; ++i) {
        const double w = 0.5 * (1.0 - std::cos(std::numbers::pi * (i + 0.5) / ramp));
        a[i] *= w;
        a[n - 1 - i] *= w;
    }
    // Zero padding to at least twice the length keeps the circular wrap-around off the record.
    const int m = cv::getOptimalDFTSize(2 * n);
    cv::Mat x = cv::Mat::zeros(1, m, CV_64F);
    std::copy(a.begin(), a.end(), x.ptr<double>());
    cv::Mat X;
    cv::dft(x, X, cv::DFT_COMPLEX_OUTPUT);
    auto* bins = X.ptr<cv::Vec2d>();
    const double df = rate_hz / m;
    for (int k = 0; k < m; ++k) {
        const double f = (k <= m / 2 ? k : k - m) * df;
        if (k == 0) {
            bins[k] = cv::Vec2d(0, 0);
            continue;
        }
        const double w = 2.0 * std::numbers::pi * f;
        // (jω)² = −ω²; zero-phase Butterworth magnitude high-pass.
        const double hp =
            1.0 / std::sqrt(1.0 + std::pow(c.highpass_hz / std::abs(f), 2.0 * c.highpass_order));
        const double g = -hp / (w * w);
        bins[k] = cv::Vec2d(bins[k][0] * g, bins[k][1] * g);
    }
    cv::Mat y;
    cv::idft(X, y, cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
    const double* yp = y.ptr<double>();
    return std::vector<double>(yp, yp + n);
}

FaceCompensation compensate_face(const core::FaceScan& face, const CompensationConfig& c) {
    FaceCompensation out;
    out.face = face.name;
    const std::int64_t np = face.n_profiles();
    out.u_mm.assign(np, Eigen::Vector3d::Zero());
    out.profile_degraded.assign(np, 0);
    auto degrade_all = [&](const std::string& why) {
        out.degraded = true;
        out.reasons.push_back(why);
        std::fill(out.profile_degraded.begin(), out.profile_degraded.end(), 1);
        out.n_degraded = np;
    };
    if (np == 0) return out;

    // Usable samples: finite; NaN samples are gaps.
    std::vector<double> t_s;
    std::vector<Eigen::Vector3d> a;
    std::int64_t n_nan = 0, n_clip = 0;
    const std::int64_t t_ref = face.profile_times_ns.front();
    std::vector<double> clipped_at;
    // Only samples near the scan count: a record may be longer (or carry a stray far-off
    // timestamp); the integration window is the scan plus kWindowMarginS on each side.
    constexpr double kWindowMarginS = 10.0;
    const double scan_end_s = seconds_between(face.profile_times_ns.back(), t_ref);
    std::int64_t n_outside = 0;
    for (std::int64_t j = 0; j < face.n_accel(); ++j) {
        const double t_raw = seconds_between(face.accel_times_ns[j], t_ref) - c.clock_offset_s;
        if (t_raw < -kWindowMarginS || t_raw > scan_end_s + kWindowMarginS) {
            ++n_outside;
            continue;
        }
        const Eigen::Vector3d v = face.accel(j);
        const double t = seconds_between(face.accel_times_ns[j], t_ref) - c.clock_offset_s;
        if (!v.allFinite()) {
            ++n_nan;
            continue;
        }
        if (v.cwiseAbs().maxCoeff() >= c.clip_mps2) {
            ++n_clip;
            clipped_at.push_back(t);
        }
        t_s.push_back(t);
        a.push_back(v);
    }
    if (n_outside)
        out.reasons.push_back(std::to_string(n_outside) +
                              " accelerometer sample(s) more than 10 s from the scan ignored");
    if (t_s.size() < 16) {
        degrade_all(face.n_accel() == 0 ? "no accelerometer samples"
                                        : "too few usable accelerometer samples (" +
                                              std::to_string(t_s.size()) + ")");
        return out;
    }
    // Nominal period: the median interval. Gaps: intervals above gap_factor × nominal.
    std::vector<double> dt(t_s.size() - 1);
    for (std::size_t j = 0; j + 1 < t_s.size(); ++j) dt[j] = t_s[j + 1] - t_s[j];
    std::vector<double> sorted = dt;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double period = sorted[sorted.size() / 2];
    if (!(period > 0)) {
        degrade_all("accelerometer timestamps not increasing");
        return out;
    }
    out.rate_hz = 1.0 / period;
    std::vector<std::pair<double, double>> bad;  // time spans where u is not to be trusted
    int n_gaps = 0;
    for (std::size_t j = 0; j < dt.size(); ++j)
        if (dt[j] > c.gap_factor * period) {
            bad.emplace_back(t_s[j], t_s[j + 1]);
            ++n_gaps;
        }
    for (double t : clipped_at) bad.emplace_back(t, t);
    if (n_gaps)
        out.reasons.push_back(std::to_string(n_gaps) + " gap(s) in the accelerometer record");
    if (n_nan) out.reasons.push_back(std::to_string(n_nan) + " non-finite accelerometer sample(s)");
    if (n_clip) out.reasons.push_back(std::to_string(n_clip) + " clipped accelerometer sample(s)");

    // World-frame acceleration on a uniform grid (linear interpolation over gaps).
    const Eigen::Matrix3d R_world_accel = face.T_world_camera.linear() * face.R_camera_accel;
    const double t0 = t_s.front(), t1 = t_s.back();
    const auto n = static_cast<std::size_t>(std::floor((t1 - t0) / period)) + 1;
    std::vector<double> ax(n), ay(n), az(n);
    std::size_t j = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double t = t0 + static_cast<double>(i) * period;
        while (j + 2 < t_s.size() && t_s[j + 1] < t) ++j;
        const double f = std::clamp((t - t_s[j]) / (t_s[j + 1] - t_s[j]), 0.0, 1.0);
        const Eigen::Vector3d v = R_world_accel * ((1.0 - f) * a[j] + f * a[j + 1]);
        ax[i] = v.x();
        ay[i] = v.y();
        az[i] = v.z();
    }
    // Gravity and bias are constant in the world during a scan: integrate_twice removes them
    // with the mean; m → mm.
    const std::vector<double> ux = integrate_twice(ax, out.rate_hz, c);
    const std::vector<double> uy = integrate_twice(ay, out.rate_hz, c);
    const std::vector<double> uz = integrate_twice(az, out.rate_hz, c);

    const double margin_lo = t0 + c.min_margin_s, margin_hi = t1 - c.min_margin_s;
    bool short_record = false;
    double sum2 = 0.0;
    std::int64_t n_applied = 0;
    for (std::int64_t k = 0; k < np; ++k) {
        const double t = seconds_between(face.profile_times_ns[k], t_ref);
        bool deg = t < margin_lo || t > margin_hi;
        short_record = short_record || deg;
        for (const auto& [b0, b1] : bad)
            deg = deg || (t >= b0 - c.degrade_pad_s && t <= b1 + c.degrade_pad_s);
        out.profile_degraded[k] = deg;
        out.n_degraded += deg;
        if (t < t0 || t > t1) continue;  // no samples at all: leave uncompensated
        const double pos = (t - t0) / period;
        const auto i0 = std::min<std::size_t>(static_cast<std::size_t>(pos), n - 2);
        const double f = pos - static_cast<double>(i0);
        const Eigen::Vector3d u(ux[i0] + f * (ux[i0 + 1] - ux[i0]),
                                uy[i0] + f * (uy[i0 + 1] - uy[i0]),
                                uz[i0] + f * (uz[i0 + 1] - uz[i0]));
        out.u_mm[k] = 1000.0 * u;
        out.peak_mm = std::max(out.peak_mm, out.u_mm[k].norm());
        sum2 += out.u_mm[k].squaredNorm();
        ++n_applied;
    }
    if (short_record)
        out.reasons.push_back("accelerometer record does not cover the scan with " +
                              fmt_s(c.min_margin_s) + " margins");
    out.applied = n_applied > 0;
    out.rms_mm = n_applied ? std::sqrt(sum2 / static_cast<double>(n_applied)) : 0.0;
    out.degraded = out.n_degraded > 0;
    if (out.degraded && out.reasons.empty()) out.reasons.push_back("degraded profiles");
    return out;
}

}  // namespace hotgauge::compensate
