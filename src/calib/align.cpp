#include "hotgauge/calib/align.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "hotgauge/core/clock.hpp"

namespace hotgauge::calib {
namespace {

constexpr double kG = 9.81;  // m/s², recording-format-v1's g_up

// A profile point: camera point (x, 0, z) and the commanded travel of its profile.
struct ScanPoint {
    Eigen::Vector3d q;
    double c;
};

// The nine unknowns of a face: camera pose at position 0 and travel vector per commanded mm.
struct FacePose {
    Eigen::Matrix3d R;
    Eigen::Vector3d t, v;
    Eigen::Vector3d world(const ScanPoint& p) const { return R * p.q + t + p.c * v; }
};

std::vector<ScanPoint> scan_points(const core::FaceScan& f) {
    std::vector<ScanPoint> pts;
    for (std::int64_t k = 0; k < f.n_profiles(); ++k) {
        const double c = f.profile_positions_mm[k] / f.travel_scale;
        for (std::int64_t i = 0; i < f.width; ++i) {
            const float x = f.x(k, i), z = f.z(k, i);
            if (std::isfinite(x) && std::isfinite(z)) pts.push_back({{x, 0.0, z}, c});
        }
    }
    return pts;
}

struct Assignment {
    std::vector<int> surface;  // per point: surface index, −1 = none
    std::vector<int> counts;   // per surface
    double rms_mm = 0.0;
};

Assignment assign(const Artifact& a, const std::vector<ScanPoint>& pts, const FacePose& pose,
                  double gate_mm) {
    const std::size_t n_surf = surface_count(a);
    Assignment out;
    out.surface.assign(pts.size(), -1);
    out.counts.assign(n_surf, 0);
    double sum2 = 0.0;
    std::size_t used = 0;
    Eigen::Vector3d n;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        const Eigen::Vector3d p = pose.world(pts[i]);
        double best = gate_mm;
        for (std::size_t j = 0; j < n_surf; ++j) {
            const double d = std::abs(surface_distance(a, j, p, n));
            if (d < best) {
                best = d;
                out.surface[i] = static_cast<int>(j);
            }
        }
        if (out.surface[i] < 0) continue;
        ++out.counts[out.surface[i]];
        sum2 += best * best;
        ++used;
    }
    out.rms_mm = used ? std::sqrt(sum2 / static_cast<double>(used)) : 0.0;
    return out;
}

// "S1 (812 points), support (20311 points)" or "no artifact surface".
std::string seen_surfaces(const Artifact& a, const Assignment& as) {
    std::string out;
    for (std::size_t j = 0; j < as.counts.size(); ++j) {
        if (as.counts[j] == 0) continue;
        const std::string& name = surface_name(a, j);
        out += (out.empty() ? "" : ", ") + name + " (" + std::to_string(as.counts[j]) + " points)";
    }
    return out.empty() ? "no artifact surface" : out;
}

Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
    const double a = w.norm();
    if (a < 1e-15) return Eigen::Matrix3d::Identity();
    return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

// One Gauss–Newton step on the assigned points; returns the step (ω, δt, δv) or an error when
// the assigned surfaces do not fix the nine unknowns.
core::Result<Eigen::Matrix<double, 9, 1>> gauss_newton_step(const Artifact& a,
                                                            const std::vector<ScanPoint>& pts,
                                                            const Assignment& as, FacePose& pose) {
    using Vec9 = Eigen::Matrix<double, 9, 1>;
    Eigen::Matrix<double, 9, 9> H = Eigen::Matrix<double, 9, 9>::Zero();
    Vec9 g = Vec9::Zero();
    Eigen::Vector3d n;
    for (std::size_t i = 0; i < pts.size(); ++i) {
        if (as.surface[i] < 0) continue;
        const Eigen::Vector3d Rq = pose.R * pts[i].q;
        const double r =
            surface_distance(a, static_cast<std::size_t>(as.surface[i]), pose.world(pts[i]), n);
        Vec9 J;
        J << Rq.cross(n), n, pts[i].c * n;  // d/dω of R ← exp(ω)·R, d/dt, d/dv
        H.selfadjointView<Eigen::Lower>().rankUpdate(J);
        g += J * r;
    }
    H = H.selfadjointView<Eigen::Lower>();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(H);
    if (!(eig.eigenvalues()(0) > 1e-9 * eig.eigenvalues()(8)))
        return core::make_error("the surfaces it sees do not fix its pose and travel");
    const Vec9 step = -H.ldlt().solve(g);
    pose.R = exp_so3(step.head<3>()) * pose.R;
    pose.t += step.segment<3>(3);
    pose.v += step.tail<3>();
    return step;
}

}  // namespace

