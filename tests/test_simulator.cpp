// The simulator, the recording format and the geometry agree: a simulated part written to disk
// and read back, reconstructed with the true vibration u(t) added, lies on the part or the
// support within 5σ of the range noise, but for the spikes the simulator says it injected.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/sim/vibration.hpp"

namespace fs = std::filesystem;
using namespace hotgauge;

namespace {

struct Fixture {
    core::Recipe recipe;
    sim::CellConfig cell;
};

Fixture load() {
    auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    EXPECT_TRUE(r) << (r ? "" : r.error().message);
    EXPECT_TRUE(c) << (c ? "" : c.error().message);
    return {*r, sim::quick(*c)};
}

fs::path temp_dir(const std::string& name) {
    const fs::path p =
        fs::temp_directory_path() / ("hotgauge_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(p);
    return p;
}

// Distance of a world point to the simulated scene of `face`: the hot part or the support plate.
double scene_distance(const sim::SimTruth& truth, const core::AxisymmetricSolid& solid,
                      bool support, const Eigen::Vector3d& p_world) {
    double d = solid.distance(truth.T_world_part.inverse() * p_world);
    if (support && std::abs(p_world.x()) <= truth.support_half_size_mm &&
        std::abs(p_world.y()) <= truth.support_half_size_mm)
        d = std::min(d, std::abs(p_world.z()));
    return d;
}

}  // namespace

TEST(Simulator, RoundTripPointsLieOnPartOrSupport) {
    Fixture fx = load();
    // Strong blows, so that the quick scans (0.24 s each) are surely shaken.
    for (auto& m : fx.cell.vibration.modes) m.amplitude_mm *= 3.0;
    sim::SimOptions opt;
    opt.seed = 42;
    opt.temperature_c = 1050.0;
    opt.t0_ns = 1'790'000'000'000'000'000;
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_TRUE(sim) << sim.error().message;
    const fs::path dir = temp_dir("sim_roundtrip");
    ASSERT_TRUE(io::write_recording(sim->recording, dir));
    auto rec = io::read_recording(dir);
    ASSERT_TRUE(rec) << rec.error().message;
    EXPECT_TRUE(rec->warnings.empty()) << rec->warnings.front();
    ASSERT_EQ(rec->faces.size(), 4u);

    const auto& truth = sim->truth;
    const auto solid = truth.solid(fx.recipe);
    const double tol = 5.0 * truth.range_noise_mm;
    std::int64_t total_on = 0, total_nominal_off = 0;
    for (std::size_t j = 0; j < rec->faces.size(); ++j) {
        const auto& face = rec->faces[j];
        const auto& ft = truth.faces[j];
        ASSERT_EQ(ft.name, face.name);
        const bool support = fx.cell.faces[j].support_visible;
        const auto corrected = core::world_cloud(face, &ft.u_mm);
        const auto nominal = core::world_cloud(face);
        std::int64_t on = 0, off_clean = 0, spikes_off = 0, nominal_off = 0, part_points = 0;
        for (std::size_t q = 0; q < corrected.points_mm.size(); ++q) {
            const std::size_t idx = corrected.profile[q] * face.width + corrected.column[q];
            const double d = scene_distance(truth, solid, support, corrected.points_mm[q]);
            if (ft.spike[idx]) {
                spikes_off += d > tol;
                continue;
            }
            if (d <= tol)
                ++on;
            else
                ++off_clean;
            part_points +=
                solid.distance(truth.T_world_part.inverse() * corrected.points_mm[q]) <= tol;
            nominal_off += scene_distance(truth, solid, support, nominal.points_mm[q]) > tol;
        }
        SCOPED_TRACE(face.name);
        EXPECT_EQ(off_clean, 0) << "non-outlier points off the surface";
        EXPECT_GT(part_points, 1000) << "the face hardly sees the part";
        // Spikes are uniform in ±5 mm: nearly all land off the surface.
        EXPECT_GE(spikes_off * 10, ft.n_spikes * 7);
        total_on += on;
        total_nominal_off += nominal_off;
    }
    // The vibration matters: without u(t) points are off by more than 5σ.
    double peak_u = 0;
    for (const auto& f : truth.faces)
        for (const auto& u : f.u_mm) peak_u = std::max(peak_u, u.norm());
    EXPECT_GT(peak_u, 0.1);
    EXPECT_GT(total_nominal_off, total_on / 100);
    fs::remove_all(dir);
}

TEST(Simulator, TruthFeaturesFollowGeometryAndTemperature) {
    const Fixture fx = load();
    sim::SimOptions opt;
    opt.temperature_c = 1000.0;
    opt.faces = {"top"};
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_TRUE(sim) << sim.error().message;
    const double growth = 1.0 + (1.2e-5 + 3.0e-9 * 980.0) * 980.0;
    EXPECT_NEAR(sim->truth.growth, growth, 1e-12);
    ASSERT_EQ(sim->truth.features.size(), 13u);
    for (const auto& f : sim->truth.features) {
        EXPECT_NEAR(f.hot_mm, f.cold_mm * growth, 1e-9) << f.name;
        const auto* spec = &fx.recipe.features[&f - sim->truth.features.data()];
        EXPECT_NEAR(f.cold_mm, spec->nominal_mm, 0.3) << f.name;  // σ 0.05 as-forged deviation
        EXPECT_NE(f.cold_mm, spec->nominal_mm) << f.name << ": truth must not be the nominal";
    }
}

TEST(Simulator, AccelerometerMatchesGravityAndCoversScan) {
    const Fixture fx = load();
    sim::SimOptions opt;
    opt.faces = {"side1"};
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_TRUE(sim);
    const auto& f = sim->recording.faces[0];
    // Mean over the record, rotated into the world, is gravity up (vibration averages out).
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (std::int64_t j = 0; j < f.n_accel(); ++j) mean += f.accel(j);
    mean /= static_cast<double>(f.n_accel());
    const Eigen::Vector3d world = f.T_world_camera.linear() * f.R_camera_accel * mean;
    EXPECT_NEAR(world.z(), 9.81, 0.05);
    EXPECT_NEAR(world.head<2>().norm(), 0.0, 0.05);
    EXPECT_LE(f.accel_times_ns.front(), f.profile_times_ns.front() - 500'000'000);
    EXPECT_GE(f.accel_times_ns.back(), f.profile_times_ns.back() + 500'000'000);
}

TEST(Vibration, AccelerationIsSecondDerivativeOfDisplacement) {
    std::mt19937_64 rng(3);
    const sim::Vibration v(sim::VibrationConfig{}, 0.0, 10.0, rng);
    const double h = 1e-5;
    double peak = 0.0;
    for (double t = 0.5; t < 9.5; t += 0.0137) {
        const Eigen::Vector3d fd =
            (v.displacement_mm(t + h) - 2.0 * v.displacement_mm(t) + v.displacement_mm(t - h)) /
            (h * h);
        const Eigen::Vector3d a = v.acceleration_mmps2(t);
        ASSERT_LT((fd - a).norm(), 0.01 + 1e-4 * a.norm()) << "t " << t;
        peak = std::max(peak, v.displacement_mm(t).norm());
    }
    EXPECT_GT(peak, 0.2);  // the press really shakes
    EXPECT_LT(peak, 1.5);  // up to about a millimetre
}

TEST(Simulator, BadFaceRequestIsAnError) {
    const Fixture fx = load();
    sim::SimOptions opt;
    opt.faces = {"front"};
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_FALSE(sim);
}
