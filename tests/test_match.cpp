// PPF matching + ICP on simulated hub-a scenes: convergence and pose accuracy over random
// placements, occlusion and spikes; "part not found" on bad scenes (issue 5, docs/matching.md).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>

#include "hotgauge/core/forged.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/match/match.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/sim/simulator.hpp"

using namespace hotgauge;

namespace {

struct Env {
    core::Recipe recipe;
    sim::CellConfig cell;
    match::Model model;
};

// The trial cell: the configured cell, scans long enough for parts offset by up to 100 mm,
// tilt up to 15°, 0.5 % spikes, no vibration (matching is tested on its own).
sim::CellConfig trial_cell(sim::CellConfig c) {
    c.vibration.enabled = false;
    c.placement.max_offset_mm = 100.0 / std::sqrt(2.0);
    c.placement.max_tilt_deg = 15.0;
    c.sensor.spike_fraction = 0.005;
    for (auto& f : c.faces) {
        f.T_world_camera.translation() -= 60.0 * f.scan_direction;
        f.scan_length_mm += 120.0;
    }
    return c;
}

const Env& env() {
    static const Env e = [] {
        auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!r || !c) std::abort();
        auto m = match::model_from_recipe(*r);
        if (!m) std::abort();
        return Env{*r, trial_cell(*c), std::move(*m)};
    }();
    return e;
}

struct Trial {
    sim::SimResult sim;
    match::MatchResult m;
    match::AxisError err;
};

Trial run_trial(const sim::CellConfig& cell, std::uint64_t seed, std::vector<std::string> faces,
                double occluded = 0.1, bool temperature_known = true,
                const match::Model* model = nullptr) {
    sim::SimOptions o;
    o.seed = seed;
    o.temperature_c = 20.0 + static_cast<double>(seed % 11) * 100.0;
    o.t0_ns = 1'790'000'000'000'000'000;
    o.faces = std::move(faces);
    o.occluded_fraction = occluded;
    auto s = sim::simulate(env().recipe, cell, o);
    if (!s) std::abort();
    Trial t{std::move(*s), {}, {}};
    match::MatchConfig mc;
    if (temperature_known) mc.scale = env().recipe.material.growth(o.temperature_c);
    t.m = match::match(model ? *model : env().model, t.sim.recording, {}, mc);
    t.err = match::axis_error(t.sim.truth.T_world_part, t.m.T_world_part);
    return t;
}

// Issue 5's acceptance: 200 random placements of the four-face quick cell (0.8 mm rays, 1 mm
// profiles), tilt up to 15°, offset up to 100 mm, a contiguous 10 % of the part occluded, 0.5 %
// spikes, σ 0.05 mm, support plate in view. A trial converges when the part is found with the
// axis within 0.02° and 0.02 mm of the truth.
TEST(Match, RandomPlacements) {
    const auto cell = sim::quick(env().cell);
    int converged = 0, found = 0;
    double worst_angle = 0, worst_radial = 0, worst_axial = 0, sum_ms = 0;
    const int n = std::getenv("HOTGAUGE_MATCH_TRIALS")
                      ? std::atoi(std::getenv("HOTGAUGE_MATCH_TRIALS"))
                      : 200;
    for (int i = 0; i < n; ++i) {
        const auto seed = static_cast<std::uint64_t>(1000 + i);
        const auto t0 = std::chrono::steady_clock::now();
        auto t = run_trial(cell, seed, {});
        sum_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                      .count();
        const bool ok = t.m.found && t.err.angle_deg <= 0.02 && t.err.radial_mm <= 0.02;
        found += t.m.found;
        converged += ok;
        if (t.m.found) {
            worst_angle = std::max(worst_angle, t.err.angle_deg);
            worst_radial = std::max(worst_radial, t.err.radial_mm);
            worst_axial = std::max(worst_axial, t.err.axial_mm);
        }
        if (!ok)
            std::printf("trial %d (seed %llu): found %d score %.3f, axis %.4f deg, %.4f mm: %s\n",
                        i, static_cast<unsigned long long>(seed), t.m.found, t.m.score,
                        t.err.angle_deg, t.err.radial_mm, t.m.reason.c_str());
    }
    std::printf(
        "%d trials: %d found, %d converged; worst found: axis %.4f deg, radial %.4f mm, "
        "axial %.4f mm; %.0f ms per trial (simulation + matching)\n",
        n, found, converged, worst_angle, worst_radial, worst_axial, sum_ms / n);
    EXPECT_GE(converged, (99 * n + 99) / 100);
}

