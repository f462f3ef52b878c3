// Vibration compensation: the FFT double integrator against closed forms, the recovered u(t)
// against the simulator's truth, and bad accelerometer data flagged, never fatal.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/sim/simulator.hpp"

using namespace hotgauge;
using compensate::CompensationConfig;

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

struct Env {
    core::Recipe recipe;
    sim::CellConfig cell;  // quick sensor, but the real accelerometer (2 kHz, 25 µg/√Hz)
};
const Env& env() {
    static const Env e = [] {
        auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        if (!r || !c) std::abort();
        sim::CellConfig q = sim::quick(*c);
        q.accel = c->accel;
        return Env{*r, q};
    }();
    return e;
}

sim::SimResult simulate(const sim::CellConfig& cell, std::uint64_t seed) {
    sim::SimOptions o;
    o.seed = seed;
    o.temperature_c = 1000.0;
    o.t0_ns = 1'790'000'000'000'000'000;
    auto s = sim::simulate(env().recipe, cell, o);
    if (!s) std::abort();
    return std::move(*s);
}

// RMS over all profiles of all faces of (u_est − u_true), per world axis, in µm; also printed
// with each face's mean difference removed (a constant offset of a whole scan, which no
// accelerometer can see).
Eigen::Vector3d residual_um(const sim::SimResult& s, const CompensationConfig& c = {}) {
    Eigen::Vector3d sum2 = Eigen::Vector3d::Zero(), sum2_centred = Eigen::Vector3d::Zero();
    double n = 0;
    for (std::size_t j = 0; j < s.recording.faces.size(); ++j) {
        const auto fc = compensate::compensate_face(s.recording.faces[j], c);
        EXPECT_TRUE(fc.applied);
        EXPECT_FALSE(fc.degraded) << fc.reasons.front();
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (std::size_t k = 0; k < fc.u_mm.size(); ++k)
            mean += 1000.0 * (fc.u_mm[k] - s.truth.faces[j].u_mm[k]);
        mean /= static_cast<double>(fc.u_mm.size());
        for (std::size_t k = 0; k < fc.u_mm.size(); ++k) {
            const Eigen::Vector3d e = 1000.0 * (fc.u_mm[k] - s.truth.faces[j].u_mm[k]);
            sum2 += e.cwiseAbs2();
            sum2_centred += (e - mean).cwiseAbs2();
            n += 1;
        }
    }
    const Eigen::Vector3d centred = (sum2_centred / n).cwiseSqrt();
    std::printf("  (without each scan's constant offset: x %.2f y %.2f z %.2f um)\n", centred.x(),
                centred.y(), centred.z());
    return (sum2 / n).cwiseSqrt();
}

}  // namespace

TEST(IntegrateTwice, SinusoidsComeBackExactly) {
    // a = −A ω² sin(ωt) + gravity + a slow drift → u = A sin(ωt) away from the record ends.
    const double fs = 2000.0, A = 0.4e-3;
    for (double f : {3.0, 8.0, 47.0}) {
        std::vector<double> a(8000);
        for (std::size_t i = 0; i < a.size(); ++i) {
            const double t = static_cast<double>(i) / fs;
            a[i] = -A * std::pow(kTwoPi * f, 2) * std::sin(kTwoPi * f * t) + 9.81 + 0.01 * t;
        }
        const auto u = compensate::integrate_twice(a, fs, {});
        double worst = 0;
        for (std::size_t i = 2000; i < a.size() - 2000; ++i) {  // 1 s margins, as in a scan
            const double t = static_cast<double>(i) / fs;
            worst = std::max(worst, std::abs(u[i] - A * std::sin(kTwoPi * f * t)));
        }
        EXPECT_LT(worst, 0.01 * A) << f << " Hz";  // 3 Hz: 0.6 %, 8 Hz: 0.1 %, 47 Hz: 0.01 %
    }
}

TEST(IntegrateTwice, RemovesWhatIsBelowTheCorner) {
    const double fs = 2000.0;
    std::vector<double> a(8000);
    for (std::size_t i = 0; i < a.size(); ++i)
        a[i] = 0.05 * std::sin(kTwoPi * 0.3 * static_cast<double>(i) / fs);  // 0.3 Hz: untrusted
    const auto u = compensate::integrate_twice(a, fs, {});
    double peak = 0;
    for (double v : u) peak = std::max(peak, std::abs(v));
    // Integrated without a high-pass this would be 0.05 / (2π·0.3)² = 14 mm (measured: 0.1 mm).
    EXPECT_LT(peak, 0.01 * 0.05 / std::pow(kTwoPi * 0.3, 2));
}

