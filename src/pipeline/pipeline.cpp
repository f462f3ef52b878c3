#include "hotgauge/pipeline/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "hotgauge/io/model_io.hpp"
#include "hotgauge/io/surface_io.hpp"

namespace hotgauge::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

nlohmann::json opt(const std::optional<double>& v) {
    return v ? nlohmann::json(*v) : nlohmann::json();
}

// Seconds between two clock readings, without int64 overflow on corrupt files (summary only).
double span_s(std::int64_t later, std::int64_t earlier) {
    return (static_cast<double>(later) - static_cast<double>(earlier)) * 1e-9;
}

// How the value was found (docs/measure-output.md): the method, the faces used, and per end of
// a height (or a diameter's edge) its estimator.
void add_method(const measure::FeatureResult& f, nlohmann::json& fj) {
    using nlohmann::json;
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

nlohmann::json untrusted_json(const std::vector<core::UntrustedProfiles>& runs) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& run : runs)
        out.push_back({{"first_profile", run.first},
                       {"last_profile", run.last},
                       {"from_s", run.t0_s},
                       {"to_s", run.t1_s},
                       {"cause", run.cause}});
    return out;
}

}  // namespace

FaceSummary summarize(const core::FaceScan& f) {
    FaceSummary s;
    s.name = f.name;
    s.profiles = f.n_profiles();
    s.width = f.width;
    for (std::size_t q = 0; q + 1 < f.profiles_mm.size(); q += 2)
        s.points += !std::isnan(f.profiles_mm[q]) && !std::isnan(f.profiles_mm[q + 1]);
    const double total = static_cast<double>(s.profiles * s.width);
    s.nan_fraction = total > 0 ? 1.0 - static_cast<double>(s.points) / total : 0.0;
    if (s.profiles > 1) s.scan_s = span_s(f.profile_times_ns.back(), f.profile_times_ns.front());
    s.accel_samples = f.n_accel();
    if (s.accel_samples > 1) {
        const double span = span_s(f.accel_times_ns.back(), f.accel_times_ns.front());
        s.accel_rate_hz = static_cast<double>(s.accel_samples - 1) / span;
        if (s.profiles > 0) {
            s.margin_before_s = span_s(f.profile_times_ns.front(), f.accel_times_ns.front());
            s.margin_after_s = span_s(f.accel_times_ns.back(), f.profile_times_ns.back());
        }
    }
    return s;
}

namespace {

// A face as known at its last profile, for the compensation: its accelerometer record up to
// that profile (on the accelerometer's clock), without the profiles themselves.
core::FaceScan record_until_last_profile(const core::FaceScan& f, double clock_offset_s) {
    core::FaceScan out;
    out.name = f.name;
    out.T_world_camera = f.T_world_camera;
    out.scan_direction = f.scan_direction;
    out.R_camera_accel = f.R_camera_accel;
    out.profile_times_ns = f.profile_times_ns;
    if (f.profile_times_ns.empty()) return out;
    const std::int64_t until =
        f.profile_times_ns.back() + static_cast<std::int64_t>(clock_offset_s * 1e9);
    std::size_t keep = 0;
    while (keep < f.accel_times_ns.size() && f.accel_times_ns[keep] <= until) ++keep;
    out.accel_times_ns.assign(f.accel_times_ns.begin(),
                              f.accel_times_ns.begin() + static_cast<std::ptrdiff_t>(keep));
    out.accel_mps2.assign(f.accel_mps2.begin(),
                          f.accel_mps2.begin() + static_cast<std::ptrdiff_t>(3 * keep));
    return out;
}

}  // namespace

struct PartRun::Impl {
    const core::Recording& rec;
    const core::Recipe& recipe;
    PipelineOptions o;
    PartResult r;
    core::FaceDisplacements u;
    core::FaceDisplacementNoise noise;
    measure::FaceUntrusted untrusted;
    std::optional<measure::PartMeasurer> measurer;  // none: nothing to measure (r says why)
    std::size_t faces_added = 0;
    double compensate_ms = 0, measure_ms = 0;

