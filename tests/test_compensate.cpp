// Vibration compensation: the FFT double integrator against closed forms, the recovered u(t)
// against the simulator's truth, and bad accelerometer data flagged, never fatal.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/pipeline/verify.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "ideal_recipe.hpp"
#include "quick_cell_env.hpp"

using namespace hotgauge;
using compensate::CompensationConfig;

namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

using test::env;
using test::simulate;

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
        for (std::size_t k = 0; k < fc.displacement_mm.size(); ++k)
            mean += 1000.0 * (fc.displacement_mm[k] - s.truth.faces[j].displacement_mm[k]);
        mean /= static_cast<double>(fc.displacement_mm.size());
        for (std::size_t k = 0; k < fc.displacement_mm.size(); ++k) {
            const Eigen::Vector3d e =
                1000.0 * (fc.displacement_mm[k] - s.truth.faces[j].displacement_mm[k]);
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
            for (const auto& u : f.displacement_mm) peak = std::max(peak, u.norm());
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

// The support plate as a displacement sensor (docs/compensation.md "The support plate"):
// impulsive blows (5 ms onset) and a 3 Hz mode put displacement below the high-pass that the
// accelerometer cannot give back ("Why 1.5 Hz": 30-50 µm RMS in z). On the faces that see the
// plate in every profile (this cell's top: its side sensors look across, not down), u_z from it
// is within the 5 µm RMS; the bottom sensor, below the plate, does not use it.
TEST(CompensateFace, ThePlateGivesZUnderImpulsiveBlows) {
    sim::CellConfig cell = env().cell;
    cell.vibration.onset_s = 0.005;
    cell.vibration.modes = {{3.0, 0.03, 0.6, Eigen::Vector3d(0.3, 0.2, 1.0).normalized()},
                            {23.0, 0.03, 0.1, Eigen::Vector3d(1.0, 0.3, 0.2).normalized()}};
    CompensationConfig accel_only;
    accel_only.plate_z = false;
    double worst_plate = 0, worst_accel = 0;
    int faces = 0;
    for (std::uint64_t seed : {4, 5, 6}) {
        const auto s = simulate(cell, seed);
        for (std::size_t j = 0; j < s.recording.faces.size(); ++j) {
            const auto& face = s.recording.faces[j];
            const auto with = compensate::compensate_face(face, {});
            const auto without = compensate::compensate_face(face, accel_only);
            if (face.name == "bottom") {
                EXPECT_EQ(with.plate_profiles, 0) << "the bottom sensor looks up";
                continue;
            }
            if (with.plate_profiles < face.n_profiles()) {  // this cell's side sensors look
                std::printf("seed %llu %s: the plate in %lld of %lld profiles\n",  // across
                            static_cast<unsigned long long>(seed), face.name.c_str(),
                            static_cast<long long>(with.plate_profiles),
                            static_cast<long long>(face.n_profiles()));
                EXPECT_NE(face.name, "top");
                continue;
            }
            ++faces;
            double s2_plate = 0, s2_accel = 0;
            for (std::size_t k = 0; k < with.displacement_mm.size(); ++k) {
                const double t = s.truth.faces[j].displacement_mm[k].z();
                s2_plate += std::pow(1000.0 * (with.displacement_mm[k].z() - t), 2);
                s2_accel += std::pow(1000.0 * (without.displacement_mm[k].z() - t), 2);
            }
            const double n = static_cast<double>(with.displacement_mm.size());
            const double plate = std::sqrt(s2_plate / n), accel = std::sqrt(s2_accel / n);
            std::printf(
                "seed %llu %s: z RMS %.2f um from the plate, %.2f um integrated (plate "
                "median's sigma %.2f um)\n",
                static_cast<unsigned long long>(seed), face.name.c_str(), plate, accel,
                1000.0 * with.plate_sigma_mm);
            worst_plate = std::max(worst_plate, plate);
            worst_accel = std::max(worst_accel, accel);
        }
    }
    EXPECT_GE(faces, 3);
    EXPECT_LE(worst_plate, 5.0);
    EXPECT_GT(worst_accel, 2.0 * worst_plate) << "the case must be one the accelerometer misses";
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

// Degraded per feature (docs/compensation.md "Gaps and degraded features"): a feature is
// degraded only when a face of its has untrusted profiles, and then its reason names them.
void expect_degraded_but_measured(const pipeline::PartResult& r, const std::string& reason_part) {
    EXPECT_TRUE(r.degraded);
    bool found = false;
    for (const auto& why : r.degraded_reasons)
        found = found || why.find(reason_part) != std::string::npos;
    EXPECT_TRUE(found) << "no reason mentioning '" << reason_part << "'";
    int measured = 0;
    for (const auto& f : r.measurement.features) {
        measured += f.hot_mm.has_value();
        EXPECT_EQ(f.degraded, f.verdict == measure::Verdict::kDegraded) << f.name;
        if (f.left_out.empty()) {
            EXPECT_FALSE(f.degraded) << f.name << " has no untrusted face";
        }
        if (f.degraded) {
            EXPECT_NE(f.reason.find(reason_part), std::string::npos) << f.reason;
        }
    }
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
    expect_degraded_but_measured(run_pipeline(s), "does not cover it");
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
    // Every value is uncompensated: each measured one is DEGRADED, none NOK, whatever it reads.
    for (const auto& f : r.measurement.features)
        EXPECT_EQ(f.verdict,
                  f.hot_mm ? measure::Verdict::kDegraded : measure::Verdict::kNotMeasured)
            << f.name << ": " << f.reason;
    EXPECT_NE(r.measurement.verdict, measure::Verdict::kNok);
}

// A value the data cannot vouch for sorts nothing: measured only with untrusted profiles and
// outside its tolerance, a feature is DEGRADED (its reason says it is outside), never NOK.
TEST(CompensateBadInput, ADegradedValueOutsideItsToleranceIsNotNok) {
    auto s = simulate(env().cell, 15);
    core::Recipe recipe = env().recipe;
    for (auto& f : recipe.features) f.tol_upper_mm = f.tol_lower_mm = -1.0;  // all "too small"
    pipeline::PipelineOptions o;
    o.T_world_part = s.truth.T_world_part;
    const auto trusted = pipeline::run(s.recording, recipe, o);
    EXPECT_EQ(trusted.measurement.verdict, measure::Verdict::kNok);
    for (auto& f : s.recording.faces) {
        f.accel_mps2.clear();
        f.accel_times_ns.clear();
    }
    const auto r = pipeline::run(s.recording, recipe, o);
    int degraded = 0;
    for (const auto& f : r.measurement.features) {
        EXPECT_NE(f.verdict, measure::Verdict::kNok) << f.name;
        if (f.verdict != measure::Verdict::kDegraded) continue;
        ++degraded;
        EXPECT_NE(f.reason.find("outside tolerance"), std::string::npos) << f.reason;
    }
    EXPECT_GE(degraded, 10);
}

namespace {

// A part scanned by the full-resolution cell of config/cell.yaml.
core::Result<sim::SimResult> simulate_full(std::uint64_t seed, double temperature_c) {
    auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    if (!c) return c.error();
    sim::SimOptions o;
    o.seed = seed;
    o.temperature_c = temperature_c;
    return sim::simulate(env().recipe, *c, o);
}

}  // namespace

// Full resolution, default vibration, pose known: after compensation every feature within
// ±0.03 mm (the measurement issue's bound under vibration). Label: accuracy.
TEST(CompensatedMeasurement, AllFeaturesUnderDefaultVibration) {
    for (std::uint64_t seed : {21, 22, 23}) {
        const auto s = simulate_full(seed, 700.0 + 100.0 * static_cast<double>(seed - 20));
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
                for (std::size_t k = 0; k < fc.displacement_mm.size(); ++k) {
                    const double d = static_cast<double>(t_end - f.profile_times_ns[k]) * 1e-9;
                    int b = 0;
                    while (d >= edges[b + 1]) ++b;
                    s2[b] +=
                        (1000.0 * (fc.displacement_mm[k] - s.truth.faces[j].displacement_mm[k]))
                            .squaredNorm();
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

namespace {

// |u_est − u_true| by a profile's distance from an accelerometer gap of `gap_ns` (bin 0: inside
// it), gaps at several places in every face's scan, beside the same profiles without the gap.
struct GapErrors {
    static constexpr int kBins = 7;
    static constexpr double kEdges[kBins + 1] = {0.0, 1e-9, 0.025, 0.05, 0.1, 0.2, 0.5, 100.0};
    std::vector<double> rms, worst, base, n;
    double untrusted_share = 0;  // of the profiles, over every face and gap
};

GapErrors gap_errors(std::int64_t gap_ns, int seeds, const CompensationConfig& c) {
    constexpr int kBins = GapErrors::kBins;
    const auto& edges = GapErrors::kEdges;
    std::vector<double> s2(kBins, 0.0), base2(kBins, 0.0), worst(kBins, 0.0), n(kBins, 0.0);
    double untrusted = 0, profiles = 0;
    for (std::uint64_t seed = 1; seed <= static_cast<std::uint64_t>(seeds); ++seed) {
        const auto s = simulate(env().cell, seed);
        for (std::size_t j = 0; j < s.recording.faces.size(); ++j) {
            const core::FaceScan& full = s.recording.faces[j];
            const auto clean = compensate::compensate_face(full, c);
            for (double at : {0.15, 0.4, 0.65, 0.9}) {  // gap start, as a fraction of the scan
                core::FaceScan f = full;
                const std::int64_t t0 = f.profile_times_ns.front(), t1 = f.profile_times_ns.back();
                const std::int64_t g0 =
                    t0 + static_cast<std::int64_t>(at * static_cast<double>(t1 - t0));
                const std::int64_t g1 = g0 + gap_ns;
                std::size_t a = 0, b = 0;
                while (a < f.accel_times_ns.size() && f.accel_times_ns[a] < g0) ++a;
                for (b = a; b < f.accel_times_ns.size() && f.accel_times_ns[b] < g1;) ++b;
                f.accel_times_ns.erase(f.accel_times_ns.begin() + a, f.accel_times_ns.begin() + b);
                f.accel_mps2.erase(f.accel_mps2.begin() + 3 * a, f.accel_mps2.begin() + 3 * b);
                const auto fc = compensate::compensate_face(f, c);
                untrusted += static_cast<double>(fc.n_degraded);
                profiles += static_cast<double>(fc.displacement_mm.size());
                for (std::size_t k = 0; k < fc.displacement_mm.size(); ++k) {
                    const std::int64_t t = f.profile_times_ns[k];
                    const double d =
                        static_cast<double>(t < g0 ? g0 - t : (t > g1 ? t - g1 : 0)) * 1e-9;
                    int bin = 0;
                    while (d >= edges[bin + 1]) ++bin;
                    const double e =
                        1000.0 *
                        (fc.displacement_mm[k] - s.truth.faces[j].displacement_mm[k]).norm();
                    s2[bin] += e * e;
                    base2[bin] +=
                        (1000.0 * (clean.displacement_mm[k] - s.truth.faces[j].displacement_mm[k]))
                            .squaredNorm();
                    worst[bin] = std::max(worst[bin], e);
                    n[bin] += 1;
                }
            }
        }
    }
    GapErrors out{{}, worst, {}, n, untrusted / std::max(1.0, profiles)};
    for (int b = 0; b < kBins; ++b) {
        out.rms.push_back(std::sqrt(s2[b] / std::max(1.0, n[b])));
        out.base.push_back(std::sqrt(base2[b] / std::max(1.0, n[b])));
    }
    return out;
}

}  // namespace

// How far an accelerometer gap spoils the displacement around it, by the gap's length (a lost
// datagram is 10 ms; docs/compensation.md "Gaps and degraded features"). The longest hole
// bridged (max_bridge_s) is read off this table: up to it the bridged displacement at 0.1–0.5 s
// is within a few µm of the compensation's own error; longer holes are not (measured
// 2026-12-03, 2 seeds: 100 ms 26.6 µm RMS at 0.1–0.2 s, 150 ms 41.3, 250 ms 21.6 and still
// 21.6 at 0.2–0.5 s, against 4.6): their face is untrusted. The quick cell's scan is shorter
// than the pad on both sides of a hole, so the table runs with the 0.1 s pad it was first read
// for; the pad in force comes from RandomHolesErrorByDistance (holes at random, press blows).
TEST(CompensateFace, GapErrorByDistanceIsWhyThePadExists) {
    CompensationConfig c;
    c.degrade_pad_s = 0.1;
    for (const auto& [gap_ms, seeds] : {std::pair{10, 4}, {30, 4}, {60, 4}, {100, 2}, {250, 1}}) {
        const GapErrors g = gap_errors(gap_ms * 1'000'000LL, seeds, c);
        std::printf(
            "%d ms gap: |error| by distance from the gap (RMS with gap / worst / RMS without)\n",
            gap_ms);
        for (int b = 0; b < GapErrors::kBins; ++b)
            std::printf("  %5.3f-%5.3f s: %6.1f / %6.1f / %5.1f um (%g profiles)\n",
                        GapErrors::kEdges[b], std::min(GapErrors::kEdges[b + 1], 9.9), g.rms[b],
                        g.worst[b], g.base[b], g.n[b]);
        // Inside the gap: far off (the profiles are left out).
        EXPECT_GT(g.rms[0], 5.0 * g.base[0]) << gap_ms << " ms";
        if (gap_ms * 1e-3 > c.max_bridge_s) {
            EXPECT_EQ(g.untrusted_share, 1.0) << gap_ms << " ms: the whole face is untrusted";
            continue;
        }
        // Beyond the pad the gap adds a few µm to the compensation's own error (with a straight
        // line over a 60 ms gap and no bridging: 290 µm RMS at 0.1–0.2 s, measured 2026-12-03).
        for (int b = 1; b < GapErrors::kBins; ++b)
            if (GapErrors::kEdges[b] >= c.degrade_pad_s - 1e-12 && g.n[b] > 0) {
                EXPECT_LT(g.rms[b], 3.0 * g.base[b] + 1.0) << gap_ms << " ms, bin " << b;
            }
        EXPECT_LT(g.untrusted_share, 1.0) << gap_ms << " ms: bridged, only the gap and its pad";
    }
}

namespace {

// The recording with the top face's accelerometer samples of 60 ms from `at` (a fraction of
// the scan) removed; at < 0: unchanged.
core::Recording with_top_gap(const core::Recording& rec, double at) {
    core::Recording out = rec;
    core::FaceScan& top = out.faces[0];
    if (at < 0) return out;
    const std::int64_t t0 = top.profile_times_ns.front(), t1 = top.profile_times_ns.back();
    const std::int64_t g0 = t0 + static_cast<std::int64_t>(at * static_cast<double>(t1 - t0));
    std::size_t a = 0, b = 0;
    while (a < top.accel_times_ns.size() && top.accel_times_ns[a] < g0) ++a;
    for (b = a; b < top.accel_times_ns.size() && top.accel_times_ns[b] < g0 + 60'000'000;) ++b;
    top.accel_times_ns.erase(top.accel_times_ns.begin() + static_cast<std::ptrdiff_t>(a),
                             top.accel_times_ns.begin() + static_cast<std::ptrdiff_t>(b));
    top.accel_mps2.erase(top.accel_mps2.begin() + static_cast<std::ptrdiff_t>(3 * a),
                         top.accel_mps2.begin() + static_cast<std::ptrdiff_t>(3 * b));
    return out;
}

}  // namespace

// Issue 17's case: a vibrated 4-face part (full resolution, part found by matching) with a 60 ms
// accelerometer gap in the top scan, at several places. The features of the other faces are OK
// and within ±0.02 mm; each top feature is within ±0.03 mm, or degraded / not measured with a
// reason that names the gap; none is off by more than 0.03 mm without a flag.
TEST(CompensatedMeasurement, AccelerometerGapInTheTopScan) {
    int degraded = 0, not_measured = 0, around = 0;
    double worst_other = 0, worst_top = 0;
    for (std::uint64_t seed : {31, 32, 33}) {
        const auto s = simulate_full(seed, 900.0 + 50.0 * static_cast<double>(seed - 30));
        ASSERT_TRUE(s);
        for (double at : {-1.0, 0.1, 0.3, 0.45, 0.6, 0.85}) {  // −1: no gap, for comparison
            pipeline::PipelineOptions po;
            const auto r = pipeline::run(with_top_gap(s->recording, at), env().recipe, po);
            ASSERT_TRUE(po.T_world_part || (r.match && r.match->found)) << "gap at " << at;
            std::printf("seed %llu, gap at %5.2f of the top scan:",
                        static_cast<unsigned long long>(seed), at);
            for (std::size_t j = 0; j < r.measurement.features.size(); ++j) {
                const auto& f = r.measurement.features[j];
                const bool on_top =
                    std::find(f.faces.begin(), f.faces.end(), "top") != f.faces.end();
                if (!f.hot_mm) {
                    std::printf(" %s: -;", f.name.c_str());
                    ++not_measured;
                    EXPECT_TRUE(on_top && at >= 0) << f.name << ": " << f.reason;
                    EXPECT_NE(f.reason.find("accelerometer gap"), std::string::npos) << f.reason;
                    continue;
                }
                const double e = *f.hot_mm - s->truth.features[j].hot_mm;
                std::printf(" %+.4f%s", e, f.degraded ? "(D)" : "");
                if (!on_top) {
                    EXPECT_EQ(f.verdict, measure::Verdict::kOk) << f.name << ": " << f.reason;
                    EXPECT_NEAR(e, 0.0, 0.02) << f.name << " gap at " << at;
                    worst_other = std::max(worst_other, std::abs(e));
                } else if (f.degraded) {
                    ++degraded;
                    EXPECT_NE(f.reason.find("accelerometer gap"), std::string::npos) << f.reason;
                } else {
                    around += at >= 0;
                    EXPECT_NEAR(e, 0.0, 0.03) << f.name << " gap at " << at << ", not flagged";
                    worst_top = std::max(worst_top, std::abs(e));
                    if (at >= 0) {
                        EXPECT_FALSE(f.left_out.empty()) << f.name;  // names the gap
                    }
                }
            }
            std::printf("\n");
        }
    }
    std::printf(
        "worst |error|: other faces %.4f mm, top features not flagged %.4f mm; top "
        "features with a gap: %d measured around it, %d degraded, %d not measured\n",
        worst_other, worst_top, around, degraded, not_measured);
}

namespace {

// The recording with a fraction of its 10 ms accelerometer datagrams lost at random (issue 18:
// a UDP stream on a busy network), on every face.
core::Recording with_lost_datagrams(const core::Recording& rec, double fraction,
                                    std::uint64_t seed) {
    core::Recording out = rec;
    std::mt19937_64 rng(seed);
    std::bernoulli_distribution lost(fraction);
    for (auto& f : out.faces) {
        core::FaceScan kept = f;
        kept.accel_times_ns.clear();
        kept.accel_mps2.clear();
        std::int64_t datagram = -1;
        bool drop = false;
        for (std::size_t j = 0; j < f.accel_times_ns.size(); ++j) {
            const std::int64_t d = (f.accel_times_ns[j] - f.accel_times_ns.front()) / 10'000'000;
            if (d != datagram) {
                datagram = d;
                drop = lost(rng);
            }
            if (drop) continue;
            kept.accel_times_ns.push_back(f.accel_times_ns[j]);
            kept.accel_mps2.insert(kept.accel_mps2.end(), f.accel_mps2.begin() + 3 * j,
                                   f.accel_mps2.begin() + 3 * j + 3);
        }
        f = std::move(kept);
    }
    return out;
}

}  // namespace

// |u_est − u_true| under random datagram loss (full-resolution cell, press blows, 10 ms holes at
// random in the record), by a profile's distance from the nearest hole, beside the same profiles
// without loss (docs/compensation.md "Holes at random", "Holes in u"). Beyond the pad
// (degrade_pad_s) what the bridge adds to the error, per axis, must stay within the σ that
// hole_sigma_mm gives each feature's u; within it, it must not (why the pad is there). Measured
// 2026-12-04, seeds 36-39: RMS 50.6 µm at 0-0.1 s, 14.2 at 0.1-0.2 s, 6.2-7.2 up to 0.5 s, 4.2
// beyond 0.6 s.
TEST(CompensateFace, RandomHolesErrorByDistance) {
    constexpr int kBins = 10;
    const double edges[kBins + 1] = {0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 100.0};
    std::vector<double> s2(kBins, 0.0), base2(kBins, 0.0), worst(kBins, 0.0), n(kBins, 0.0);
    std::vector<double> base_worst(kBins, 0.0);
    compensate::CompensationConfig c;
    c.degrade_pad_s = 0.0;  // every profile outside a hole, to see how far each one spoils
    for (std::uint64_t seed = 36; seed <= 39; ++seed) {
        const auto sim = simulate_full(seed, 1050.0);
        ASSERT_TRUE(sim);
        const sim::SimResult& s = *sim;
        std::vector<compensate::FaceCompensation> clean;  // each face without loss
        for (const auto& face : s.recording.faces)
            clean.push_back(compensate::compensate_face(face, c));
        for (double fraction : {0.003, 0.01, 0.02}) {
            for (std::uint64_t pattern = 0; pattern < 3; ++pattern) {
                const auto lossy = with_lost_datagrams(s.recording, fraction, 100 * seed + pattern);
                for (std::size_t j = 0; j < lossy.faces.size(); ++j) {
                    const auto& f = lossy.faces[j];
                    const auto fc = compensate::compensate_face(f, c);
                    for (std::size_t k = 0; k < fc.displacement_mm.size(); ++k) {
                        if (fc.profile_degraded[k]) continue;
                        const double t = 1e-9 * static_cast<double>(f.profile_times_ns[k] -
                                                                    f.profile_times_ns[0]);
                        double d = 1e9;
                        for (const auto& u : fc.untrusted)
                            if (u.cause == "accelerometer gap")
                                d = std::min(d, std::max(u.t0_s - t, t - u.t1_s));
                        if (d > 1e8) continue;  // no hole on this face
                        int bin = 0;
                        while (d >= edges[bin + 1]) ++bin;
                        const auto& truth = s.truth.faces[j].displacement_mm[k];
                        const double err = 1000.0 * (fc.displacement_mm[k] - truth).norm();
                        const double base = 1000.0 * (clean[j].displacement_mm[k] - truth).norm();
                        s2[bin] += err * err;
                        base2[bin] += base * base;
                        worst[bin] = std::max(worst[bin], err);
                        base_worst[bin] = std::max(base_worst[bin], base);
                        n[bin] += 1;
                    }
                }
            }
        }
    }
    std::printf(
        "by distance from the nearest hole: RMS / worst; without loss: RMS / worst; "
        "excess per axis against hole_sigma_mm\n");
    const compensate::CompensationConfig defaults;
    core::DisplacementNoise table;  // hole_sigma of one hole at 0, by distance
    table.holes_s = {{0.0, 0.0}};
    table.hole_sigma_mm = defaults.hole_sigma_mm;
    std::vector<double> excess(kBins, 0.0);
    for (int b = 0; b < kBins; ++b) {
        const double m = std::max(1.0, n[b]);
        excess[b] = std::sqrt(std::max(0.0, s2[b] / m - base2[b] / m) / 3.0);
        const double sigma_um = 1000.0 * table.hole_sigma(0, edges[b] + 1e-6);
        std::printf(
            "  %4.2f-%4.2f s: %6.1f / %6.1f; %5.1f / %5.1f um (%g profiles); %5.1f "
            "against %5.1f um\n",
            edges[b], std::min(edges[b + 1], 9.9), std::sqrt(s2[b] / m), worst[b],
            std::sqrt(base2[b] / m), base_worst[b], n[b], excess[b], sigma_um);
        if (edges[b] < defaults.degrade_pad_s - 1e-9 || n[b] == 0) continue;
        EXPECT_LT(excess[b], 1.25 * sigma_um + 1.5) << "beyond the pad, bin " << b;
    }
    EXPECT_GT(excess[0], 1000.0 * table.hole_sigma(0, defaults.degrade_pad_s + 1e-6))
        << "0-0.05 s from a hole: why the pad is there";
}

// Lost accelerometer datagrams must never make a good part NOK (issue 18 found 2–30 % loss
// reading 0.09–0.9 mm off and, at 30 %, both good parts NOK): every feature is OK within
// 0.02 mm (issue 18's bound), or degraded with a reason (untrusted profiles, or a silhouette
// edge beside holes), or not measured.
TEST(CompensatedMeasurement, LostDatagramsNeverMakeAGoodPartNok) {
    // The silhouette rule is the idealised recipe's (a forging's side heights use level planes).
    const core::Recipe ideal = test::idealised(env().recipe);
    int by_silhouette = 0;  // degraded by the silhouette rule (docs/compensation.md)
    for (std::uint64_t seed : {34, 35}) {
        const auto s = simulate_full(seed, 1000.0 + 50.0 * static_cast<double>(seed - 34));
        ASSERT_TRUE(s);
        for (double fraction : {0.02, 0.05, 0.1, 0.3}) {
            const auto r =
                pipeline::run(with_lost_datagrams(s->recording, fraction, seed), ideal, {});
            ASSERT_TRUE(r.match && r.match->found) << fraction;
            int ok = 0, degraded = 0, not_measured = 0;
            double worst_ok = 0, worst_degraded = 0;
            for (std::size_t j = 0; j < r.measurement.features.size(); ++j) {
                const auto& f = r.measurement.features[j];
                EXPECT_NE(f.verdict, measure::Verdict::kNok) << f.name << " at " << fraction;
                if (!f.hot_mm) {
                    ++not_measured;
                    continue;
                }
                const double e = std::abs(*f.hot_mm - s->truth.features[j].hot_mm);
                if (f.degraded) {
                    ++degraded;
                    worst_degraded = std::max(worst_degraded, e);
                    const bool silhouette = f.reason.find("silhouette edge") != std::string::npos;
                    by_silhouette += silhouette;
                    EXPECT_TRUE(silhouette ||
                                f.reason.find("untrusted profiles") != std::string::npos ||
                                f.reason.find("accelerometer's holes") != std::string::npos)
                        << f.name << ": " << f.reason;
                } else {
                    ++ok;
                    worst_ok = std::max(worst_ok, e);
                    EXPECT_LT(e, 0.02) << f.name << " at " << fraction << ", not flagged";
                }
            }
            std::printf(
                "seed %llu, %2.0f %% of the datagrams lost: %d OK (worst %.4f mm), %d "
                "degraded (worst %.4f mm), %d not measured; part %s\n",
                static_cast<unsigned long long>(seed), 100 * fraction, ok, worst_ok, degraded,
                worst_degraded, not_measured, measure::to_string(r.measurement.verdict));
        }
    }
    EXPECT_GT(by_silhouette, 0) << "the silhouette rule never applied: the loss misses the sides";
}

// A master whose certified features could only be measured degraded is not checked on them:
// the check fails as inconclusive (the PLC reads degraded, not NOK), naming why.
TEST(CompensateBadInput, AMasterMeasuredDegradedIsInconclusive) {
    auto s = simulate(env().cell, 17);
    const auto trusted_run = run_pipeline(s);
    core::MasterCertificate cert;
    cert.master = "M-1";
    cert.recipe = env().recipe.name;
    cert.tolerance_mm = 1.0;  // generous: only the data's trust can fail it
    for (std::size_t j = 0; j < s.truth.features.size(); ++j)  // what the quick cell measures
        if (trusted_run.measurement.features[j].cold_mm)
            cert.features.push_back(
                {s.truth.features[j].name, s.truth.features[j].cold_mm, 0.001, {}});
    ASSERT_GE(cert.features.size(), 8u);
    const auto trusted = pipeline::verify(trusted_run, cert);
    ASSERT_TRUE(trusted);
    EXPECT_TRUE(trusted->passed);
    for (auto& f : s.recording.faces) {
        f.accel_mps2.clear();
        f.accel_times_ns.clear();
    }
    const auto v = pipeline::verify(run_pipeline(s), cert);
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->passed);
    EXPECT_TRUE(v->inconclusive);
    for (const auto& f : v->features) {
        EXPECT_TRUE(f.degraded) << f.name;
        EXPECT_NE(f.reason.find("degraded"), std::string::npos) << f.reason;
    }

    // Not measured (a face left out: its scan lost its start twice) is inconclusive too; only
    // a trusted value outside its tolerance fails the master (the PLC reads NOK).
    auto missing = trusted_run;
    for (auto& f : missing.measurement.features)
        if (f.name == cert.features[0].name) {
            f.cold_mm.reset();
            f.verdict = measure::Verdict::kNotMeasured;
            f.reason = "face 'top' is not in the recording";
        }
    const auto gap = pipeline::verify(missing, cert);
    ASSERT_TRUE(gap);
    EXPECT_FALSE(gap->passed);
    EXPECT_TRUE(gap->inconclusive);
    auto wrong = missing;
    for (auto& f : wrong.measurement.features)
        if (f.name == cert.features[1].name) *f.cold_mm += 2.0;  // outside the 1 mm tolerance
    const auto failed = pipeline::verify(wrong, cert);
    ASSERT_TRUE(failed);
    EXPECT_FALSE(failed->passed);
    EXPECT_FALSE(failed->inconclusive);
}

namespace {

// White noise of one-sided density `density_ug` µg/√Hz at `fs`, gravity and press modes on top.
std::vector<double> noisy_accel(double density_ug, double fs, std::size_t n, std::uint64_t seed,
                                bool modes) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    const double sigma = density_ug * 1e-6 * 9.80665 * std::sqrt(fs / 2.0);
    std::vector<double> a(n);
    for (std::size_t i = 0; i < n; ++i) {
        const double t = static_cast<double>(i) / fs;
        a[i] = 9.80665 + sigma * normal(rng);
        if (modes)  // the default cell's modes at 0.6, 0.25 and 0.08 mm: 1.5-7 m/s²
            a[i] += 1.5 * std::sin(kTwoPi * 8 * t) + 5.2 * std::sin(kTwoPi * 23 * t + 1.0) +
                    7.0 * std::sin(kTwoPi * 47 * t + 2.0);
    }
    return a;
}

}  // namespace

// The accelerometer's noise is read off the record's top band, under press modes 300 times
// stronger than the noise.
TEST(CompensationNoise, DensityReadOffTheTopBandUnderPressModes) {
    const double fs = 2000.0;
    std::array<std::vector<double>, 3> a;
    const double truth_ug[3] = {25.0, 10.0, 60.0};
    for (int k = 0; k < 3; ++k) a[k] = noisy_accel(truth_ug[k], fs, 6400, 11 + k, true);
    const auto d = compensate::accel_noise_density(a, fs);
    for (int k = 0; k < 3; ++k) {
        const double ug = std::sqrt(d[k]) / 9.80665 * 1e6;
        EXPECT_NEAR(ug, truth_ug[k], 0.08 * truth_ug[k]) << "axis " << k;
    }
    // Too short a record to tell: nothing, not a guess.
    std::array<std::vector<double>, 3> short_record{std::vector<double>(500, 9.8),
                                                    std::vector<double>(500, 0.0),
                                                    std::vector<double>(500, 0.0)};
    EXPECT_EQ(compensate::accel_noise_density(short_record, fs)[0], 0.0);
}

// The predicted error against the integrator itself: 300 records of white noise through
// integrate_twice, the displacement's variance and its covariance 0.1 and 0.3 s apart in the middle
// of the record, where the profiles are (the tapers and margins keep them off the ends).
TEST(CompensationNoise, PredictsWhatTheIntegratorMakesOfWhiteNoise) {
    const double fs = 2000.0, density_ug = 25.0;
    const std::size_t n = 6400;  // a 1.2 s scan with 1 s margins
    const CompensationConfig c;
    const double s_a = std::pow(density_ug * 1e-6 * 9.80665, 2);
    const core::DisplacementNoise model = compensate::displacement_noise({s_a, s_a, s_a}, c);
    ASSERT_TRUE(model.known());
    double var = 0, cov1 = 0, cov3 = 0;
    std::size_t m = 0;
    for (int trial = 0; trial < 300; ++trial) {
        const auto u =
            compensate::integrate_twice(noisy_accel(density_ug, fs, n, 100 + trial, false), fs, c);
        for (std::size_t i = 2000; i < 4400; i += 50, ++m) {
            var += u[i] * u[i] * 1e6;  // m² → mm²
            cov1 += u[i] * u[i + 200] * 1e6;
            cov3 += u[i] * u[i - 600] * 1e6;
        }
    }
    var /= static_cast<double>(m), cov1 /= static_cast<double>(m), cov3 /= static_cast<double>(m);
    std::printf(
        "displacement error: σ %.2f µm (model %.2f), cov at 0.1 s %.3f (model %.3f), at "
        "0.3 s %.3f (model %.3f) µm²\n",
        1e3 * std::sqrt(var), 1e3 * std::sqrt(model.cov(2, 0.0)), 1e6 * cov1,
        1e6 * model.cov(2, 0.1), 1e6 * cov3, 1e6 * model.cov(2, 0.3));
    EXPECT_NEAR(std::sqrt(var), std::sqrt(model.cov(2, 0.0)), 0.08 * std::sqrt(var));
    EXPECT_NEAR(cov1, model.cov(2, 0.1), 0.1 * var);
    EXPECT_NEAR(cov3, model.cov(2, 0.3), 0.1 * var);
}

// A face whose accelerometer timestamps jitter (1.6 % of the period on the independent
// recordings): the density is read off the samples as they came, not off the grid, whose
// interpolation between jittered timestamps halves the top band's power; a 50 ms hole in the
// record is left out, not read as a quiet stretch.
TEST(CompensationNoise, JitteredTimestampsAndAHoleDoNotHideTheNoise) {
    const double fs = 2000.0, density_ug = 25.0;
    core::FaceScan face;
    face.name = "top";
    for (int k = 0; k < 1200; ++k) face.profile_times_ns.push_back(1'000'000'000 + k * 1'000'000LL);
    const auto a = noisy_accel(density_ug, fs, 6400, 5, true);
    std::mt19937_64 rng(9);
    std::normal_distribution<double> jitter(0.0, 8000.0);  // ns
    for (std::size_t j = 0; j < a.size(); ++j) {
        if (j >= 3000 && j < 3100) continue;  // the hole
        face.accel_times_ns.push_back(static_cast<std::int64_t>(j) * 500'000 +
                                      std::llround(jitter(rng)));
        for (const double v : {a[j], 0.3 * a[j] - 2.9, 0.0})
            face.accel_mps2.push_back(static_cast<float>(v));
    }
    const auto fc = compensate::compensation_error(face, {});
    ASSERT_TRUE(fc.noise.known());
    EXPECT_NEAR(fc.accel_noise_ug[0], density_ug, 0.1 * density_ug);
    EXPECT_NEAR(fc.accel_noise_ug[1], 0.3 * density_ug, 0.1 * 0.3 * density_ug);
}
