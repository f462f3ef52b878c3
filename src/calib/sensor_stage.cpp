#include "hotgauge/calib/sensor_stage.hpp"

#include <Eigen/QR>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

namespace hotgauge::calib {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// A reading's stripe needs this many usable columns (not measured).
constexpr int kMinLitColumns = 16;
// Level plates' placeholder x = kPlaceholderPitch·u·height: any x that grows with the column will
// do, only the range law is used from that fit (not measured).
constexpr double kPlaceholderPitch = 1e-3;

// The stripe of every reading: per column its row, and what the stage says of the point.
struct Stripe {
    std::vector<double> rows;
    double height_mm, tan_tilt;
};

core::Result<std::vector<Stripe>> stripes(const std::vector<StageReading>& readings) {
    std::vector<Stripe> out;
    for (std::size_t i = 0; i < readings.size(); ++i) {
        const StageReading& r = readings[i];
        const std::string w = "stage reading " + std::to_string(i + 1) + ": ";
        if (!(std::abs(r.tilt_deg) < 60.0))
            return core::make_error(w + "tilt " + std::to_string(r.tilt_deg) +
                                    "° (at most 60°: the line must stay in the field)");
        if (r.tilt_deg != 0.0 && std::abs(r.tilt_deg) < 5.0)
            return core::make_error(w + "tilt " + std::to_string(r.tilt_deg) +
                                    "°: level is 0, a tilted plate 5° or more (x = (z − height) / "
                                    "tan(tilt) multiplies z's noise by 1/tan(tilt))");
        if (!(r.height_mm > 0.0)) return core::make_error(w + "height must be positive");
        Stripe s{stripe_rows(r.laser), r.height_mm, std::tan(r.tilt_deg * kDeg)};
        // A point whose extraction window and background band (4 + 3 rows) are cut by the
        // image's edge is biased (66 µm RMS where a tilted line leaves the image): left out.
        constexpr double kEdgeRows = 7.0;
        for (double& v : s.rows)
            if (v < kEdgeRows || v > r.laser.height - 1 - kEdgeRows)
                v = std::numeric_limits<double>::quiet_NaN();
        int lit = 0;
        for (double v : s.rows) lit += std::isfinite(v);
        if (lit < kMinLitColumns) return core::make_error(w + "no laser line in the image");
        out.push_back(std::move(s));
    }
    return out;
}

// Level plates: (u, v, x, z = height), x a placeholder that grows with the column: the fit's fan
// insists on one; only the range law is used from this fit.
std::vector<acquire::CalibrationSample> level_samples(const std::vector<Stripe>& s) {
    std::vector<acquire::CalibrationSample> out;
    for (const auto& r : s)
        if (r.tan_tilt == 0.0)
            for (std::size_t u = 0; u < r.rows.size(); ++u)
                if (std::isfinite(r.rows[u]))
                    out.push_back({static_cast<double>(u), r.rows[u],
                                   kPlaceholderPitch * static_cast<double>(u) * r.height_mm,
                                   r.height_mm});
    return out;
}

// Tilted plates: z from the level plates' range law, x where the plate's line has that z.
std::vector<acquire::CalibrationSample> tilted_samples(const std::vector<Stripe>& s,
                                                       const acquire::Triangulation& law) {
    std::vector<acquire::CalibrationSample> out;
    for (const auto& r : s) {
        if (r.tan_tilt == 0.0) continue;
        for (std::size_t u = 0; u < r.rows.size(); ++u) {
            if (!std::isfinite(r.rows[u])) continue;
            const double z = law.to_camera(static_cast<double>(u), r.rows[u]).z_mm;
            if (std::isfinite(z))
                out.push_back(
                    {static_cast<double>(u), r.rows[u], (z - r.height_mm) / r.tan_tilt, z});
        }
    }
    return out;
}

// The x law, x = z·(s0 + s1·t + … + sm·tᵐ) per column, with each s_j a polynomial of degree
// kAcross in the column: one smooth surface over the image (the lens's distortion is smooth),
// fitted to every tilted sample at once, so that a column's law does not carry its own few
// samples' noise. Returns the RMS of x.
constexpr int kAcross = 6;  // (not measured)

core::Result<double> fit_x_surface(const std::vector<acquire::CalibrationSample>& samples,
                                   int x_degree, acquire::CalibratedModel& m) {
    const double mid_u = 0.5 * (m.width_px - 1), mid_v = 0.5 * (m.height_px - 1);
    const int n = (kAcross + 1) * (x_degree + 1);
    Eigen::MatrixXd A(static_cast<Eigen::Index>(samples.size()), n);
    Eigen::VectorXd b(A.rows());
    for (Eigen::Index k = 0; k < A.rows(); ++k) {
        const acquire::CalibrationSample& s = samples[static_cast<std::size_t>(k)];
        const double a = (s.u_px - mid_u) / mid_u, t = (s.v_px - mid_v) / mid_v;
        double pa = 1.0;
        for (int i = 0; i <= kAcross; ++i, pa *= a) {
            double pt = 1.0;
            for (int j = 0; j <= x_degree; ++j, pt *= t)
                A(k, i * (x_degree + 1) + j) = s.z_mm * pa * pt;
        }
        b(k) = s.x_mm;
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    if (qr.rank() < n)
        return core::make_error(
            "the tilted plates' lines do not cover the image enough to fix "
            "the x law (rank " +
            std::to_string(qr.rank()) + " of " + std::to_string(n) +
            "): tilt the plate at more heights");
    const Eigen::VectorXd c = qr.solve(b);
    m.x_degree = x_degree;
    m.x_coefficients.assign(static_cast<std::size_t>(m.width_px) * (x_degree + 1), 0.0);
    for (int col = 0; col < m.width_px; ++col) {
        const double a = (col - mid_u) / mid_u;
        double pa = 1.0;
        for (int i = 0; i <= kAcross; ++i, pa *= a)
            for (int j = 0; j <= x_degree; ++j)
                m.x_coefficients[static_cast<std::size_t>(col) * (x_degree + 1) + j] +=
                    pa * c(i * (x_degree + 1) + j);
    }
    return std::sqrt((A * c - b).squaredNorm() / static_cast<double>(A.rows()));
}

// The fan (x = k·(u − u0)·z) that best fits the tilted samples: the model's u0_px and
// x_pitch_mm, which the x law supersedes but which describe the head (and start to_image).
void fit_fan(const std::vector<acquire::CalibrationSample>& samples, acquire::CalibratedModel& m) {
    Eigen::MatrixXd A(static_cast<Eigen::Index>(samples.size()), 2);
    Eigen::VectorXd b(A.rows());
    for (Eigen::Index k = 0; k < A.rows(); ++k) {
        const acquire::CalibrationSample& s = samples[static_cast<std::size_t>(k)];
        A(k, 0) = s.u_px * s.z_mm;
        A(k, 1) = -s.z_mm;
        b(k) = s.x_mm;
    }
    const Eigen::Vector2d fan = A.colPivHouseholderQr().solve(b);
    if (fan(0) > 0.0) {
        m.x_pitch_mm = fan(0) * m.reference_range_mm;
        m.u0_px = fan(1) / fan(0);
    }
}

}  // namespace

core::Result<StageFit> calibrate_sensor_stage(const std::vector<StageReading>& readings, int degree,
                                              int x_degree) {
    if (degree < 1 || degree > 5 || x_degree < 1 || x_degree > 5)
        return core::make_error("stage: degree and x_degree must be in [1, 5]");
    auto s = stripes(readings);
    if (!s) return s.error();
    int n_level = 0;
    for (const auto& r : *s) n_level += r.tan_tilt == 0.0;
    const int n_tilted = static_cast<int>(s->size()) - n_level;
    if (n_level < degree + 2 || n_tilted < x_degree + 1)
        return core::make_error(
            "stage: " + std::to_string(n_level) + " level and " + std::to_string(n_tilted) +
            " tilted readings; the range law of "
            "degree " +
            std::to_string(degree) + " needs " + std::to_string(degree + 2) +
            " level ones, the x law " + std::to_string(x_degree + 1) + " tilted ones");
    acquire::CalibrationOptions o;
    o.width_px = readings.front().laser.width;
    o.height_px = readings.front().laser.height;
    o.degree = degree;
    // 1. The range law per column from the level plates alone.
    const std::vector<acquire::CalibrationSample> level = level_samples(*s);
    auto fit = acquire::fit_calibrated_model(level, o);
    if (!fit) return core::make_error("stage, level plates: " + fit.error().message);
    auto law = acquire::Triangulation::calibrated(fit->model);
    if (!law) return law.error();
    // 2. The x law from the tilted plates, through the range law.
    const auto tilted_points = tilted_samples(*s, *law);
    auto rms_x = fit_x_surface(tilted_points, x_degree, fit->model);
    if (!rms_x) return core::make_error("stage, tilted plates: " + rms_x.error().message);
    fit->rms_x_mm = *rms_x;
    fit_fan(tilted_points, fit->model);
    if (auto ok = acquire::Triangulation::calibrated(fit->model); !ok)
        return core::make_error("stage, tilted plates: " + ok.error().message);
    StageFit out;
    out.model = fit->model;
    out.rms_z_mm = fit->rms_z_mm;
    out.rms_x_mm = fit->rms_x_mm;
    out.samples = static_cast<int>(level.size() + tilted_points.size());
    out.readings = static_cast<int>(readings.size());
    return out;
}

}  // namespace hotgauge::calib
