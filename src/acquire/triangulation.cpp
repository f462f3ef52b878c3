// Triangulation models (docs/acquisition.md "Triangulation"): the paper's direct-beam law (§2,
// Eq. 1–2) extended to the image plane, and a calibrated per-column rational model with its
// least-squares fitter.
#include "hotgauge/acquire/triangulation.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <string>

namespace hotgauge::acquire {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kDeg = std::numbers::pi / 180.0;

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return buf;
}

bool in_field(double coord, int size) { return coord >= -0.5 && coord <= size - 0.5; }

// Calibrated model, one column: z(t) = P(t) / (1 + q·t) and dz/dt.
struct ColumnValue {
    double z, dz_dt;
};
ColumnValue column_z(const double* coef, int degree, double t) {
    double p = coef[degree], dp = 0.0;
    for (int j = degree - 1; j >= 0; --j) {
        dp = dp * t + p;
        p = p * t + coef[j];
    }
    const double q = coef[degree + 1], den = 1.0 + q * t;
    return {p / den, (dp * den - p * q) / (den * den)};
}

double row_mid(int height) { return 0.5 * (height - 1); }

// z and dz/dt at fractional column u (clamped to the outer columns' centres), linear between
// the two neighbouring columns.
ColumnValue calibrated_z(const CalibratedModel& m, double u, double t) {
    const int stride = m.degree + 2;
    if (m.width_px == 1) return column_z(m.coefficients.data(), m.degree, t);
    const double uc = std::clamp(u, 0.0, m.width_px - 1.0);
    const int c0 = std::min(static_cast<int>(uc), m.width_px - 2);
    const double f = uc - c0;
    const ColumnValue a = column_z(m.coefficients.data() + c0 * stride, m.degree, t);
    const ColumnValue b = column_z(m.coefficients.data() + (c0 + 1) * stride, m.degree, t);
    return {(1.0 - f) * a.z + f * b.z, (1.0 - f) * a.dz_dt + f * b.dz_dt};
}

// x/z of column c at t by its own law (x_degree > 0).
double column_slope(const CalibratedModel& m, int c, double t) {
    const double* s = m.x_coefficients.data() + c * (m.x_degree + 1);
    double v = s[m.x_degree];
    for (int j = m.x_degree - 1; j >= 0; --j) v = v * t + s[j];
    return v;
}
// x/z at fractional column u, t: the fan's (x_degree 0), or the columns' laws linear between
// columns and, beyond the outer columns' centres (to the field's half pixel), from the outer pair.
double calibrated_slope(const CalibratedModel& m, double u, double t) {
    if (m.x_degree == 0) return (u - m.u0_px) * m.x_pitch_mm / m.reference_range_mm;
    if (m.width_px == 1) return column_slope(m, 0, t);
    const int c0 = std::clamp(static_cast<int>(std::floor(u)), 0, m.width_px - 2);
    const double f = u - c0;
    return (1.0 - f) * column_slope(m, c0, t) + f * column_slope(m, c0 + 1, t);
}

// The column whose x/z at t is `slope` (x/z grows with the column, checked at construction),
// extrapolated beyond the outer columns (the caller checks the field). Exact: the slope is
// linear between column centres.
double column_for_slope(const CalibratedModel& m, double t, double slope) {
    if (m.x_degree == 0) return m.u0_px + slope * m.reference_range_mm / m.x_pitch_mm;
    if (m.width_px == 1) return 0.0;
    int lo = 0, hi = m.width_px - 1;
    const double s_lo = column_slope(m, lo, t), s_hi = column_slope(m, hi, t);
    // Outside the column centres: extrapolated from the outer pair, to the field's half pixel.
    if (slope <= s_lo || slope >= s_hi) {
        const int c = slope <= s_lo ? 0 : m.width_px - 2;
        const double a = column_slope(m, c, t), b = column_slope(m, c + 1, t);
        return c + (slope - a) / (b - a);
    }
    while (hi - lo > 1) {
        const int mid = (lo + hi) / 2;
        (column_slope(m, mid, t) <= slope ? lo : hi) = mid;
    }
    const double a = column_slope(m, lo, t), b = column_slope(m, hi, t);
    return lo + (slope - a) / (b - a);
}

