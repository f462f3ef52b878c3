#include "hotgauge/calib/align.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "align_steps.hpp"
#include "hotgauge/core/clock.hpp"

namespace hotgauge::calib {
namespace {

constexpr double kG = 9.81;  // m/s², recording-format-v1's g_up
constexpr double kRadToDeg = 180.0 / M_PI;
// The weak direction's words: its largest unknown, then up to this many in all, each carrying at
// least this share of it (not measured).
constexpr int kMaxUnknownsNamed = 3;
constexpr double kMinShareNamed = 0.1;
// Finding the balls again from the placed face: it is within about 1 mm, and a start 2° off
// shears a 40 mm ball by about 0.6 mm in the recorded geometry (docs/calibration.md "Faces").
constexpr double kNearStartErrorMm = 5.0;
// A face's accelerometer record needs this many readings for its mean and scatter (not measured).
constexpr std::int64_t kMinAccelReadings = 10;
// The gravity directions' spread: the centred cross-covariance's second singular value, in g²,
// below this the directions lie (nearly) on one line (not measured).
constexpr double kMinGravitySpread = 0.1;

using detail::Matrix9;

// The nine unknowns in words, in the order of `readable` below.
const char* const kUnknown[9] = {"rotation about the camera's x",
                                 "rotation about the camera's y",
                                 "rotation about the camera's z",
                                 "position along the camera's x",
                                 "position along the camera's y",
                                 "position along the camera's z",
                                 "travel scale",
                                 "scan direction's tilt toward the camera's x",
                                 "scan direction's tilt toward the camera's z"};

// Rows: the unknowns in words (camera axes; travel along, and across toward camera x and z) per
// tangent unknown (rotation vector and position in world axes, travel vector).
Matrix9 readable(const detail::FacePose& pose) {
    const Eigen::Matrix3d R = pose.R.toRotationMatrix();
    const Eigen::Vector3d s = pose.v.normalized();
    const Eigen::Vector3d ex = (R.col(0) - R.col(0).dot(s) * s).normalized();
    Matrix9 T = Matrix9::Zero();
    T.block<3, 3>(0, 0) = R.transpose();
    T.block<3, 3>(3, 3) = R.transpose();
    T.block<1, 3>(6, 6) = s.transpose();
    T.block<1, 3>(7, 6) = ex.transpose();
    T.block<1, 3>(8, 6) = s.cross(ex).transpose();
    return T;
}

// Each readable unknown's limit in its tangent unit (rad, mm, mm/mm).
Eigen::Matrix<double, 9, 1> limits_vector(const AlignLimits& lim) {
    Eigen::Matrix<double, 9, 1> d;
    const double rot = lim.max_sigma_rotation_deg / kRadToDeg;
    d << rot, rot, rot, lim.max_sigma_position_mm, lim.max_sigma_position_mm,
        lim.max_sigma_position_mm, lim.max_sigma_travel_ppm * 1e-6,
        lim.max_sigma_direction_deg / kRadToDeg, lim.max_sigma_direction_deg / kRadToDeg;
    return d;
}

// The weak direction in the face's unknowns ("position along the camera's x (97 %) with …"),
// each measured against its limit.
std::string unknowns_in_words(const Eigen::Matrix<double, 9, 1>& e, bool& travel) {
    std::vector<int> order(9);
    for (int i = 0; i < 9; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](int a, int b) { return e(a) * e(a) > e(b) * e(b); });
    std::string words;
    for (int k = 0;
         k < kMaxUnknownsNamed && (k == 0 || e(order[k]) * e(order[k]) >= kMinShareNamed); ++k) {
        const int percent = static_cast<int>(std::lround(100 * e(order[k]) * e(order[k])));
        words +=
            std::string(k ? ", " : "") + kUnknown[order[k]] + " " + std::to_string(percent) + " %";
        travel |= order[k] >= 6;
    }
    return words;
}

// The least well fixed combination of unknowns (each against its limit), in words a person can
// act on. When it moves the scene mostly by turning it about a line near the balls (three balls
// in a row), that line is named: world coordinates, mm.
std::string weak_direction(const Matrix9& information, const detail::FacePose& pose,
                           const Eigen::Vector3d& scene_mm, const AlignLimits& lim) {
    const Matrix9 T = readable(pose);
    const Eigen::Matrix<double, 9, 1> d = limits_vector(lim);
    const Matrix9 Hn = d.asDiagonal() * (T * information * T.transpose()) * d.asDiagonal();
    const Eigen::SelfAdjointEigenSolver<Matrix9> eig(Hn);
    const Eigen::Matrix<double, 9, 1> e = eig.eigenvectors().col(0);
    bool travel = false;
    const std::string words = unknowns_in_words(e, travel);
    const Eigen::Matrix<double, 9, 1> delta = T.transpose() * (d.asDiagonal() * e);
    const Eigen::Vector3d w = delta.head<3>();
    // The scene's point, seen at travel c, moves by ω × (x − t − c·v) + δt + c·δv.
    const double c = pose.scan(scene_mm).y();
    const Eigen::Vector3d at_scene =
        w.cross(scene_mm - pose.t - c * pose.v) + delta.segment<3>(3) + c * delta.tail<3>();
    constexpr double kSceneMm = 100.0;  // the size of an artifact
    char line[160] = "";
    const bool turns = w.norm() * kSceneMm > at_scene.norm();
    if (turns) {
        const Eigen::Vector3d axis = w.normalized();
        const Eigen::Vector3d p = scene_mm + w.cross(at_scene) / w.squaredNorm();
        std::snprintf(line, sizeof line,
                      "a turn about the line along (%.2f, %.2f, %.2f) through (%.1f, %.1f, %.1f) "
                      "mm",
                      axis.x(), axis.y(), axis.z(), p.x(), p.y(), p.z());
    }
    std::string advice = turns ? "the balls it sees lie near that line: add balls away from it "
                                 "(other heights, other places across the view)"
                               : "more balls in this face's view, or larger ones";
    if (travel) advice += ", spread along the scan";
    return "the weak direction is " +
           (turns ? line + (" (in the face's unknowns: " + words + ")") : words) + ": " + advice;
}

PoseSigma pose_sigma(const Matrix9& C, const detail::FacePose& pose) {
    const Matrix9 T = readable(pose);
    const Matrix9 Cr = T * C * T.transpose();
    PoseSigma s;
    for (int k = 0; k < 3; ++k) {
        s.position_mm(k) = std::sqrt(C(3 + k, 3 + k));  // world axes
        s.rotation_deg(k) = std::sqrt(Cr(k, k)) * kRadToDeg;
    }
    s.travel_scale_ppm = std::sqrt(Cr(6, 6)) / pose.v.norm() * 1e6;
    s.direction_deg = std::sqrt(std::max(Cr(7, 7), Cr(8, 8))) / pose.v.norm() * kRadToDeg;
    return s;
}

// The first σ over its limit, in words ("σ of the camera position along world y is 0.0071 mm
// (limit 0.005 mm)"), or empty.
std::string sigma_over_limit(const PoseSigma& s, const AlignLimits& lim) {
    const char* axis[3] = {"x", "y", "z"};
    char buf[160];
    for (int k = 0; k < 3; ++k) {
        if (!(s.position_mm(k) <= lim.max_sigma_position_mm)) {
            std::snprintf(buf, sizeof buf,
                          "σ of the camera position along world %s is %.4f mm (limit %.4f mm)",
                          axis[k], s.position_mm(k), lim.max_sigma_position_mm);
            return buf;
        }
        if (!(s.rotation_deg(k) <= lim.max_sigma_rotation_deg)) {
            std::snprintf(buf, sizeof buf,
                          "σ of the rotation about the camera's %s is %.5f° (limit %.5f°)", axis[k],
                          s.rotation_deg(k), lim.max_sigma_rotation_deg);
            return buf;
        }
    }
    if (!(s.travel_scale_ppm <= lim.max_sigma_travel_ppm)) {
        std::snprintf(buf, sizeof buf, "σ of the travel scale is %.1f ppm (limit %.1f ppm)",
                      s.travel_scale_ppm, lim.max_sigma_travel_ppm);
        return buf;
    }
    if (!(s.direction_deg <= lim.max_sigma_direction_deg)) {
        std::snprintf(buf, sizeof buf, "σ of the scan direction is %.5f° (limit %.5f°)",
                      s.direction_deg, lim.max_sigma_direction_deg);
        return buf;
    }
    return {};
}

// "0.0372": a figure with `digits` decimals.
std::string fixed(double v, int digits) {
    char buf[48];
    std::snprintf(buf, sizeof buf, "%.*f", digits, v);
    return buf;
}

std::string ball_names(const Artifact& a, const std::vector<detail::BallSeen>& balls) {
    std::string out;
    for (const auto& b : balls) out += (out.empty() ? "" : ", ") + a.spheres[b.sphere].name;
    return out.empty() ? "none" : out;
}

// How far the recording's geometry put the balls from where the fit puts them, worst.
double start_error(const std::vector<detail::BallSeen>& balls, const detail::FacePose& recorded,
                   const detail::FacePose& fitted) {
    double worst = 0.0;
    for (const auto& b : balls) {
        const detail::ScanPoint p{{b.u.x(), 0.0, b.u.z()}, b.u.y()};
        worst = std::max(worst, (recorded.world(p) - fitted.world(p)).norm());
    }
    return worst;
}

FaceCalibration geometry_of(const core::FaceScan& f, const detail::FacePose& pose) {
    FaceCalibration g;
    g.name = f.name;
    g.T_world_camera = Eigen::Isometry3d::Identity();
    g.T_world_camera.linear() = pose.R.toRotationMatrix();
    g.T_world_camera.translation() = pose.t;
    g.travel_scale = pose.v.norm();
    g.scan_direction = pose.v / g.travel_scale;
    g.R_camera_accel = f.R_camera_accel;
    g.recorded_camera_to_world = f.T_world_camera;
    return g;
}

// Step 1: the balls found near where the recording's geometry puts them, the face placed from
// their centres, then the balls found again from there (a start 2° off shears a ball by 0.6 mm in
// the recorded geometry, more than the RANSAC band) and the face placed again. `balls`: the ones
// used.
core::Result<detail::FacePose> place_face(const Artifact& a,
                                          const std::vector<detail::ScanPoint>& pts,
                                          const detail::FacePose& recorded, const AlignLimits& lim,
                                          std::vector<detail::BallSeen>& balls) {
    const auto too_few = [&] {
        return core::make_error("sees " + std::to_string(balls.size()) + " ball(s) (" +
                                ball_names(a, balls) + ") with at least " +
                                std::to_string(lim.min_points_per_sphere) + " points within " +
                                fixed(lim.max_start_error_mm, 1) +
                                " mm of where the recording's geometry puts them; needs " +
                                std::to_string(lim.min_spheres));
    };
    balls = detail::find_balls(a, pts, recorded, lim);
    if (static_cast<int>(balls.size()) < lim.min_spheres) return too_few();
    auto placed = detail::place_from_balls(a, balls, recorded);
    if (!placed) return placed.error();
    if (static_cast<int>(balls.size()) < lim.min_spheres) return too_few();
    const double off = start_error(balls, recorded, *placed);
    if (off > lim.max_start_error_mm)
        return core::make_error("the recording's geometry put the balls " + fixed(off, 1) +
                                " mm from where they are (limit " +
                                fixed(lim.max_start_error_mm, 1) +
                                " mm): another artifact's certificate, or the wrong cell");
    AlignLimits near = lim;
    near.max_start_error_mm = kNearStartErrorMm;
    std::vector<detail::BallSeen> again = detail::find_balls(a, pts, *placed, near);
    if (static_cast<int>(again.size()) < lim.min_spheres) return placed;
    auto replaced = detail::place_from_balls(a, again, *placed);
    if (!replaced || static_cast<int>(again.size()) < lim.min_spheres) return placed;
    balls = std::move(again);
    return replaced;
}

void describe_fit(const Artifact& a, const detail::PointFit& fit, const AlignLimits& lim,
                  FaceAlignment& out) {
    out.rms_mm = fit.rms_mm;
    out.iterations = fit.iterations;
    out.map = fit.map;
    for (std::size_t j = 0; j < fit.counts.size(); ++j) {
        if (fit.counts[j] > 0)
            out.surfaces.push_back(
                {surface_name(a, j), fit.counts[j], fit.rms_surface_mm[j], fit.mean_mm[j]});
        out.points[surface_name(a, j)] = fit.counts[j];
        if (j < a.spheres.size() && fit.counts[j] >= lim.min_points_per_sphere)
            out.spheres.push_back(a.spheres[j].name);
    }
}

}  // namespace

