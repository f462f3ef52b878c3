#include "hotgauge/core/forged.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace hotgauge::core {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kMaxSag = 0.0005;   // mm: largest sag of a fillet chord (cold)
constexpr int kMinChords = 16;       // per fillet arc
constexpr double kNarrowFace = 0.4;  // a fillet's tangent length <= this × each of its faces

// One conical piece of a section's wall: r(z) = r_a + k·tan(draft)·(|z − zp| − |z_a − zp|),
// k = −1 outside (narrower away from the parting plane), +1 in a bore (wider away from it).
struct Wall {
    std::string name, section, from_level, to_level;  // a level "" is the parting plane
    bool inner = false;
    double z0 = 0, z1 = 0, r_a = 0, z_a = 0, tan_draft = 0, zp = 0;
    double r(double z) const {
        const double k = inner ? 1.0 : -1.0;
        return r_a + k * tan_draft * (std::abs(z - zp) - std::abs(z_a - zp));
    }
};

struct Vertex {
    Eigen::Vector2d p;
    std::string level;  // "" on the parting plane or the axis
    bool parting = false;
    std::string corner;  // its name once named; "" : not filleted
};

// The part's actual levels, diameters and parting plane.
struct Actual {
    const Recipe& recipe;
    const ForgedShape& shape;
    double zp = 0;
    double level(const std::string& n) const {
        const auto it = shape.levels_mm.find(n);
        return it != shape.levels_mm.end() ? it->second : recipe.level(n).value_or(0.0);
    }
    double diameter(const Section& s) const {
        const auto it = shape.diameters_mm.find(s.name);
        return it != shape.diameters_mm.end() ? it->second : s.diameter_mm;
    }
    double tan_draft(const std::string& wall) const {
        const auto it = shape.draft_deg.find(wall);
        return it != shape.draft_deg.end() ? std::tan(it->second * kDeg) : 0.0;
    }
};

// The parting plane keeps its place between the two nominal levels around it.
Result<double> parting_plane(const Actual& a) {
    const Recipe& r = a.recipe;
    double lo = 0, hi = 0;
    for (const auto& [n, z] : r.levels_mm) {
        lo = std::min(lo, z);
        hi = std::max(hi, z);
    }
    const double zp = r.forging ? r.forging->parting_z_mm : 0.5 * (lo + hi);
    const std::pair<std::string, double>*below = nullptr, *above = nullptr;
    for (const auto& l : r.levels_mm) {
        if (l.second < zp && (!below || l.second > below->second)) below = &l;
        if (l.second > zp && (!above || l.second < above->second)) above = &l;
    }
    if (!below || !above)
        return make_error(r.source + ": forging.parting_z_mm " + std::to_string(zp) +
                          " must lie strictly between two levels of the part");
    const double f = (zp - below->second) / (above->second - below->second);
    return a.level(below->first) + f * (a.level(above->first) - a.level(below->first));
}

// The level its diameter is defined at: its feature's edge, else the parting plane for a wall
// across it, else the wall's end nearest the parting plane.
double anchor_z(const Actual& a, const Section& s, double z0, double z1) {
    for (const auto& f : a.recipe.features)
        if (f.kind == FeatureKind::kDiameter && f.section == s.name) return a.level(f.edge_at);
    if (z0 < a.zp && z1 > a.zp) return a.zp;
    return std::abs(z0 - a.zp) < std::abs(z1 - a.zp) ? z0 : z1;
}