// The model: meridian references at azimuth 0, unit outward normals, every sample on the surface.
// A recipe with a forging drawing: the part it draws at half its limits (drafts and fillets; the
// fillets' chords joined within 5 µm); without one, the sharp, vertical idealisation.
TEST(MatchModel, RecipeModelSamplesTheSurface) {
    core::Recipe sharp = env().recipe;
    sharp.forging.reset();
    const auto sharp_model = match::model_from_recipe(sharp);
    ASSERT_TRUE(sharp_model);
    const auto axi = core::AxisymmetricSolid::from_recipe(sharp);
    core::ForgedShape shape;
    for (const auto& w : core::forged_walls(env().recipe))
        shape.draft_deg[w.name] = 0.5 * env().recipe.draft_of(w.section);
    for (const auto& c : core::forged_corners(env().recipe))
        shape.fillet_mm[c.name] = 0.5 * env().recipe.fillet_at(c.level);
    const auto drawn = core::build_forged(env().recipe, shape);
    ASSERT_TRUE(drawn);
    const auto forged = drawn->solid();
    struct Case {
        const match::Model& m;
        double on_mm;
        std::function<double(const Eigen::Vector3d&)> distance;
        std::function<bool(const Eigen::Vector3d&)> inside;
    };
    const std::array<Case, 2> cases{{
        {env().model, 0.006, [&](const Eigen::Vector3d& p) { return forged.distance(p); },
         [&](const Eigen::Vector3d& p) { return forged.inside(p); }},
        {*sharp_model, 1e-4, [&](const Eigen::Vector3d& p) { return axi.distance(p); },
         [&](const Eigen::Vector3d& p) { return axi.inside(std::hypot(p.x(), p.y()), p.z()); }},
    }};
    for (const auto& c : cases) {
        const auto& m = c.m;
        EXPECT_TRUE(m.axisymmetric);
        EXPECT_TRUE(m.validate()) << m.validate().error().message;
        EXPECT_GT(m.points.size(), 1000u);
        EXPECT_GT(m.refs.size(), 30u);
        EXPECT_LT(m.refs.size(), 200u);
        for (std::size_t i = 0; i < m.points.size(); ++i) {
            const Eigen::Vector3d p = m.points[i].cast<double>(), n = m.normals[i].cast<double>();
            ASSERT_LT(c.distance(p), c.on_mm) << i;
            ASSERT_NEAR(n.norm(), 1.0, 1e-5);
            // Outward: a step along the normal leaves the material, a step against it enters it.
            EXPECT_FALSE(c.inside(p + 0.02 * n)) << i;
            EXPECT_TRUE(c.inside(p - 0.02 * n)) << i;
        }
        for (auto r : m.refs) {
            EXPECT_NEAR(m.points[r].y(), 0.0f, 1e-6f);
            EXPECT_GT(m.points[r].x(), 0.0f);
        }
        // The key is symmetric in the sense PPF needs: equal for a rigidly moved pair.
        const Eigen::Isometry3f T(Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()) *
                                  Eigen::Translation3f(10, -20, 30));
        int same = 0, total = 0;
        for (std::size_t i = 0; i + 7 < m.points.size(); i += 37) {
            const auto j = i + 7;
            const auto k1 = m.key(m.points[i], m.normals[i], m.points[j], m.normals[j]);
            const auto k2 = m.key(T * m.points[i], T.linear() * m.normals[i], T * m.points[j],
                                  T.linear() * m.normals[j]);
            same += k1 == k2;
            ++total;
        }
        EXPECT_GE(same, total * 95 / 100);  // float round-off may flip a bin edge
    }
    // The drawn model's walls are drafted and its corners filleted: more segments, few upright.
    int upright = 0, walls = 0;
    for (const auto& seg : env().model.profile) {
        walls += seg.wall;
        upright += seg.wall && seg.r0 == seg.r1;
    }
    EXPECT_GT(env().model.profile.size(), 2 * sharp_model->profile.size());
    EXPECT_GE(walls, 7);
    EXPECT_EQ(upright, 0);
}