core::Result<FaceAlignment> align_face(const Artifact& a, const core::FaceScan& f,
                                       const AlignLimits& lim) {
    const std::string w = "face " + f.name + ": ";
    const std::vector<detail::ScanPoint> pts = detail::scan_points(f);
    const detail::FacePose recorded{Eigen::Quaterniond(f.T_world_camera.linear()),
                                    f.T_world_camera.translation(),
                                    f.travel_scale * f.scan_direction};
    std::vector<detail::BallSeen> balls;
    auto placed = place_face(a, pts, recorded, lim, balls);
    if (!placed) return core::make_error(w + placed.error().message);
    auto fit = detail::fit_points(a, pts, *placed);
    if (!fit) return core::make_error(w + fit.error().message);
    Eigen::Vector3d scene = Eigen::Vector3d::Zero();
    for (const auto& b : balls) scene += a.spheres[b.sphere].center_mm / double(balls.size());
    FaceAlignment out;
    describe_fit(a, *fit, lim, out);
    out.start_error_mm = start_error(balls, recorded, fit->pose);
    // A pose the balls do not fix first: its fit's RMS means nothing.
    if (!fit->covariance_ok)
        return core::make_error(w + "the balls it sees (" + ball_names(a, balls) +
                                ") do not fix its pose and travel; " +
                                weak_direction(fit->information, fit->pose, scene, lim));
    if (!(out.rms_mm <= lim.max_rms_mm))
        return core::make_error(w + "residual RMS " + fixed(out.rms_mm, 4) +
                                " mm exceeds the limit of " + fixed(lim.max_rms_mm, 4) +
                                " mm (wrong artifact, moved during the scan, or a bad start)");
    out.sigma = pose_sigma(fit->covariance, fit->pose);
    if (const std::string over = sigma_over_limit(out.sigma, lim); !over.empty())
        return core::make_error(w + "not fixed well enough: " + over + "; " +
                                weak_direction(fit->information, fit->pose, scene, lim));
    out.geometry = geometry_of(f, fit->pose);
    return out;
}

