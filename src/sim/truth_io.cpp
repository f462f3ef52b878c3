#include <cstdio>
#include <fstream>
#include <map>
#include <ostream>

#include "hotgauge/io/npy.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::sim {
namespace {

std::string num(double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.17g", v);
    return buf;
}

std::string matrix_rows(const Eigen::Matrix4d& M) {
    std::string s = "[";
    for (int r = 0; r < 4; ++r) {
        s += r ? ", [" : "[";
        for (int c = 0; c < 4; ++c) s += (c ? ", " : "") + num(M(r, c));
        s += "]";
    }
    return s + "]";
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

void write_map(std::ostream& f, const char* key, const std::map<std::string, double>& m,
               const char* indent = "") {
    f << indent << key << ":" << (m.empty() ? " {}" : "") << "\n";
    for (const auto& [k, v] : m) f << indent << "  " << quoted(k) << ": " << num(v) << "\n";
}

std::string profile(const core::ForgedSolid::Profile& p) {
    std::string s = "[";
    for (std::size_t i = 0; i < p.size(); ++i)
        s += (i ? ", [" : "[") + num(p[i].x()) + ", " + num(p[i].y()) + "]";
    return s + "]";
}

// The drawn as-forged geometry, cold, part frame (docs/simulator.md "As-forged parts").
void write_forged(std::ostream& f, const core::ForgedPart& part) {
    f << "forged:           # cold mm, part frame; profiles (r, z) about each half's own axis\n"
      << "  parting_z_mm: " << num(part.parting_z_mm) << "\n"
      << "  die_shift_mm: [" << num(part.shape.die_shift_mm.x()) << ", "
      << num(part.shape.die_shift_mm.y()) << "]   # the upper half's axis, part x, y\n";
    write_map(f, "draft_deg", part.draft_deg, "  ");
    write_map(f, "fillet_mm", part.fillet_mm, "  ");
    write_map(f, "fillet_drawn_mm", part.shape.fillet_mm, "  ");
    f << "  profile_lower_sharp: " << profile(part.lower_sharp) << "\n"
      << "  profile_upper_sharp: " << profile(part.upper_sharp) << "\n"
      << "  profile_lower: " << profile(part.lower) << "\n"
      << "  profile_upper: " << profile(part.upper) << "\n";
}

}  // namespace

core::Result<void> write_truth(const SimTruth& truth, const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return core::make_error(dir.string() + ": cannot create directory: " + ec.message());
    {
        std::ofstream f(dir / "part_pose.yaml");
        f << "# true pose of the part: maps part coordinates into world, row-major, mm\n"
          << "world_from_part: " << matrix_rows(truth.T_world_part.matrix()) << "\n";
        if (!f) return core::make_error((dir / "part_pose.yaml").string() + ": write failed");
    }
    std::ofstream f(dir / "truth.yaml");
    f << "# ground truth of a simulated part (hotgauge simulate)\n"
      << "world_from_part: " << matrix_rows(truth.T_world_part.matrix()) << "\n"
      << "temperature_c: " << num(truth.temperature_c) << "\n"
      << "growth: " << num(truth.growth) << "   # 1 + alpha(T) (T - 20)\n"
      << "range_noise_mm: " << num(truth.range_noise_mm) << "\n"
      << "levels_mm:        # actual cold part\n";
    for (const auto& [k, v] : truth.levels_mm) f << "  " << quoted(k) << ": " << num(v) << "\n";
    f << "diameters_mm:\n";
    for (const auto& [k, v] : truth.diameters_mm) f << "  " << quoted(k) << ": " << num(v) << "\n";
    if (!truth.bad_mm.empty()) write_map(f, "bad_mm", truth.bad_mm);
    if (truth.forged) write_forged(f, *truth.forged);
    f << "features:\n";
    for (const auto& ft : truth.features)
        f << "  - {name: " << quoted(ft.name) << ", hot_mm: " << num(ft.hot_mm)
          << ", cold_mm: " << num(ft.cold_mm) << "}\n";
    f << "faces:\n";
    for (const auto& face : truth.faces) {
        double peak = 0.0;
        for (const auto& u : face.displacement_mm) peak = std::max(peak, u.norm());
        f << "  - {name: " << quoted(face.name) << ", profiles: " << face.displacement_mm.size()
          << ", spikes: " << face.n_spikes << ", peak_displacement_mm: " << num(peak) << "}\n";
        const auto fdir = dir / face.name;
        std::filesystem::create_directories(fdir, ec);
        if (ec)
            return core::make_error(fdir.string() + ": cannot create directory: " + ec.message());
        std::vector<double> u;
        for (const auto& v : face.displacement_mm) u.insert(u.end(), {v.x(), v.y(), v.z()});
        const auto n = static_cast<std::int64_t>(face.displacement_mm.size());
        if (auto r = io::write_npy(fdir / "u_true.npy", "<f8", {n, 3}, u.data(), u.size() * 8); !r)
            return r;
        const std::int64_t w = n ? static_cast<std::int64_t>(face.spike.size()) / n : 0;
        if (auto r = io::write_npy(fdir / "spikes.npy", "|u1", {n, w}, face.spike.data(),
                                   face.spike.size());
            !r)
            return r;
    }
    if (!f) return core::make_error((dir / "truth.yaml").string() + ": write failed");
    return {};
}

}  // namespace hotgauge::sim
