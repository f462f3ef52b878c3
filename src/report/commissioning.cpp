#include "hotgauge/report/commissioning.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <numbers>

#include "hotgauge/report/html.hpp"
#include "pictures.hpp"

namespace hotgauge::report {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

constexpr const char* kStyle = R"(
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; margin-bottom: 1em; }
th, td { padding: 3px 8px; text-align: right; border-bottom: 1px solid #ddd; white-space: nowrap; }
th:first-child, td:first-child { text-align: left; }
td.over { background: #ffcdd2; }
.verdict { font-weight: bold; padding: 2px 8px; border-radius: 3px; color: #fff; }
.v-PASSED { background: #2e7d32; } .v-REFUSED { background: #c62828; }
.pictures { display: flex; flex-wrap: wrap; gap: 16px; }
figure { margin: 0; } figure img { width: 480px; image-rendering: pixelated; border: 1px solid #ccc; }
.sign { margin-top: 3em; } .sign span { display: inline-block; width: 22em; border-top: 1px solid #222;
  margin-right: 3em; padding-top: 4px; }
)";

std::string td(double v, int decimals, bool over = false) {
    return std::string(over ? "<td class='over'>" : "<td>") + fixed(v, decimals) + "</td>";
}

// σ of every aligned face against its limit; a refused face with its reason.
std::string sigma_table(const calib::Commissioning& c) {
    const calib::AlignLimits& l = c.limits;
    std::string s =
        "<table class='sigma'><tr><th>face</th><th>RMS mm</th><th>balls</th><th>balls off by "
        "mm</th>"
        "<th>σ x mm</th><th>σ y mm</th><th>σ z mm</th><th>σ rot x °</th><th>σ rot y °</th>"
        "<th>σ rot z °</th><th>travel scale</th><th>σ ppm</th><th>σ direction °</th></tr>\n";
    for (const auto& f : c.faces) {
        s += "<tr><td>" + escape(f.name) + "</td>";
        if (!f.aligned) {
            s += "<td colspan='12' style='text-align:left'>refused: " + escape(f.refused) +
                 "</td></tr>\n";
            continue;
        }
        const calib::FaceAlignment& a = *f.aligned;
        const calib::PoseSigma& g = a.sigma;
        s += td(a.rms_mm, 4, a.rms_mm > l.max_rms_mm) + "<td>" + std::to_string(a.spheres.size()) +
             "</td>" + td(a.start_error_mm, 3);
        for (int k = 0; k < 3; ++k)
            s += td(g.position_mm(k), 4, g.position_mm(k) > l.max_sigma_position_mm);
        for (int k = 0; k < 3; ++k)
            s += td(g.rotation_deg(k), 5, g.rotation_deg(k) > l.max_sigma_rotation_deg);
        s += td(a.geometry.travel_scale, 6) +
             td(g.travel_scale_ppm, 1, g.travel_scale_ppm > l.max_sigma_travel_ppm) +
             td(g.direction_deg, 5, g.direction_deg > l.max_sigma_direction_deg) + "</tr>\n";
    }
    return s + "<tr><td>limit</td>" + td(l.max_rms_mm, 4) + "<td>" + std::to_string(l.min_spheres) +
           "</td>" + td(l.max_start_error_mm, 1) + td(l.max_sigma_position_mm, 4) +
           td(l.max_sigma_position_mm, 4) + td(l.max_sigma_position_mm, 4) +
           td(l.max_sigma_rotation_deg, 5) + td(l.max_sigma_rotation_deg, 5) +
           td(l.max_sigma_rotation_deg, 5) + "<td></td>" + td(l.max_sigma_travel_ppm, 1) +
           td(l.max_sigma_direction_deg, 5) + "</tr></table>\n";
}

// Where the recording put the face and where the artifact says it is.
std::string geometry_table(const calib::Commissioning& c) {
    std::string s =
        "<table class='geometry'><tr><th>face</th><th>recorded position mm</th>"
        "<th>calibrated position mm</th><th>moved mm</th><th>turned °</th>"
        "<th>travel scale</th><th>scan direction turned °</th></tr>\n";
    for (const auto& f : c.faces) {
        if (!f.aligned) continue;
        const calib::FaceCalibration& a = f.recorded;
        const calib::FaceCalibration& b = f.aligned->geometry;
        auto xyz = [](const Eigen::Vector3d& p) {
            return fixed(p.x(), 3) + ", " + fixed(p.y(), 3) + ", " + fixed(p.z(), 3);
        };
        const double turned =
            Eigen::AngleAxisd(a.T_world_camera.linear().transpose() * b.T_world_camera.linear())
                .angle() *
            kDeg;
        const double dir =
            std::acos(std::clamp(a.scan_direction.dot(b.scan_direction), -1.0, 1.0)) * kDeg;
        s += "<tr><td>" + escape(f.name) + "</td><td>" + xyz(a.T_world_camera.translation()) +
             "</td><td>" + xyz(b.T_world_camera.translation()) + "</td>" +
             td((b.T_world_camera.translation() - a.T_world_camera.translation()).norm(), 3) +
             td(turned, 4) + "<td>" + fixed(a.travel_scale, 6) + " → " + fixed(b.travel_scale, 6) +
             "</td>" + td(dir, 4) + "</tr>\n";
    }
    return s + "</table>\n";
}

std::string surfaces_table(const calib::FaceAlignment& a) {
    std::string s =
        "<table class='surfaces'><tr><th>surface</th><th>points</th>"
        "<th>RMS mm</th><th>mean mm</th></tr>\n";
    for (const auto& f : a.surfaces)
        s += "<tr><td>" + escape(f.name) + "</td><td>" + std::to_string(f.points) + "</td>" +
             td(f.rms_mm, 4) + td(f.mean_mm, 4) + "</tr>\n";
    return s + "</table>\n";
}

// The residual map, one cell per pixel block, on the part report's diverging scale at ±3 × the
// face's RMS (no point: black).
RgbImage residual_picture(const calib::ResidualMap& m, double scale_mm) {
    constexpr int kBlock = 4;
    RgbImage img(m.columns * kBlock, m.rows * kBlock);
    for (int r = 0; r < m.rows; ++r)
        for (int c = 0; c < m.columns; ++c) {
            const float v = m.mean_mm[static_cast<std::size_t>(r) * m.columns + c];
            const Colour col = std::isfinite(v) ? deviation_colour(v, scale_mm) : kNoPointColour;
            for (int y = 0; y < kBlock; ++y)
                for (int x = 0; x < kBlock; ++x) img.set(c * kBlock + x, r * kBlock + y, col);
        }
    return img;
}

std::string faces_section(const calib::Commissioning& c) {
    std::string s;
    for (const auto& f : c.faces) {
        if (!f.aligned) continue;
        const calib::FaceAlignment& a = *f.aligned;
        const double scale = 3.0 * a.rms_mm;
        const calib::ResidualMap& m = a.map;
        s += "<h3>" + escape(f.name) + "</h3>\n<div class='pictures'>" + surfaces_table(a) +
             "<figure><img alt='residual map of " + escape(f.name) + "' src='" +
             png_data_uri(residual_picture(m, scale)) + "'><figcaption>Mean residual per cell, x " +
             fixed(m.x0_mm, 0) + " … " + fixed(m.x1_mm, 0) + " mm across, travel " +
             fixed(m.c0_mm, 0) + " … " + fixed(m.c1_mm, 0) + " mm down; blue −" + fixed(scale, 3) +
             " mm (inside the surface), red +" + fixed(scale, 3) +
             " mm, black no point used.</figcaption></figure></div>\n";
    }
    return s;
}

}  // namespace

std::string commissioning_html(const calib::Commissioning& c, const std::string& recording,
                               const std::string& artifact_file) {
    const bool passed = c.calibration.has_value();
    const std::string verdict = passed ? "PASSED" : "REFUSED";
    std::string s =
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>"
        "Commissioning: faces aligned to " +
        escape(c.artifact) + "</title><style>" + kStyle +
        "</style></head><body>\n<h1>Commissioning: "
        "faces aligned to " +
        escape(c.artifact) + "</h1>\n<p><span class='verdict v-" + verdict + "'>" + verdict +
        "</span> ";
    s += passed ? "every face is fixed within the limits (docs/calibration.md \"Limits\")."
                : escape(c.refused) + ". The calibration in force stays as it is.";
    s += "</p>\n<table class='summary'><tr><td>artifact scan</td><td style='text-align:left'>" +
         escape(recording) +
         "</td></tr><tr><td>artifact certificate</td>"
         "<td style='text-align:left'>" +
         escape(artifact_file) + "</td></tr>";
    if (passed)
        s += "<tr><td>calibrated at</td><td style='text-align:left'>" +
             escape(c.calibration->calibrated_at) +
             "</td></tr><tr><td>accelerometer mount</td>"
             "<td style='text-align:left'>" +
             (c.calibration->residuals.at("accel.mount_measured") > 0.0
                  ? "measured from gravity, residual " +
                        fixed(c.calibration->residuals.at("accel.gravity_rms_mps2"), 4) + " m/s²"
                  : std::string("NOT MEASURED: gravity leaves ") +
                        fixed(c.calibration->residuals.at("accel.gravity_rms_mps2"), 4) +
                        " m/s² that one head with one bias cannot explain; recorded mounts kept") +
             "</td></tr>";
    s += "</table>\n<h2>How well each face is fixed (one standard deviation)</h2>\n" +
         sigma_table(c) +
         "<p>σ from the covariance of the fit at the solution (Ceres), scaled by the residual; "
         "positions along world axes, rotations about the camera's axes. A cell over its limit "
         "is red.</p>\n<h2>Geometry before and after</h2>\n" +
         geometry_table(c) + "<h2>Faces</h2>\n" + faces_section(c) +
         "<p class='sign'><span>commissioned by (name, signature)</span><span>date</span></p>\n"
         "</body></html>\n";
    return s;
}

}  // namespace hotgauge::report