// The t where column u's z is z_mm (z(u, ·) is monotonic over the field, checked at
// construction): safeguarded Newton; NaN when the field does not reach z_mm.
double t_for_z(const CalibratedModel& m, double u, double z_mm) {
    const double mid = row_mid(m.height_px);
    double lo = -0.5 / mid - 1.0, hi = 1.0 + 0.5 / mid;
    const double g_lo = calibrated_z(m, u, lo).z - z_mm, g_hi = calibrated_z(m, u, hi).z - z_mm;
    if (g_lo == 0.0) return lo;
    if (g_hi == 0.0) return hi;
    if ((g_lo > 0.0) == (g_hi > 0.0)) return kNaN;
    const bool rising = g_hi > 0.0;
    double t = lo + (hi - lo) * g_lo / (g_lo - g_hi);
    for (int iteration = 0; iteration < 100; ++iteration) {
        const ColumnValue f = calibrated_z(m, u, t);
        const double g = f.z - z_mm;
        if (g == 0.0) break;
        if ((g > 0.0) == rising)
            hi = t;
        else
            lo = t;
        double next = t - g / f.dz_dt;
        if (!(next >= lo && next <= hi)) next = 0.5 * (lo + hi);  // Newton left the bracket
        const bool done = std::abs(next - t) < 1e-14;
        t = next;
        if (done) break;
    }
    return t;
}

// The per-column x law: sizes, finite, and x/z growing with the column at every 4th row and the
// field's edges (to_image's column search needs it).
core::Result<void> check_x_law(const CalibratedModel& m) {
    if (m.x_degree < 0 || m.x_degree > 5)
        return core::make_error("x_degree must be in [0, 5], got " + std::to_string(m.x_degree));
    const std::size_t need =
        m.x_degree == 0 ? 0 : static_cast<std::size_t>(m.width_px) * (m.x_degree + 1);
    if (m.x_coefficients.size() != need)
        return core::make_error("x_coefficients: " + std::to_string(need) + " expected (" +
                                std::to_string(m.width_px) + " columns × x_degree + 1), got " +
                                std::to_string(m.x_coefficients.size()));
    for (double c : m.x_coefficients)
        if (!std::isfinite(c)) return core::make_error("x_coefficients must be finite");
    const double mid = row_mid(m.height_px);
    for (int v = 0; m.x_degree > 0 && v <= m.height_px + 3; v += 4) {
        const double row = std::min(v - 0.5, m.height_px - 0.5), t = (row - mid) / mid;
        for (int c = 1; c < m.width_px; ++c)
            if (!(column_slope(m, c, t) > column_slope(m, c - 1, t)))
                return core::make_error("x_coefficients: x/z does not grow from column " +
                                        std::to_string(c - 1) + " to " + std::to_string(c) +
                                        " at row " + num(row));
    }
    return {};
}

// Per column, x = z·(s0 + … + sm·tᵐ) by least squares on x; the RMS of x over all samples.
core::Result<double> fit_x_law(std::span<const CalibrationSample> samples,
                               const std::vector<std::vector<std::size_t>>& by_column, int degree,
                               CalibratedModel& m) {
    const double mid = row_mid(m.height_px);
    m.x_degree = degree;
    m.x_coefficients.assign(static_cast<std::size_t>(m.width_px) * (degree + 1), 0.0);
    double sum_sq = 0.0;
    for (int c = 0; c < m.width_px; ++c) {
        const auto& idx = by_column[static_cast<std::size_t>(c)];
        const auto n = static_cast<Eigen::Index>(idx.size());
        Eigen::MatrixXd a(n, degree + 1);
        Eigen::VectorXd b(n);
        for (Eigen::Index k = 0; k < n; ++k) {
            const CalibrationSample& s = samples[idx[static_cast<std::size_t>(k)]];
            const double t = (s.v_px - mid) / mid;
            double power = s.z_mm;
            for (int j = 0; j <= degree; ++j, power *= t) a(k, j) = power;
            b[k] = s.x_mm;
        }
        const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
        if (qr.rank() < degree + 1)
            return core::make_error("column " + std::to_string(c) +
                                    ": samples do not determine its x law (rank " +
                                    std::to_string(qr.rank()) + ")");
        const Eigen::VectorXd sol = qr.solve(b);
        std::copy(sol.data(), sol.data() + degree + 1,
                  m.x_coefficients.data() + static_cast<std::size_t>(c) * (degree + 1));
        sum_sq += (a * sol - b).squaredNorm();
    }
    return std::sqrt(sum_sq / static_cast<double>(samples.size()));
}