TEST(MatchModel, BadConfigIsAnError) {
    match::ModelConfig c;
    c.sampling_mm = 0;
    auto m = match::model_from_recipe(env().recipe, c);
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message.find("sampling_mm"), std::string::npos);
    c = {};
    c.angle_bins = 1000;
    EXPECT_FALSE(match::model_from_recipe(env().recipe, c));
}

// Seen from above only, an upside-down hub resembles the upright one (algorithm-notes); the
// verification by fit must not pick the flip. From above, the walls are at grazing incidence and
// return little: the axis position across is weakly observed, to ~0.1 mm where the model is the
// part (this ideal part and the sharp model), to ~0.45 mm where its fillets and drafts are the
// drawing's middle and the part's are not (the drawn model); all four faces together fix it to
// µm, RandomPlacements.
TEST(Match, TopFaceOnlyIsNotFlipped) {
    core::Recipe sharp = env().recipe;
    sharp.forging.reset();
    const auto sharp_model = match::model_from_recipe(sharp);
    ASSERT_TRUE(sharp_model);
    const auto cell = sim::quick(env().cell);
    for (const auto& [model, radial_mm] :
         {std::pair{&env().model, 0.6}, std::pair{&*sharp_model, 0.3}}) {
        for (std::uint64_t seed = 1; seed <= 20; ++seed) {
            auto t = run_trial(cell, 500 + seed, {"top"}, 0.1, true, model);
            ASSERT_TRUE(t.m.found) << seed << ": " << t.m.reason;
            EXPECT_LT(t.err.angle_deg, 0.05) << seed;
            EXPECT_LT(t.err.radial_mm, radial_mm) << seed;
            std::printf(
                "top only, %s model, seed %llu: score %.3f, axis %.4f deg, radial %.4f mm\n",
                model == &env().model ? "drawn" : "sharp",
                static_cast<unsigned long long>(500 + seed), t.m.score, t.err.angle_deg,
                t.err.radial_mm);
        }
    }
}

void expect_not_found(const match::MatchResult& m, const std::string& why) {
    EXPECT_FALSE(m.found);
    EXPECT_NE(m.reason.find("part not found"), std::string::npos) << m.reason;
    EXPECT_NE(m.reason.find(why), std::string::npos) << m.reason;
}

TEST(MatchBadInput, EmptyRecording) {
    core::Recording rec;
    expect_not_found(match::match(env().model, rec, {}), "empty or tiny");
}

TEST(MatchBadInput, TinyScene) {
    auto t = run_trial(sim::quick(env().cell), 7, {"top"}, 0.0);
    auto& f = t.sim.recording.faces[0];
    // Keep one short stretch of one profile.
    const std::int64_t k_keep = f.n_profiles() / 2;
    for (std::int64_t k = 0; k < f.n_profiles(); ++k)
        for (std::int64_t i = 0; i < f.width; ++i)
            if (k != k_keep || i < f.width / 2 || i > f.width / 2 + 20)
                f.profiles_mm[(k * f.width + i) * 2] = f.profiles_mm[(k * f.width + i) * 2 + 1] =
                    std::numeric_limits<float>::quiet_NaN();
    expect_not_found(match::match(env().model, t.sim.recording, {}), "empty or tiny");
}