TEST(CompensateFace, DefaultVibrationWithin5um) {
    double loudest = 0;
    for (std::uint64_t seed : {1, 2, 3, 4, 5, 6}) {
        const auto s = simulate(env().cell, seed);
        const Eigen::Vector3d r = residual_um(s);
        double peak = 0;
        for (const auto& f : s.truth.faces)
            for (const auto& u : f.u_mm) peak = std::max(peak, u.norm());
        std::printf(
            "default vibration (8/23/47 Hz, peak |u| %.3f mm), seed %llu: residual RMS "
            "x %.2f y %.2f z %.2f um\n",
            peak, static_cast<unsigned long long>(seed), r.x(), r.y(), r.z());
        loudest = std::max(loudest, peak);
        for (int k = 0; k < 3; ++k) EXPECT_LE(r[k], 5.0) << "axis " << k << " seed " << seed;
    }
    EXPECT_GT(loudest, 0.3);  // the press really shook some of these scans
}

TEST(CompensateFace, ThreeHertzModeWithin20um) {
    sim::CellConfig cell = env().cell;
    cell.vibration.modes = {{3.0, 0.03, 0.6, Eigen::Vector3d(0.3, 0.2, 1.0).normalized()},
                            {23.0, 0.03, 0.1, Eigen::Vector3d(1.0, 0.3, 0.2).normalized()}};
    for (std::uint64_t seed : {4, 5, 6}) {
        const auto s = simulate(cell, seed);
        const Eigen::Vector3d r = residual_um(s);
        std::printf("3 Hz dominant mode, seed %llu: residual RMS x %.2f y %.2f z %.2f um\n",
                    static_cast<unsigned long long>(seed), r.x(), r.y(), r.z());
        for (int k = 0; k < 3; ++k) EXPECT_LE(r[k], 20.0) << "axis " << k;
    }
}

TEST(CompensateFace, ClockOffsetIsApplied) {
    // The accelerometer's clock runs 3 ms ahead: uncorrected, the 47 Hz mode is off in phase.
    auto s = simulate(env().cell, 6);
    for (auto& f : s.recording.faces)
        for (auto& t : f.accel_times_ns) t += 3'000'000;
    CompensationConfig c;
    const double wrong = residual_um(s, c).norm();
    c.clock_offset_s = 0.003;
    const double right = residual_um(s, c).norm();
    std::printf("clock skew 3 ms: residual %.1f um uncorrected, %.2f um with the offset\n", wrong,
                right);
    EXPECT_GT(wrong, 5.0 * right);
    EXPECT_LT(right, 8.0);
}

namespace {

// Runs the whole pipeline on a recording with true pose; returns the result.
pipeline::PartResult run_pipeline(const sim::SimResult& s, const CompensationConfig& c = {}) {
    pipeline::PipelineOptions o;
    o.T_world_part = s.truth.T_world_part;
    o.pose_source = "truth";
    o.compensation = c;
    return pipeline::run(s.recording, env().recipe, o);
}

void expect_degraded_but_measured(const pipeline::PartResult& r, const std::string& reason_part) {
    EXPECT_TRUE(r.degraded);
    bool found = false;
    for (const auto& why : r.degraded_reasons)
        found = found || why.find(reason_part) != std::string::npos;
    EXPECT_TRUE(found) << "no reason mentioning '" << reason_part << "'";
    int measured = 0;
    for (const auto& f : r.measurement.features) measured += f.hot_mm.has_value();
    EXPECT_GE(measured, 10) << "the part must still be measured";
    EXPECT_NE(pipeline::to_json(r).find("\"degraded\":true"), std::string::npos);
}

}  // namespace

TEST(CompensateBadInput, RecordShorterThanTheScan) {
    auto s = simulate(env().cell, 7);
    auto& f = s.recording.faces[0];
    // Keep only samples from 0.2 s after the first profile on.
    const std::int64_t cut = f.profile_times_ns.front() + 200'000'000;
    std::size_t k = 0;
    while (k < f.accel_times_ns.size() && f.accel_times_ns[k] < cut) ++k;
    f.accel_times_ns.erase(f.accel_times_ns.begin(), f.accel_times_ns.begin() + k);
    f.accel_mps2.erase(f.accel_mps2.begin(), f.accel_mps2.begin() + 3 * k);
    expect_degraded_but_measured(run_pipeline(s), "does not cover the scan");
}

