#include "drift.hpp"

#include <algorithm>
#include <cmath>

namespace hotgauge::measure::detail {

void DriftSum::add(const FaceFrame& fr, std::int64_t k, const Eigen::Vector3d& w_part) {
    const core::DisplacementNoise* noise = fr.noise;
    if (!noise || !noise->known() || k < 0 || k >= fr.n) return;
    auto it =
        std::find_if(faces_.begin(), faces_.end(), [&](const Face& f) { return f.fr == &fr; });
    if (it == faces_.end()) {
        // M = R_part_world · R_world_camera, so R_world_part = R_world_camera · Mᵀ.
        faces_.push_back(
            {&fr,
             fr.scan->T_world_camera.linear() * fr.M.transpose(),
             {},
             std::vector<Eigen::Vector3d>(noise->holes_s.size(), Eigen::Vector3d::Zero())});
        it = faces_.end() - 1;
    }
    const auto& t = fr.scan->profile_times_ns;
    const double s = 1e-9 * static_cast<double>(t[static_cast<std::size_t>(k)] - t.front());
    const auto bin = static_cast<std::size_t>(std::lround(std::max(0.0, s) / noise->lag_s));
    if (it->bins.size() <= bin) it->bins.resize(bin + 1, Eigen::Vector3d::Zero());
    const Eigen::Vector3d w_world = it->R_world_part * w_part;
    it->bins[bin] += w_world;
    Eigen::Vector3d w_holes = w_world;
    for (int a = 0; a < 3; ++a)
        if (!noise->hole_axes[static_cast<std::size_t>(a)]) w_holes[a] = 0.0;
    for (std::size_t h = 0; h < it->holes.size(); ++h)
        if (const double sigma = noise->hole_sigma(h, s); sigma > 0.0)
            it->holes[h] += sigma * w_holes;
}

double DriftSum::u_holes() const {
    double var = 0;
    for (const Face& f : faces_)
        for (const auto& h : f.holes) var += h.squaredNorm();
    return std::sqrt(var);
}

double DriftSum::u() const {
    double var = 0;
    for (const Face& f : faces_) {
        const auto& acov = f.fr->noise->acov_mm2;
        const std::size_t n = f.bins.size();
        for (int a = 0; a < 3; ++a) {
            const auto& c = acov[static_cast<std::size_t>(a)];
            for (std::size_t i = 0; i < n; ++i) {
                const double wi = f.bins[i][a];
                if (wi == 0.0) continue;
                const std::size_t j0 = i + 1 > c.size() ? i + 1 - c.size() : 0;
                const std::size_t j1 = std::min(n, i + c.size());
                for (std::size_t j = j0; j < j1; ++j)
                    var += wi * f.bins[j][a] * c[i > j ? i - j : j - i];
            }
        }
    }
    return std::sqrt(std::max(0.0, var));
}

void add_holes_term(std::vector<std::pair<std::string, double>>& budget, const DriftSum& d) {
    if (const double u = d.u_holes(); u > 0.0) budget.emplace_back(kHolesTerm, u);
}

void add_plane(DriftSum& d, const std::vector<const FaceFrame*>& frames,
               const std::vector<std::int64_t>& keys, const Eigen::Vector3d& w) {
    if (keys.empty()) return;
    const Eigen::Vector3d each = w / static_cast<double>(keys.size());
    for (const std::int64_t key : keys) {
        const auto face = static_cast<std::size_t>(key >> 32);
        if (face < frames.size()) d.add(*frames[face], key & 0xffffffff, each);
    }
}

void add_radial(DriftSum& d, const FaceFrame& fr, std::int64_t k, const Eigen::Vector2d& radial_sum,
                const Eigen::Vector3d& e1, const Eigen::Vector3d& e2, double n) {
    if (n > 0.0) d.add(fr, k, 2.0 / n * (radial_sum.x() * e1 + radial_sum.y() * e2));
}

}  // namespace hotgauge::measure::detail