TEST(MatchBadInput, SceneWithoutThePart) {
    // The part lies far outside every scan: the scans see the support plate only.
    sim::SimOptions o;
    o.seed = 3;
    o.t0_ns = 1'790'000'000'000'000'000;
    o.T_world_part = Eigen::Isometry3d(Eigen::Translation3d(2000, 0, 0));
    auto s = sim::simulate(env().recipe, sim::quick(env().cell), o);
    ASSERT_TRUE(s);
    const auto m = match::match(env().model, s->recording, {});
    EXPECT_FALSE(m.found);
    EXPECT_NE(m.reason.find("part not found"), std::string::npos) << m.reason;
}

// A model of another part: hub-a's scans must not be taken for it, whatever pose fits best.
core::Recipe other_part(const std::string& kind) {
    core::Recipe r = env().recipe;
    r.name = kind;
    if (kind == "disc") {  // a plain disc of about hub-a's size
        r.levels_mm = {{"bottom", 0.0}, {"top", 40.0}};
        r.outer = {{"disc", "bottom", "top", 150.0}};
        r.inner.clear();
        r.forging.reset();  // hub-a's drawing (its parting plane between its flange levels) is not
                            // a disc's
    } else {                // hub-b: hub-a's layout, other proportions
        for (auto& [name, z] : r.levels_mm)
            if (name == "flange_top") z = 66.0;
        for (auto& sec : r.outer)
            if (sec.name == "flange") sec.diameter_mm = 120.0;
        for (auto& sec : r.inner)
            if (sec.name == "top recess") sec.diameter_mm = 40.0;
    }
    return r;
}

TEST(MatchBadInput, ModelOfAnotherPart) {
    auto t = run_trial(sim::quick(env().cell), 11, {});
    ASSERT_TRUE(t.m.found) << t.m.reason;  // hub-a itself is found in this scene
    for (const std::string kind : {"disc", "hub-b"}) {
        auto model = match::model_from_recipe(other_part(kind));
        ASSERT_TRUE(model) << model.error().message;
        match::MatchConfig mc;
        mc.scale = env().recipe.material.growth(t.sim.truth.temperature_c);
        mc.min_score = env().recipe.matching.min_score;
        const auto m = match::match(*model, t.sim.recording, {}, mc);
        std::printf("%s model on a hub-a scene: %s (score %.3f)\n", kind.c_str(),
                    m.found ? "FOUND" : m.reason.c_str(), m.score);
        expect_not_found(m, "best score");
    }
}

// The spin about the axis is a convention: the measurement does not depend on it.
TEST(Match, MeasurementIgnoresTheSpin) {
    auto t = run_trial(sim::quick(env().cell), 21, {}, 0.0);
    const auto& T = t.sim.truth.T_world_part;
    const auto a = measure::measure_part(env().recipe, t.sim.recording, T);
    const auto b = measure::measure_part(env().recipe, t.sim.recording,
                                         T * Eigen::AngleAxisd(1.234, Eigen::Vector3d::UnitZ()));
    ASSERT_EQ(a.features.size(), b.features.size());
    int measured = 0;
    for (std::size_t j = 0; j < a.features.size(); ++j) {
        ASSERT_EQ(a.features[j].hot_mm.has_value(), b.features[j].hot_mm.has_value());
        if (!a.features[j].hot_mm) continue;
        ++measured;
        EXPECT_NEAR(*a.features[j].hot_mm, *b.features[j].hot_mm, 2e-3) << a.features[j].name;
    }
    EXPECT_GE(measured, 10);
}