core::Result<FaceAlignment> align_face(const Artifact& a, const core::FaceScan& f,
                                       const AlignLimits& lim) {
    const std::string w = "face " + f.name + ": ";
    const std::vector<ScanPoint> pts = scan_points(f);
    FacePose pose{f.T_world_camera.linear(), f.T_world_camera.translation(),
                  f.travel_scale * f.scan_direction};
    FaceAlignment out;
    double gate = lim.max_start_error_mm;
    Assignment as;
    for (out.iterations = 1; out.iterations <= 60; ++out.iterations) {
        as = assign(a, pts, pose, gate);
        auto step = gauss_newton_step(a, pts, as, pose);
        if (!step)
            return core::make_error(w + "sees " + seen_surfaces(a, as) + ": " +
                                    step.error().message + " (needs 3 spheres)");
        const double floor_mm = 5.0 * 0.05;  // 5σ of a good sensor; the gate never goes below
        const bool settled = gate <= floor_mm * 1.0001 || gate <= 4.0 * as.rms_mm * 1.0001;
        if (settled && step->head<3>().norm() < 1e-9 && step->tail<6>().norm() < 1e-6) break;
        gate = std::min(gate, std::max(floor_mm, 4.0 * as.rms_mm));
    }
    if (out.iterations > 60)
        return core::make_error(w + "the fit did not settle in 60 iterations (residual RMS " +
                                std::to_string(as.rms_mm) + " mm)");
    as = assign(a, pts, pose, gate);
    out.rms_mm = as.rms_mm;
    for (std::size_t j = 0; j < as.counts.size(); ++j) {
        const bool sphere = j < a.spheres.size();
        const std::string& name = surface_name(a, j);
        out.points[name] = as.counts[j];
        if (sphere && as.counts[j] >= lim.min_points_per_sphere) out.spheres.push_back(name);
    }
    if (static_cast<int>(out.spheres.size()) < lim.min_spheres) {
        std::string seen;
        for (const auto& s : out.spheres) seen += (seen.empty() ? "" : ", ") + s;
        return core::make_error(w + "sees " + std::to_string(out.spheres.size()) + " sphere(s) (" +
                                (seen.empty() ? "none" : seen) + ") with at least " +
                                std::to_string(lim.min_points_per_sphere) + " points; needs " +
                                std::to_string(lim.min_spheres));
    }
    if (out.rms_mm > lim.max_rms_mm)
        return core::make_error(w + "residual RMS " + std::to_string(out.rms_mm) +
                                " mm exceeds the limit of " + std::to_string(lim.max_rms_mm) +
                                " mm (wrong artifact, moved during the scan, or a bad start)");
    FaceGeometry& g = out.geometry;
    g.name = f.name;
    g.T_world_camera = Eigen::Isometry3d::Identity();
    g.T_world_camera.linear() = pose.R;
    g.T_world_camera.translation() = pose.t;
    g.travel_scale = pose.v.norm();
    g.scan_direction = pose.v / g.travel_scale;
    g.R_camera_accel = f.R_camera_accel;
    return out;
}

core::Result<AccelMount> estimate_accel_mount(const core::Recording& rec,
                                              const std::vector<FaceGeometry>& faces,
                                              const AlignLimits& lim) {
    std::vector<Eigen::Vector3d> D, G;  // gravity direction in the camera frame, mean reading
    for (const auto& f : rec.faces) {
        const FaceGeometry* g = nullptr;
        for (const auto& c : faces)
            if (c.name == f.name) g = &c;
        if (!g || f.n_accel() < 10)
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
    if (!(svd.singularValues()(1) > 0.1 * kG * kG))
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
    if (m.residual_mps2 > lim.max_gravity_residual_mps2)
        return core::make_error("accelerometer: gravity residual " +
                                std::to_string(m.residual_mps2) + " m/s² exceeds " +
                                std::to_string(lim.max_gravity_residual_mps2) + " m/s²");
    return m;
}

core::Result<Calibration> calibrate_faces(const Artifact& artifact, const core::Recording& rec,
                                          const Calibration& base, const AlignLimits& lim) {
    if (rec.recipe != artifact.name)
        return core::make_error("the recording's recipe is '" + rec.recipe +
                                "', not the artifact '" + artifact.name + "'");
    for (const auto& f : base.faces)
        if (!rec.face(f.name))
            return core::make_error("face " + f.name +
                                    " of the calibration in force is not in the artifact "
                                    "recording: scan every face");
    Calibration c = base;
    c.method = "artifact";
    c.calibrated_at = core::iso8601_utc(core::realtime_ns());
    c.residuals.clear();
    c.faces.clear();
    for (const auto& f : rec.faces) {
        auto fa = align_face(artifact, f, lim);
        if (!fa) return fa.error();
        c.residuals[f.name + ".rms_mm"] = fa->rms_mm;
        c.residuals[f.name + ".spheres"] = static_cast<double>(fa->spheres.size());
        c.faces.push_back(fa->geometry);
    }
    auto mount = estimate_accel_mount(rec, c.faces, lim);
    if (!mount) return mount.error();
    for (auto& f : c.faces) f.R_camera_accel = mount->R_camera_accel;
    c.accel_bias_mps2 = mount->bias_mps2;
    c.residuals["accel.gravity_rms_mps2"] = mount->residual_mps2;
    return c;
}

}  // namespace hotgauge::calib