// The wall pieces of one contour, bottom to top (a section across the parting plane: two).
Result<std::vector<Wall>> contour_walls(const Actual& a, const std::vector<Section>& sections,
                                        bool inner) {
    std::vector<Wall> out;
    for (std::size_t i = 0; i < sections.size(); ++i) {
        const Section& s = sections[i];
        if (i > 0 && s.from_level != sections[i - 1].to_level)
            return make_error(a.recipe.source + ": a forged part needs stacked sections: '" +
                              s.name + "' does not start where '" + sections[i - 1].name +
                              "' ends");
        const double z0 = a.level(s.from_level), z1 = a.level(s.to_level);
        Wall w{s.name,
               s.name,
               s.from_level,
               s.to_level,
               inner,
               z0,
               z1,
               0.5 * a.diameter(s),
               anchor_z(a, s, z0, z1),
               0.0,
               a.zp};
        if (!(z0 < a.zp && z1 > a.zp)) {
            w.tan_draft = a.tan_draft(w.name);
            out.push_back(w);
            continue;
        }
        Wall lower = w, upper = w;
        lower.name = s.name + " lower";
        upper.name = s.name + " upper";
        lower.to_level = upper.from_level = "";
        lower.z1 = upper.z0 = a.zp;
        lower.tan_draft = a.tan_draft(lower.name);
        upper.tan_draft = a.tan_draft(upper.name);
        // The piece without the anchor continues the anchored one at the parting plane.
        Wall& anchored = w.z_a < a.zp ? lower : upper;
        Wall& other = w.z_a < a.zp ? upper : lower;
        other.r_a = anchored.r(a.zp);
        other.z_a = a.zp;
        out.push_back(lower);
        out.push_back(upper);
    }
    return out;
}

// A contour's vertices bottom to top; the parting-plane vertex once.
std::vector<Vertex> chain(const std::vector<Wall>& walls) {
    std::vector<Vertex> v;
    for (const auto& w : walls) {
        const Vertex a{{w.r(w.z0), w.z0}, w.from_level, w.from_level.empty(), ""};
        const Vertex b{{w.r(w.z1), w.z1}, w.to_level, w.to_level.empty(), ""};
        if (v.empty() || v.back().p != a.p) v.push_back(a);
        v.push_back(b);
    }
    return v;
}

// Names every filleted vertex (on a level, off the axis) by its level and place in it.
void name_corners(std::vector<Vertex>& poly) {
    std::map<std::string, std::vector<Vertex*>> by_level;
    for (auto& v : poly)
        if (!v.level.empty() && !v.parting && v.p.x() > 0) by_level[v.level].push_back(&v);
    for (auto& [level, vs] : by_level) {
        std::sort(vs.begin(), vs.end(),
                  [](const Vertex* x, const Vertex* y) { return x->p.x() < y->p.x(); });
        for (std::size_t i = 0; i < vs.size(); ++i)
            vs[i]->corner = vs.size() == 2 ? level + (i == 0 ? " inner" : " outer")
                                           : level + " " + std::to_string(i + 1);
    }
}

struct Sharp {
    std::vector<Wall> outer, inner;
    std::vector<Vertex> poly;  // closed, counter-clockwise in (r, z): material on the left
};

// The sharp profile: up the outer walls, down the inner walls (or the axis).
Result<Sharp> sharp_profile(const Actual& a) {
    const Recipe& r = a.recipe;
    if (r.outer.empty()) return make_error(r.source + ": a forged part needs outer sections");
    auto outer = contour_walls(a, r.outer, false);
    if (!outer) return outer.error();
    auto inner = contour_walls(a, r.inner, true);
    if (!inner) return inner.error();
    Sharp s{*outer, *inner, chain(*outer)};
    const auto& bottom = r.outer.front().from_level;
    const auto& top = r.outer.back().to_level;
    std::vector<Vertex> in = chain(*inner);
    if (r.inner.empty())
        in = {{{0.0, a.level(bottom)}, "", false, ""},
              {{0.0, a.zp}, "", true, ""},
              {{0.0, a.level(top)}, "", false, ""}};
    else if (r.inner.front().from_level != bottom || r.inner.back().to_level != top)
        return make_error(r.source + ": a forged part's bores must run from its lowest level '" +
                          bottom + "' to its highest '" + top + "'");
    s.poly.insert(s.poly.end(), in.rbegin(), in.rend());
    if (std::count_if(s.poly.begin(), s.poly.end(), [](const Vertex& v) { return v.parting; }) != 2)
        return make_error(r.source + ": the parting plane must cross one outer and one inner wall");
    name_corners(s.poly);
    return s;
}