core::Error direct_error(const std::string& what) {
    return core::make_error("direct-beam triangulation: " + what);
}

core::Error fit_error(const std::string& what) {
    return core::make_error("calibration fit: " + what);
}

// The samples' indices grouped by their nearest column; every sample finite and in the field.
core::Result<std::vector<std::vector<std::size_t>>> samples_by_column(
    std::span<const CalibrationSample> samples, const CalibrationOptions& options) {
    const int width = options.width_px;
    std::vector<std::vector<std::size_t>> by_column(static_cast<std::size_t>(width));
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const CalibrationSample& s = samples[i];
        if (!std::isfinite(s.x_mm) || !(s.z_mm > 0.0) || !in_field(s.u_px, width) ||
            !in_field(s.v_px, options.height_px))
            return fit_error("sample " + std::to_string(i) + " (u " + num(s.u_px) + ", v " +
                             num(s.v_px) + ", x " + num(s.x_mm) + ", z " + num(s.z_mm) +
                             ") is outside the field or not finite");
        by_column[static_cast<std::size_t>(std::lround(std::clamp(s.u_px, 0.0, width - 1.0)))]
            .push_back(i);
    }
    return by_column;
}

// Column c's law z(t) = P(t) / (1 + q·t) from its samples `idx`, into coef (degree + 2 values:
// P's, then q).
core::Result<void> fit_column_z(std::span<const CalibrationSample> samples,
                                const std::vector<std::size_t>& idx, int c, int degree, double mid,
                                double* coef) {
    const int stride = degree + 2;
    std::vector<double> rows;
    for (std::size_t i : idx) rows.push_back(samples[i].v_px);
    std::sort(rows.begin(), rows.end());
    const auto distinct = std::unique(rows.begin(), rows.end()) - rows.begin();
    if (distinct < stride)
        return fit_error("column " + std::to_string(c) + " has samples at " +
                         std::to_string(distinct) + " distinct rows; degree " +
                         std::to_string(degree) + " needs " + std::to_string(stride));
    // z·(1 + q·t) = P(t) is linear in (p, q); dividing each equation by the previous
    // (1 + q·t) makes it a z residual (Sanathanan–Koerner), exact after one pass on clean data.
    const auto n = static_cast<Eigen::Index>(idx.size());
    Eigen::MatrixXd a(n, stride);
    Eigen::VectorXd b(n), weight = Eigen::VectorXd::Ones(n), sol;
    for (int pass = 0; pass < 3; ++pass) {
        for (Eigen::Index k = 0; k < n; ++k) {
            const CalibrationSample& s = samples[idx[static_cast<std::size_t>(k)]];
            const double t = (s.v_px - mid) / mid;
            double power = 1.0;
            for (int j = 0; j <= degree; ++j) {
                a(k, j) = power * weight[k];
                power *= t;
            }
            a(k, degree + 1) = -t * s.z_mm * weight[k];
            b[k] = s.z_mm * weight[k];
        }
        const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
        if (qr.rank() < stride)
            return fit_error("column " + std::to_string(c) +
                             ": samples do not determine the model (rank " +
                             std::to_string(qr.rank()) + ")");
        sol = qr.solve(b);
        for (Eigen::Index k = 0; k < n; ++k) {
            const CalibrationSample& s = samples[idx[static_cast<std::size_t>(k)]];
            const double den = 1.0 + sol[degree + 1] * (s.v_px - mid) / mid;
            weight[k] = den > 1e-3 ? 1.0 / den : 1.0;
        }
    }
    std::copy(sol.data(), sol.data() + stride, coef);
    return {};
}

