// PLY, binary little-endian 1.0 (http://paulbourke.net/dataformats/ply/).
#include "hotgauge/io/ply.hpp"

#include <bit>
#include <fstream>
#include <string>

namespace hotgauge::io {

static_assert(std::endian::native == std::endian::little, "PLY data is written as raw bytes");

core::Result<void> write_ply(const std::filesystem::path& path,
                             const std::vector<Eigen::Vector3d>& points_mm) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return core::make_error(path.string() + ": cannot open for writing");
    out << "ply\nformat binary_little_endian 1.0\ncomment hotgauge world cloud, mm\nelement vertex "
        << points_mm.size()
        << "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    std::vector<float> buf;
    buf.reserve(points_mm.size() * 3);
    for (const Eigen::Vector3d& p : points_mm) {
        buf.push_back(static_cast<float>(p.x()));
        buf.push_back(static_cast<float>(p.y()));
        buf.push_back(static_cast<float>(p.z()));
    }
    out.write(reinterpret_cast<const char*>(buf.data()),
              static_cast<std::streamsize>(buf.size() * sizeof(float)));
    out.close();
    if (!out) return core::make_error(path.string() + ": write failed");
    return {};
}

}  // namespace hotgauge::io