// With matching in the loop (no pose given), full resolution, press vibration compensated: all 13
// features within the measurement issue's ±0.03 mm of the truth, and within a few µm of the
// measurement with the true pose.
TEST(MatchInTheLoop, AllFeaturesFullResolution) {
    auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    ASSERT_TRUE(c);
    for (std::uint64_t seed : {31, 32, 33}) {
        sim::SimOptions o;
        o.seed = seed;
        o.temperature_c = 800.0 + 100.0 * static_cast<double>(seed - 30);
        o.t0_ns = 1'790'000'000'000'000'000;
        auto s = sim::simulate(env().recipe, *c, o);
        ASSERT_TRUE(s);
        const auto r = pipeline::run(s->recording, env().recipe, {});
        ASSERT_TRUE(r.match && r.match->found) << (r.match ? r.match->reason : "no match ran");
        EXPECT_EQ(r.pose_source, "match");
        pipeline::PipelineOptions truth;
        truth.T_world_part = s->truth.T_world_part;
        const auto rt = pipeline::run(s->recording, env().recipe, truth);
        const auto e = match::axis_error(s->truth.T_world_part, r.match->T_world_part);
        std::printf(
            "seed %llu: match score %.3f, axis %.4f deg %.4f mm; errors (match | vs truth pose):",
            static_cast<unsigned long long>(seed), r.match->score, e.angle_deg, e.radial_mm);
        for (std::size_t j = 0; j < r.measurement.features.size(); ++j) {
            const auto& f = r.measurement.features[j];
            ASSERT_TRUE(f.hot_mm) << f.name << ": " << f.reason;
            ASSERT_TRUE(rt.measurement.features[j].hot_mm) << f.name;
            const double err = *f.hot_mm - s->truth.features[j].hot_mm;
            const double vs = *f.hot_mm - *rt.measurement.features[j].hot_mm;
            std::printf(" %+.3f|%+.4f", err, vs);
            EXPECT_NEAR(err, 0.0, 0.03) << f.name;
            EXPECT_NEAR(vs, 0.0, 0.005) << f.name;
        }
        std::printf("\n");
    }
}

// Issue 36: a forging off nominal by 1.5 mm on one feature is found, and its value follows the
// part, not the model (a score that acted as a dimension check had called a 0.75 mm thin flange
// "not found"). Quick cell, forged parts, the pipeline as the cell runs it.
TEST(MatchInTheLoop, AFeature1_5mmOffIsFoundAndFollowed) {
    const auto cell = sim::quick(env().cell);
    for (const auto& [name, mm] : {std::pair{"Diameter 3", 1.5}, std::pair{"Height 2", -1.5},
                                   std::pair{"Diameter 1", -1.5}}) {
        sim::SimOptions o;
        o.seed = 2001;
        o.forged = true;
        o.temperature_c = 1000.0;
        o.t0_ns = 1'790'000'000'000'000'000;
        o.bad_mm[name] = mm;
        auto s = sim::simulate(env().recipe, cell, o);
        ASSERT_TRUE(s);
        const auto r = pipeline::run(s->recording, env().recipe, {});
        ASSERT_TRUE(r.match && r.match->found)
            << name << ": " << (r.match ? r.match->reason : "no match ran");
        int seen = 0;
        for (std::size_t j = 0; j < r.measurement.features.size(); ++j) {
            const auto& f = r.measurement.features[j];
            if (f.name != name) continue;
            ++seen;
            ASSERT_TRUE(f.hot_mm) << f.name << ": " << f.reason;
            // The quick cell's 0.8 mm rays and 1 mm profiles: ±0.05 mm, not the full cell's ±0.02.
            EXPECT_NEAR(*f.hot_mm, s->truth.features[j].hot_mm, 0.05) << name;
            EXPECT_NEAR(*f.hot_mm - f.nominal_mm * env().recipe.material.growth(1000.0), mm, 0.3)
                << name << ": the part's value, not the model's";
            std::printf("%s %+.1f mm: score %.3f, error %+.4f mm\n", name, mm, r.match->score,
                        *f.hot_mm - s->truth.features[j].hot_mm);
        }
        EXPECT_EQ(seen, 1) << name;
    }
}

