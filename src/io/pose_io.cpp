#include "hotgauge/io/pose_io.hpp"

#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::io {

core::Result<Eigen::Isometry3d> read_part_pose(const std::filesystem::path& file) {
    const YamlReader y(file.string());
    try {
        const YAML::Node root = y.load();
        y.expect_map(root, "pose file", {"world_from_part"});
        const YAML::Node m = y.require(root, "pose file", "world_from_part");
        if (!m.IsSequence() || m.size() != 4) y.fail(m, "world_from_part: expected 4 rows");
        Eigen::Matrix4d M;
        for (int r = 0; r < 4; ++r) {
            const auto row = y.numbers(m[r], "world_from_part", 4);
            for (int c = 0; c < 4; ++c) M(r, c) = row[c];
        }
        if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-12)
            y.fail(m, "world_from_part: last row must be [0, 0, 0, 1]");
        if (!core::is_rotation(M.topLeftCorner<3, 3>()))
            y.fail(m, "world_from_part: not a proper rotation (orthonormal, det +1)");
        Eigen::Isometry3d T;
        T.matrix() = M;
        return T;
    } catch (const YamlError& e) {
        return core::make_error(e.what());
    } catch (const YAML::Exception& e) {
        return core::make_error(file.string() + ":" + std::to_string(e.mark.line + 1) + ": " +
                                e.msg);
    }
}

}  // namespace hotgauge::io
