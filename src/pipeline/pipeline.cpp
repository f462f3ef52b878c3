#include "hotgauge/pipeline/pipeline.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "hotgauge/model/model_io.hpp"
#include "hotgauge/model/surface_io.hpp"

namespace hotgauge::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// Seconds between two clock readings, without int64 overflow on corrupt files (summary only).
double span_s(std::int64_t later, std::int64_t earlier) {
    return (static_cast<double>(later) - static_cast<double>(earlier)) * 1e-9;
}

// The (x, z) pairs without a NaN, counted in blocks of a fixed size (a loop the compiler
// vectorizes: the count was 2 % of a part's time in `hotgauge remeasure`).
std::int64_t count_points(const std::vector<float>& xz) {
    constexpr std::size_t kBlock = 16;  // values: 8 points
    const std::size_t n = xz.size() - xz.size() % 2;
    std::int64_t points = 0;
    std::size_t q = 0;
    for (; q + kBlock <= n; q += kBlock) {
        int in_block = 0;
        for (std::size_t j = 0; j < kBlock; j += 2)  // NaN is the one value not equal to itself
            in_block += static_cast<int>(xz[q + j] == xz[q + j]) &
                        static_cast<int>(xz[q + j + 1] == xz[q + j + 1]);
        points += in_block;
    }
    for (; q < n; q += 2) points += !std::isnan(xz[q]) && !std::isnan(xz[q + 1]);
    return points;
}

}  // namespace

FaceSummary summarize(const core::FaceScan& f) {
    FaceSummary s;
    s.name = f.name;
    s.profiles = f.n_profiles();
    s.width = f.width;
    s.points = count_points(f.profiles_mm);
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
    out.geometry() = f.geometry();
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
    r.compensation.back().plate_profiles = fc.plate_profiles;
    r.compensation.back().plate_sigma_mm = fc.plate_sigma_mm;
    if (auto e = fc.applied ? compensate::compensation_error(face, o.compensation)
                            : compensate::CompensationError{};
        e.noise.known()) {
        if (fc.plate_profiles == face.n_profiles()) {  // u_z measured, not integrated
            e.noise.hole_axes[2] = false;
            e.noise.acov_mm2[2] = {fc.plate_sigma_mm * fc.plate_sigma_mm, 0.0};
        }
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
        auto loaded = model::read_model(source.model_file);
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
    auto samples = mesh.empty() ? model::read_scan_samples(source.scan)
                                : model::read_mesh_samples(mesh, kMeshSpacingMm);
    if (!samples) return samples.error();
    return match::model_from_samples(
        recipe.name, mesh.empty() ? "scan " + source.scan.string() : "mesh " + mesh.string(),
        std::move(samples->points), std::move(samples->normals), config);
}

PartResult run(const core::Recording& rec, const core::Recipe& recipe, const PipelineOptions& o) {
    return PartRun(rec, recipe, o).finish();
}

}  // namespace hotgauge::pipeline