// The fan: x = k·(u − u0)·z, linear in (k, k·u0) with regressors (u·z, −z). Sets m.x_pitch_mm
// and m.u0_px; the RMS of x over all samples.
core::Result<double> fit_fan(std::span<const CalibrationSample> samples, double reference_range_mm,
                             CalibratedModel& m) {
    Eigen::MatrixXd ax(static_cast<Eigen::Index>(samples.size()), 2);
    Eigen::VectorXd bx(ax.rows());
    for (std::size_t i = 0; i < samples.size(); ++i) {
        const auto k = static_cast<Eigen::Index>(i);
        ax(k, 0) = samples[i].u_px * samples[i].z_mm;
        ax(k, 1) = -samples[i].z_mm;
        bx[k] = samples[i].x_mm;
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(ax);
    const Eigen::Vector2d fan =
        qr.rank() == 2 ? Eigen::Vector2d(qr.solve(bx)) : Eigen::Vector2d(0, 0);
    if (!(fan[0] > 0.0))
        return fit_error(
            "the samples' x do not determine the laser fan (need samples in several "
            "columns with x growing with the column)");
    m.x_pitch_mm = fan[0] * reference_range_mm;
    m.u0_px = fan[1] / fan[0];
    return std::sqrt((ax * fan - bx).squaredNorm() / static_cast<double>(samples.size()));
}

}  // namespace

core::Result<Triangulation> Triangulation::direct_beam(const DirectBeamParams& p) {
    const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
    if (!positive(p.a0_mm)) return direct_error("a0_mm must be > 0, got " + num(p.a0_mm));
    if (!positive(p.b0_mm)) return direct_error("b0_mm must be > 0, got " + num(p.b0_mm));
    if (!(p.alpha_deg > 0.0 && p.alpha_deg < 90.0))
        return direct_error("alpha_deg must be in (0, 90), got " + num(p.alpha_deg));
    if (!(p.beta_deg > 0.0 && p.beta_deg < 180.0))
        return direct_error("beta_deg must be in (0, 180), got " + num(p.beta_deg));
    if (!positive(p.pixel_size_mm))
        return direct_error("pixel_size_mm must be > 0, got " + num(p.pixel_size_mm));
    if (!positive(p.x_pitch_mm))
        return direct_error("x_pitch_mm must be > 0, got " + num(p.x_pitch_mm));
    if (!positive(p.reference_range_mm))
        return direct_error("reference_range_mm must be > 0, got " + num(p.reference_range_mm));
    if (!std::isfinite(p.u0_px)) return direct_error("u0_px must be finite");
    if (!std::isfinite(p.v0_px)) return direct_error("v0_px must be finite");
    if (p.width_px < 1 || p.height_px < 2)
        return direct_error("width_px ≥ 1 and height_px ≥ 2 needed, got " +
                            std::to_string(p.width_px) + " × " + std::to_string(p.height_px));

    // Eq. 1, a0·tanα = b0·tanβ: the laser line, the lens plane and the imager plane meet in one
    // line, so every range is in focus. Within 1 % (rounded values); a0 and b0 swapped or
    // tanβ = (b0/a0)·tanα instead would be off by a factor (a0/b0)².
    const double alpha = p.alpha_deg * kDeg, beta = p.beta_deg * kDeg;
    const double lhs = p.a0_mm * std::tan(alpha), rhs = p.b0_mm * std::tan(beta);
    if (!(std::abs(lhs - rhs) <= 0.01 * lhs)) {
        const double beta_eq1 = std::atan2(p.a0_mm * std::tan(alpha), p.b0_mm) / kDeg;
        return direct_error("beta_deg " + num(p.beta_deg) +
                            " violates the Scheimpflug condition a0·tan(alpha) = b0·tan(beta) "
                            "(paper Eq. 1), which gives beta_deg " +
                            num(beta_eq1) + " for these a0_mm, b0_mm, alpha_deg");
    }
    DirectBeam d{p, std::sin(alpha), std::sin(beta), std::sin(alpha + beta)};

    // The field's rows must stay before Eq. 2's pole (infinite range where
    // b0·sinα = x·sin(α + β)) and image points in front of the camera.
    const double x_far = (p.height_px - 0.5 - p.v0_px) * p.pixel_size_mm;
    if (!(p.b0_mm * d.sin_a - x_far * d.sin_ab > 1e-9 * p.b0_mm)) {
        const double pole = p.v0_px + p.b0_mm * d.sin_a / d.sin_ab / p.pixel_size_mm;
        return direct_error("rows up to " + num(p.height_px - 0.5) +
                            " reach the pole of Eq. 2 (infinite range) at row " + num(pole) +
                            ": no valid range; check v0_px, pixel_size_mm, b0_mm, alpha_deg, "
                            "beta_deg");
    }
    const double x_near = (-0.5 - p.v0_px) * p.pixel_size_mm;
    const double z_near =
        p.reference_range_mm + p.a0_mm * x_near * d.sin_b / (p.b0_mm * d.sin_a - x_near * d.sin_ab);
    if (!(z_near > 0.0))
        return direct_error("row -0.5 images a range of " + num(z_near) +
                            " mm, behind the camera: no valid range; check reference_range_mm, "
                            "v0_px, a0_mm");
    return Triangulation(d, p.width_px, p.height_px);
}

