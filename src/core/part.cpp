#include "hotgauge/core/part.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hotgauge::core {

std::optional<double> Recipe::level(const std::string& level_name) const {
    for (const auto& [n, z] : levels_mm)
        if (n == level_name) return z;
    return std::nullopt;
}

const Section* Recipe::section(const std::string& section_name) const {
    for (const auto* list : {&outer, &inner})
        for (const auto& s : *list)
            if (s.name == section_name) return &s;
    return nullptr;
}

namespace {

constexpr double kProbe = 1e-6;  // mm: how far off a candidate surface membership is tested

// sqrt(x² + y²) without std::hypot's overflow care, which costs 5× and is not needed at mm scale.
inline double radius(double x, double y) { return std::sqrt(x * x + y * y); }

std::vector<double> sorted_unique(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
    return v;
}

double segment_distance(double r, double z, const AxisymmetricSolid::Segment& s) {
    // Segment in (r, z): cylinder -> r = value, z in [lo, hi]; plane -> z = value, r in [lo, hi].
    const double along = s.cylinder ? z : r;
    const double across = s.cylinder ? r : z;
    const double d_along = along < s.lo ? s.lo - along : (along > s.hi ? along - s.hi : 0.0);
    return radius(d_along, across - s.value);
}

}  // namespace

AxisymmetricSolid::AxisymmetricSolid(std::vector<Slab> outer, std::vector<Slab> inner)
    : outer_(std::move(outer)), inner_(std::move(inner)) {
    std::vector<double> zs, rs{0.0};
    z_min_ = std::numeric_limits<double>::max();
    z_max_ = std::numeric_limits<double>::lowest();
    for (const auto* list : {&outer_, &inner_})
        for (const auto& s : *list) {
            zs.push_back(s.z0);
            zs.push_back(s.z1);
            rs.push_back(s.radius);
        }
    for (const auto& s : outer_) {
        z_min_ = std::min(z_min_, s.z0);
        z_max_ = std::max(z_max_, s.z1);
        r_max_ = std::max(r_max_, s.radius);
    }
    zs = sorted_unique(zs);
    rs = sorted_unique(rs);
    // A candidate line is part of the boundary wherever material differs on its two sides.
    for (double z : zs)
        for (std::size_t j = 0; j + 1 < rs.size(); ++j) {
            const double rm = 0.5 * (rs[j] + rs[j + 1]);
            if (inside(rm, z - kProbe) != inside(rm, z + kProbe))
                boundary_.push_back({false, z, rs[j], rs[j + 1]});
        }
    for (double r : rs) {
        if (r <= 0.0) continue;
        for (std::size_t j = 0; j + 1 < zs.size(); ++j) {
            const double zm = 0.5 * (zs[j] + zs[j + 1]);
            if (inside(r - kProbe, zm) != inside(r + kProbe, zm))
                boundary_.push_back({true, r, zs[j], zs[j + 1]});
        }
    }
}

AxisymmetricSolid AxisymmetricSolid::from_recipe(const Recipe& recipe,
                                                 const std::map<std::string, double>& level_mm,
                                                 const std::map<std::string, double>& diameter_mm,
                                                 double scale) {
    auto level = [&](const std::string& n) {
        auto it = level_mm.find(n);
        return scale * (it != level_mm.end() ? it->second : recipe.level(n).value_or(0.0));
    };
    auto slabs = [&](const std::vector<Section>& sections) {
        std::vector<Slab> out;
        for (const auto& s : sections) {
            auto it = diameter_mm.find(s.name);
            const double d = it != diameter_mm.end() ? it->second : s.diameter_mm;
            out.push_back({level(s.from_level), level(s.to_level), 0.5 * d * scale});
        }
        return out;
    };
    return AxisymmetricSolid(slabs(recipe.outer), slabs(recipe.inner));
}

bool AxisymmetricSolid::inside(double r, double z) const {
    bool in = false;
    for (const auto& s : outer_)
        if (z > s.z0 && z < s.z1 && r < s.radius) in = true;
    if (!in) return false;
    for (const auto& s : inner_)
        if (z > s.z0 && z < s.z1 && r < s.radius) return false;
    return true;
}

double AxisymmetricSolid::distance(const Eigen::Vector3d& p) const {
    const double r = radius(p.x(), p.y());
    double best = std::numeric_limits<double>::max();
    for (const auto& s : boundary_) best = std::min(best, segment_distance(r, p.z(), s));
    return best;
}

std::optional<AxisymmetricSolid::Hit> AxisymmetricSolid::intersect(const Eigen::Vector3d& o,
                                                                   const Eigen::Vector3d& d,
                                                                   double t_max) const {
    constexpr double kMinT = 1e-9;
    const double a = d.x() * d.x() + d.y() * d.y();
    const double b = 2.0 * (o.x() * d.x() + o.y() * d.y());
    const double c0 = o.x() * o.x() + o.y() * o.y();
    // Quick reject: the ray never comes within the bounding cylinder.
    if (a > 0.0) {
        const double t_closest = -b / (2.0 * a);
        const double r2_min = c0 + b * t_closest + a * t_closest * t_closest;
        if (r2_min > r_max_ * r_max_ * 1.0000001) return std::nullopt;
    }
    double best_t = t_max;
    const Segment* best = nullptr;
    for (const auto& s : boundary_) {
        if (s.cylinder) {
            if (a <= 0.0) continue;
            const double c = c0 - s.value * s.value;
            const double disc = b * b - 4.0 * a * c;
            if (disc < 0.0) continue;
            const double sq = std::sqrt(disc);
            for (double t : {(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)}) {
                if (t <= kMinT || t >= best_t) continue;
                const double z = o.z() + t * d.z();
                if (z >= s.lo && z <= s.hi) {
                    best_t = t;
                    best = &s;
                }
            }
        } else {
            if (d.z() == 0.0) continue;
            const double t = (s.value - o.z()) / d.z();
            if (t <= kMinT || t >= best_t) continue;
            const double r = radius(o.x() + t * d.x(), o.y() + t * d.y());
            if (r >= s.lo && r <= s.hi) {
                best_t = t;
                best = &s;
            }
        }
    }
    if (!best) return std::nullopt;
    const Eigen::Vector3d p = o + best_t * d;
    Eigen::Vector3d n;
    if (best->cylinder) {
        const double r = radius(p.x(), p.y());
        const double sign = inside(best->value - kProbe, p.z()) ? 1.0 : -1.0;
        n = sign * Eigen::Vector3d(p.x() / r, p.y() / r, 0.0);
    } else {
        const double r = radius(p.x(), p.y());
        n = Eigen::Vector3d(0, 0, inside(r, best->value - kProbe) ? 1.0 : -1.0);
    }
    return Hit{best_t, n};
}

}  // namespace hotgauge::core
