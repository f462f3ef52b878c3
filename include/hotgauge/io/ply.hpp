#pragma once
// PLY point clouds for inspection in CloudCompare / MeshLab.
#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

// Writes `points_mm` as a binary little-endian PLY with float32 x, y, z (world frame, mm) and the
// header comment "hotgauge world cloud, mm". An Error names the file when it cannot be written.
core::Result<void> write_ply(const std::filesystem::path& path,
                             const std::vector<Eigen::Vector3d>& points_mm);

}  // namespace hotgauge::io
