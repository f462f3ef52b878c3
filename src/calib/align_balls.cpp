// Step 1 of the face alignment: the balls found from a start up to a few mm and degrees off, and
// the face placed from their centres (docs/calibration.md "Faces").
#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <random>

#include "align_steps.hpp"

namespace hotgauge::calib::detail {
namespace {

// Sensor noise is about 0.05 mm; a point belongs to a candidate ball within 10σ of its surface.
// The recorded geometry distorts a ball by its travel-scale and direction errors only (0.1 %
// of 40 mm: 0.04 mm), so the band holds the whole ball.
constexpr double kBandMm = 0.5;
constexpr int kRansacRounds = 600;          // hypotheses per ball (not measured)
constexpr std::size_t kScoreSample = 3000;  // candidates a hypothesis is scored on
// Deterministic: the same scan gives the same calibration (docs/calibration.md "Faces").
constexpr unsigned kRansacSeed = 20261207u;
// A four-point sphere is a hypothesis when its radius is within this fraction of the
// certificate's (not measured).
constexpr double kRadiusFraction = 0.1;
// Four points whose system's determinant is below this are taken as on one plane (a guard, not
// measured).
constexpr double kMinDeterminant = 1e-6;
// Gauss–Newton on a ball's centre: at most this many steps, done when a step is below this (mm,
// far below the 0.05 mm noise) (not measured).
constexpr int kCentreIterations = 8;
constexpr double kCentreStepMm = 1e-7;
// Ceres on the balls' centres (a few balls × 3 residuals): iterations and tolerances (not
// measured).
constexpr int kCentresMaxIterations = 100;
constexpr double kCentresFunctionTolerance = 1e-14;
constexpr double kCentresParameterTolerance = 1e-12;

// The sphere through four points, or false when they are (nearly) on one plane.
bool sphere_through(const Eigen::Vector3d* p, Eigen::Vector3d& centre, double& radius) {
    Eigen::Matrix4d A;
    Eigen::Vector4d b;
    for (int i = 0; i < 4; ++i) {  // 2·p·c − k = |p|², k = |c|² − r²
        A.row(i) << 2.0 * p[i].transpose(), -1.0;
        b(i) = p[i].squaredNorm();
    }
    const Eigen::FullPivLU<Eigen::Matrix4d> lu(A);
    if (!lu.isInvertible() || std::abs(A.determinant()) < kMinDeterminant) return false;
    const Eigen::Vector4d x = lu.solve(b);
    centre = x.head<3>();
    const double r2 = centre.squaredNorm() - x(3);
    if (!(r2 > 0.0)) return false;
    radius = std::sqrt(r2);
    return true;
}

int count_in_band(const std::vector<Eigen::Vector3d>& pts, std::size_t stride,
                  const Eigen::Vector3d& c, double r) {
    int n = 0;
    for (std::size_t i = 0; i < pts.size(); i += stride)
        n += std::abs((pts[i] - c).norm() - r) < kBandMm;
    return n;
}

// Gauss–Newton on the centre of a ball of known radius, over the points within the band.
Eigen::Vector3d refine_centre(const std::vector<Eigen::Vector3d>& pts, Eigen::Vector3d c, double r,
                              int& used, double& rms) {
    for (int it = 0; it < kCentreIterations; ++it) {
        Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
        Eigen::Vector3d g = Eigen::Vector3d::Zero();
        double sum2 = 0.0;
        used = 0;
        for (const auto& p : pts) {
            const Eigen::Vector3d d = p - c;
            const double dist = d.norm(), e = dist - r;
            if (!(std::abs(e) < kBandMm)) continue;
            const Eigen::Vector3d J = -d / dist;  // d e / d c
            H += J * J.transpose();
            g += J * e;
            sum2 += e * e;
            ++used;
        }
        if (used < 4) return c;
        rms = std::sqrt(sum2 / used);
        const Eigen::Vector3d step = -H.ldlt().solve(g);
        c += step;
        if (step.norm() < kCentreStepMm) break;
    }
    return c;
}

// The largest set of candidate points on one sphere of radius r (RANSAC), its centre refined.
bool find_ball(const std::vector<Eigen::Vector3d>& cand, double r, Eigen::Vector3d& centre,
               int& used, double& rms) {
    std::mt19937 rng(kRansacSeed);
    std::uniform_int_distribution<std::size_t> pick(0, cand.size() - 1);
    const std::size_t stride = std::max<std::size_t>(1, cand.size() / kScoreSample);
    int best = 0;
    for (int round = 0; round < kRansacRounds; ++round) {
        Eigen::Vector3d p[4], c;
        for (auto& q : p) q = cand[pick(rng)];
        double radius = 0.0;
        if (!sphere_through(p, c, radius) || std::abs(radius - r) > kRadiusFraction * r) continue;
        const int n = count_in_band(cand, stride, c, r);
        if (n > best) {
            best = n;
            centre = c;
        }
    }
    if (best == 0) return false;
    centre = refine_centre(cand, centre, r, used, rms);
    return true;
}

}  // namespace

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

Eigen::Vector3d FacePose::scan(const Eigen::Vector3d& p) const {
    const Eigen::Matrix3d Rm = R.toRotationMatrix();
    Eigen::Matrix3d A;
    A << Rm.col(0), v, Rm.col(2);
    return A.lu().solve(p - t);
}

std::vector<BallSeen> find_balls(const Artifact& a, const std::vector<ScanPoint>& pts,
                                 const FacePose& recorded, const AlignLimits& lim) {
    std::vector<BallSeen> out;
    std::vector<Eigen::Vector3d> world(pts.size());
    for (std::size_t i = 0; i < pts.size(); ++i) world[i] = recorded.world(pts[i]);
    for (std::size_t j = 0; j < a.spheres.size(); ++j) {
        const ArtifactSphere& s = a.spheres[j];
        const double r = 0.5 * s.diameter_mm, reach = r + lim.max_start_error_mm;
        std::vector<Eigen::Vector3d> cand;
        for (const auto& p : world)
            if ((p - s.center_mm).squaredNorm() < reach * reach) cand.push_back(p);
        if (static_cast<int>(cand.size()) < lim.min_points_per_sphere) continue;
        BallSeen b;
        Eigen::Vector3d centre;
        if (!find_ball(cand, r, centre, b.points, b.rms_mm) || b.points < lim.min_points_per_sphere)
            continue;
        b.sphere = static_cast<int>(j);
        b.u = recorded.scan(centre);
        out.push_back(b);
    }
    return out;
}

namespace {

// A ball's centre placed by the pose, minus the artifact's: three residuals.
struct CentreResidual {
    Eigen::Vector3d u, centre;
    template <typename T>
    bool operator()(const T* q, const T* t, const T* v, T* r) const {
        const T p[3] = {T(u.x()), T(0), T(u.z())};
        T Rp[3];
        const T wxyz[4] = {q[3], q[0], q[1], q[2]};  // Eigen stores x, y, z, w
        ceres::UnitQuaternionRotatePoint(wxyz, p, Rp);
        for (int k = 0; k < 3; ++k) r[k] = Rp[k] + t[k] + T(u.y()) * v[k] - T(centre[k]);
        return true;
    }
};

FacePose solve_centres(const Artifact& a, const std::vector<BallSeen>& balls, FacePose pose) {
    ceres::Problem problem;
    for (const auto& b : balls)
        problem.AddResidualBlock(new ceres::AutoDiffCostFunction<CentreResidual, 3, 4, 3, 3>(
                                     new CentreResidual{b.u, a.spheres[b.sphere].center_mm}),
                                 nullptr, pose.R.coeffs().data(), pose.t.data(), pose.v.data());
    problem.SetManifold(pose.R.coeffs().data(), new ceres::EigenQuaternionManifold);
    ceres::Solver::Options opt;
    opt.logging_type = ceres::SILENT;
    opt.max_num_iterations = kCentresMaxIterations;
    opt.function_tolerance = kCentresFunctionTolerance;
    opt.parameter_tolerance = kCentresParameterTolerance;
    ceres::Solver::Summary summary;
    ceres::Solve(opt, &problem, &summary);
    pose.R.normalize();
    return pose;
}

}  // namespace

core::Result<FacePose> place_from_balls(const Artifact& a, std::vector<BallSeen>& balls,
                                        const FacePose& recorded) {
    // The balls fit each other to the sensor's noise; one 2 mm off is another ball or debris.
    constexpr double kMisfitMm = 2.0;
    while (balls.size() >= 3) {
        const FacePose pose = solve_centres(a, balls, recorded);
        std::size_t worst = 0;
        for (std::size_t i = 0; i < balls.size(); ++i) {
            const ScanPoint p{{balls[i].u.x(), 0.0, balls[i].u.z()}, balls[i].u.y()};
            balls[i].placed_mm = (pose.world(p) - a.spheres[balls[i].sphere].center_mm).norm();
            if (balls[i].placed_mm > balls[worst].placed_mm) worst = i;
        }
        if (balls[worst].placed_mm <= kMisfitMm || balls.size() == 3) {
            if (balls[worst].placed_mm > kMisfitMm)
                return core::make_error("the balls it sees do not fit the artifact: " +
                                        a.spheres[balls[worst].sphere].name + " is " +
                                        std::to_string(balls[worst].placed_mm) +
                                        " mm from where the others put it");
            return pose;
        }
        balls.erase(balls.begin() + static_cast<std::ptrdiff_t>(worst));
    }
    return core::make_error("fewer than 3 balls to place it from");
}

}  // namespace hotgauge::calib::detail
