#pragma once
// Geometric least-squares fitting of planes and circles (orthogonal distances), with robust
// variants (docs/measurement.md). Pure functions on plain data; every degenerate input (too few
// points, collinear points, non-finite values) is an Error, never a NaN result.
#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::measure {

struct PlaneFit {
    Eigen::Vector3d point = Eigen::Vector3d::Zero();    // centroid of the points used
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit
    double rms_mm = 0.0;                                // RMS orthogonal residual
    std::int64_t n_points = 0;
    double distance(const Eigen::Vector3d& p) const { return normal.dot(p - point); }  // signed
};

// Orthogonal-distance least-squares plane (NIST Plane convention: point = centroid).
core::Result<PlaneFit> fit_plane(std::span<const Eigen::Vector3d> points);

struct CircleFit {
    Eigen::Vector2d center = Eigen::Vector2d::Zero();
    double radius = 0.0;
    double rms_mm = 0.0;  // RMS of geometric residuals |p − c| − r
    std::int64_t n_points = 0;
    double u_radius_mm = 0.0;  // standard uncertainty of the radius from the fit (Jacobian, s²)
    double u_center_mm = 0.0;  // standard uncertainty of the centre (sqrt of the larger eigenvalue)
    int iterations = 0;        // Levenberg–Marquardt iterations
};

// Algebraic circle fit (Taubin), unbiased enough on partial arcs to seed the geometric fit.
core::Result<CircleFit> fit_circle_algebraic(std::span<const Eigen::Vector2d> points);
// Geometric (orthogonal-distance) circle: Levenberg–Marquardt seeded by fit_circle_algebraic.
core::Result<CircleFit> fit_circle(std::span<const Eigen::Vector2d> points);

struct Circle3dFit {
    Eigen::Vector3d center = Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  // unit normal of the circle's plane
    double radius = 0.0;
    double rms_mm = 0.0;  // RMS in-plane residual
    std::int64_t n_points = 0;
};

// NIST's 3D circle: least-squares plane, projection onto it, geometric 2D circle in it.
core::Result<Circle3dFit> fit_circle3d(std::span<const Eigen::Vector3d> points);

// Robust fits: iterative rejection of points whose |residual| exceeds
// max(k_sigma · rms, min_threshold_mm), refitting until no point changes (paper §4.3.1).
struct RejectOptions {
    double k_sigma = 3.0;
    double min_threshold_mm = 0.0;
    int max_rounds = 10;
};
struct RobustPlaneFit {
    PlaneFit fit;
    std::vector<std::uint8_t> inlier;  // per input point
};
struct RobustCircleFit {
    CircleFit fit;
    std::vector<std::uint8_t> inlier;
};
core::Result<RobustPlaneFit> fit_plane_robust(std::span<const Eigen::Vector3d> points,
                                              const RejectOptions& options = {});
core::Result<RobustCircleFit> fit_circle_robust(std::span<const Eigen::Vector2d> points,
                                                const RejectOptions& options = {});

// RANSAC seed for a plane among other surfaces: the plane with most points within
// `threshold_mm`, refined by least squares on its inliers. Deterministic for a given seed.
struct RansacOptions {
    double threshold_mm = 0.2;
    int iterations = 200;
    std::uint64_t seed = 1;
};
core::Result<RobustPlaneFit> ransac_plane(std::span<const Eigen::Vector3d> points,
                                          const RansacOptions& options = {});

// Between-value standard deviation τ of values v with standard uncertainties u: the spread the
// values show beyond their own uncertainties, 0 when they agree within them (DerSimonian & Laird
// 1986, the random-effects moment estimator; checked against statsmodels, data/oracle). An
// uncertainty below 1e-6 counts as 1e-6: an exact value takes most of the weight, not all of it.
// Error: fewer than two values, sizes differ, a non-finite value or a negative uncertainty.
core::Result<double> between_std(std::span<const double> v, std::span<const double> u);

}  // namespace hotgauge::measure
