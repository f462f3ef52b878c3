#include "hotgauge/io/pose_io.hpp"

#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::io {

core::Result<Eigen::Isometry3d> read_part_pose(const std::filesystem::path& file) {
    const YamlReader y(file.string());
    return y.guarded<Eigen::Isometry3d>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "pose file", {"world_from_part"});
        return y.isometry(y.require(root, "pose file", "world_from_part"), "world_from_part");
    });
}

}  // namespace hotgauge::io