core::Result<AccelMount> estimate_accel_mount(const core::Recording& rec,
                                              const std::vector<FaceCalibration>& faces,
                                              const AlignLimits& lim) {
    std::vector<Eigen::Vector3d> D, G;  // gravity direction in the camera frame, mean reading
    for (const auto& f : rec.faces) {
        const FaceCalibration* g = nullptr;
        for (const auto& c : faces)
            if (c.name == f.name) g = &c;
        if (!g || f.n_accel() < kMinAccelReadings)
            return core::make_error("face " + f.name + ": no accelerometer record or geometry");
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (std::int64_t j = 0; j < f.n_accel(); ++j) mean += f.accel(j);
        mean /= static_cast<double>(f.n_accel());
        double var = 0.0;
        for (std::int64_t j = 0; j < f.n_accel(); ++j) var += (f.accel(j) - mean).squaredNorm();
        const double rms = std::sqrt(var / static_cast<double>(f.n_accel()));
        if (rms > lim.max_static_rms_mps2)
            return core::make_error("face " + f.name + ": accelerometer scatter " +
                                    std::to_string(rms) + " m/s² exceeds " +
                                    std::to_string(lim.max_static_rms_mps2) +
                                    " m/s²: the head was not still (press running?)");
        D.push_back(g->T_world_camera.linear().transpose() * Eigen::Vector3d(0, 0, kG));
        G.push_back(mean);
    }
    if (D.size() < 3)
        return core::make_error("accelerometer: " + std::to_string(D.size()) +
                                " face(s); gravity fixes the mount and bias from 3 or more faces "
                                "whose gravity directions are not on one line");
    Eigen::Vector3d d_mean = Eigen::Vector3d::Zero(), g_mean = Eigen::Vector3d::Zero();
    for (std::size_t j = 0; j < D.size(); ++j) {
        d_mean += D[j] / static_cast<double>(D.size());
        g_mean += G[j] / static_cast<double>(G.size());
    }
    Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
    for (std::size_t j = 0; j < D.size(); ++j) H += (D[j] - d_mean) * (G[j] - g_mean).transpose();
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
    if (!(svd.singularValues()(1) > kMinGravitySpread * kG * kG))
        return core::make_error(
            "accelerometer: the faces' gravity directions lie on one line: gravity cannot fix the "
            "mount (scan 3 or more faces that look in different directions)");
    Eigen::Matrix3d S = Eigen::Matrix3d::Identity();
    S(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() > 0 ? 1.0 : -1.0;
    const Eigen::Matrix3d Q = svd.matrixV() * S * svd.matrixU().transpose();  // D → G: R_caᵀ
    AccelMount m;
    m.R_camera_accel = Q.transpose();
    m.bias_mps2 = g_mean - Q * d_mean;
    double sum2 = 0.0;
    for (std::size_t j = 0; j < D.size(); ++j)
        sum2 += (G[j] - Q * D[j] - m.bias_mps2).squaredNorm();
    m.residual_mps2 = std::sqrt(sum2 / static_cast<double>(D.size()));
    return m;
}

namespace {

// The figures of an aligned face, written into calibration.yaml's residuals.
void write_residuals(const FaceAlignment& fa, const std::string& face,
                     std::map<std::string, double>& r) {
    r[face + ".rms_mm"] = fa.rms_mm;
    r[face + ".spheres"] = static_cast<double>(fa.spheres.size());
    r[face + ".start_error_mm"] = fa.start_error_mm;
    for (int k = 0; k < 3; ++k) {
        const std::string axis(1, "xyz"[k]);
        r[face + ".sigma_position_" + axis + "_mm"] = fa.sigma.position_mm(k);
        r[face + ".sigma_rotation_" + axis + "_deg"] = fa.sigma.rotation_deg(k);
    }
    r[face + ".sigma_travel_ppm"] = fa.sigma.travel_scale_ppm;
    r[face + ".sigma_direction_deg"] = fa.sigma.direction_deg;
}

}  // namespace

Commissioning commission_faces(const Artifact& artifact, const core::Recording& rec,
                               const Calibration& base, const AlignLimits& lim) {
    Commissioning out;
    out.artifact = artifact.name;
    out.limits = lim;
    if (rec.recipe != artifact.name) {
        out.refused = "the recording's recipe is '" + rec.recipe + "', not the artifact '" +
                      artifact.name + "'";
        return out;
    }
    for (const auto& f : base.faces)
        if (!rec.face(f.name)) {
            out.refused = "face " + f.name +
                          " of the calibration in force is not in the artifact recording: scan "
                          "every face";
            return out;
        }
    Calibration c = base;
    c.method = "artifact";
    c.calibrated_at = core::iso8601_utc(core::realtime_ns());
    c.residuals.clear();
    c.faces.clear();
    for (const auto& f : rec.faces) {
        FaceOutcome& o = out.faces.emplace_back();
        o.name = f.name;
        o.recorded.geometry() = f.geometry();
        auto fa = align_face(artifact, f, lim);
        if (!fa) {
            o.refused = fa.error().message;
            if (out.refused.empty()) out.refused = o.refused;
            continue;
        }
        write_residuals(*fa, f.name, c.residuals);
        c.faces.push_back(fa->geometry);
        o.aligned = std::move(*fa);
    }
    if (!out.refused.empty()) return out;
    auto mount = estimate_accel_mount(rec, c.faces, lim);
    if (!mount) {
        out.refused = mount.error().message;
        return out;
    }
    c.residuals["accel.gravity_rms_mps2"] = mount->residual_mps2;
    // Readings that one head with one bias cannot explain (an accelerometer per face, each with
    // its own bias, as recording-format-v1 allows) leave the mounts as recorded: not measured.
    const bool one_head = mount->residual_mps2 <= lim.max_gravity_residual_mps2;
    c.residuals["accel.mount_measured"] = one_head ? 1.0 : 0.0;
    if (one_head) {
        for (auto& f : c.faces) f.R_camera_accel = mount->R_camera_accel;
        c.accel_bias_mps2 = mount->bias_mps2;
    }
    out.calibration = std::move(c);
    return out;
}

core::Result<Calibration> calibrate_faces(const Artifact& artifact, const core::Recording& rec,
                                          const Calibration& base, const AlignLimits& lim) {
    Commissioning c = commission_faces(artifact, rec, base, lim);
    if (!c.calibration) return core::make_error(c.refused);
    return std::move(*c.calibration);
}

}  // namespace hotgauge::calib