    Impl(const core::Recording& rec_, const core::Recipe& recipe_, const PipelineOptions& o_)
        : rec(rec_), recipe(recipe_), o(o_) {}
    void compensate(const core::FaceScan& face);
    std::optional<Eigen::Isometry3d> find_pose();
    void add_faces(std::size_t first, std::size_t end);
};

// One face's compensation into the summaries, the warnings, u and the untrusted runs. What it
// found is a warning: a feature is degraded only when it relies on the profiles it touched.
void PartRun::Impl::compensate(const core::FaceScan& face) {
    const auto t0 = Clock::now();
    auto fc = compensate::compensate_face(face, o.compensation);
    r.compensation.push_back({fc.face, fc.applied, fc.degraded, fc.reasons, fc.n_degraded,
                              fc.peak_mm, fc.rms_mm, fc.rate_hz, fc.untrusted});
    if (auto e = fc.applied ? compensate::compensation_error(face, o.compensation)
                            : compensate::CompensationError{};
        e.noise.known()) {
        auto& c = r.compensation.back();
        c.accel_noise_ug = e.accel_noise_ug;
        for (int a = 0; a < 3; ++a) c.drift_sigma_mm[a] = std::sqrt(e.noise.cov(a, 0.0));
        noise.insert_or_assign(face.name, std::move(e.noise));
    }
    for (const auto& why : fc.reasons) r.warnings.push_back(face.name + ": compensation: " + why);
    if (fc.applied) u.insert_or_assign(face.name, std::move(fc.displacement_mm));
    if (!fc.untrusted.empty()) untrusted.insert_or_assign(face.name, std::move(fc.untrusted));
    compensate_ms += ms_since(t0);
}

// The pose: given, or found with every face's displacement as known at the last profile (the
// last face's from its record up to that profile).
std::optional<Eigen::Isometry3d> PartRun::Impl::find_pose() {
    if (o.T_world_part) {
        r.pose_source = o.pose_source;
        return o.T_world_part;
    }
    const auto t0 = Clock::now();
    core::FaceDisplacements u_now = u;
    if (o.compensate && !rec.faces.empty()) {
        auto fc = compensate::compensate_face(
            record_until_last_profile(rec.faces.back(), o.compensation.clock_offset_s),
            o.compensation);
        if (fc.applied)
            u_now.insert_or_assign(rec.faces.back().name, std::move(fc.displacement_mm));
    }
    std::optional<match::Model> built;
    const match::Model* model = o.model;
    if (!model) {
        auto m = part_model(recipe);
        if (!m) {
            r.measurement = measure::unmeasured(recipe, rec, "no part model: " + m.error().message);
            return std::nullopt;
        }
        built = std::move(*m);
        model = &*built;
    }
    match::MatchConfig cfg = o.match;
    cfg.min_score = recipe.matching.min_score;
    cfg.score_band_mm = recipe.matching.score_band_mm;
    // The hot part is larger than the cold model: scale it when the temperature is known, let
    // ICP estimate the scale when it is not.
    if (rec.temperature_c) cfg.scale = recipe.material.growth(*rec.temperature_c);
    // Every profile, the untrusted ones too: their bridged displacement is noisy, not biased,
    // while leaving a band of a face out tilts the nominal model towards the other surfaces
    // (measured: a side height 0.030 mm off instead of 0.011, docs/compensation.md).
    r.match = match::match(*model, rec, u_now, cfg);
    r.stage_ms.emplace_back("match", ms_since(t0));
    if (!r.match->found) {
        r.measurement = measure::unmeasured(recipe, rec, r.match->reason);
        return std::nullopt;
    }
    r.pose_source = "match";
    return r.match->T_world_part;
}

void PartRun::Impl::add_faces(std::size_t first, std::size_t end) {
    const auto t0 = Clock::now();
    measurer->add_faces(first, end, u, untrusted, noise);
    faces_added = end;
    measure_ms += ms_since(t0);
}