// The fillet at corner i (radius as drawn; cut down to fit its faces) as chord points.
std::vector<Eigen::Vector2d> fillet_points(const std::vector<Vertex>& poly, std::size_t i,
                                           double radius, double& built) {
    const std::size_t n = poly.size();
    const Eigen::Vector2d p = poly[i].p, prev = poly[(i + n - 1) % n].p, next = poly[(i + 1) % n].p;
    const double len1 = (p - prev).norm(), len2 = (next - p).norm();
    const Eigen::Vector2d u1 = (p - prev) / len1, u2 = (next - p) / len2;
    const double turn = std::atan2(u1.x() * u2.y() - u1.y() * u2.x(), u1.dot(u2));
    const double half_tan = std::tan(0.5 * std::abs(turn));
    built = 0.0;
    if (radius <= 0.0 || half_tan < 1e-12) return {p};
    // Radius and tangent length both within 0.4 of either face.
    built = std::min(radius, kNarrowFace * std::min(len1, len2) / std::max(1.0, half_tan));
    const double tangent = built * half_tan;
    const Eigen::Vector2d t1 = p - tangent * u1;
    const Eigen::Vector2d left(-u1.y(), u1.x());
    const Eigen::Vector2d centre = t1 + (turn > 0 ? 1.0 : -1.0) * built * left;
    const double step = 2.0 * std::acos(std::max(0.0, 1.0 - kMaxSag / built));
    const int chords = std::max(kMinChords, static_cast<int>(std::ceil(std::abs(turn) / step)));
    const Eigen::Vector2d from = t1 - centre;
    const double a0 = std::atan2(from.y(), from.x());
    std::vector<Eigen::Vector2d> pts;
    for (int j = 0; j <= chords; ++j) {
        const double ang = a0 + turn * j / chords;
        pts.push_back(centre + built * Eigen::Vector2d(std::cos(ang), std::sin(ang)));
    }
    return pts;
}

// Cuts the closed polygon at its two parting-plane vertices: the upper chain (outer to inner over
// the top) and the lower chain (inner to outer under the bottom).
std::pair<ForgedSolid::Profile, ForgedSolid::Profile> split(const std::vector<Vertex>& poly) {
    std::vector<std::size_t> cut;
    for (std::size_t i = 0; i < poly.size(); ++i)
        if (poly[i].parting) cut.push_back(i);
    ForgedSolid::Profile lower, upper;
    for (std::size_t i = cut[0]; i <= cut[1]; ++i) upper.push_back(poly[i].p);
    for (std::size_t k = cut[1]; k <= cut[0] + poly.size(); ++k)
        lower.push_back(poly[k % poly.size()].p);
    return {lower, upper};
}

std::vector<Vertex> with_fillets(const std::vector<Vertex>& poly, const ForgedShape& shape,
                                 std::map<std::string, double>& built) {
    std::vector<Vertex> out;
    for (std::size_t i = 0; i < poly.size(); ++i) {
        const auto it = shape.fillet_mm.find(poly[i].corner);
        if (poly[i].corner.empty() || it == shape.fillet_mm.end()) {
            if (!poly[i].corner.empty()) built[poly[i].corner] = 0.0;
            out.push_back(poly[i]);
            continue;
        }
        for (const auto& q : fillet_points(poly, i, it->second, built[poly[i].corner]))
            out.push_back({q, "", false, ""});
    }
    return out;
}