core::Result<Triangulation> Triangulation::calibrated(CalibratedModel m) {
    const auto fail = [](const std::string& what) {
        return core::make_error("calibrated triangulation: " + what);
    };
    if (m.width_px < 1 || m.height_px < 2)
        return fail("width_px ≥ 1 and height_px ≥ 2 needed, got " + std::to_string(m.width_px) +
                    " × " + std::to_string(m.height_px));
    if (m.degree < 1 || m.degree > 5)
        return fail("degree must be in [1, 5], got " + std::to_string(m.degree));
    const int stride = m.degree + 2;
    if (m.coefficients.size() != static_cast<std::size_t>(m.width_px) * stride)
        return fail("coefficients: " + std::to_string(m.width_px) + " columns × " +
                    std::to_string(stride) + " expected, got " +
                    std::to_string(m.coefficients.size()));
    if (!(std::isfinite(m.x_pitch_mm) && m.x_pitch_mm > 0.0))
        return fail("x_pitch_mm must be > 0, got " + num(m.x_pitch_mm));
    if (!(std::isfinite(m.reference_range_mm) && m.reference_range_mm > 0.0))
        return fail("reference_range_mm must be > 0, got " + num(m.reference_range_mm));
    if (!std::isfinite(m.u0_px)) return fail("u0_px must be finite");
    for (double c : m.coefficients)
        if (!std::isfinite(c)) return fail("coefficients must be finite");

    // Each column: denominator positive and z positive and strictly monotonic over the field
    // (checked at every row and the field's edges), all in the same direction: the inverse
    // brackets v, and interpolation between columns must not fold.
    const double mid = row_mid(m.height_px);
    int direction = 0;
    for (int c = 0; c < m.width_px; ++c) {
        const double* coef = m.coefficients.data() + c * stride;
        const double q = coef[m.degree + 1], t_edge = (m.height_px - 0.5 - mid) / mid;
        if (!(1.0 + q * t_edge > 1e-3 && 1.0 - q * t_edge > 1e-3))
            return fail("column " + std::to_string(c) +
                        ": the denominator 1 + q·t vanishes in "
                        "the field (q = " +
                        num(q) + ")");
        double previous = kNaN, previous_v = kNaN;
        for (int i = -1; i <= m.height_px; ++i) {
            const double v = std::clamp(static_cast<double>(i), -0.5, m.height_px - 0.5);
            const double z = column_z(coef, m.degree, (v - mid) / mid).z;
            if (!(z > 0.0))
                return fail("column " + std::to_string(c) + ": z = " + num(z) + " mm at row " +
                            num(v) + " (in front of the camera expected)");
            if (i > -1) {
                const int dir = z > previous ? 1 : (z < previous ? -1 : 0);
                if (dir == 0 || (direction != 0 && dir != direction))
                    return fail("column " + std::to_string(c) +
                                ": z is not strictly monotonic in the row (" + num(previous) +
                                " mm at row " + num(previous_v) + ", " + num(z) + " mm at row " +
                                num(v) + ")");
                direction = dir;
            }
            previous = z;
            previous_v = v;
        }
    }
    if (auto ok = check_x_law(m); !ok) return fail(ok.error().message);
    const int width = m.width_px, height = m.height_px;
    return Triangulation(std::move(m), width, height);
}

