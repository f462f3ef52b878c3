#include "hotgauge/match/model.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

#include "hotgauge/core/forged.hpp"

namespace hotgauge::match {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

// Bin of an angle in [0, π].
inline std::uint32_t angle_bin(float cos_angle, int bins) {
    const float a = std::acos(std::clamp(cos_angle, -1.0f, 1.0f));
    return static_cast<std::uint32_t>(
        std::min(bins - 1, static_cast<int>(a * static_cast<float>(bins) / kPi)));
}

Eigen::Vector3d bbox_extent(const std::vector<Eigen::Vector3f>& pts) {
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
    Eigen::Vector3f hi = -lo;
    for (const auto& p : pts) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    return (hi - lo).cast<double>();
}

core::Result<void> check_config(const ModelConfig& c) {
    if (!(c.sampling_mm > 0.01 && c.sampling_mm < 1e3))
        return core::make_error("model: sampling_mm must be in (0.01, 1000)");
    if (!(c.distance_step_mm >= 0 && c.distance_step_mm < 1e3))
        return core::make_error("model: distance_step_mm must be in [0, 1000)");
    if (c.angle_bins < 4 || c.angle_bins > 64)
        return core::make_error("model: angle_bins must be in [4, 64]");
    if (c.alpha_bins < 4 || c.alpha_bins > 360)
        return core::make_error("model: alpha_bins must be in [4, 360]");
    return {};
}

void finish(Model& m) {
    m.step_mm = m.config.distance_step_mm > 0 ? m.config.distance_step_mm : m.config.sampling_mm;
    m.diameter_mm = bbox_extent(m.points).norm();
    build_table(m);
}

// The sharp, vertical boundary of the recipe's sections, collinear neighbours joined (fewer
// segments for ICP's closest point), each turned so that the material is on its left.
core::Result<std::vector<ProfileSegment>> sharp_profile(const core::Recipe& recipe) {
    const auto solid = core::AxisymmetricSolid::from_recipe(recipe);
    std::vector<core::AxisymmetricSolid::Segment> joined;
    for (const auto& seg : solid.boundary()) {
        auto joins = [&](core::AxisymmetricSolid::Segment& p) {
            return p.cylinder == seg.cylinder && p.value == seg.value &&
                   (p.hi == seg.lo || seg.hi == p.lo);
        };
        auto it = std::find_if(joined.begin(), joined.end(), joins);
        if (it == joined.end()) {
            joined.push_back(seg);
        } else {
            it->lo = std::min(it->lo, seg.lo);
            it->hi = std::max(it->hi, seg.hi);
        }
    }
    constexpr double kProbe = 1e-3;
    std::vector<ProfileSegment> out;
    for (const auto& g : joined) {
        ProfileSegment p = g.cylinder ? ProfileSegment{g.value, g.lo, g.value, g.hi, true}
                                      : ProfileSegment{g.lo, g.value, g.hi, g.value, false};
        // The left of a cylinder going up is −r; of a plane going out, +z.
        const bool left_is_material = g.cylinder
                                          ? solid.inside(g.value - kProbe, 0.5 * (g.lo + g.hi))
                                          : solid.inside(0.5 * (g.lo + g.hi), g.value + kProbe);
        if (!left_is_material) {
            std::swap(p.r0, p.r1);
            std::swap(p.z0, p.z1);
        }
        out.push_back(p);
    }
    return out;
}

// A polyline with points dropped while each dropped point stays within `tol_mm` of the chord
// that replaces it: a fillet's chords are made for the simulator's sub-micrometre sag, far finer
// than matching needs.
std::vector<Eigen::Vector2d> simplify(const std::vector<Eigen::Vector2d>& p, double tol_mm) {
    if (p.size() < 3) return p;
    auto off_chord = [&](std::size_t a, std::size_t b, std::size_t k) {
        const Eigen::Vector2d d = p[b] - p[a];
        const double t = std::clamp((p[k] - p[a]).dot(d) / d.squaredNorm(), 0.0, 1.0);
        return (p[a] + t * d - p[k]).norm();
    };
    std::vector<Eigen::Vector2d> out{p.front()};
    std::size_t a = 0;
    for (std::size_t b = 2; b < p.size(); ++b)
        for (std::size_t k = a + 1; k < b; ++k)
            if (off_chord(a, b, k) > tol_mm) {
                a = b - 1;
                out.push_back(p[a]);
                break;
            }
    out.push_back(p.back());
    return out;
}

// The part as its forging drawing draws it, at half the drawing's limits (model.hpp): both
// halves' profiles about one axis, without the parting plane between them. A segment is a wall
// when it is steeper than 45° and longer than any fillet chord left by simplify().
core::Result<std::vector<ProfileSegment>> drawn_profile(const core::Recipe& recipe) {
    core::ForgedShape shape;
    for (const auto& w : core::forged_walls(recipe))
        shape.draft_deg[w.name] = 0.5 * recipe.draft_of(w.section);
    for (const auto& c : core::forged_corners(recipe))
        shape.fillet_mm[c.name] = 0.5 * recipe.fillet_at(c.level);
    auto part = core::build_forged(recipe, shape);
    if (!part)
        return core::make_error(recipe.source +
                                ": the drawn part for matching: " + part.error().message);
    constexpr double kChordTolMm = 0.005, kWallMinMm = 1.0;
    std::vector<ProfileSegment> out;
    for (const auto* half : {&part->lower, &part->upper}) {
        const auto p = simplify(*half, kChordTolMm);
        for (std::size_t i = 0; i + 1 < p.size(); ++i) {
            const Eigen::Vector2d a = p[i], b = p[i + 1], d = b - a;
            if (d.norm() <= 0.0 || (a.x() <= 0.0 && b.x() <= 0.0)) continue;  // on the axis
            const bool wall = std::abs(d.y()) > std::abs(d.x()) && d.norm() > kWallMinMm;
            out.push_back({a.x(), a.y(), b.x(), b.y(), wall});
        }
    }
    return out;
}

}  // namespace

