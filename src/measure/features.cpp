// Feature measurement on registered scans (docs/measurement.md): the faces prepared in the part
// frame (frame.cpp), each feature measured by its kind (diameter.cpp, height.cpp) from planes
// (surfaces.cpp) and edges (edges.cpp), then thermal scaling to the cold equivalent and verdicts.
#include "hotgauge/measure/features.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "corner.hpp"
#include "drift.hpp"
#include "feature_kinds.hpp"
#include "frame.hpp"
#include "hotgauge/core/parallel.hpp"
#include "hotgauge/core/text.hpp"

namespace hotgauge::measure {
namespace {

using core::FeatureSpec;
// A pyrometer reading outside this is a fault, not a temperature (forging: 700–1300 °C).
constexpr double kMinTemperatureC = -50.0;
constexpr double kMaxTemperatureC = 1600.0;
// The faces keep samples this far (hot, mm) beyond the part's grown bounds: the part's bounding
// cylinder +5 mm (docs/measurement.md, "Preparation"; not measured).
constexpr double kBoundsMarginMm = 5.0;
// The growth's relative slack at a measured temperature: the α model's error (not measured).
constexpr double kAlphaModelSlack = 0.002;

// The prepared faces a feature may use, by name.
using FrameRefs = std::map<std::string, const detail::FaceFrame*>;

void measure_one(const detail::Context& ctx, const FrameRefs& frames, const FeatureSpec& f,
                 FeatureResult& r, detail::CornerMemo* memo = nullptr) {
    std::vector<const detail::FaceFrame*> used;
    for (const auto& name : f.faces) {
        auto it = frames.find(name);
        if (it != frames.end()) {
            used.push_back(it->second);
            continue;
        }
        // A forging's diameter: its first face sees the edge; the others may see its wall, for
        // the draft, and the draft comes from the drawing without them (docs/recipes.md).
        if (ctx.recipe.forging && f.kind == core::FeatureKind::kDiameter && name != f.faces[0])
            continue;
        r.reason = "face '" + name + "' is not in the recording";
        r.face_missing = true;
        return;
    }
    if (f.kind == core::FeatureKind::kDiameter)
        detail::measure_diameter(ctx, f, used, r, memo);
    else if (f.kind == core::FeatureKind::kHeight)
        detail::measure_height(ctx, f, used, r);
    // a die shift comes from the diameters' circles, once they are all measured (finish)
}

FeatureResult skeleton(const FeatureSpec& f) {
    FeatureResult r;
    r.name = f.name;
    r.kind = f.kind;
    r.slot = f.slot;
    r.faces = f.faces;
    r.nominal_mm = f.nominal_mm;
    r.tol_lower_mm = f.tol_lower_mm;
    r.tol_upper_mm = f.tol_upper_mm;
    r.required = f.required;
    return r;
}

// NOK (of a trusted value) before not measured (of a required feature) before degraded before OK.
Verdict overall(const std::vector<FeatureResult>& features) {
    bool any_not = features.empty(), any_degraded = false;
    for (const auto& f : features) {
        if (f.verdict == Verdict::kNok) return Verdict::kNok;
        any_not = any_not || (f.verdict == Verdict::kNotMeasured && f.required);
        any_degraded = any_degraded || f.verdict == Verdict::kDegraded;
    }
    return any_not ? Verdict::kNotMeasured : any_degraded ? Verdict::kDegraded : Verdict::kOk;
}

// The part's bounding cylinder in its frame (hot, with room for an unknown temperature and the
// edge windows): the samples a face keeps near the part.
struct Bounds {
    double r_max, z_lo, z_hi;
};
Bounds part_bounds(const detail::Context& ctx) {
    double z_min = 0.0, z_max = 0.0;
    for (const auto& [name, z] : ctx.recipe.levels_mm) {
        z_min = std::min(z_min, z);
        z_max = std::max(z_max, z);
    }
    const double margin = kBoundsMarginMm;
    const double gmax = ctx.ex.g * (1.0 + ctx.ex.slack);
    return {ctx.solid.max_radius() * gmax + margin, std::min(z_min, z_min * gmax) - margin,
            std::max(z_max, z_max * gmax) + margin};
}

// Cold equivalent, deviation and verdict of a measured feature; tolerances are on cold values.
void judge(const core::Recording& rec, const core::ThermalModel& material,
           const std::optional<double>& growth, double temperature_u_c, FeatureResult& r) {
    if (!r.hot_mm) {
        r.verdict = Verdict::kNotMeasured;
        return;
    }
    r.reason.clear();
    if (!growth) {
        r.verdict = Verdict::kNotMeasured;
        r.reason = rec.temperature_c
                       ? "part temperature " + std::to_string(*rec.temperature_c) +
                             " °C outside the plausible range: cold equivalent not available"
                       : "no part temperature in the recording: cold equivalent not available";
        return;
    }
    r.cold_mm = *r.hot_mm / *growth;
    // g(T) = 1 + α0·(T − 20) + α1·(T − 20)², so dg/dT = α0 + 2·α1·(T − 20).
    const double dg_dt =
        material.alpha0_per_k + 2.0 * material.alpha1_per_k2 * (*rec.temperature_c - 20.0);
    r.u_cold_mm = std::hypot(r.u_mm / *growth, *r.cold_mm * dg_dt * temperature_u_c / *growth);
    r.deviation_mm = *r.cold_mm - r.nominal_mm;
    const bool ok = *r.deviation_mm >= r.tol_lower_mm && *r.deviation_mm <= r.tol_upper_mm;
    if (r.degraded) {  // whatever the deviation: a value the data cannot vouch for sorts nothing
        r.verdict = Verdict::kDegraded;
        r.reason = "degraded: " + (r.degraded_because.empty() ? "measured with untrusted profiles"
                                                              : r.degraded_because);
        for (const auto& run : r.left_out) r.reason += "; " + run;
        if (!ok) r.reason += " (deviation outside tolerance)";
        return;
    }
    r.verdict = ok ? Verdict::kOk : Verdict::kNok;
    if (!ok) r.reason = "deviation outside tolerance";
}

// The untrusted runs of a feature's faces, described.
std::vector<std::string> untrusted_of(const FeatureSpec& f, const FaceUntrusted& untrusted) {
    std::vector<std::string> out;
    for (const auto& face : f.faces)
        if (auto it = untrusted.find(face); it != untrusted.end())
            for (const auto& run : it->second) out.push_back(core::describe(face, run));
    return out;
}

// A feature relies on untrusted profiles when it cannot be measured without them, or when
// leaving them out took more than half of its points: what is left is too thin to vouch for the
// value (measured: a side height on 45 of its points, 0.033 mm off, docs/compensation.md).
constexpr double kMinTrustedShare = 0.5;

// A height's silhouette end is where (nearly) all of its brackets overlap, so its extreme
// brackets set it: the few profiles a bridge gets wrong beside an accelerometer hole, lost in a
// plane or a circle fit, moved side heights 0.02-0.04 mm with u 0.005 mm (2 % datagram loss,
// 0.1 s pad; docs/compensation.md "Silhouette edges beside holes"). A diameter's edge circle is
// a fit through all of its brackets: the holes' term of its u speaks for it.
const char* const kSilhouetteBesideHoles =
    "silhouette edge on a face whose accelerometer record has holes";
bool silhouette(const FeatureResult& r) {
    return r.kind == core::FeatureKind::kHeight &&
           std::any_of(r.ends.begin(), r.ends.end(),
                       [](const EdgeEstimate& e) { return e.estimator == "silhouette edge"; });
}
// The "accelerometer holes" term of its u (0: none).
double holes_u(const FeatureResult& r) {
    for (const auto& [name, u] : r.u_budget)
        if (name == detail::kHolesTerm) return u;
    return 0.0;
}

// Why a value measured around untrusted profiles is not vouched for, or nothing: a height's
// silhouette end; the holes' own term of its u (a height between two faces' planes moved
// 0.031-0.035 mm beside a hole: its faces' levels move with their errors, which cancel only
// within one face); or a u that alone fills the bound the gauge is held to. A hole can leave a
// part of an edge's circle to profiles far from the others: Diameter 3 read 0.032 mm off with
// u 0.061 mm (its sectors' spread) and a holes term of 0.004 mm (independent-paper-7, 2 % loss).
std::string beside_holes(const FeatureResult& r, const MeasureConfig& c) {
    if (silhouette(r)) return kSilhouetteBesideHoles;
    if (const double u = holes_u(r); u > c.max_holes_u_mm)
        return "the accelerometer's holes leave u " + core::fixed(u, 4) + " mm in it, more than " +
               core::fixed(c.max_holes_u_mm, 4);
    if (r.u_mm > c.max_u_beside_holes_mm)
        return "measured around the accelerometer's holes with u " + core::fixed(r.u_mm, 4) +
               " mm, more than " + core::fixed(c.max_u_beside_holes_mm, 4);
    return {};
}

// The expected hot geometry: from the temperature when it is plausible, else with room for it.
detail::Expect expect(const core::Recipe& recipe, const core::Recording& rec,
                      const MeasureConfig& config, std::optional<double>& growth) {
    detail::Expect ex;
    if (rec.temperature_c && *rec.temperature_c >= kMinTemperatureC &&
        *rec.temperature_c <= kMaxTemperatureC) {
        growth = recipe.material.growth(*rec.temperature_c);
        ex.g = *growth;
        ex.slack = kAlphaModelSlack;
    } else {
        ex.g = 1.0 + 0.5 * config.unknown_growth;
        ex.slack = 0.5 * config.unknown_growth;
    }
    return ex;
}

// A forging's level may sit as far off nominal as a sorting gauge must follow (hub-a.md: at
// least ±1.5 mm): the level planes are looked for that much farther.
constexpr double kSortingWindowMm = 1.5;
MeasureConfig for_recipe(const core::Recipe& recipe, MeasureConfig c) {
    if (recipe.forging) c.plane_band_mm += kSortingWindowMm;
    return c;
}

}  // namespace

const char* to_string(Verdict v) {
    switch (v) {
        case Verdict::kOk:
            return "OK";
        case Verdict::kDegraded:
            return "DEGRADED";
        case Verdict::kNok:
            return "NOK";
        case Verdict::kNotMeasured:
            return "NOT_MEASURED";
    }
    return "NOT_MEASURED";
}

PartMeasurement unmeasured(const core::Recipe& recipe, const core::Recording& rec,
                           const std::string& reason) {
    PartMeasurement out;
    out.temperature_c = rec.temperature_c;
    if (rec.temperature_c && *rec.temperature_c >= kMinTemperatureC &&
        *rec.temperature_c <= kMaxTemperatureC)
        out.growth = recipe.material.growth(*rec.temperature_c);
    for (const auto& f : recipe.features) {
        out.features.push_back(skeleton(f));
        out.features.back().reason = reason;
    }
    out.verdict = Verdict::kNotMeasured;
    return out;
}

struct PartMeasurer::Impl {
    const core::Recording& rec;
    Eigen::Isometry3d T_part_world;
    std::optional<double> growth;
    detail::Context ctx;
    Bounds bounds;
    // Every face added, its untrusted profiles left out; and, for the faces with untrusted runs,
    // the same face with them (std::map: the frames do not move as faces are added).
    std::map<std::string, detail::FaceFrame> frames, frames_all;
    FaceUntrusted untrusted;
    std::vector<std::optional<FeatureResult>> measured;  // per recipe feature, once measured
    // A forging's diameter is measured as soon as its first face is in: the others see only its
    // wall, which the corner may not need (every edge of an ideal part), so the daemon need not
    // wait for the last face. Per feature, its faces not in then; measured again when one of
    // them comes in and sees the edge's plane, or when the corner looked to the wall's faces.
    std::vector<std::vector<std::string>> early_without;
    // Per feature, its corner from the faces that see its plane, without and with their
    // untrusted profiles: kept while only faces that see its wall come in.
    std::vector<std::array<detail::CornerMemo, 2>> memos;