ProfilePoint Triangulation::to_camera(double u_px, double v_px) const {
    if (!in_field(u_px, width_) || !in_field(v_px, height_)) return {kNaN, kNaN};
    if (const auto* d = std::get_if<DirectBeam>(&model_)) {
        const DirectBeamParams& p = d->p;
        const double x_img = (v_px - p.v0_px) * p.pixel_size_mm;  // Eq. 2's x
        const double y = p.a0_mm * x_img * d->sin_b / (p.b0_mm * d->sin_a - x_img * d->sin_ab);
        const double z = p.reference_range_mm + y;
        return {(u_px - p.u0_px) * p.x_pitch_mm * z / p.reference_range_mm, z};
    }
    const auto& m = std::get<CalibratedModel>(model_);
    const double mid = row_mid(m.height_px), t = (v_px - mid) / mid;
    const double z = calibrated_z(m, u_px, t).z;
    return {z * calibrated_slope(m, u_px, t), z};
}

void Triangulation::to_camera(std::span<const StripePoint> profile, double column_offset_px,
                              double row_offset_px, float* out) const {
    constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();
    const auto* d = std::get_if<DirectBeam>(&model_);
    if (!d) {
        for (std::size_t i = 0; i < profile.size(); ++i, out += 2) {
            const bool ok = profile[i].status == StripeStatus::kOk;
            const ProfilePoint p = ok ? to_camera(static_cast<double>(i) + column_offset_px,
                                                  profile[i].row + row_offset_px)
                                      : ProfilePoint{kNaN, kNaN};
            out[0] = static_cast<float>(p.x_mm);
            out[1] = static_cast<float>(p.z_mm);
        }
        return;
    }
    // Eq. 2 with its constants hoisted: z = ref + k1·x / (k2 − k3·x), x = (v − v0)·pixel.
    const DirectBeamParams& p = d->p;
    const double k1 = p.a0_mm * d->sin_b, k2 = p.b0_mm * d->sin_a, k3 = d->sin_ab;
    const double x_per_z = p.x_pitch_mm / p.reference_range_mm;
    const double v_lo = -0.5, v_hi = height_ - 0.5, u_hi = width_ - 0.5;
    for (std::size_t i = 0; i < profile.size(); ++i, out += 2) {
        const double u = static_cast<double>(i) + column_offset_px;
        const double v = static_cast<double>(profile[i].row) + row_offset_px;
        if (profile[i].status != StripeStatus::kOk || !(v >= v_lo && v <= v_hi) || u < -0.5 ||
            u > u_hi) {
            out[0] = out[1] = kNaNf;
            continue;
        }
        const double x_img = (v - p.v0_px) * p.pixel_size_mm;
        const double z = p.reference_range_mm + k1 * x_img / (k2 - x_img * k3);
        out[0] = static_cast<float>((u - p.u0_px) * x_per_z * z);
        out[1] = static_cast<float>(z);
    }
}