float pair_angle(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2) {
    const Eigen::Vector3f q = to_ref_frame(p1, n1) * p2.homogeneous();
    return std::atan2(-q.z(), q.y());
}

Eigen::Matrix<float, 3, 4> to_ref_frame(const Eigen::Vector3f& p, const Eigen::Vector3f& n) {
    // Rotation about n × x by the angle between n and x.
    const Eigen::Vector3f axis(0.0f, n.z(), -n.y());
    const float s = axis.norm();
    Eigen::Matrix3f R;
    if (s < 1e-7f)
        R = n.x() > 0 ? Eigen::Matrix3f::Identity()
                      : Eigen::Matrix3f(Eigen::AngleAxisf(kPi, Eigen::Vector3f::UnitY()));
    else
        R = Eigen::AngleAxisf(std::atan2(s, n.x()), axis / s).toRotationMatrix();
    Eigen::Matrix<float, 3, 4> T;
    T.leftCols<3>() = R;
    T.col(3) = -R * p;
    return T;
}

int Model::n_distance_bins() const {
    return std::max(1, static_cast<int>(std::ceil(diameter_mm / step_mm)) + 1);
}

std::uint32_t Model::n_keys() const {
    const auto a = static_cast<std::uint32_t>(config.angle_bins);
    return static_cast<std::uint32_t>(n_distance_bins()) * a * a * a;
}