TEST(CompensateBadInput, GapInTheRecord) {
    auto s = simulate(env().cell, 8);
    auto& f = s.recording.faces[1];
    const std::size_t mid = f.accel_times_ns.size() / 2;
    f.accel_times_ns.erase(f.accel_times_ns.begin() + mid, f.accel_times_ns.begin() + mid + 100);
    f.accel_mps2.erase(f.accel_mps2.begin() + 3 * mid, f.accel_mps2.begin() + 3 * (mid + 100));
    const auto r = run_pipeline(s);
    expect_degraded_but_measured(r, "gap");
    EXPECT_GT(r.compensation[1].n_degraded, 40);  // 50 ms gap + 2 × 50 ms pad at 1 kHz lines
}

// Samples inside the scan (1 s after the record starts, where the first profile is).
std::size_t scan_sample(const core::FaceScan& f, double after_first_profile_s) {
    const std::int64_t t =
        f.profile_times_ns.front() + static_cast<std::int64_t>(after_first_profile_s * 1e9);
    std::size_t j = 0;
    while (j < f.accel_times_ns.size() && f.accel_times_ns[j] < t) ++j;
    return j;
}

TEST(CompensateBadInput, ClippedSamples) {
    // A device whose range the blows exceed: its output rails at ±range. Range chosen just under
    // the largest reading on the scan, so a few peaks clip.
    auto s = simulate(env().cell, 9);
    auto& f = s.recording.faces[0];
    float peak = 0;
    for (std::size_t j = scan_sample(f, 0.0); j < scan_sample(f, 0.2); ++j)
        for (int c = 0; c < 3; ++c) peak = std::max(peak, std::abs(f.accel_mps2[3 * j + c]));
    const float range = 0.98f * peak;
    for (auto& v : f.accel_mps2) v = std::clamp(v, -range, range);
    CompensationConfig c;
    c.clip_mps2 = 0.999 * range;
    expect_degraded_but_measured(run_pipeline(s, c), "clipped");
}

TEST(CompensateBadInput, NonFiniteSamples) {
    auto s = simulate(env().cell, 10);
    auto& f = s.recording.faces[2];
    const std::size_t j0 = scan_sample(f, 0.1);
    for (std::size_t j = j0; j < j0 + 20; ++j) f.accel_mps2[3 * j + 1] = std::nanf("");
    expect_degraded_but_measured(run_pipeline(s), "non-finite");
}

TEST(CompensateBadInput, TroubleOutsideTheScanIsOnlyAWarning) {
    // NaN samples in the margin before the scan do not touch any profile's displacement.
    auto s = simulate(env().cell, 12);
    auto& f = s.recording.faces[0];
    for (std::size_t j = 100; j < 110; ++j) f.accel_mps2[3 * j] = std::nanf("");
    const auto r = run_pipeline(s);
    EXPECT_FALSE(r.degraded);
    bool warned = false;
    for (const auto& w : r.warnings) warned = warned || w.find("non-finite") != std::string::npos;
    EXPECT_TRUE(warned);
}

TEST(CompensateBadInput, FarOffTimestampIsIgnored) {
    // One sample 11.6 days later: still strictly increasing, so a valid recording. It must not
    // stretch the integration grid over days.
    auto s = simulate(env().cell, 13);
    auto& f = s.recording.faces[0];
    f.accel_times_ns.back() += 1'000'000'000'000'000;
    const auto r = run_pipeline(s);
    bool noted = false;
    for (const auto& w : r.warnings) noted = noted || w.find("ignored") != std::string::npos;
    EXPECT_TRUE(noted);
    EXPECT_TRUE(r.compensation[0].applied);
}

TEST(CompensateBadInput, ClocksCenturiesApart) {
    // Camera clock ~228 years before the accelerometer's: the difference does not fit in int64
    // nanoseconds (UBSan in the sanitizer build checks that nothing overflows).
    auto s = simulate(env().cell, 14);
    for (auto& t : s.recording.faces[0].profile_times_ns) t -= 9'000'000'000'000'000'000;
    const auto r = run_pipeline(s);
    EXPECT_TRUE(r.degraded);
    EXPECT_FALSE(r.compensation[0].applied);
    EXPECT_NE(pipeline::to_json(r).find("\"faces\""), std::string::npos);
}

