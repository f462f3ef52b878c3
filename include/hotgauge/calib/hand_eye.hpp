#pragma once
// Hand-eye calibration for a sensor head moved by a robot (paper §4.1, Eq. 10–13;
// docs/calibration.md "Hand-eye"): from N robot poses and the poses of a fixed target as the
// camera sees it, the camera's pose on the flange X, solving A·X = X·B (and A·X = Z·B) with
// OpenCV's calibrateHandEye (calibrateRobotWorldHandEye), by several methods side by side.
#include <Eigen/Geometry>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::calib {

struct HandEyeSample {
    Eigen::Isometry3d T_base_flange;    // the robot's pose (its controller's report), mm
    Eigen::Isometry3d T_camera_target;  // the fixed target as the camera sees it, mm
};

struct HandEyeSolution {
    std::string method;                 // Tsai, Park, Daniilidis, Shah, Li, Park+refined
    Eigen::Isometry3d T_flange_camera;  // X
    // The target in the base frame through every pose, T_base_flange·X·T_camera_target, is one
    // fixed pose when X is right: its RMS spread about the mean, rotation (deg) and translation.
    double rotation_rms_deg = 0, translation_rms_mm = 0;
};

// OpenCV's Tsai, Park and Daniilidis (A·X = X·B, calibrateHandEye) and Shah and Li (A·X = Z·B,
// calibrateRobotWorldHandEye) side by side, then Park's refined jointly with the target's base
// pose (Gauss–Newton on every sample's pose error), the last one the one to use.
// At least 3 poses whose motions turn about at least two directions (more than 5° apart);
// fewer is an error saying how many there are and what is missing.
core::Result<std::vector<HandEyeSolution>> solve_hand_eye(std::span<const HandEyeSample> samples);

// The poses file (docs/calibration.md "Hand-eye"): format hotgauge-hand-eye-poses-1, `poses`, a
// list of {base_from_flange, camera_from_target}, 4×4 row-major rigid transforms in mm.
// Errors name file:line and the key.
core::Result<std::vector<HandEyeSample>> read_hand_eye_poses(const std::filesystem::path& file);

}  // namespace hotgauge::calib