std::uint32_t Model::key(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1,
                         const Eigen::Vector3f& p2, const Eigen::Vector3f& n2) const {
    const Eigen::Vector3f d = p2 - p1;
    const float dist = d.norm();
    if (dist < 1e-6f) return kNoKey;
    const auto db = static_cast<std::uint32_t>(dist / static_cast<float>(step_mm));
    if (db >= static_cast<std::uint32_t>(n_distance_bins())) return kNoKey;
    const Eigen::Vector3f u = d / dist;
    const int a = config.angle_bins;
    const auto ua = static_cast<std::uint32_t>(a);
    const std::uint32_t f2 = angle_bin(n1.dot(u), a), f3 = angle_bin(n2.dot(u), a),
                        f4 = angle_bin(n1.dot(n2), a);
    // Two points of one plane (normals parallel, both across d) say only that the plane is a
    // plane; on a flanged part they are most pairs and most of the voting time.
    if (f4 == 0 && f2 == ua / 2 && f3 == ua / 2) return kNoKey;
    return ((db * ua + f2) * ua + f3) * ua + f4;
}

void build_table(Model& m) {
    const std::uint32_t n_keys = m.n_keys();
    std::vector<std::uint32_t> keys;
    std::vector<Model::Entry> raw;
    for (std::uint32_t r = 0; r < m.refs.size(); ++r) {
        const std::uint32_t i = m.refs[r];
        const auto T = to_ref_frame(m.points[i], m.normals[i]);
        for (std::uint32_t j = 0; j < m.points.size(); ++j) {
            if (j == i) continue;
            const std::uint32_t k = m.key(m.points[i], m.normals[i], m.points[j], m.normals[j]);
            if (k == kNoKey) continue;
            const Eigen::Vector3f q = T * m.points[j].homogeneous();
            keys.push_back(k);
            raw.push_back({r, std::atan2(-q.z(), q.y())});
        }
    }
    m.key_begin.assign(n_keys + 1, 0);
    for (std::uint32_t k : keys) ++m.key_begin[k + 1];
    for (std::uint32_t k = 0; k < n_keys; ++k) m.key_begin[k + 1] += m.key_begin[k];
    std::vector<Model::Entry> all(raw.size());
    std::vector<std::uint32_t> fill(m.key_begin.begin(), m.key_begin.end() - 1);
    for (std::size_t e = 0; e < raw.size(); ++e) all[fill[keys[e]]++] = raw[e];
    // One entry per (reference, α bin) under a key, α at the bin centre: a scene pair votes once
    // for a model reference and angle however many model pairs share them (Hinterstoisser et al.
    // 2016), which also keeps revolved pairs of an axisymmetric model from being counted ~100×.
    const int A = m.config.alpha_bins;
    const float bin = 2 * kPi / static_cast<float>(A);
    auto alpha_bin = [&](float a) {
        return std::clamp(static_cast<int>((a + kPi) / bin), 0, A - 1);
    };
    m.entries.clear();
    std::uint32_t begin = 0;
    for (std::uint32_t k = 0; k < n_keys; ++k) {
        const std::uint32_t end = m.key_begin[k + 1];
        std::vector<std::uint64_t> codes;
        for (std::uint32_t e = begin; e < end; ++e)
            codes.push_back(std::uint64_t{all[e].ref} * static_cast<std::uint64_t>(A) +
                            static_cast<std::uint64_t>(alpha_bin(all[e].alpha)));
        std::sort(codes.begin(), codes.end());
        codes.erase(std::unique(codes.begin(), codes.end()), codes.end());
        m.key_begin[k] = static_cast<std::uint32_t>(m.entries.size());
        for (std::uint64_t c : codes)
            m.entries.push_back(
                {static_cast<std::uint32_t>(c / static_cast<std::uint64_t>(A)),
                 -kPi + (static_cast<float>(c % static_cast<std::uint64_t>(A)) + 0.5f) * bin});
        begin = end;
    }
    m.key_begin[n_keys] = static_cast<std::uint32_t>(m.entries.size());
}