TEST(CompensateBadInput, NoAccelerometerAtAll) {
    auto s = simulate(env().cell, 11);
    for (auto& f : s.recording.faces) {
        f.accel_mps2.clear();
        f.accel_times_ns.clear();
    }
    const auto r = run_pipeline(s);
    expect_degraded_but_measured(r, "no accelerometer samples");
    for (const auto& c : r.compensation) EXPECT_FALSE(c.applied);
}

// Full resolution, default vibration, pose known: after compensation every feature within
// ±0.03 mm (the measurement issue's bound under vibration). Label: accuracy.
TEST(CompensatedMeasurement, AllFeaturesUnderDefaultVibration) {
    auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    ASSERT_TRUE(c);
    for (std::uint64_t seed : {21, 22, 23}) {
        sim::SimOptions o;
        o.seed = seed;
        o.temperature_c = 700.0 + 100.0 * static_cast<double>(seed - 20);
        auto s = sim::simulate(env().recipe, *c, o);
        ASSERT_TRUE(s);
        const auto r = run_pipeline(*s);
        EXPECT_FALSE(r.degraded);
        std::printf("seed %llu compensated errors:", static_cast<unsigned long long>(seed));
        for (std::size_t j = 0; j < r.measurement.features.size(); ++j) {
            const auto& f = r.measurement.features[j];
            ASSERT_TRUE(f.hot_mm) << f.name << ": " << f.reason;
            std::printf(" %+.3f", *f.hot_mm - s->truth.features[j].hot_mm);
            EXPECT_NEAR(*f.hot_mm, s->truth.features[j].hot_mm, 0.03) << f.name;
        }
        std::printf("\n");
    }
}

// Why profiles within min_margin_s of a record end are degraded: the zero-phase high-pass needs
// the record on both sides of a profile. Records cut `cut` s after the last profile; RMS of
// |u_est − u_true| by the profile's distance from the record end (printed: docs/compensation.md).
TEST(CompensateFace, TailErrorIsWhyTheMarginRuleExists) {
    const double edges[] = {0.0, 0.1, 0.2, 0.3, 0.5, 1.0, 100.0};
    constexpr int kBins = 6;
    auto table = [&](double cut) {
        std::vector<double> s2(kBins, 0.0), n(kBins, 0.0);
        for (std::uint64_t seed = 1; seed <= 6; ++seed) {
            const auto s = simulate(env().cell, seed);
            for (std::size_t j = 0; j < s.recording.faces.size(); ++j) {
                core::FaceScan f = s.recording.faces[j];
                const auto t_end = f.profile_times_ns.back() + static_cast<std::int64_t>(cut * 1e9);
                std::size_t keep = 0;
                while (keep < f.accel_times_ns.size() && f.accel_times_ns[keep] <= t_end) ++keep;
                f.accel_times_ns.resize(keep);
                f.accel_mps2.resize(keep * 3);
                const auto fc = compensate::compensate_face(f, {});
                for (std::size_t k = 0; k < fc.u_mm.size(); ++k) {
                    const double d = static_cast<double>(t_end - f.profile_times_ns[k]) * 1e-9;
                    int b = 0;
                    while (d >= edges[b + 1]) ++b;
                    s2[b] += (1000.0 * (fc.u_mm[k] - s.truth.faces[j].u_mm[k])).squaredNorm();
                    n[b] += 1;
                }
            }
        }
        std::printf("record ends %.2f s after the last profile; RMS |error| by distance:", cut);
        std::vector<double> rms(kBins, NAN);
        for (int b = 0; b < kBins; ++b) {
            if (n[b] == 0) continue;
            rms[b] = std::sqrt(s2[b] / n[b]);
            std::printf(" %.1f-%.1f s: %.1f um;", edges[b], std::min(edges[b + 1], 9.9), rms[b]);
        }
        std::printf("\n");
        return rms;
    };
    const auto short_record = table(0.05);
    const auto at_margin = table(CompensationConfig{}.min_margin_s);
    const auto long_record = table(1.0);
    EXPECT_GT(short_record[0], 5.0 * long_record[5]);  // next to the end: far off
    EXPECT_GT(short_record[1], 3.0 * long_record[5]);
    EXPECT_LT(at_margin[4], 1.5 * long_record[5]);  // at the margin: about as good as inside
    EXPECT_LT(long_record[5], 8.0);
}
