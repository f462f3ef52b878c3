// The oracle for the parallel code (issue 22): matching and the whole pipeline on N threads give
// what they give on one, to the bit. N = 4 is more threads than the cell PC's two cores, so the
// pieces interleave differently from run to run; N = 3 divides no piece count evenly.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <string>

#include "hotgauge/io/recipe.hpp"
#include "hotgauge/match/match.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/sim/simulator.hpp"

using namespace hotgauge;

namespace {

struct Env {
    core::Recipe recipe;
    match::Model model;
    sim::SimResult sim;
};

// The cell at half its resolution: 0.4 mm rays, 0.4 mm profiles (the quick cell's 0.8 and 1 mm
// leave three heights with too few points).
sim::CellConfig half_resolution(sim::CellConfig cell) {
    cell.sensor.width /= 2;
    cell.sensor.pitch_mm *= 2.0;
    for (auto& f : cell.faces) f.profile_spacing_mm *= 2.0;
    return cell;
}

// One hub-a part at 1000 °C under the press vibration, all four faces at half resolution: in it
// the pipeline finds the part, compensates every face and measures all 13 features, which is
// every piece that runs on threads.
const Env& env() {
    static const Env e = [] {
        auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!r || !c) std::abort();
        match::ModelConfig mc;
        mc.sampling_mm = r->matching.sampling_mm;  // as pipeline::run builds it
        auto m = match::model_from_recipe(*r, mc);
        sim::SimOptions o;
        o.seed = 5;
        o.temperature_c = 1000.0;
        o.t0_ns = 1'790'000'000'000'000'000;
        auto s = sim::simulate(*r, half_resolution(*c), o);
        if (!m || !s) std::abort();
        return Env{std::move(*r), std::move(*m), std::move(*s)};
    }();
    return e;
}

// Equal to the bit (a NaN equals the same NaN), both printed to the last digit when not.
testing::AssertionResult same(double a, double b) {
    if (std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b))
        return testing::AssertionSuccess();
    return testing::AssertionFailure() << std::setprecision(17) << a << " != " << b;
}
testing::AssertionResult same(const std::optional<double>& a, const std::optional<double>& b) {
    if (a.has_value() != b.has_value()) return testing::AssertionFailure() << "one is missing";
    return a ? same(*a, *b) : testing::AssertionSuccess();
}

void expect_same(const match::MatchResult& a, const match::MatchResult& b) {
    EXPECT_EQ(a.found, b.found);
    EXPECT_EQ(a.reason, b.reason);
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            EXPECT_TRUE(same(a.T_world_part(i, j), b.T_world_part(i, j)))
                << "T_world_part(" << i << ", " << j << ")";
    EXPECT_TRUE(same(a.score, b.score)) << "score";
    EXPECT_TRUE(same(a.scale, b.scale)) << "scale";
    EXPECT_TRUE(same(a.votes, b.votes)) << "votes";
    EXPECT_TRUE(same(a.rms_mm, b.rms_mm)) << "rms_mm";
    EXPECT_EQ(a.scale_estimated, b.scale_estimated);
    EXPECT_EQ(a.hypotheses, b.hypotheses);
    EXPECT_EQ(a.inliers, b.inliers);
    EXPECT_EQ(a.iterations, b.iterations);
    EXPECT_EQ(a.scene_points, b.scene_points);
    EXPECT_EQ(a.reference_points, b.reference_points);
    EXPECT_EQ(a.background_removed, b.background_removed);
}

void expect_same(const measure::EdgeEstimate& a, const measure::EdgeEstimate& b) {
    EXPECT_EQ(a.level, b.level);
    EXPECT_EQ(a.estimator, b.estimator);
    EXPECT_EQ(a.faces, b.faces);
    EXPECT_TRUE(same(a.value_mm, b.value_mm)) << a.level << " value_mm";
    EXPECT_TRUE(same(a.u_mm, b.u_mm)) << a.level << " u_mm";
    EXPECT_EQ(a.n_points, b.n_points) << a.level;
}