core::Result<Model> model_from_recipe(const core::Recipe& recipe, const ModelConfig& config) {
    if (auto ok = check_config(config); !ok) return ok.error();
    if (recipe.outer.empty())
        return core::make_error(recipe.source + ": no outer sections: no geometry to match");
    auto profile = recipe.forging ? drawn_profile(recipe) : sharp_profile(recipe);
    if (!profile) return profile.error();
    Model m;
    m.name = recipe.name;
    m.source = "recipe " + recipe.source;
    m.config = config;
    m.axisymmetric = true;
    m.profile = std::move(*profile);
    // Meridian samples (r, z) with their outward normals, then revolved: the sample at azimuth 0
    // of each meridian sample is a reference point. A fillet's chords share their samples: one
    // where their run has gathered a sampling distance, not one each.
    const double s = config.sampling_mm;
    double run = 0;
    for (const auto& seg : m.profile) {
        const double dr = seg.r1 - seg.r0, dz = seg.z1 - seg.z0, len = seg.length();
        const double nr = dz / len, nz = -dr / len;
        int n = std::max(1, static_cast<int>(std::lround(len / s)));
        if (seg.fillet_chord()) {
            run += len;
            n = run >= s ? 1 : 0;
            if (n) run = 0;
        } else {
            run = 0;
        }
        for (int q = 0; q < n; ++q) {
            const double t = (q + 0.5) / n;
            const double r = seg.r0 + t * dr, z = seg.z0 + t * dz;
            const int m_az =
                std::max(1, static_cast<int>(std::lround(2 * std::numbers::pi * r / s)));
            for (int a = 0; a < m_az; ++a) {
                const double phi = 2 * std::numbers::pi * a / m_az;
                const double c = std::cos(phi), sn = std::sin(phi);
                if (a == 0) m.refs.push_back(static_cast<std::uint32_t>(m.points.size()));
                m.points.emplace_back(static_cast<float>(r * c), static_cast<float>(r * sn),
                                      static_cast<float>(z));
                m.normals.emplace_back(static_cast<float>(nr * c), static_cast<float>(nr * sn),
                                       static_cast<float>(nz));
            }
        }
    }
    finish(m);
    return m;
}

core::Result<Model> model_from_samples(std::string name, std::string source,
                                       std::vector<Eigen::Vector3f> points,
                                       std::vector<Eigen::Vector3f> normals,
                                       const ModelConfig& config) {
    if (auto ok = check_config(config); !ok) return ok.error();
    if (points.size() != normals.size())
        return core::make_error(source + ": " + std::to_string(points.size()) + " points but " +
                                std::to_string(normals.size()) + " normals");
    if (points.size() < 10) return core::make_error(source + ": fewer than 10 surface samples");
    Model m;
    m.name = std::move(name);
    m.source = std::move(source);
    m.config = config;
    for (std::size_t i = 0; i < points.size(); ++i) {
        if (!points[i].allFinite() || !normals[i].allFinite() || normals[i].norm() < 0.5f)
            return core::make_error(m.source + ": sample " + std::to_string(i) +
                                    " has a non-finite point or no normal");
        normals[i].normalize();
    }
    // Voting samples: per voxel of the sampling size, the sample nearest the voxel's mean.
    struct Cell {
        Eigen::Vector3f sum = Eigen::Vector3f::Zero();
        int n = 0;
        std::uint32_t best = 0;
        float best_d = std::numeric_limits<float>::max();
    };
    std::unordered_map<std::int64_t, Cell> cells;
    const auto s = static_cast<float>(config.sampling_mm);
    auto cell_of = [&](const Eigen::Vector3f& p) {
        const auto c = (p / s).array().floor().cast<std::int64_t>();
        return (c.x() * 73856093) ^ (c.y() * 19349663) ^ (c.z() * 83492791);
    };
    for (const auto& p : points) {
        Cell& c = cells[cell_of(p)];
        c.sum += p;
        ++c.n;
    }
    for (std::uint32_t i = 0; i < points.size(); ++i) {
        Cell& c = cells[cell_of(points[i])];
        const float d = (points[i] - c.sum / static_cast<float>(c.n)).squaredNorm();
        if (d < c.best_d) {
            c.best_d = d;
            c.best = i;
        }
    }
    std::vector<std::uint32_t> chosen;
    for (const auto& [k, c] : cells) chosen.push_back(c.best);
    std::sort(chosen.begin(), chosen.end());  // deterministic order
    for (std::uint32_t i : chosen) {
        m.refs.push_back(static_cast<std::uint32_t>(m.points.size()));
        m.points.push_back(points[i]);
        m.normals.push_back(normals[i]);
    }
    m.dense_points = std::move(points);
    m.dense_normals = std::move(normals);
    finish(m);
    return m;
}

