#pragma once
// The two steps of calib::align_face (docs/calibration.md "Faces"), private to calib:
//  1. find_balls + place_from_balls: each ball found among the points near where the recorded
//     geometry puts it (RANSAC on its known radius), and the face placed from the balls' centres;
//  2. fit_points: every point on the artifact fitted by Ceres (trust region, rotation on SO(3),
//     Cauchy loss) with the pose's covariance in physical units.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "hotgauge/calib/align.hpp"
#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::calib::detail {

// A profile point: camera point (x, 0, z) and the commanded travel c of its profile.
struct ScanPoint {
    Eigen::Vector3d q;
    double c;
};

std::vector<ScanPoint> scan_points(const core::FaceScan& face);

// The nine unknowns of a face: camera pose at travel 0 and travel vector per commanded mm, so
// that world = R·q + t + c·v, an affine map of the scan coordinates u = (x, c, z).
struct FacePose {
    Eigen::Quaterniond R = Eigen::Quaterniond::Identity();
    Eigen::Vector3d t = Eigen::Vector3d::Zero(), v = Eigen::Vector3d::UnitY();
    Eigen::Vector3d world(const ScanPoint& p) const { return R * p.q + t + p.c * v; }
    // The scan coordinates u = (x, c, z) of a world point (the affine map inverted).
    Eigen::Vector3d scan(const Eigen::Vector3d& world) const;
};

// A ball of the artifact as one face sees it.
struct BallSeen {
    int sphere = -1;         // index into Artifact::spheres
    Eigen::Vector3d u;       // its centre in scan coordinates (x, c, z)
    int points = 0;          // points within the RANSAC band
    double rms_mm = 0.0;     // their distance from the fitted ball, RMS
    double placed_mm = 0.0;  // distance of the placed centre from the artifact's (step 1)
};

// Per artifact sphere, its ball among the points that `recorded` puts within
// limits.max_start_error_mm of it: the largest set of points on one sphere of the artifact's
// radius (RANSAC, deterministic), then its centre refined. Balls with fewer than
// limits.min_points_per_sphere points are left out.
std::vector<BallSeen> find_balls(const Artifact& artifact, const std::vector<ScanPoint>& points,
                                 const FacePose& recorded, const AlignLimits& limits);

// The pose that maps the balls' scan coordinates onto the artifact's centres (least squares on
// the nine unknowns, from `recorded`). A ball that does not fit the others (another ball found in
// its place) is dropped while 3 remain; `balls` is left with the ones used.
core::Result<FacePose> place_from_balls(const Artifact& artifact, std::vector<BallSeen>& balls,
                                        const FacePose& recorded);

// Tangent-space order of the covariance: rotation vector (rad, world axes), t (mm), v (mm/mm).
using Matrix9 = Eigen::Matrix<double, 9, 9>;

struct PointFit {
    FacePose pose;
    Matrix9 covariance = Matrix9::Zero();         // scaled by the residual variance
    bool covariance_ok = false;                   // false: the Jacobian is rank deficient
    Matrix9 information = Matrix9::Zero();        // JᵀJ / σ² at the solution, same order
    double rms_mm = 0.0;                          // RMS of the points used
    std::vector<int> counts;                      // points used per artifact surface
    std::vector<double> mean_mm, rms_surface_mm;  // per artifact surface, over those points
    ResidualMap map;
    int iterations = 0;
};

// Every point within reach of an artifact surface fitted to it, starting from `start` (within
// about 0.1 mm: place_from_balls); two rounds, the second on the points within 5σ of the first.
core::Result<PointFit> fit_points(const Artifact& artifact, const std::vector<ScanPoint>& points,
                                  const FacePose& start);

}  // namespace hotgauge::calib::detail