void expect_same(const measure::FeatureResult& a, const measure::FeatureResult& b) {
    SCOPED_TRACE(a.name);
    EXPECT_EQ(a.name, b.name);
    EXPECT_STREQ(measure::to_string(a.verdict), measure::to_string(b.verdict));
    EXPECT_EQ(a.reason, b.reason);
    EXPECT_EQ(a.degraded, b.degraded);
    EXPECT_EQ(a.face_missing, b.face_missing);
    EXPECT_EQ(a.low_coverage, b.low_coverage);
    EXPECT_EQ(a.left_out, b.left_out);
    EXPECT_TRUE(same(a.hot_mm, b.hot_mm)) << "hot_mm";
    EXPECT_TRUE(same(a.cold_mm, b.cold_mm)) << "cold_mm";
    EXPECT_TRUE(same(a.u_cold_mm, b.u_cold_mm)) << "u_cold_mm";
    EXPECT_TRUE(same(a.deviation_mm, b.deviation_mm)) << "deviation_mm";
    EXPECT_TRUE(same(a.fit_rms_mm, b.fit_rms_mm)) << "fit_rms_mm";
    EXPECT_TRUE(same(a.u_mm, b.u_mm)) << "u_mm";
    EXPECT_TRUE(same(a.sector_spread_mm, b.sector_spread_mm)) << "sector_spread_mm";
    EXPECT_TRUE(same(a.sector_between_mm, b.sector_between_mm)) << "sector_between_mm";
    EXPECT_TRUE(same(a.arc_deg, b.arc_deg)) << "arc_deg";
    EXPECT_EQ(a.n_points, b.n_points);
    EXPECT_EQ(a.n_sectors, b.n_sectors);
    EXPECT_EQ(a.method, b.method);
    ASSERT_EQ(a.u_budget.size(), b.u_budget.size());
    for (std::size_t k = 0; k < a.u_budget.size(); ++k) {
        EXPECT_EQ(a.u_budget[k].first, b.u_budget[k].first);
        EXPECT_TRUE(same(a.u_budget[k].second, b.u_budget[k].second)) << a.u_budget[k].first;
    }
    ASSERT_EQ(a.ends.size(), b.ends.size());
    for (std::size_t k = 0; k < a.ends.size(); ++k) expect_same(a.ends[k], b.ends[k]);
}

// The machine interface without the wall times: a catch-all for what the fields above miss,
// fields added later included (doubles are written to the last digit).
std::string json_without_times(pipeline::PartResult r) {
    r.stage_ms.clear();
    if (r.match) r.match->stage_ms.clear();
    return pipeline::to_json(r);
}

pipeline::PartResult run_on(int threads) {
    pipeline::PipelineOptions o;
    o.model = &env().model;
    o.match.threads = threads;
    o.measure.threads = threads;
    return pipeline::run(env().sim.recording, env().recipe, o);
}

}  // namespace

// Matching alone, without compensation and with the scale estimated by ICP (no temperature
// given): the path the pipeline below does not take.
TEST(Threads, MatchIsTheSameOnOneAndNThreads) {
    match::MatchConfig mc;
    mc.threads = 1;
    const auto one = match::match(env().model, env().sim.recording, {}, mc);
    ASSERT_TRUE(one.found) << one.reason;
    ASSERT_TRUE(one.scale_estimated);
    for (int n : {3, 4}) {
        SCOPED_TRACE(testing::Message() << n << " threads");
        mc.threads = n;
        expect_same(one, match::match(env().model, env().sim.recording, {}, mc));
    }
}

TEST(Threads, PipelineIsTheSameOnOneAndNThreads) {
    const auto one = run_on(1);
    // The scene exercises every threaded piece, or the comparison below proves little.
    ASSERT_TRUE(one.match && one.match->found) << (one.match ? one.match->reason : "no match");
    ASSERT_EQ(one.compensation.size(), env().sim.recording.faces.size());
    for (const auto& c : one.compensation) EXPECT_TRUE(c.applied) << c.face;
    ASSERT_EQ(one.measurement.features.size(), env().recipe.features.size());
    for (const auto& f : one.measurement.features)
        EXPECT_TRUE(f.hot_mm) << f.name << ": " << f.reason;
    const std::string json_one = json_without_times(one);
    for (int n : {3, 4}) {
        SCOPED_TRACE(testing::Message() << n << " threads");
        const auto many = run_on(n);
        ASSERT_TRUE(many.match);
        expect_same(*one.match, *many.match);
        ASSERT_EQ(many.measurement.features.size(), one.measurement.features.size());
        for (std::size_t j = 0; j < one.measurement.features.size(); ++j)
            expect_same(one.measurement.features[j], many.measurement.features[j]);
        EXPECT_STREQ(measure::to_string(one.measurement.verdict),
                     measure::to_string(many.measurement.verdict));
        EXPECT_EQ(json_one, json_without_times(many));
    }
}