core::Result<void> Model::validate() const {
    auto bad = [&](const std::string& what) { return core::make_error("model: " + what); };
    if (auto ok = check_config(config); !ok) return ok.error();
    if (!(step_mm > 0) || !(diameter_mm > 0) || diameter_mm / step_mm > 1e5)
        return bad("distance step or diameter out of range");
    if (points.size() != normals.size() || points.empty())
        return bad("voting samples and normals differ in number or are empty");
    if (dense_points.size() != dense_normals.size())
        return bad("dense samples and normals differ in number");
    if (axisymmetric ? profile.empty() : dense_points.empty())
        return bad(axisymmetric ? "axisymmetric model without a profile"
                                : "model without dense samples");
    // A checksum only says the bytes are what a writer wrote; a NaN sample would make every
    // part "not found" (issue 18, finding 7).
    const auto finite = [](const std::vector<Eigen::Vector3f>& v) {
        return std::all_of(v.begin(), v.end(), [](const auto& p) { return p.allFinite(); });
    };
    if (!finite(points) || !finite(dense_points)) return bad("a sample point is not finite");
    for (const auto& n : normals)
        if (!n.allFinite() || std::abs(n.norm() - 1.0f) > 1e-3f) return bad("a normal is not unit");
    for (const auto& n : dense_normals)
        if (!n.allFinite() || std::abs(n.norm() - 1.0f) > 1e-3f)
            return bad("a dense normal is not unit");
    // ICP's closest-point grid lists segments by a 16-bit index and spans the profile in 1 mm
    // cells; each wall is two unknowns of a dense normal matrix.
    constexpr std::size_t kMaxSegments = 65535, kMaxWalls = 256;
    constexpr double kMaxMm = 1e4, kMinLengthMm = 1e-6;
    if (profile.size() > kMaxSegments) return bad("more than 65535 profile segments");
    const auto inside = [&](double v, double lo) {
        return std::isfinite(v) && v >= lo && v <= kMaxMm;
    };
    for (const auto& s : profile)
        if (!inside(s.r0, 0.0) || !inside(s.r1, 0.0) || !inside(s.z0, -kMaxMm) ||
            !inside(s.z1, -kMaxMm) || !(s.length() >= kMinLengthMm))
            return bad(
                "a profile segment is not finite, outside ±10 m, has a negative radius or "
                "no length");
    if (std::count_if(profile.begin(), profile.end(), [](const auto& s) { return s.wall; }) >
        static_cast<std::ptrdiff_t>(kMaxWalls))
        return bad("more than 256 walls in the profile");
    for (auto r : refs)
        if (r >= points.size()) return bad("a reference index is out of range");
    if (static_cast<double>(n_keys()) * 4 > 4e9) return bad("table too large");
    if (key_begin.size() != std::size_t{n_keys()} + 1 || key_begin.front() != 0 ||
        key_begin.back() != entries.size())
        return bad("table offsets do not match the table size");
    if (!std::is_sorted(key_begin.begin(), key_begin.end())) return bad("table offsets unsorted");
    for (const auto& e : entries)
        if (e.ref >= refs.size() || !(std::abs(e.alpha) <= kPi + 1e-4f))
            return bad("a table entry is out of range");
    return {};
}

}  // namespace hotgauge::match