PartRun::PartRun(const core::Recording& rec, const core::Recipe& recipe, const PipelineOptions& o)
    : impl_(std::make_unique<Impl>(rec, recipe, o)) {
    Impl& m = *impl_;
    m.r.part_id = rec.part_id;
    m.r.recipe = recipe.name;
    m.r.captured_at = rec.captured_at;
    m.r.warnings = rec.warnings;
    if (rec.recipe != recipe.name)
        m.r.warnings.push_back("recording names recipe '" + rec.recipe + "', measured with '" +
                               recipe.name + "'");
    m.r.compensated = o.compensate;
    const std::size_t n = rec.faces.size();
    if (o.compensate)
        for (std::size_t i = 0; i + 1 < n; ++i) m.compensate(rec.faces[i]);
    m.r.T_world_part = m.find_pose();
    if (m.r.T_world_part) m.measurer.emplace(recipe, rec, *m.r.T_world_part, o.measure);
}

void PartRun::measure_all_but_last() {
    Impl& m = *impl_;
    if (m.measurer && m.faces_added == 0 && m.rec.faces.size() > 1)
        m.add_faces(0, m.rec.faces.size() - 1);
}

PartRun::~PartRun() = default;

PartResult PartRun::finish() {
    Impl& m = *impl_;
    const std::size_t n = m.rec.faces.size();
    if (m.o.compensate && n > 0) m.compensate(m.rec.faces.back());
    for (const auto& f : m.rec.faces) m.r.faces.push_back(summarize(f));
    m.r.displacement_mm = m.u;
    if (m.o.compensate) m.r.stage_ms.emplace(m.r.stage_ms.begin(), "compensate", m.compensate_ms);
    if (!m.measurer) return std::move(m.r);
    if (n > m.faces_added) m.add_faces(m.faces_added, n);
    const auto t0 = Clock::now();
    m.r.measurement = m.measurer->finish();
    m.measure_ms += ms_since(t0);
    m.r.stage_ms.emplace_back("measure", m.measure_ms);
    for (const auto& f : m.r.measurement.features)
        if (f.verdict == measure::Verdict::kDegraded) {
            m.r.degraded = true;
            m.r.degraded_reasons.push_back(f.name + ": " + f.reason);
        }
    return std::move(m.r);
}

core::Result<match::Model> part_model(const core::Recipe& recipe, const ModelSource& source) {
    if (!source.model_file.empty()) {
        auto loaded = io::read_model(source.model_file);
        if (!loaded) return loaded.error();
        if (loaded->name != recipe.name)
            return core::make_error(source.model_file.string() + ": model of part '" +
                                    loaded->name + "', the recipe is '" + recipe.name + "'");
        return loaded;
    }
    match::ModelConfig config;
    config.sampling_mm = source.sampling_mm.value_or(recipe.matching.sampling_mm);
    const std::filesystem::path mesh = source.mesh.empty() && source.scan.empty()
                                           ? std::filesystem::path(recipe.mesh_file)
                                           : source.mesh;
    if (mesh.empty() && source.scan.empty()) {
        auto built = match::model_from_recipe(recipe, config);
        if (!built)
            return core::make_error("recipe " + recipe.name +
                                    ": part model: " + built.error().message);
        return built;
    }
    constexpr double kMeshSpacingMm = 0.5;  // dense samples of a mesh: the ICP surface
    auto samples = mesh.empty() ? io::read_scan_samples(source.scan)
                                : io::read_mesh_samples(mesh, kMeshSpacingMm);
    if (!samples) return samples.error();
    return match::model_from_samples(
        recipe.name, mesh.empty() ? "scan " + source.scan.string() : "mesh " + mesh.string(),
        std::move(samples->points), std::move(samples->normals), config);
}

PartResult run(const core::Recording& rec, const core::Recipe& recipe, const PipelineOptions& o) {
    return PartRun(rec, recipe, o).finish();
}

