#pragma once
// Part pose files: `world_from_part: [[r11,r12,r13,tx],[...],[...],[0,0,0,1]]` (row-major, mm),
// as the simulator writes beside its ground truth and `hotgauge measure --part-pose` reads.
#include <Eigen/Geometry>
#include <filesystem>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

core::Result<Eigen::Isometry3d> read_part_pose(const std::filesystem::path& file);

}  // namespace hotgauge::io
