#pragma once
// Finding the part: PPF Hough voting over the scans of all faces in the world frame, pose
// clustering, verification of the best clusters by ICP, and a robust point-to-plane ICP on the
// dense scans (docs/matching.md).
#include <Eigen/Geometry>
#include <map>
#include <string>
#include <vector>

#include "hotgauge/core/recording.hpp"
#include "hotgauge/match/model.hpp"

namespace hotgauge::match {

struct MatchConfig {
    double scene_sampling_mm = 0.0;       // voting samples; 0: the model's sampling
    double normal_radius_mm = 1.5;        // scene normals from the scan grid within this radius
    int max_reference_points = 60;        // scene reference points (evenly spread subset)
    double cluster_angle_deg = 15.0;      // poses closer than this (axis or rotation) cluster
    double cluster_distance_mm = 0.0;     // ... and closer than this; 0: 2 × sampling
    int max_hypotheses = 6;               // best clusters verified by ICP
    bool remove_background_plane = true;  // a plane larger than the part is not the part
    double background_band_mm = 1.5;
    // ICP
    double icp_grid_mm = 1.5;  // dense ICP samples: the scan grid thinned to this pitch
    int icp_max_iterations = 30;
    double icp_stop_mm = 1e-4;  // stop when the largest point motion is below this
    // Verdict
    double inlier_band_mm = 0.3;  // a scan point this close to the fitted surface supports it
    // The score's band (0: inlier_band_mm): a part off nominal by as much as a sorting gauge must
    // follow still lies within it, so the score finds the part and never checks a dimension.
    double score_band_mm = 0.0;
    double min_score = 0.6;  // found when score >= this (recipe matching.min_score)
    std::int64_t min_inliers = 500;
    // Model scale (thermal growth): fixed when known, else estimated by ICP.
    std::optional<double> scale;
    // Voting and the scene preparation run on this many threads (0: one per core). Each piece's
    // result is kept apart and combined in one order, so the pose does not depend on it
    // (tests/test_threads.cpp).
    int threads = 0;
};

struct MatchResult {
    bool found = false;
    std::string reason;  // why not found
    Eigen::Isometry3d T_world_part = Eigen::Isometry3d::Identity();
    double score = 0;  // fraction of scan points near the part that lie on the model
    double scale = 1;  // model scale used or estimated
    bool scale_estimated = false;
    double votes = 0;    // PPF votes of the winning cluster
    int hypotheses = 0;  // clusters verified
    double rms_mm = 0;   // ICP residual RMS of the inliers
    std::int64_t inliers = 0;
    int iterations = 0;
    std::int64_t scene_points = 0, reference_points = 0, background_removed = 0;
    std::vector<std::pair<std::string, double>> stage_ms;
};

// Finds the model in the faces of `rec` (world frame; each face moved by its compensation `u`
// when given). Never reports a pose as found when its score is below the threshold.
MatchResult match(const Model& model, const core::Recording& rec, const core::FaceDisplacements& u,
                  const MatchConfig& config = {});

// For an axisymmetric model: the pose with the same axis and origin, spun about the axis to the
// canonical angle (the smallest rotation that takes the part's +z onto the axis).
Eigen::Isometry3d canonical_spin(const Eigen::Isometry3d& T_world_part);

// Pose errors of an axisymmetric part, spin ignored: angle between the axes (degrees), distance
// of the true origin from the estimated axis line (mm), offset of the origins along the axis (mm).
struct AxisError {
    double angle_deg = 0, radial_mm = 0, axial_mm = 0;
};
AxisError axis_error(const Eigen::Isometry3d& T_true, const Eigen::Isometry3d& T_est);

}  // namespace hotgauge::match