std::string to_json(const PartResult& r) {
    using nlohmann::json;
    const auto& m = r.measurement;
    json j;
    j["part_id"] = r.part_id;
    j["recipe"] = r.recipe;
    j["captured_at"] = r.captured_at;
    j["temperature_c"] = opt(m.temperature_c);
    j["growth"] = opt(m.growth);
    j["verdict"] = measure::to_string(m.verdict);
    j["pose_source"] = r.pose_source.empty() ? json() : json(r.pose_source);
    if (r.match) {
        const auto& mr = *r.match;
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
        j["match"] = pose;
    } else {
        j["match"] = json();
    }
    j["degraded"] = r.degraded;
    j["degraded_reasons"] = r.degraded_reasons;
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
                                 {"drift_sigma_mm", c.drift_sigma_mm}});
    j["compensation"] = comp;
    j["faces"] = json::array();
    for (const auto& f : r.faces)
        j["faces"].push_back({{"name", f.name},
                              {"profiles", f.profiles},
                              {"width", f.width},
                              {"points", f.points},
                              {"nan_fraction", f.nan_fraction},
                              {"scan_s", f.scan_s},
                              {"accel_samples", f.accel_samples},
                              {"accel_rate_hz", f.accel_rate_hz},
                              {"accel_margin_before_s", opt(f.margin_before_s)},
                              {"accel_margin_after_s", opt(f.margin_after_s)}});
    j["features"] = json::array();
    for (const auto& f : m.features) {
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
        j["features"].push_back(fj);
    }
    j["warnings"] = r.warnings;
    json st = json::object();
    for (const auto& [k, v] : r.stage_ms) st[k] = v;
    j["stage_ms"] = st;
    return j.dump();
}

std::string to_table(const PartResult& r) {
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
    std::snprintf(line, sizeof line, "%-8s %8s %6s %10s %6s %8s %8s %8s %9s %9s\n", "face",
                  "profiles", "width", "points", "NaN %", "scan s", "accel", "accel Hz", "before s",
                  "after s");
    s += line;
    for (const auto& f : r.faces) {
        std::snprintf(
            line, sizeof line, "%-8s %8lld %6lld %10lld %6.2f %8.3f %8lld %8.1f %9.3f %9.3f\n",
            f.name.c_str(), static_cast<long long>(f.profiles), static_cast<long long>(f.width),
            static_cast<long long>(f.points), 100.0 * f.nan_fraction, f.scan_s,
            static_cast<long long>(f.accel_samples), f.accel_rate_hz,
            f.margin_before_s.value_or(NAN), f.margin_after_s.value_or(NAN));
        s += line;
    }
    if (r.compensated)
        for (const auto& c : r.compensation) {
            std::snprintf(line, sizeof line, "%-8s compensation %s: peak %.3f mm, rms %.3f mm\n",
                          c.face.c_str(), c.applied ? "applied" : "NOT applied", c.peak_mm,
                          c.rms_mm);
            s += line;
            for (const auto& run : c.untrusted)
                s += "         left out of the fits: " + core::describe(c.face, run) + "\n";
        }
    else
        s += "vibration compensation: off\n";
    for (const auto& why : r.degraded_reasons) s += "degraded: " + why + "\n";
    s += "\n";
    std::snprintf(line, sizeof line, "%-8s %-15s %9s %9s %9s %8s %15s %-12s %7s %7s %7s\n", "face",
                  "feature", "hot mm", "cold mm", "nominal", "dev mm", "tolerance", "verdict",
                  "rms mm", "points", "u mm");
    s += line;
    for (const auto& f : m.features) {
        std::string faces;
        for (const auto& fc : f.faces) faces += (faces.empty() ? "" : ",") + fc;
        auto num = [](const std::optional<double>& v, const char* fmt) {
            char b[32];
            if (!v) return std::string("-");
            std::snprintf(b, sizeof b, fmt, *v);
            return std::string(b);
        };
        char tol[32];
        std::snprintf(tol, sizeof tol, "%+.2f/%+.2f", f.tol_lower_mm, f.tol_upper_mm);
        std::snprintf(
            line, sizeof line, "%-8s %-15s %9s %9s %9.3f %8s %15s %-12s %7s %7lld %7s\n",
            faces.c_str(), f.name.c_str(), num(f.hot_mm, "%.3f").c_str(),
            num(f.cold_mm, "%.3f").c_str(), f.nominal_mm, num(f.deviation_mm, "%+.3f").c_str(), tol,
            measure::to_string(f.verdict), f.hot_mm ? num(f.fit_rms_mm, "%.3f").c_str() : "-",
            static_cast<long long>(f.n_points), f.hot_mm ? num(f.u_mm, "%.4f").c_str() : "-");
        s += line;
        if (!f.reason.empty()) s += "         └ " + f.reason + "\n";
    }
    return s;
}

}  // namespace hotgauge::pipeline