ImagePoint Triangulation::to_image(double x_mm, double z_mm) const {
    constexpr ImagePoint kNone{kNaN, kNaN};
    if (!(z_mm > 0.0) || !std::isfinite(x_mm)) return kNone;
    if (const auto* d = std::get_if<DirectBeam>(&model_)) {
        const DirectBeamParams& p = d->p;
        // Eq. 2 solved for x: x = b0·y·sinα / (a0·sinβ + y·sin(α + β)).
        const double y = z_mm - p.reference_range_mm;
        const double den = p.a0_mm * d->sin_b + y * d->sin_ab;
        if (!(den > 0.0)) return kNone;
        const double v = p.v0_px + p.b0_mm * y * d->sin_a / den / p.pixel_size_mm;
        const double u = p.u0_px + x_mm * p.reference_range_mm / (p.x_pitch_mm * z_mm);
        if (!in_field(u, p.width_px) || !in_field(v, p.height_px)) return kNone;
        return {u, v};
    }
    const auto& m = std::get<CalibratedModel>(model_);
    // u from x/z, t from z in that column; with a per-column x law each depends on the other:
    // alternate until u settles (their coupling is the lens's distortion, small).
    const double slope = x_mm / z_mm, mid = row_mid(m.height_px);
    double u = column_for_slope(m, 0.0, slope), t = kNaN;
    for (int iteration = 0; iteration < 50; ++iteration) {
        t = t_for_z(m, std::clamp(u, -0.5, m.width_px - 0.5), z_mm);
        if (!std::isfinite(t) || m.x_degree == 0) break;
        const double next = column_for_slope(m, t, slope);
        const bool done = std::abs(next - u) < 1e-10;
        u = next;
        if (done) break;
    }
    if (!std::isfinite(t) || !in_field(u, m.width_px)) return kNone;
    return {u, mid + t * mid};
}

void triangulate(const Triangulation& triangulation, std::span<const StripePoint> profile,
                 std::vector<float>& profiles_mm, double column_offset_px, double row_offset_px) {
    // Grow geometrically: an exact reserve per profile would copy the whole scan every time.
    const std::size_t first = profiles_mm.size();
    if (profiles_mm.capacity() < first + 2 * profile.size())
        profiles_mm.reserve(std::max(2 * profiles_mm.capacity(), first + 2 * profile.size()));
    profiles_mm.resize(first + 2 * profile.size());
    triangulation.to_camera(profile, column_offset_px, row_offset_px, profiles_mm.data() + first);
}

core::Result<CalibrationFit> fit_calibrated_model(std::span<const CalibrationSample> samples,
                                                  const CalibrationOptions& options) {
    if (options.width_px < 1 || options.height_px < 2)
        return fit_error("width_px ≥ 1 and height_px ≥ 2 needed");
    if (options.degree < 1 || options.degree > 5)
        return fit_error("degree must be in [1, 5], got " + std::to_string(options.degree));
    if (!(options.reference_range_mm > 0.0))
        return fit_error("reference_range_mm must be > 0, got " + num(options.reference_range_mm));
    if (options.x_degree < 0 || options.x_degree > 5)
        return fit_error("x_degree must be in [0, 5], got " + std::to_string(options.x_degree));
    const int width = options.width_px, degree = options.degree, stride = degree + 2;
    const double mid = row_mid(options.height_px);
    const auto by_column = samples_by_column(samples, options);
    if (!by_column) return by_column.error();

    CalibrationFit fit;
    CalibratedModel& m = fit.model;
    m.width_px = width;
    m.height_px = options.height_px;
    m.degree = degree;
    m.reference_range_mm = options.reference_range_mm;
    m.coefficients.resize(static_cast<std::size_t>(width) * stride);
    double sum_sq = 0.0;
    for (int c = 0; c < width; ++c) {
        const auto& idx = (*by_column)[static_cast<std::size_t>(c)];
        double* coef = m.coefficients.data() + c * stride;
        if (auto ok = fit_column_z(samples, idx, c, degree, mid, coef); !ok) return ok.error();
        for (std::size_t i : idx) {
            const double r =
                column_z(coef, degree, (samples[i].v_px - mid) / mid).z - samples[i].z_mm;
            sum_sq += r * r;
            fit.max_abs_z_mm = std::max(fit.max_abs_z_mm, std::abs(r));
        }
    }
    fit.rms_z_mm = std::sqrt(sum_sq / static_cast<double>(samples.size()));

    auto rms_x = fit_fan(samples, options.reference_range_mm, m);
    if (!rms_x) return rms_x.error();
    fit.rms_x_mm = *rms_x;
    if (options.x_degree > 0) {
        auto rms = fit_x_law(samples, *by_column, options.x_degree, m);
        if (!rms) return fit_error(rms.error().message);
        fit.rms_x_mm = *rms;
    }

    auto check = Triangulation::calibrated(m);
    if (!check) return fit_error(check.error().message);
    return fit;
}

