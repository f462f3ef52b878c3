#include "hotgauge/compensate/compensate.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <opencv2/core.hpp>
#include <optional>

namespace hotgauge::compensate {
namespace {

constexpr double kNsPerS = 1e9;
constexpr double kG = 9.80665;  // m/s² per g

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

// A stretch of the uniform grid with no measured sample behind it, [first, last].
struct GridGap {
    std::size_t first, last;
};

// integrate_twice returns zeros for fewer samples than this: no record to speak of (a guard
// kept from the first version, d17be8d, not a measured limit).
constexpr int kMinIntegrableSamples = 8;
// The Tukey taper's ramps take at most this share (1/4) of the record at each end (not measured).
constexpr int kMaxRampDivisor = 4;
// The noise density is read off the top band [0.3, 0.45] × the rate, far above any press mode,
// from at least 4 segments (docs/compensation.md, "Its own error"; the count not measured).
constexpr double kTopBandLo = 0.3, kTopBandHi = 0.45;
constexpr int kMinNoiseSegments = 4;
// The displacement error's frequency grid spans fc/20 to 40·fc (it holds all but 1e-5 of
// hp²/(2πf)⁴), and its lags reach 2.5 s or 4 corner periods, past the error's correlation
// (docs/compensation.md, "Its own error").
constexpr double kGridBelowCorner = 20.0, kGridAboveCorner = 40.0;
constexpr double kMinLagSpanS = 2.5, kLagPeriods = 4.0;
// The bridge's ridge on BᵀWB: this share of its mean diagonal, plus a floor for an all-zero one
// (not measured).
constexpr double kRidgeRel = 1e-12, kRidgeFloor = 1e-30;

}  // namespace

std::vector<double> integrate_twice(const std::vector<double>& accel, double rate_hz,
                                    const CompensationConfig& c) {
    const int n = static_cast<int>(accel.size());
    if (n < kMinIntegrableSamples || !(rate_hz > 0)) return std::vector<double>(accel.size(), 0.0);
    // Gravity and bias are constant: the mean goes. Not a linear trend: removing one from the
    // acceleration adds a ramp that integrates to a cubic (measured: 27 % error on a 47 Hz sine).
    std::vector<double> a = accel;
    double mean = 0;
    for (double v : a) mean += v;
    mean /= static_cast<double>(n);
    for (double& v : a) v -= mean;
    // Tukey taper: cosine ramps at both ends, flat in between.
    const int ramp = std::min(n / kMaxRampDivisor, static_cast<int>(c.taper_s * rate_hz));
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
        // Eq. 6–7 (seed paper §4.1): each line X(k) over (jω_k)² = −ω_k², here also times a
        // zero-phase Butterworth magnitude high-pass.
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

std::array<double, 3> accel_noise_density(const std::array<std::vector<double>, 3>& accel_world,
                                          double rate_hz, const std::vector<std::size_t>& breaks) {
    constexpr std::size_t kSegment = 256;
    std::array<double, 3> out{0, 0, 0};
    const std::size_t n = accel_world[0].size();
    if (!(rate_hz > 0)) return out;
    cv::Mat window(1, kSegment, CV_64F);
    double w2 = 0;
    for (std::size_t i = 0; i < kSegment; ++i) {
        const double w = 0.5 * (1.0 - std::cos(2.0 * std::numbers::pi * static_cast<double>(i) /
                                               static_cast<double>(kSegment)));
        window.at<double>(static_cast<int>(i)) = w;
        w2 += w * w;
    }
    // Segments overlap by half and lie within the runs between breaks.
    std::vector<std::size_t> starts;
    std::size_t run = 0;
    for (std::size_t b = 0; b <= breaks.size(); ++b) {
        const std::size_t end = b < breaks.size() ? std::min(breaks[b] + 1, n) : n;
        for (std::size_t s0 = run; s0 + kSegment <= end; s0 += kSegment / 2) starts.push_back(s0);
        run = std::max(run, end);
    }
    if (starts.size() < kMinNoiseSegments) return out;  // too little record to tell
    const int k_lo = static_cast<int>(std::ceil(kTopBandLo * kSegment)),
              k_hi = static_cast<int>(kTopBandHi * kSegment);
    for (int a = 0; a < 3; ++a) {
        std::vector<double> p;
        for (const std::size_t s0 : starts) {
            cv::Mat x(1, kSegment, CV_64F, const_cast<double*>(accel_world[a].data() + s0));
            cv::Mat X;
            cv::dft(x.mul(window), X, cv::DFT_COMPLEX_OUTPUT);
            for (int k = k_lo; k <= k_hi; ++k) {
                const cv::Vec2d v = X.at<cv::Vec2d>(k);
                p.push_back(2.0 * (v[0] * v[0] + v[1] * v[1]) / (rate_hz * w2));
            }
        }
        std::nth_element(p.begin(), p.begin() + static_cast<std::ptrdiff_t>(p.size() / 2), p.end());
        out[a] = p[p.size() / 2] / std::numbers::ln2;
    }
    return out;
}

core::DisplacementNoise displacement_noise(const std::array<double, 3>& density_si,
                                           const CompensationConfig& c) {
    constexpr double kLagS = 0.01;
    constexpr int kFreqs = 800;
    // hp²/(2πf)⁴ peaks near the corner: a log grid from fc/20 to 40·fc holds all but 1e-5 of it.
    const double fc = c.highpass_hz, lo = std::log(fc / kGridBelowCorner),
                 hi = std::log(kGridAboveCorner * fc);
    core::DisplacementNoise out;
    if (!(fc > 0)) return out;
    // Past the error's correlation (it lasts about a period of the corner), so that the sums
    // over it stay a variance.
    const int lags = static_cast<int>(std::max(kMinLagSpanS, kLagPeriods / fc) / kLagS) + 1;
    std::vector<double> shape(static_cast<std::size_t>(lags), 0.0);
    for (int j = 0; j < kFreqs; ++j) {
        const double f = std::exp(lo + (hi - lo) * (j + 0.5) / kFreqs);
        const double df = f * (hi - lo) / kFreqs;
        const double hp2 = 1.0 / (1.0 + std::pow(fc / f, 2.0 * c.highpass_order));
        const double g = hp2 / std::pow(2.0 * std::numbers::pi * f, 4.0) * df;
        // cos(2πf·k·lag) by turning a unit vector k times (200 000 cosines took 3 ms a face).
        const double step = 2.0 * std::numbers::pi * f * kLagS;
        const double cs = std::cos(step), sn = std::sin(step);
        double re = 1.0, im = 0.0;
        for (int k = 0; k < lags; ++k) {
            shape[static_cast<std::size_t>(k)] += g * re;
            const double re1 = re * cs - im * sn;
            im = im * cs + re * sn;
            re = re1;
        }
    }
    out.lag_s = kLagS;
    for (int a = 0; a < 3; ++a) {
        out.acov_mm2[a] = shape;
        for (double& v : out.acov_mm2[a]) v *= density_si[a] * 1e6;  // m² → mm²
    }
    return out;
}

namespace {

// Double integration of a record with gaps (filled by straight lines), per world axis: what the
// fill got wrong changes the velocity and the position across each gap, an error that the
// high-pass spreads hundreds of milliseconds around it. Both are unknowns: the response to a
// constant and to a ramp over each gap (the same for every axis) is added with the weights that
// make the displacement smallest outside the gaps and the tapers (a vibration has no drift), by
// least squares; a tiny ridge keeps a gap no used sample sees from making it singular.
std::array<std::vector<double>, 3> integrate_across_gaps(
    const std::array<std::vector<double>, 3>& accel, double rate_hz,
    const std::vector<GridGap>& gaps, const CompensationConfig& c) {
    std::array<std::vector<double>, 3> u;
    for (int k = 0; k < 3; ++k) u[k] = integrate_twice(accel[k], rate_hz, c);
    const auto n = static_cast<Eigen::Index>(accel[0].size());
    // Each gap costs two integrations and the solve grows with their square: a record this
    // broken keeps its straight lines (its profiles are untrusted around every gap anyway).
    constexpr std::size_t kMaxBridgedGaps = 256;
    if (gaps.empty() || n == 0 || gaps.size() > kMaxBridgedGaps) return u;
    const auto m = static_cast<Eigen::Index>(2 * gaps.size());
    Eigen::MatrixXd B(n, m);
    for (std::size_t g = 0; g < gaps.size(); ++g) {
        std::vector<double> box(static_cast<std::size_t>(n), 0.0), ramp = box;
        const double mid = 0.5 * static_cast<double>(gaps[g].first + gaps[g].last);
        for (std::size_t i = gaps[g].first; i <= gaps[g].last && i < box.size(); ++i) {
            box[i] = 1.0;
            ramp[i] = static_cast<double>(i) - mid;
        }
        B.col(static_cast<Eigen::Index>(2 * g)) =
            Eigen::Map<const Eigen::VectorXd>(integrate_twice(box, rate_hz, c).data(), n);
        B.col(static_cast<Eigen::Index>(2 * g + 1)) =
            Eigen::Map<const Eigen::VectorXd>(integrate_twice(ramp, rate_hz, c).data(), n);
    }
    Eigen::VectorXd use = Eigen::VectorXd::Ones(n);
    const auto ends = std::min<Eigen::Index>(n / 2, static_cast<Eigen::Index>(c.taper_s * rate_hz));
    use.head(ends).setZero();
    use.tail(ends).setZero();
    for (const GridGap& g : gaps)
        for (auto i = static_cast<Eigen::Index>(g.first);
             i <= static_cast<Eigen::Index>(g.last) && i < n; ++i)
            use(i) = 0.0;
    Eigen::MatrixXd BtWB = B.transpose() * use.asDiagonal() * B;
    BtWB.diagonal().array() += kRidgeRel * (BtWB.trace() / static_cast<double>(m) + kRidgeFloor);
    const auto ldlt = BtWB.ldlt();
    for (int k = 0; k < 3; ++k) {
        Eigen::Map<Eigen::VectorXd> uk(u[k].data(), n);
        const Eigen::VectorXd w = ldlt.solve(-(B.transpose() * use.asDiagonal() * uk));
        if (w.allFinite()) uk += B * w;
    }
    return u;
}

// Only samples this close to the scan count: a record may be longer (or carry a stray far-off
// timestamp) and must not stretch the integration grid (docs/compensation.md "Per face", 1).
// compensate_face's warning says "10 s" in its text.
constexpr double kWindowMarginS = 10.0;
// Fewer usable samples than this and nothing is compensated: a floor under the median period
// and the integration, kept from the first version (d17be8d), not a measured limit.
constexpr std::size_t kMinUsableSamples = 16;
constexpr double kMmPerM = 1000.0;

// The accelerometer samples near the scan, with what was wrong with the others.
struct Samples {
    std::vector<double> t;  // s after the face's first profile, on the camera's clock
    std::vector<Eigen::Vector3d> a;
    std::vector<double> non_finite_at, clipped_at;  // left out: their times
    std::int64_t outside = 0;                       // more than kWindowMarginS from the scan
};

// Non-finite and clipped samples are left out (a clipped reading is the range, not the
// acceleration): the integration bridges them as gaps.
Samples usable_samples(const core::FaceScan& face, const CompensationConfig& c) {
    Samples out;
    const std::int64_t t_ref = face.profile_times_ns.front();
    // The integration window is the scan plus kWindowMarginS on each side.
    const double scan_end_s = seconds_between(face.profile_times_ns.back(), t_ref);
    for (std::int64_t j = 0; j < face.n_accel(); ++j) {
        const double t = seconds_between(face.accel_times_ns[j], t_ref) - c.clock_offset_s;
        if (t < -kWindowMarginS || t > scan_end_s + kWindowMarginS) {
            ++out.outside;
            continue;
        }
        const Eigen::Vector3d v = face.accel(j);
        if (!v.allFinite())
            out.non_finite_at.push_back(t);
        else if (v.cwiseAbs().maxCoeff() >= c.clip_mps2)
            out.clipped_at.push_back(t);
        else {
            out.t.push_back(t);
            out.a.push_back(v);
        }
    }
    return out;
}

// The usable record: its first and last sample (s after the face's first profile)
// and its nominal period.
struct RecordSpan {
    double t0_s, t1_s, period_s;
};

// The upper median of v (not empty), which it reorders.
double median_of(std::vector<double>& v) {
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
}

// Nominal period: the median interval (at least 2 samples).
double median_period(const Samples& smp) {
    std::vector<double> dt(smp.t.size() - 1);
    for (std::size_t j = 0; j + 1 < smp.t.size(); ++j) dt[j] = smp.t[j + 1] - smp.t[j];
    return median_of(dt);
}

// The usable record's span, or why there is none to integrate (then `rec` is not set).
struct RecordOrWhy {
    RecordSpan rec{};
    std::string unusable;
};

RecordOrWhy record_span(const core::FaceScan& face, const Samples& smp) {
    if (smp.t.size() < kMinUsableSamples)
        return {{},
                face.n_accel() == 0 ? "no accelerometer samples"
                                    : "too few usable accelerometer samples (" +
                                          std::to_string(smp.t.size()) + ")"};
    const RecordSpan rec{smp.t.front(), smp.t.back(), median_period(smp)};
    if (!(rec.period_s > 0)) return {{}, "accelerometer timestamps not increasing"};
    return {rec, ""};
}

// A time span where u cannot be trusted, and why.
struct Trouble {
    double t0, t1;
    std::string cause;
};

bool any_within(const std::vector<double>& times, double t0, double t1) {
    return std::any_of(times.begin(), times.end(), [&](double t) { return t >= t0 && t <= t1; });
}

// Intervals above gap_factor × period between usable samples, named by what left the samples
// out; lone bad samples inside shorter intervals are spans of their own.
std::vector<Trouble> find_trouble(const Samples& s, double period, const CompensationConfig& c) {
    std::vector<Trouble> out;
    for (std::size_t j = 0; j + 1 < s.t.size(); ++j) {
        const double t0 = s.t[j], t1 = s.t[j + 1];
        if (t1 - t0 <= c.gap_factor * period) continue;
        out.push_back({t0, t1,
                       any_within(s.non_finite_at, t0, t1) ? "non-finite accelerometer samples"
                       : any_within(s.clipped_at, t0, t1)  ? "clipped accelerometer samples"
                                                           : "accelerometer gap"});
    }
    auto lone = [&](const std::vector<double>& times, const char* cause) {
        for (double t : times)
            if (std::none_of(out.begin(), out.end(),
                             [t](const Trouble& b) { return t >= b.t0 && t <= b.t1; }))
                out.push_back({t, t, cause});
    };
    lone(s.non_finite_at, "non-finite accelerometer samples");
    lone(s.clipped_at, "clipped accelerometer samples");
    return out;
}

// The trouble as warnings: the number of gaps, of non-finite and of clipped samples.
std::vector<std::string> trouble_reasons(const Samples& s, const std::vector<Trouble>& trouble) {
    std::vector<std::string> out;
    const auto n_gaps =
        std::count_if(trouble.begin(), trouble.end(), [](const Trouble& b) { return b.t1 > b.t0; });
    if (n_gaps) out.push_back(std::to_string(n_gaps) + " gap(s) in the accelerometer record");
    if (!s.non_finite_at.empty())
        out.push_back(std::to_string(s.non_finite_at.size()) +
                      " non-finite accelerometer sample(s)");
    if (!s.clipped_at.empty())
        out.push_back(std::to_string(s.clipped_at.size()) + " clipped accelerometer sample(s)");
    return out;
}

// The world-frame acceleration on a uniform grid from s.t.front(), straight lines over gaps.
std::array<std::vector<double>, 3> to_grid(const Samples& s, const Eigen::Matrix3d& R_world_accel,
                                           double period) {
    const double t0 = s.t.front();
    const auto n = static_cast<std::size_t>(std::floor((s.t.back() - t0) / period)) + 1;
    std::array<std::vector<double>, 3> g;
    for (auto& axis : g) axis.resize(n);
    std::size_t j = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double t = t0 + static_cast<double>(i) * period;
        while (j + 2 < s.t.size() && s.t[j + 1] < t) ++j;
        const double f = std::clamp((t - s.t[j]) / (s.t[j + 1] - s.t[j]), 0.0, 1.0);
        const Eigen::Vector3d v = R_world_accel * ((1.0 - f) * s.a[j] + f * s.a[j + 1]);
        for (int k = 0; k < 3; ++k) g[k][i] = v[k];
    }
    return g;
}

// The grid points to_grid filled with straight lines where the trouble is (grid from t0 s, `n_grid`
// points): a gap's points strictly between its usable samples; a lone bad sample's nearest point,
// unless it is the grid's first or last.
std::vector<GridGap> grid_gaps(const std::vector<Trouble>& trouble, double t0, double period,
                               std::size_t n_grid) {
    std::vector<GridGap> out;
    for (const Trouble& b : trouble) {
        if (b.t1 <= b.t0) {  // a lone bad sample: the grid point it left to the straight line
            const long long i = std::llround((b.t0 - t0) / period);
            if (i > 0 && i + 1 < static_cast<long long>(n_grid))
                out.push_back({static_cast<std::size_t>(i), static_cast<std::size_t>(i)});
            continue;
        }
        const auto g0 = static_cast<std::size_t>(std::floor((b.t0 - t0) / period)) + 1;
        const auto g1 = static_cast<std::size_t>(std::ceil((b.t1 - t0) / period)) - 1;
        if (b.t1 > b.t0 && g1 >= g0) out.push_back({g0, g1});
    }
    return out;
}

// u at each profile's time (linear interpolation on the grid, m → mm: docs/compensation.md
// "Per face", 4); a profile outside the record stays uncompensated (0).
struct ProfileDisplacement {
    std::vector<Eigen::Vector3d> displacement_mm;
    double peak_mm = 0.0, rms_mm = 0.0;  // of |u| over the compensated profiles
    bool applied = false;                // some profile was compensated
};

ProfileDisplacement displacement_per_profile(const core::FaceScan& face,
                                             const std::array<std::vector<double>, 3>& u_m,
                                             const RecordSpan& rec) {
    ProfileDisplacement out;
    const std::int64_t np = face.n_profiles();
    out.displacement_mm.assign(np, Eigen::Vector3d::Zero());
    const std::size_t n = u_m[0].size();
    double sum2 = 0.0;
    std::int64_t n_applied = 0;
    for (std::int64_t k = 0; k < np; ++k) {
        const double t = seconds_between(face.profile_times_ns[k], face.profile_times_ns.front());
        if (t < rec.t0_s || t > rec.t1_s || n < 2) continue;  // no samples: leave uncompensated
        const double pos = (t - rec.t0_s) / rec.period_s;
        const auto i0 = std::min<std::size_t>(static_cast<std::size_t>(pos), n - 2);
        const double f = pos - static_cast<double>(i0);
        for (int a = 0; a < 3; ++a)
            out.displacement_mm[k][a] = kMmPerM * (u_m[a][i0] + f * (u_m[a][i0 + 1] - u_m[a][i0]));
        out.peak_mm = std::max(out.peak_mm, out.displacement_mm[k].norm());
        sum2 += out.displacement_mm[k].squaredNorm();
        ++n_applied;
    }
    out.applied = n_applied > 0;
    out.rms_mm = n_applied ? std::sqrt(sum2 / static_cast<double>(n_applied)) : 0.0;
    return out;
}

// The support plate per profile (CompensationConfig::plate_z): −median of the nominal world z of
// the samples that lie within plate_band_mm of z = 0 once `u` is applied; NaN with fewer than
// plate_min_points. `sigma_mm`: the median over the profiles of the median's standard error
// (1.2533 · 1.4826 · MAD / √n).
std::vector<double> plate_u_z(const core::FaceScan& face, const std::vector<Eigen::Vector3d>& u,
                              const CompensationConfig& c, double& sigma_mm) {
    const std::int64_t np = face.n_profiles();
    std::vector<double> out(static_cast<std::size_t>(np), std::numeric_limits<double>::quiet_NaN());
    sigma_mm = 0.0;
    if (face.profiles_mm.size() != static_cast<std::size_t>(np * face.width * 2) ||
        face.profile_positions_mm.size() != static_cast<std::size_t>(np))
        return out;  // times only (the pose's look at a record still growing)
    const Eigen::Matrix3d R = face.T_world_camera.linear();
    std::vector<double> z, dev, se;
    for (std::int64_t k = 0; k < np; ++k) {
        const double base = face.T_world_camera.translation().z() +
                            face.profile_positions_mm[k] * face.scan_direction.z();
        z.clear();
        for (std::int64_t i = 0; i < face.width; ++i) {
            const double wz = R(2, 0) * face.x(k, i) + R(2, 2) * face.z(k, i) + base;
            if (std::abs(wz + u[k].z()) <= c.plate_band_mm) z.push_back(wz);  // NaN: false
        }
        if (static_cast<int>(z.size()) < c.plate_min_points) continue;
        const double med = median_of(z);
        dev.clear();
        for (double v : z) dev.push_back(std::abs(v - med));
        se.push_back(1.2533 * 1.4826 * median_of(dev) / std::sqrt(static_cast<double>(z.size())));
        out[k] = -med;
    }
    sigma_mm = se.empty() ? 0.0 : median_of(se);
    return out;
}

std::string end_cause(const CompensationConfig& c) {
    return "accelerometer record does not cover it with " + fmt_s(c.min_margin_s) + " margins";
}

// A hole longer than max_bridge_s near the scan (within min_margin_s of it; times from the first
// profile, the scan lasting `scan_s`) cannot be bridged within the compensation's error budget:
// what the head did in it spoils the displacement far beyond the pad. Its reason, or nothing.
std::optional<std::string> too_long_to_bridge(const std::vector<Trouble>& trouble, double scan_s,
                                              double period, const CompensationConfig& c) {
    for (const Trouble& b : trouble)  // b.t0, b.t1: the usable samples on either side
        if (b.t1 - b.t0 - period > c.max_bridge_s && b.t1 > -c.min_margin_s &&
            b.t0 < scan_s + c.min_margin_s)
            return b.cause + " of " + std::to_string(std::lround((b.t1 - b.t0 - period) * 1000)) +
                   " ms at " + fmt_s(b.t0) + ": longer than the " + fmt_s(c.max_bridge_s) +
                   " that can be bridged";
    return std::nullopt;
}

// Which profiles the trouble (padded by degrade_pad_s) or the record's ends (min_margin_s)
// reach, as runs of one cause.
std::vector<core::UntrustedProfiles> untrusted_runs(const core::FaceScan& face,
                                                    const std::vector<Trouble>& trouble,
                                                    double rec_t0, double rec_t1,
                                                    const CompensationConfig& c) {
    const std::string ends = end_cause(c);
    std::vector<core::UntrustedProfiles> out;
    const std::int64_t t_ref = face.profile_times_ns.front();
    for (std::int64_t k = 0; k < face.n_profiles(); ++k) {
        const double t = seconds_between(face.profile_times_ns[k], t_ref);
        const std::string* cause = nullptr;
        for (const Trouble& b : trouble)
            if (t >= b.t0 - c.degrade_pad_s && t <= b.t1 + c.degrade_pad_s) cause = &b.cause;
        if (!cause && (t < rec_t0 + c.min_margin_s || t > rec_t1 - c.min_margin_s)) cause = &ends;
        if (!cause) continue;
        if (!out.empty() && out.back().last == k - 1 && out.back().cause == *cause) {
            out.back().last = k;
            out.back().t1_s = t;
        } else {
            out.push_back({k, k, t, t, *cause});
        }
    }
    return out;
}

// Nothing compensated yet: u zero and every profile trusted.
FaceCompensation uncompensated(const core::FaceScan& face) {
    FaceCompensation out;
    out.face = face.name;
    const std::int64_t np = face.n_profiles();
    out.displacement_mm.assign(np, Eigen::Vector3d::Zero());
    out.profile_degraded.assign(np, 0);
    return out;
}

// Every profile untrusted, for one reason.
void degrade_all(const core::FaceScan& face, const std::string& why, FaceCompensation& out) {
    const std::int64_t np = face.n_profiles();
    out.degraded = true;
    out.reasons.push_back(why);
    std::fill(out.profile_degraded.begin(), out.profile_degraded.end(), 1);
    out.n_degraded = np;
    out.untrusted = {{0, np - 1, 0.0,
                      seconds_between(face.profile_times_ns.back(), face.profile_times_ns.front()),
                      why}};
}

// The untrusted runs into the per-profile flags, with the record's ends as a reason once; then
// the too-long-hole rule (docs/compensation.md "Holes too long to bridge"): such a hole near the
// scan makes every profile untrusted.
void mark_untrusted(const core::FaceScan& face, const std::vector<Trouble>& trouble,
                    const RecordSpan& rec, const CompensationConfig& c, FaceCompensation& out) {
    out.untrusted = untrusted_runs(face, trouble, rec.t0_s, rec.t1_s, c);
    for (const auto& run : out.untrusted) {
        for (std::int64_t k = run.first; k <= run.last; ++k) out.profile_degraded[k] = 1;
        out.n_degraded += run.last - run.first + 1;
        const std::string why = "accelerometer record does not cover the scan with " +
                                fmt_s(c.min_margin_s) + " margins";
        if (run.cause == end_cause(c) &&
            std::find(out.reasons.begin(), out.reasons.end(), why) == out.reasons.end())
            out.reasons.push_back(why);
    }
    const double scan_s =
        seconds_between(face.profile_times_ns.back(), face.profile_times_ns.front());
    if (const auto why = too_long_to_bridge(trouble, scan_s, rec.period_s, c))
        degrade_all(face, *why, out);
}

}  // namespace

FaceCompensation compensate_face(const core::FaceScan& face, const CompensationConfig& c) {
    FaceCompensation out = uncompensated(face);
    if (face.n_profiles() == 0) return out;

    const Samples smp = usable_samples(face, c);
    if (smp.outside)  // the text names kWindowMarginS
        out.reasons.push_back(std::to_string(smp.outside) +
                              " accelerometer sample(s) more than 10 s from the scan ignored");
    const auto [rec, unusable] = record_span(face, smp);
    if (!unusable.empty()) {
        degrade_all(face, unusable, out);
        return out;
    }
    out.rate_hz = 1.0 / rec.period_s;
    const std::vector<Trouble> trouble = find_trouble(smp, rec.period_s, c);
    for (std::string& why : trouble_reasons(smp, trouble)) out.reasons.push_back(std::move(why));

    // The paper's rotation M (§4.1, step 2) on the acceleration rather than on the displacement:
    // constant during a scan, it commutes with the integration (linear, per axis).
    const auto grid =
        to_grid(smp, face.T_world_camera.linear() * face.R_camera_accel, rec.period_s);
    const auto gaps = grid_gaps(trouble, rec.t0_s, rec.period_s, grid[0].size());
    // §4.1 step 1, Eq. 5–7 per world axis (integrate_twice), the gaps bridged. Gravity and bias
    // are constant in the world during a scan: integrate_twice removes them with the mean.
    const auto u_m = integrate_across_gaps(grid, out.rate_hz, gaps, c);

    ProfileDisplacement d = displacement_per_profile(face, u_m, rec);
    // Only a sensor above the plate sees its top: from below, the part's end face lies at
    // z = 0 as well.
    if (c.plate_z && face.T_world_camera.translation().z() > 0.0) {
        const auto uz = plate_u_z(face, d.displacement_mm, c, out.plate_sigma_mm);
        for (std::size_t k = 0; k < uz.size(); ++k)
            if (std::isfinite(uz[k])) {
                d.displacement_mm[k].z() = uz[k];
                ++out.plate_profiles;
            }
    }
    out.displacement_mm = std::move(d.displacement_mm);
    out.applied = d.applied;
    out.peak_mm = d.peak_mm;
    out.rms_mm = d.rms_mm;
    mark_untrusted(face, trouble, rec, c, out);
    out.degraded = out.n_degraded > 0;
    if (out.degraded && out.reasons.empty()) out.reasons.push_back("degraded profiles");
    return out;
}

CompensationError compensation_error(const core::FaceScan& face, const CompensationConfig& c) {
    CompensationError out;
    if (face.n_profiles() == 0) return out;
    const Samples smp = usable_samples(face, c);
    if (smp.t.size() < kMinUsableSamples) return out;
    const double period = median_period(smp);
    if (!(period > 0)) return out;
    // The samples as they came, not the grid: interpolating between jittered timestamps damps
    // the top band (a 1.6 % jitter on the independent recordings). Segments stop at the gaps.
    const Eigen::Matrix3d R_world_accel = face.T_world_camera.linear() * face.R_camera_accel;
    std::array<std::vector<double>, 3> raw;
    std::vector<std::size_t> breaks;
    for (std::size_t j = 0; j < smp.a.size(); ++j) {
        const Eigen::Vector3d v = R_world_accel * smp.a[j];
        for (int k = 0; k < 3; ++k) raw[k].push_back(v[k]);
        if (j + 1 < smp.t.size() && smp.t[j + 1] - smp.t[j] > c.gap_factor * period)
            breaks.push_back(j);
    }
    const auto density = accel_noise_density(raw, 1.0 / period, breaks);
    if (!(density[0] > 0)) return out;  // too little record: not known
    for (int a = 0; a < 3; ++a) out.accel_noise_ug[a] = std::sqrt(density[a]) / kG * 1e6;
    out.noise = displacement_noise(density, c);
    for (const Trouble& b : find_trouble(smp, period, c)) out.noise.holes_s.push_back({b.t0, b.t1});
    out.noise.hole_sigma_mm = c.hole_sigma_mm;
    return out;
}

}  // namespace hotgauge::compensate