    Impl(const core::Recipe& recipe, const core::Recording& r,
         const Eigen::Isometry3d& T_world_part, const MeasureConfig& config)
        : rec(r),
          T_part_world(T_world_part.inverse()),
          ctx{recipe, core::AxisymmetricSolid::from_recipe(recipe),
              expect(recipe, r, config, growth), for_recipe(recipe, config)},
          bounds(part_bounds(ctx)),
          measured(recipe.features.size()),
          early_without(recipe.features.size()),
          memos(recipe.features.size()) {}

    FrameRefs refs(const FeatureSpec& f, bool with_untrusted) const {
        FrameRefs out;
        for (const auto& name : f.faces) {
            auto all = frames_all.find(name);
            if (with_untrusted && all != frames_all.end())
                out.emplace(name, &all->second);
            else if (auto it = frames.find(name); it != frames.end())
                out.emplace(name, &it->second);
        }
        return out;
    }
    static bool early(const core::Recipe& recipe, const FeatureSpec& f) {
        return recipe.forging && f.kind == core::FeatureKind::kDiameter && !f.faces.empty();
    }
    bool ready(const FeatureSpec& f) const {
        if (early(ctx.recipe, f)) return frames.contains(f.faces[0]);
        return std::all_of(f.faces.begin(), f.faces.end(),
                           [&](const std::string& n) { return frames.contains(n); });
    }
    std::vector<std::string> not_in(const FeatureSpec& f) const {
        std::vector<std::string> out;
        for (const auto& n : f.faces)
            if (!frames.contains(n)) out.push_back(n);
        return out;
    }
    void recheck_early(std::size_t i);
    FeatureResult measure_feature(std::size_t i);
};

// An early diameter once more of its faces are in: kept when none of them sees the edge's plane
// and the corner did not look to the wall's faces (the value is then what all faces give).
void PartMeasurer::Impl::recheck_early(std::size_t i) {
    const FeatureSpec& f = ctx.recipe.features[i];
    auto& missing = early_without[i];
    for (const auto& name : missing) {
        auto it = frames.find(name);
        if (it == frames.end()) continue;
        // A face that sees the edge's plane (by its view alone, so with or without its untrusted
        // profiles) changes the corner's own fit.
        if (detail::sees_edge_plane(ctx, f, it->second)) memos[i] = {};
        if (measured[i] && (measured[i]->wall_faces_used || !memos[i][0].fitted))
            measured[i].reset();
    }
    std::erase_if(missing, [&](const std::string& n) { return frames.contains(n); });
}

// A feature measured without the untrusted profiles of its faces; when it relies on them (not
// measurable without them, or less than kMinTrustedShare of its points left), measured with
// them and degraded; not measurable with them either: the full data's reason.
FeatureResult PartMeasurer::Impl::measure_feature(std::size_t i) {
    const FeatureSpec& f = ctx.recipe.features[i];
    FeatureResult r = skeleton(f);
    measure_one(ctx, refs(f, false), f, r, &memos[i][0]);
    r.left_out = untrusted_of(f, untrusted);
    if (r.left_out.empty()) return r;
    FeatureResult again = skeleton(f);
    measure_one(ctx, refs(f, true), f, again, &memos[i][1]);
    // Per end too: a height's one small end may lose most of its points to them.
    const auto few = [](std::int64_t left, std::int64_t all) {
        return static_cast<double>(left) < kMinTrustedShare * static_cast<double>(all);
    };
    bool thin = r.hot_mm && again.hot_mm && few(r.n_points, again.n_points);
    if (r.hot_mm && again.hot_mm && r.ends.size() == again.ends.size())
        for (std::size_t j = 0; j < r.ends.size(); ++j)
            thin = thin || few(r.ends[j].n_points, again.ends[j].n_points);
    r.wall_faces_used = r.wall_faces_used || again.wall_faces_used;
    again.wall_faces_used = r.wall_faces_used;
    if (r.hot_mm && !thin) {  // measured around them
        r.degraded_because = beside_holes(r, ctx.c);
        r.degraded = !r.degraded_because.empty();
        return r;
    }
    again.left_out = std::move(r.left_out);
    again.degraded = again.hot_mm.has_value();
    return again;
}

PartMeasurer::PartMeasurer(const core::Recipe& recipe, const core::Recording& rec,
                           const Eigen::Isometry3d& T_world_part, const MeasureConfig& config)
    : impl_(std::make_unique<Impl>(recipe, rec, T_world_part, config)) {}
PartMeasurer::~PartMeasurer() = default;

void PartMeasurer::add_faces(std::size_t first, std::size_t end, const core::FaceDisplacements& u,
                             const FaceUntrusted& untrusted,
                             const core::FaceDisplacementNoise& noise) {
    Impl& m = *impl_;
    const auto find = [](const auto& map, const std::string& name) {
        auto it = map.find(name);
        return it == map.end() ? nullptr : &it->second;
    };
    // Faces are independent: prepared over the cores, with and without their untrusted runs.
    std::vector<std::pair<std::size_t, bool>> jobs;
    for (std::size_t i = first; i < end && i < m.rec.faces.size(); ++i) {
        jobs.emplace_back(i, false);
        if (find(untrusted, m.rec.faces[i].name)) jobs.emplace_back(i, true);
    }
    std::vector<detail::FaceFrame> prepared(jobs.size());
    core::parallel_for(jobs.size(), m.ctx.c.threads, [&](std::size_t j, unsigned) {
        const core::FaceScan& f = m.rec.faces[jobs[j].first];
        prepared[j] = detail::make_frame(f, m.T_part_world, find(u, f.name),
                                         jobs[j].second ? nullptr : find(untrusted, f.name),
                                         m.bounds.r_max, m.bounds.z_lo, m.bounds.z_hi);
        prepared[j].noise = find(noise, f.name);
    });
    m.ctx.memo->clear();  // its planes were fitted on the faces as they were
    for (std::size_t j = 0; j < jobs.size(); ++j) {
        const std::string& name = m.rec.faces[jobs[j].first].name;
        (jobs[j].second ? m.frames_all : m.frames).insert_or_assign(name, std::move(prepared[j]));
        if (jobs[j].second) m.untrusted[name] = *find(untrusted, name);
    }
    // Every feature whose faces are in: independent of each other, over the cores.
    std::vector<std::size_t> ready;
    for (std::size_t i = 0; i < m.measured.size(); ++i) {
        if (m.measured[i] && !m.early_without[i].empty()) m.recheck_early(i);
        if (!m.measured[i] && m.ready(m.ctx.recipe.features[i])) ready.push_back(i);
    }
    core::parallel_for(ready.size(), m.ctx.c.threads, [&](std::size_t j, unsigned) {
        m.measured[ready[j]] = m.measure_feature(ready[j]);
    });
    for (std::size_t i : ready) m.early_without[i] = m.not_in(m.ctx.recipe.features[i]);
}

PartMeasurement PartMeasurer::finish() {
    Impl& m = *impl_;
    PartMeasurement out;
    out.temperature_c = m.rec.temperature_c;
    out.growth = m.growth;
    for (std::size_t i = 0; i < m.measured.size(); ++i) {
        const FeatureSpec& f = m.ctx.recipe.features[i];
        FeatureResult r = m.measured[i] ? std::move(*m.measured[i]) : skeleton(f);
        if (!m.measured[i]) measure_one(m.ctx, m.refs(f, false), f, r);  // names the missing face
        out.features.push_back(std::move(r));
    }
    for (auto& r : out.features) {
        if (r.kind == core::FeatureKind::kDieShift && !r.face_missing)
            detail::measure_die_shift(m.ctx, out.features, r);
        judge(m.rec, m.ctx.recipe.material, out.growth, m.ctx.c.temperature_u_c, r);
    }
    out.verdict = overall(out.features);
    return out;
}

PartMeasurement measure_part(const core::Recipe& recipe, const core::Recording& rec,
                             const Eigen::Isometry3d& T_world_part,
                             const core::FaceDisplacements& u, const MeasureConfig& config,
                             const FaceUntrusted& untrusted,
                             const core::FaceDisplacementNoise& noise) {
    PartMeasurer m(recipe, rec, T_world_part, config);
    m.add_faces(0, rec.faces.size(), u, untrusted, noise);
    return m.finish();
}

void degrade_measured(PartMeasurement& m, const std::string& why) {
    for (auto& f : m.features) {
        if (f.verdict != Verdict::kOk && f.verdict != Verdict::kNok) continue;
        const bool outside = f.verdict == Verdict::kNok;
        f.verdict = Verdict::kDegraded;
        f.degraded = true;
        f.reason = "degraded: " + why + (outside ? " (deviation outside tolerance)" : "");
    }
    m.verdict = overall(m.features);
}

}  // namespace hotgauge::measure