core::Result<DirectBeamParams> design_direct_beam(const DirectBeamDesign& d) {
    const auto fail = [](const std::string& what) {
        return core::make_error("direct-beam design: " + what);
    };
    if (!(d.min_range_mm > 0.0 && d.min_range_mm < d.standoff_mm &&
          d.standoff_mm < d.max_range_mm && std::isfinite(d.max_range_mm)))
        return fail("0 < min_range_mm < standoff_mm < max_range_mm needed, got " +
                    num(d.min_range_mm) + ", " + num(d.standoff_mm) + ", " + num(d.max_range_mm));
    if (!(d.baseline_mm > 0.0)) return fail("baseline_mm must be > 0, got " + num(d.baseline_mm));
    if (!(d.pitch_mm > 0.0)) return fail("pitch_mm must be > 0, got " + num(d.pitch_mm));
    if (!(d.pixel_size_mm > 0.0))
        return fail("pixel_size_mm must be > 0, got " + num(d.pixel_size_mm));
    if (d.width < 1 || d.height_px < 2) return fail("width_px ≥ 1 and height_px ≥ 2 needed");

    // The lens sits baseline_mm beside the laser and looks at the reference spot.
    const double a0 = std::hypot(d.baseline_mm, d.standoff_mm);
    const double alpha = std::atan2(d.baseline_mm, d.standoff_mm);
    const double y_near = d.min_range_mm - d.standoff_mm, y_far = d.max_range_mm - d.standoff_mm;
    const double rows_mm = (d.height_px - 1) * d.pixel_size_mm;
    // For a lens distance b0, β from Eq. 1 and the image shift of a range shift y from Eq. 2.
    struct Image {
        bool valid;
        double near, far, beta;
    };
    const auto image = [&](double b0) {
        const double beta = std::atan2(a0 * std::tan(alpha), b0);
        const double sa = std::sin(alpha), sb = std::sin(beta), sab = std::sin(alpha + beta);
        const double den_near = a0 * sb + y_near * sab, den_far = a0 * sb + y_far * sab;
        return Image{den_near > 0.0 && den_far > 0.0, b0 * y_near * sa / den_near,
                     b0 * y_far * sa / den_far, beta};
    };
    // The imaged span grows with b0 (magnification); bisect for the imager's rows, b0 < a0.
    double lo = 1e-9 * a0, hi = a0;
    for (int i = 0; i < 200; ++i) {
        const double b0 = 0.5 * (lo + hi);
        const Image im = image(b0);
        if (!im.valid || im.far - im.near > rows_mm)
            hi = b0;
        else
            lo = b0;
    }
    const Image im = image(lo);
    if (!im.valid || std::abs(im.far - im.near - rows_mm) > 1e-9 * rows_mm)
        return fail("no lens distance b0 < a0 images the range onto " +
                    std::to_string(d.height_px) + " rows of " + num(d.pixel_size_mm) + " mm");
    DirectBeamParams p;
    p.a0_mm = a0;
    p.b0_mm = lo;
    p.alpha_deg = alpha / kDeg;
    p.beta_deg = im.beta / kDeg;
    p.pixel_size_mm = d.pixel_size_mm;
    p.v0_px = -im.near / d.pixel_size_mm;  // row 0 sees min_range_mm
    p.u0_px = 0.5 * (d.width - 1);         // ray i of the simulator is column i
    p.x_pitch_mm = d.pitch_mm;
    p.reference_range_mm = d.standoff_mm;
    p.width_px = d.width;
    p.height_px = d.height_px;
    auto check = Triangulation::direct_beam(p);
    if (!check) return fail(check.error().message);
    return p;
}

}  // namespace hotgauge::acquire