// A feature's value at its theoretical sharp corner (cold).
double sharp_value(const FeatureSpec& f, const Actual& a, const Sharp& s,
                   const Eigen::Vector2d& shift) {
    if (f.kind == FeatureKind::kDieShift) return shift.norm();
    if (f.kind == FeatureKind::kHeight)
        return std::abs(a.level(f.to_level) - a.level(f.from_level));
    const double z = a.level(f.edge_at);
    for (const auto* walls : {&s.outer, &s.inner})
        for (const auto& w : *walls) {
            // A wall across the parting plane: its piece on the level's side.
            if (w.section != f.section || (w.to_level.empty() && z > a.zp) ||
                (w.from_level.empty() && z < a.zp))
                continue;
            return 2.0 * w.r(z);
        }
    return 0.0;
}

}  // namespace

std::vector<ForgedWall> forged_walls(const Recipe& recipe) {
    const ForgedShape nominal;
    Actual a{recipe, nominal};
    std::vector<ForgedWall> out;
    auto zp = parting_plane(a);
    if (!zp) return out;
    a.zp = *zp;
    for (const auto* list : {&recipe.outer, &recipe.inner})
        if (auto walls = contour_walls(a, *list, list == &recipe.inner))
            for (const auto& w : *walls) out.push_back({w.name, w.section});
    return out;
}

std::vector<ForgedCorner> forged_corners(const Recipe& recipe) {
    const ForgedShape nominal;
    Actual a{recipe, nominal};
    std::vector<ForgedCorner> out;
    auto zp = parting_plane(a);
    if (!zp) return out;
    a.zp = *zp;
    auto s = sharp_profile(a);
    if (!s) return out;
    for (const auto& v : s->poly)
        if (!v.corner.empty()) out.push_back({v.corner, v.level});
    return out;
}

Result<ForgedPart> build_forged(const Recipe& recipe, const ForgedShape& shape) {
    Actual a{recipe, shape};
    auto zp = parting_plane(a);
    if (!zp) return zp.error();
    a.zp = *zp;
    auto s = sharp_profile(a);
    if (!s) return s.error();
    ForgedPart part;
    part.shape = shape;
    part.parting_z_mm = a.zp;
    std::tie(part.lower_sharp, part.upper_sharp) = split(s->poly);
    std::tie(part.lower, part.upper) = split(with_fillets(s->poly, shape, part.fillet_mm));
    for (const auto* walls : {&s->outer, &s->inner})
        for (const auto& w : *walls) part.draft_deg[w.name] = std::atan(w.tan_draft) / kDeg;
    for (const auto& f : recipe.features)
        part.feature_cold_mm[f.name] = sharp_value(f, a, *s, shape.die_shift_mm);
    const auto& poly = s->poly;
    for (std::size_t i = 0; i < poly.size(); ++i) {
        const Vertex& v = poly[i];
        const Vertex& w = poly[(i + 1) % poly.size()];
        if (!v.level.empty() && v.level == w.level)
            part.level_faces_mm.emplace_back(v.level, w.p.x() - v.p.x());
    }
    return part;
}

ForgedSolid ForgedPart::solid() const {
    const double k = shape.scale;
    auto scaled = [k](ForgedSolid::Profile p) {
        for (auto& q : p) q *= k;
        return p;
    };
    return ForgedSolid(scaled(lower), scaled(upper), k * parting_z_mm, k * shape.die_shift_mm);
}

double draw_within(double max, std::mt19937_64& rng) {
    if (max <= 0.0) return 0.0;
    return std::uniform_real_distribution<double>(std::min(1.0, max), max)(rng);
}

bool flat_faces_kept(const ForgedPart& undrafted, const ForgedPart& part) {
    const auto& w0 = undrafted.level_faces_mm;
    const auto& w = part.level_faces_mm;
    if (w0.size() != w.size()) return false;
    for (std::size_t i = 0; i < w.size(); ++i) {
        const double width0 = std::abs(w0[i].second);
        const double width = w0[i].second < 0 ? -w[i].second : w[i].second;
        if (width < std::min(width0, std::max(0.3, 0.2 * width0))) return false;
    }
    return true;
}

}  // namespace hotgauge::core
