#pragma once
// Small geometry helpers shared by every module (frames and units: docs/architecture.md).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "hotgauge/core/recording.hpp"

namespace hotgauge::core {

// True when R is a proper rotation: RᵀR = I and det R = +1, each within `tol`.
bool is_rotation(const Eigen::Matrix3d& R, double tol = 1e-6);

// A world-frame point cloud of one face, with the (profile, column) each point came from.
struct FaceCloud {
    std::vector<Eigen::Vector3d> points_mm;
    std::vector<std::int32_t> profile;  // k of each point
    std::vector<std::int32_t> column;   // i of each point
};

// World points of every valid (non-NaN) profile point. With `displacement_mm` (one world-frame
// sensor displacement per profile, mm) each profile is moved by +u (the compensation sign
// convention of recording-format-v1); without it the nominal cloud is returned.
FaceCloud world_cloud(const FaceScan& face,
                      const std::vector<Eigen::Vector3d>* displacement_mm = nullptr);

}  // namespace hotgauge::core
