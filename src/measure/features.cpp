// Feature measurement on registered scans (docs/measurement.md): the faces prepared in the part
// frame (frame.cpp), each feature measured by its kind (diameter.cpp, height.cpp) from planes
// (surfaces.cpp) and edges (edges.cpp), then thermal scaling to the cold equivalent and verdicts.
#include "hotgauge/measure/features.hpp"

#include <algorithm>
#include <cmath>

#include "feature_kinds.hpp"
#include "frame.hpp"
#include "hotgauge/core/parallel.hpp"

namespace hotgauge::measure {
namespace {

using core::FeatureSpec;
// A pyrometer reading outside this is a fault, not a temperature (forging: 700–1300 °C).
constexpr double kMinTemperatureC = -50.0;
constexpr double kMaxTemperatureC = 1600.0;

void measure_one(const detail::Context& ctx, const std::map<std::string, detail::FaceFrame>& frames,
                 const FeatureSpec& f, FeatureResult& r) {
    std::vector<const detail::FaceFrame*> used;
    for (const auto& name : f.faces) {
        auto it = frames.find(name);
        if (it == frames.end()) {
            r.reason = "face '" + name + "' is not in the recording";
            return;
        }
        used.push_back(&it->second);
    }
    if (f.kind == core::FeatureKind::kDiameter)
        detail::measure_diameter(ctx, f, used, r);
    else
        detail::measure_height(ctx, f, used, r);
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
    return r;
}

// NOK (of a trusted value) before not measured before degraded before OK.
Verdict overall(const std::vector<FeatureResult>& features) {
    bool any_not = features.empty(), any_degraded = false;
    for (const auto& f : features) {
        if (f.verdict == Verdict::kNok) return Verdict::kNok;
        any_not = any_not || f.verdict == Verdict::kNotMeasured;
        any_degraded = any_degraded || f.verdict == Verdict::kDegraded;
    }
    return any_not ? Verdict::kNotMeasured : any_degraded ? Verdict::kDegraded : Verdict::kOk;
}

// Every face in the part frame, within the part's bounding cylinder (hot, with room for an
// unknown temperature and the edge windows); faces are independent: spread over the cores.
std::map<std::string, detail::FaceFrame> prepare_faces(const detail::Context& ctx,
                                                       const core::Recording& rec,
                                                       const Eigen::Isometry3d& T_part_world,
                                                       const FaceDisplacements& u,
                                                       const FaceUntrusted& untrusted) {
    double z_min = 0.0, z_max = 0.0;
    for (const auto& [name, z] : ctx.recipe.levels_mm) {
        z_min = std::min(z_min, z);
        z_max = std::max(z_max, z);
    }
    const double margin = 5.0;
    const double gmax = ctx.ex.g * (1.0 + ctx.ex.slack);
    std::vector<detail::FaceFrame> prepared(rec.faces.size());
    core::parallel_for(rec.faces.size(), ctx.c.threads, [&](std::size_t i, unsigned) {
        const auto& face = rec.faces[i];
        auto it = u.find(face.name);
        auto un = untrusted.find(face.name);
        prepared[i] = detail::make_frame(
            face, T_part_world, it == u.end() ? nullptr : &it->second,
            un == untrusted.end() ? nullptr : &un->second, ctx.solid.max_radius() * gmax + margin,
            std::min(z_min, z_min * gmax) - margin, std::max(z_max, z_max * gmax) + margin);
    });
    std::map<std::string, detail::FaceFrame> frames;
    for (std::size_t i = 0; i < rec.faces.size(); ++i)
        frames.emplace(rec.faces[i].name, std::move(prepared[i]));
    return frames;
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
        r.reason = "degraded: measured with untrusted profiles";
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

// The features of faces with untrusted profiles, measured again with them: a feature that relies
// on them takes that value and is degraded; one that is not measurable with them either is not
// measured, for the reason the full data gives; the others keep their value without them.
void measure_with_untrusted(const detail::Context& ctx, const core::Recording& rec,
                            const Eigen::Isometry3d& T_part_world, const FaceDisplacements& u,
                            const FaceUntrusted& untrusted, std::vector<FeatureResult>& measured) {
    std::vector<std::size_t> retry;
    for (std::size_t i = 0; i < measured.size(); ++i) {
        measured[i].left_out = untrusted_of(ctx.recipe.features[i], untrusted);
        if (!measured[i].left_out.empty()) retry.push_back(i);
    }
    if (retry.empty()) return;
    const auto frames = prepare_faces(ctx, rec, T_part_world, u, {});
    core::parallel_for(retry.size(), ctx.c.threads, [&](std::size_t j, unsigned) {
        FeatureResult& r = measured[retry[j]];
        FeatureResult again = skeleton(ctx.recipe.features[retry[j]]);
        measure_one(ctx, frames, ctx.recipe.features[retry[j]], again);
        const bool thin = r.hot_mm && again.hot_mm &&
                          static_cast<double>(r.n_points) <
                              kMinTrustedShare * static_cast<double>(again.n_points);
        if (r.hot_mm && !thin) return;  // measured around them
        again.left_out = std::move(r.left_out);
        again.degraded = again.hot_mm.has_value();
        r = std::move(again);
    });
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

PartMeasurement measure_part(const core::Recipe& recipe, const core::Recording& rec,
                             const Eigen::Isometry3d& T_world_part, const FaceDisplacements& u,
                             const MeasureConfig& config, const FaceUntrusted& untrusted) {
    PartMeasurement out;
    out.temperature_c = rec.temperature_c;
    detail::Expect ex;
    const bool plausible_t = rec.temperature_c && *rec.temperature_c >= kMinTemperatureC &&
                             *rec.temperature_c <= kMaxTemperatureC;
    if (plausible_t) {
        out.growth = recipe.material.growth(*rec.temperature_c);
        ex.g = *out.growth;
        ex.slack = 0.002;  // α model error
    } else {
        ex.g = 1.0 + 0.5 * config.unknown_growth;
        ex.slack = 0.5 * config.unknown_growth;
    }
    const detail::Context ctx{recipe, core::AxisymmetricSolid::from_recipe(recipe), ex, config};
    const auto frames = prepare_faces(ctx, rec, T_world_part.inverse(), u, untrusted);
    // Features are independent of each other: spread over the cores.
    std::vector<FeatureResult> measured(recipe.features.size());
    core::parallel_for(recipe.features.size(), config.threads, [&](std::size_t i, unsigned) {
        measured[i] = skeleton(recipe.features[i]);
        measure_one(ctx, frames, recipe.features[i], measured[i]);
    });
    if (!untrusted.empty())
        measure_with_untrusted(ctx, rec, T_world_part.inverse(), u, untrusted, measured);
    for (FeatureResult& r : measured) {
        judge(rec, recipe.material, out.growth, config.temperature_u_c, r);
        out.features.push_back(std::move(r));
    }
    out.verdict = overall(out.features);
    return out;
}

}  // namespace hotgauge::measure