// No pyrometer reading: ICP estimates the thermal growth as a seventh unknown.
TEST(Match, UnknownTemperatureEstimatesTheScale) {
    for (std::uint64_t seed : {41, 48}) {  // 820 °C and 420 °C (run_trial: 20 + 100·(seed % 11))
        auto t = run_trial(sim::quick(env().cell), seed, {}, 0.1, false);
        ASSERT_TRUE(t.m.found) << t.m.reason;
        EXPECT_TRUE(t.m.scale_estimated);
        // The scale comes from the levels (the radii are free, docs/matching.md), whose as-forged
        // deviations (σ 0.05 mm over 8–76 mm) allow it to be this close to the growth, no closer.
        EXPECT_NEAR(t.m.scale, t.sim.truth.growth, 2e-3) << seed;
        EXPECT_LT(t.err.angle_deg, 0.02);
        EXPECT_LT(t.err.radial_mm, 0.02);
        std::printf("seed %llu: scale %.6f (true growth %.6f), axis %.4f deg %.4f mm\n",
                    static_cast<unsigned long long>(seed), t.m.scale, t.sim.truth.growth,
                    t.err.angle_deg, t.err.radial_mm);
    }
}

// A general model (dense oriented samples, as from a mesh or a reference scan): all samples are
// references, ICP uses the FLANN k-d tree. Built here from hub-a's surface sampled every 0.7 mm.
TEST(Match, GeneralModelFromSamples) {
    const auto solid = core::AxisymmetricSolid::from_recipe(env().recipe);
    std::vector<Eigen::Vector3f> pts, nrm;
    for (const auto& seg : solid.boundary()) {
        const int n = std::max(1, static_cast<int>((seg.hi - seg.lo) / 0.7));
        for (int q = 0; q < n; ++q) {
            const double along = seg.lo + (q + 0.5) * (seg.hi - seg.lo) / n;
            const double r = seg.cylinder ? seg.value : along, z = seg.cylinder ? along : seg.value;
            const double sign = seg.cylinder ? (solid.inside(r - 1e-3, z) ? 1 : -1)
                                             : (solid.inside(r, z - 1e-3) ? 1 : -1);
            const int m = std::max(1, static_cast<int>(2 * M_PI * r / 0.7));
            for (int a = 0; a < m; ++a) {
                const double phi = 2 * M_PI * a / m;
                pts.push_back(
                    Eigen::Vector3d(r * std::cos(phi), r * std::sin(phi), z).cast<float>());
                nrm.push_back((seg.cylinder
                                   ? Eigen::Vector3d(sign * std::cos(phi), sign * std::sin(phi), 0)
                                   : Eigen::Vector3d(0, 0, sign))
                                  .cast<float>());
            }
        }
    }
    auto model = match::model_from_samples("hub-a", "test samples", pts, nrm);
    ASSERT_TRUE(model) << model.error().message;
    EXPECT_FALSE(model->axisymmetric);
    EXPECT_EQ(model->refs.size(), model->points.size());
    auto t = run_trial(sim::quick(env().cell), 61, {});
    match::MatchConfig mc;
    mc.scale = env().recipe.material.growth(t.sim.truth.temperature_c);
    const auto m = match::match(*model, t.sim.recording, {}, mc);
    ASSERT_TRUE(m.found) << m.reason << " score " << m.score << " inliers " << m.inliers << " hyp "
                         << m.hypotheses << " votes " << m.votes;
    const auto e = match::axis_error(t.sim.truth.T_world_part, m.T_world_part);
    std::printf("general model: %zu samples, %zu voting; score %.3f, axis %.4f deg %.4f mm\n",
                pts.size(), model->points.size(), m.score, e.angle_deg, e.radial_mm);
    EXPECT_LT(e.angle_deg, 0.05);
    EXPECT_LT(e.radial_mm, 0.05);
}

}  // namespace
