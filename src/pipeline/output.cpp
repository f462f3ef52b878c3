// pipeline::to_json and pipeline::to_table (declared in pipeline.hpp): a part result as the
// stable JSON object (docs/measure-output.md) and as the human table.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "hotgauge/pipeline/pipeline.hpp"

namespace hotgauge::pipeline {
namespace {

using nlohmann::json;

json opt(const std::optional<double>& v) { return v ? json(*v) : json(); }

// How the value was found (docs/measure-output.md): the method, the faces used, and per end of
// a height (or a diameter's edge) its estimator.
void add_method(const measure::FeatureResult& f, json& fj) {
    if (f.method.empty()) return;
    fj["method"] = f.method;
    json budget = json::object();
    for (const auto& [name, u] : f.u_budget) budget[name] = u;
    fj["u_budget_mm"] = budget;
    std::vector<std::string> used;
    json ends = json::array();
    for (const auto& e : f.ends) {
        for (const auto& face : e.faces)
            if (std::find(used.begin(), used.end(), face) == used.end()) used.push_back(face);
        json ej = {{"level", e.level},
                   {"estimator", e.estimator},
                   {"faces", e.faces},
                   {"u_mm", e.u_mm},
                   {"n_points", e.n_points}};
        ej[f.kind == core::FeatureKind::kDiameter ? "radius_mm" : "z_mm"] = e.value_mm;
        ends.push_back(ej);
    }
    fj["faces_used"] = used;
    if (f.kind == core::FeatureKind::kDiameter) {
        if (!ends.empty()) fj["edge"] = ends.front();
    } else {
        fj["ends"] = ends;
    }
}

json untrusted_json(const std::vector<core::UntrustedProfiles>& runs) {
    json out = json::array();
    for (const auto& run : runs)
        out.push_back({{"first_profile", run.first},
                       {"last_profile", run.last},
                       {"from_s", run.t0_s},
                       {"to_s", run.t1_s},
                       {"cause", run.cause}});
    return out;
}

// JSON "match".
json match_json(const match::MatchResult& mr) {
    json pose;
    pose["found"] = mr.found;
    pose["reason"] = mr.reason.empty() ? json() : json(mr.reason);
    pose["score"] = mr.score;
    pose["inliers"] = mr.inliers;
    pose["rms_mm"] = mr.rms_mm;
    pose["scale"] = mr.scale;
    pose["scale_estimated"] = mr.scale_estimated;
    pose["votes"] = mr.votes;
    pose["hypotheses"] = mr.hypotheses;
    pose["icp_iterations"] = mr.iterations;
    pose["scene_samples"] = mr.scene_points;
    pose["background_removed"] = mr.background_removed;
    json T = json::array();
    for (int i = 0; i < 4; ++i)
        T.push_back({mr.T_world_part(i, 0), mr.T_world_part(i, 1), mr.T_world_part(i, 2),
                     mr.T_world_part(i, 3)});
    pose["world_from_part"] = T;
    json ms = json::object();
    for (const auto& [k, v] : mr.stage_ms) ms[k] = v;
    pose["stage_ms"] = ms;
    return pose;
}

// JSON "compensation".
json compensation_json(const PartResult& r) {
    json comp = json::object();
    comp["enabled"] = r.compensated;
    comp["faces"] = json::array();
    for (const auto& c : r.compensation)
        comp["faces"].push_back({{"face", c.face},
                                 {"applied", c.applied},
                                 {"degraded", c.degraded},
                                 {"reasons", c.reasons},
                                 {"degraded_profiles", c.n_degraded},
                                 {"untrusted", untrusted_json(c.untrusted)},
                                 {"peak_displacement_mm", c.peak_mm},
                                 {"rms_displacement_mm", c.rms_mm},
                                 {"accel_rate_hz", c.rate_hz},
                                 {"accel_noise_ug_per_rthz", c.accel_noise_ug},
                                 {"drift_sigma_mm", c.drift_sigma_mm},
                                 {"plate_profiles", c.plate_profiles},
                                 {"plate_sigma_mm", c.plate_sigma_mm}});
    return comp;
}

// JSON "faces".
json faces_json(const std::vector<FaceSummary>& faces) {
    json out = json::array();
    for (const auto& f : faces)
        out.push_back({{"name", f.name},
                       {"profiles", f.profiles},
                       {"width", f.width},
                       {"points", f.points},
                       {"nan_fraction", f.nan_fraction},
                       {"scan_s", f.scan_s},
                       {"accel_samples", f.accel_samples},
                       {"accel_rate_hz", f.accel_rate_hz},
                       {"accel_margin_before_s", opt(f.margin_before_s)},
                       {"accel_margin_after_s", opt(f.margin_after_s)}});
    return out;
}

// One element of JSON "features".
json feature_json(const measure::FeatureResult& f) {
    json fj;
    fj["name"] = f.name;
    fj["slot"] = f.slot;
    fj["kind"] = f.kind == core::FeatureKind::kDiameter ? "diameter"
                 : f.kind == core::FeatureKind::kHeight ? "height"
                                                        : "die_shift";
    fj["faces"] = f.faces;
    fj["hot_mm"] = opt(f.hot_mm);
    fj["cold_mm"] = opt(f.cold_mm);
    fj["nominal_mm"] = f.nominal_mm;
    fj["deviation_mm"] = opt(f.deviation_mm);
    fj["tolerance_mm"] = {f.tol_lower_mm, f.tol_upper_mm};
    fj["verdict"] = measure::to_string(f.verdict);
    fj["required"] = f.required;
    fj["reason"] = f.reason.empty() ? json() : json(f.reason);
    fj["degraded"] = f.degraded;
    fj["face_missing"] = f.face_missing;
    fj["low_coverage"] = f.low_coverage;
    fj["left_out"] = f.left_out;
    const bool measured = f.hot_mm.has_value();
    fj["fit_rms_mm"] = measured ? json(f.fit_rms_mm) : json();
    fj["n_points"] = f.n_points;
    fj["u_mm"] = measured ? json(f.u_mm) : json();
    fj["u_cold_mm"] = opt(f.u_cold_mm);
    fj["sector_spread_mm"] = opt(f.sector_spread_mm);
    fj["sector_between_mm"] = opt(f.sector_between_mm);
    fj["n_sectors"] = f.n_sectors;
    if (f.kind == core::FeatureKind::kDiameter && measured) fj["arc_deg"] = f.arc_deg;
    add_method(f, fj);
    return fj;
}

// The table's first lines: the part, its verdict and, when matching ran, the match.
std::string headline(const PartResult& r) {
    const auto& m = r.measurement;
    std::string s;
    char line[512];
    char temperature[32] = "unknown";
    if (m.temperature_c)
        std::snprintf(temperature, sizeof temperature, "%.1f °C", *m.temperature_c);
    std::snprintf(line, sizeof line, "part %s  recipe %s  temperature %s  pose %s  verdict %s%s\n",
                  r.part_id.c_str(), r.recipe.c_str(), temperature,
                  r.pose_source.empty() ? "none" : r.pose_source.c_str(),
                  measure::to_string(m.verdict),
                  r.degraded && m.verdict != measure::Verdict::kDegraded ? " (DEGRADED)" : "");
    s += line;
    if (r.match) {
        const auto& mr = *r.match;
        const Eigen::Vector3d a = mr.T_world_part.linear().col(2),
                              o = mr.T_world_part.translation();
        if (mr.found)
            std::snprintf(line, sizeof line,
                          "match: score %.3f (%lld points), rms %.4f mm, scale %.5f%s, axis "
                          "(%.5f %.5f %.5f) through (%.3f %.3f %.3f) mm\n",
                          mr.score, static_cast<long long>(mr.inliers), mr.rms_mm, mr.scale,
                          mr.scale_estimated ? " (estimated)" : "", a.x(), a.y(), a.z(), o.x(),
                          o.y(), o.z());
        else
            std::snprintf(line, sizeof line, "match: %s\n", mr.reason.c_str());
        s += line;
    }
    return s;
}

// What was acquired per face, one line each under a header.
std::string faces_table(const std::vector<FaceSummary>& faces) {
    std::string s;
    char line[512];
    std::snprintf(line, sizeof line, "%-8s %8s %6s %10s %6s %8s %8s %8s %9s %9s\n", "face",
                  "profiles", "width", "points", "NaN %", "scan s", "accel", "accel Hz", "before s",
                  "after s");
    s += line;
    for (const auto& f : faces) {
        std::snprintf(
            line, sizeof line, "%-8s %8lld %6lld %10lld %6.2f %8.3f %8lld %8.1f %9.3f %9.3f\n",
            f.name.c_str(), static_cast<long long>(f.profiles), static_cast<long long>(f.width),
            static_cast<long long>(f.points), 100.0 * f.nan_fraction, f.scan_s,
            static_cast<long long>(f.accel_samples), f.accel_rate_hz,
            f.margin_before_s.value_or(NAN), f.margin_after_s.value_or(NAN));
        s += line;
    }
    return s;
}

// What compensation did per face and the profiles it left out, or that it was off.
std::string compensation_lines(const PartResult& r) {
    if (!r.compensated) return "vibration compensation: off\n";
    std::string s;
    char line[512];
    for (const auto& c : r.compensation) {
        std::snprintf(line, sizeof line, "%-8s compensation %s: peak %.3f mm, rms %.3f mm\n",
                      c.face.c_str(), c.applied ? "applied" : "NOT applied", c.peak_mm, c.rms_mm);
        s += line;
        for (const auto& run : c.untrusted)
            s += "         left out of the fits: " + core::describe(c.face, run) + "\n";
    }
    return s;
}

// `v` printed with `fmt`, or "-" when absent.
std::string num_or_dash(const std::optional<double>& v, const char* fmt) {
    char b[32];
    if (!v) return std::string("-");
    std::snprintf(b, sizeof b, fmt, *v);
    return std::string(b);
}

// The features, one line each under a header, with the reason below a line that has one.
std::string features_table(const std::vector<measure::FeatureResult>& features) {
    std::string s;
    char line[512];
    std::snprintf(line, sizeof line, "%-8s %-15s %9s %9s %9s %8s %15s %-12s %7s %7s %7s\n", "face",
                  "feature", "hot mm", "cold mm", "nominal", "dev mm", "tolerance", "verdict",
                  "rms mm", "points", "u mm");
    s += line;
    for (const auto& f : features) {
        std::string faces;
        for (const auto& fc : f.faces) faces += (faces.empty() ? "" : ",") + fc;
        char tol[32];
        std::snprintf(tol, sizeof tol, "%+.2f/%+.2f", f.tol_lower_mm, f.tol_upper_mm);
        std::snprintf(line, sizeof line, "%-8s %-15s %9s %9s %9.3f %8s %15s %-12s %7s %7lld %7s\n",
                      faces.c_str(), f.name.c_str(), num_or_dash(f.hot_mm, "%.3f").c_str(),
                      num_or_dash(f.cold_mm, "%.3f").c_str(), f.nominal_mm,
                      num_or_dash(f.deviation_mm, "%+.3f").c_str(), tol,
                      measure::to_string(f.verdict),
                      f.hot_mm ? num_or_dash(f.fit_rms_mm, "%.3f").c_str() : "-",
                      static_cast<long long>(f.n_points),
                      f.hot_mm ? num_or_dash(f.u_mm, "%.4f").c_str() : "-");
        s += line;
        if (!f.reason.empty()) s += "         └ " + f.reason + "\n";
    }
    return s;
}

}  // namespace

std::string to_json(const PartResult& r) {
    const auto& m = r.measurement;
    json j;
    j["part_id"] = r.part_id;
    j["recipe"] = r.recipe;
    j["captured_at"] = r.captured_at;
    j["temperature_c"] = opt(m.temperature_c);
    j["growth"] = opt(m.growth);
    j["verdict"] = measure::to_string(m.verdict);
    j["pose_source"] = r.pose_source.empty() ? json() : json(r.pose_source);
    j["match"] = r.match ? match_json(*r.match) : json();
    j["degraded"] = r.degraded;
    j["degraded_reasons"] = r.degraded_reasons;
    j["compensation"] = compensation_json(r);
    j["faces"] = faces_json(r.faces);
    j["features"] = json::array();
    for (const auto& f : m.features) j["features"].push_back(feature_json(f));
    j["warnings"] = r.warnings;
    json st = json::object();
    for (const auto& [k, v] : r.stage_ms) st[k] = v;
    j["stage_ms"] = st;
    return j.dump();
}

std::string to_table(const PartResult& r) {
    std::string s = headline(r) + faces_table(r.faces) + compensation_lines(r);
    for (const auto& why : r.degraded_reasons) s += "degraded: " + why + "\n";
    s += "\n";
    return s + features_table(r.measurement.features);
}

}  // namespace hotgauge::pipeline
