// The simulator, the recording format and the geometry agree: a simulated part written to disk
// and read back, reconstructed with the true vibration u(t) added, lies on the part or the
// support within 5σ of the range noise, but for the spikes the simulator says it injected.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "hotgauge/core/geometry.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/sim/geometry.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/sim/vibration.hpp"

namespace fs = std::filesystem;
using namespace hotgauge;

namespace {

struct Fixture {
    core::Recipe recipe;
    sim::CellConfig cell;
};

// hub-a in the quick version of a cell: config/cell.yaml, or config/cells/side15.yaml (side
// sensors 15° down).
Fixture load(const char* cell_file = "config/cell.yaml") {
    auto r = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    auto c = sim::read_cell_config(std::string(HOTGAUGE_SOURCE_DIR "/") + cell_file);
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

// A cell config file with one key edited: its text, where `key` is (line, 1-based; empty when
// the file lacks it), and the edited file read back from a temporary folder (removed with it).
struct CellEdit {
    CellEdit(const fs::path& file, std::string key_text, const std::string& name)
        : key(std::move(key_text)), dir(temp_dir(name)) {
        std::ifstream in(file);
        std::stringstream buffer;
        buffer << in.rdbuf();
        text = buffer.str();
        at = text.find(key);
        if (at != std::string::npos)
            line = std::to_string(
                1 + std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n'));
        fs::create_directories(dir);
    }
    ~CellEdit() { fs::remove_all(dir); }
    core::Result<sim::CellConfig> with(const std::string& replacement) const {
        std::string t = text;
        t.replace(at, key.size(), replacement);
        std::ofstream(dir / "cell.yaml") << t;
        return sim::read_cell_config(dir / "cell.yaml");
    }
    std::string key, text, line;
    std::size_t at = std::string::npos;
    fs::path dir;
};

// Distance of a world point to the simulated scene of `face`: the hot part or the support plate
// (a square at z = 0; noise may carry a point lit at its very edge a little past it, as the side
// sensors that look down see the plate's edges).
double scene_distance(const sim::SimTruth& truth, const core::AxisymmetricSolid& solid,
                      bool support, const Eigen::Vector3d& p_world) {
    double d = solid.distance(truth.T_world_part.inverse() * p_world);
    if (support) {
        const double h = truth.support_half_size_mm;
        const double dx = std::max(std::abs(p_world.x()) - h, 0.0);
        const double dy = std::max(std::abs(p_world.y()) - h, 0.0);
        d = std::min(d, std::sqrt(dx * dx + dy * dy + p_world.z() * p_world.z()));
    }
    return d;
}

}  // namespace

// Simulates a four-face part in `fx`'s cell under strong vibration, writes and reads it back and
// checks every non-spike point against the scene (the file's header comment).
void round_trip(Fixture fx, const std::string& name) {
    // Strong blows, so that the quick scans (0.24 s each) are surely shaken.
    for (auto& m : fx.cell.vibration.modes) m.amplitude_mm *= 3.0;
    sim::SimOptions opt;
    opt.seed = 42;
    opt.temperature_c = 1050.0;
    opt.t0_ns = 1'790'000'000'000'000'000;
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_TRUE(sim) << sim.error().message;
    const fs::path dir = temp_dir("sim_roundtrip_" + name);
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
        const auto corrected = core::world_cloud(face, &ft.displacement_mm);
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
        SCOPED_TRACE(name + " " + face.name);
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
        for (const auto& u : f.displacement_mm) peak_u = std::max(peak_u, u.norm());
    EXPECT_GT(peak_u, 0.1);
    EXPECT_GT(total_nominal_off, total_on / 100);
    fs::remove_all(dir);
}

TEST(Simulator, RoundTripPointsLieOnPartOrSupport) { round_trip(load(), "cell"); }

// The second cell: the side scans look 15° down onto the flange and boss tops; with and
// without the imager's line of sight checked.
TEST(Simulator, Side15PointsLieOnPartOrSupport) {
    Fixture fx = load("config/cells/side15.yaml");
    ASSERT_TRUE(fx.cell.sensor.imager_occlusion);
    round_trip(fx, "side15");
    fx.cell.sensor.imager_occlusion = false;
    round_trip(fx, "side15_no_occlusion");
}

namespace {

// Side-scan points (world) by the surface of the hot part they lie on, or the plate.
struct SurfaceCounts {
    std::int64_t rim = 0, flange_top = 0, boss_top = 0, spigot = 0, nose = 0, plate = 0;
    double rim_y_min = 1e9, rim_y_max = -1e9;  // rim points' world y
};

SurfaceCounts count_surfaces(const sim::SimTruth& truth, const core::FaceScan& face) {
    const double g = truth.growth, tol = 0.01;
    auto level = [&](const char* n) { return g * truth.levels_mm.at(n); };
    auto radius = [&](const char* n) { return 0.5 * g * truth.diameters_mm.at(n); };
    const double r_flange = radius("flange"), r_boss = radius("boss");
    const double r_recess = radius("top recess"), r_spigot = radius("spigot");
    const double r_nose = radius("spigot nose");
    const double z_under = level("flange_under"), z_ftop = level("flange_top");
    const double z_btop = level("boss_top"), z_step = level("spigot_step");
    SurfaceCounts c;
    const Eigen::Isometry3d T_part_world = truth.T_world_part.inverse();
    for (const auto& p : core::world_cloud(face).points_mm) {
        const Eigen::Vector3d q = T_part_world * p;
        const double r = q.head<2>().norm(), z = q.z();
        if (std::abs(r - r_flange) < tol && z > z_under && z < z_ftop) {
            ++c.rim;
            c.rim_y_min = std::min(c.rim_y_min, p.y());
            c.rim_y_max = std::max(c.rim_y_max, p.y());
        } else if (std::abs(z - z_ftop) < tol && r > r_boss && r < r_flange) {
            ++c.flange_top;
        } else if (std::abs(z - z_btop) < tol && r > r_recess && r < r_boss) {
            ++c.boss_top;
        } else if (std::abs(r - r_spigot) < tol && z > z_step && z < z_under) {
            ++c.spigot;
        } else if (std::abs(r - r_nose) < tol && z > 0.0 && z < z_step) {
            ++c.nose;
        } else if (std::abs(p.z()) < tol) {
            ++c.plate;
        }
    }
    return c;
}

}  // namespace

// The side15 cell's field holds what the side features are measured from, for every placement
// the accuracy runs use (tests/test_measure.cpp: seeds 1–20, same placement draw here, as the
// quick cell and the face subset do not change it) and the extreme ones (±40 mm corners, cold
// and at 1300 °C): the flange rim across the part's whole width in y, the flange top, the boss
// top, the spigot, the spigot nose (the spigot_end edge; only its lower ~5 mm, the spigot step
// shadows the rest) and the plate, in both side scans. Exact points (no noise, dropouts, spikes,
// vibration), quick resolution (W/4 rays at 4x pitch, 1 mm profiles).
TEST(Simulator, Side15SideScansSeeFlangeAndBossTops) {
    Fixture fx = load("config/cells/side15.yaml");
    fx.cell.vibration.enabled = false;
    fx.cell.sensor.range_noise_mm = 0.0;
    fx.cell.sensor.dropout_fraction = 0.0;
    fx.cell.sensor.spike_fraction = 0.0;
    std::vector<sim::SimOptions> cases;
    for (std::uint64_t seed = 1; seed <= 20; ++seed) {
        sim::SimOptions o;
        o.seed = seed;
        o.temperature_c = 20.0 + std::fmod(static_cast<double>(seed) * 367.0, 1280.0);
        cases.push_back(o);
    }
    const double m = fx.cell.placement.max_offset_mm;
    for (double t : {20.0, 1300.0})
        for (double x : {-m, m})
            for (double y : {-m, m}) {
                sim::SimOptions o;
                o.seed = 100;
                o.temperature_c = t;
                o.T_world_part = Eigen::Isometry3d(Eigen::Translation3d(x, y, 0.0));
                cases.push_back(o);
            }
    for (auto& o : cases) {
        o.t0_ns = 1'790'000'000'000'000'000;
        o.faces = {"side1", "side2"};
        auto sim = sim::simulate(fx.recipe, fx.cell, o);
        ASSERT_TRUE(sim) << sim.error().message;
        const Eigen::Vector3d at = sim->truth.T_world_part.translation();
        const double r_flange = 0.5 * sim->truth.growth * sim->truth.diameters_mm.at("flange");
        for (const auto& face : sim->recording.faces) {
            const auto c = count_surfaces(sim->truth, face);
            SCOPED_TRACE(face.name + " seed " + std::to_string(o.seed) + " T " +
                         std::to_string(o.temperature_c) + " at " + std::to_string(at.x()) + ", " +
                         std::to_string(at.y()));
            // Fewest seen (quick resolution): rim 2116, flange top 2104, boss top 344, spigot
            // 1911, nose 200, plate 24442.
            EXPECT_GT(c.rim, 1000);
            EXPECT_GT(c.flange_top, 1000);
            EXPECT_GT(c.boss_top, 150);
            EXPECT_GT(c.spigot, 1000);
            EXPECT_GT(c.nose, 100);
            EXPECT_GT(c.plate, 10000);
            // The rim is seen up to grazing incidence on both sides of the part's centre in y.
            EXPECT_LT(c.rim_y_min, at.y() - 0.9 * r_flange);
            EXPECT_GT(c.rim_y_max, at.y() + 0.9 * r_flange);
        }
    }
}

// Without the imager's line of sight every ray that returned with it returns again (no dropouts
// or spikes, so nothing random decides whether a ray returns): the side scans keep the points the
// imager could not see.
TEST(Simulator, WithoutImagerOcclusionSideScansReturnAtLeastAsMuch) {
    Fixture fx = load("config/cells/side15.yaml");
    fx.cell.vibration.enabled = false;
    fx.cell.sensor.dropout_fraction = 0.0;  // each ray's return then depends on geometry only
    fx.cell.sensor.spike_fraction = 0.0;
    sim::SimOptions opt;
    opt.seed = 3;
    opt.temperature_c = 1050.0;
    opt.t0_ns = 1'790'000'000'000'000'000;
    opt.faces = {"side1", "side2"};
    auto with = sim::simulate(fx.recipe, fx.cell, opt);
    fx.cell.sensor.imager_occlusion = false;
    auto without = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_TRUE(with && without);
    ASSERT_EQ(with->recording.faces.size(), 2u);
    for (std::size_t j = 0; j < 2; ++j) {
        const auto& a = with->recording.faces[j];
        const auto& b = without->recording.faces[j];
        SCOPED_TRACE(a.name);
        ASSERT_EQ(a.profiles_mm.size(), b.profiles_mm.size());
        std::int64_t n_with = 0, n_without = 0, lost = 0;
        for (std::size_t k = 0; k < a.profiles_mm.size(); k += 2) {
            const bool ra = std::isfinite(a.profiles_mm[k]), rb = std::isfinite(b.profiles_mm[k]);
            n_with += ra;
            n_without += rb;
            lost += ra && !rb;
        }
        std::printf("%s: %lld returns with imager occlusion, %lld without\n", a.name.c_str(),
                    static_cast<long long>(n_with), static_cast<long long>(n_without));
        EXPECT_EQ(lost, 0);
        EXPECT_GE(n_without, n_with);
    }
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
    ASSERT_EQ(sim->truth.features.size(), fx.recipe.features.size());
    for (const auto& f : sim->truth.features) {
        EXPECT_NEAR(f.hot_mm, f.cold_mm * growth, 1e-9) << f.name;
        const auto* spec = &fx.recipe.features[&f - sim->truth.features.data()];
        EXPECT_NEAR(f.cold_mm, spec->nominal_mm, 0.3) << f.name;  // σ 0.05 as-forged deviation
        // One axis, not forged: the die shift is its nominal 0 (test_forged draws one).
        if (spec->kind == core::FeatureKind::kDieShift) {
            EXPECT_EQ(f.cold_mm, 0.0);
            continue;
        }
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

// sensor.imager_occlusion: default true, read from the file, anything but a boolean is an error
// naming file:line and the key.
TEST(CellConfig, ImagerOcclusionIsReadStrictly) {
    auto plain = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    ASSERT_TRUE(plain) << plain.error().message;
    EXPECT_TRUE(plain->sensor.imager_occlusion);
    const std::string side15 = HOTGAUGE_SOURCE_DIR "/config/cells/side15.yaml";
    auto c = sim::read_cell_config(side15);
    ASSERT_TRUE(c) << c.error().message;
    EXPECT_TRUE(c->sensor.imager_occlusion);
    ASSERT_EQ(c->faces.size(), 4u);
    const double s = std::sin(15.0 * std::numbers::pi / 180.0);
    const double co = std::cos(15.0 * std::numbers::pi / 180.0);
    EXPECT_LT((c->faces[2].T_world_camera.linear().col(2) - Eigen::Vector3d(co, 0, -s)).norm(),
              1e-12);
    EXPECT_LT((c->faces[3].T_world_camera.linear().col(2) - Eigen::Vector3d(-co, 0, -s)).norm(),
              1e-12);
    // The optical axis passes 890 mm away through the flange rim at mid-thickness (nominal).
    for (int j : {2, 3}) {
        const auto& T = c->faces[static_cast<std::size_t>(j)].T_world_camera;
        const Eigen::Vector3d at_mid_scan =
            T.translation() + 120.0 * Eigen::Vector3d::UnitY() + 890.0 * T.linear().col(2);
        EXPECT_LT((at_mid_scan - Eigen::Vector3d(j == 2 ? -69.2 : 69.2, 0, 55.15)).norm(), 1e-9);
    }

    const CellEdit edit(side15, "imager_occlusion: true", "cell_config");
    ASSERT_FALSE(edit.line.empty());
    auto with_value = [&](const std::string& v) { return edit.with("imager_occlusion: " + v); };
    auto off = with_value("false");
    ASSERT_TRUE(off) << off.error().message;
    EXPECT_FALSE(off->sensor.imager_occlusion);
    for (const std::string bad : {"maybe", "[true]", "1.5"}) {
        auto r = with_value(bad);
        ASSERT_FALSE(r) << bad;
        EXPECT_NE(r.error().message.find("cell.yaml:" + edit.line + ": sensor.imager_occlusion"),
                  std::string::npos)
            << r.error().message;
    }
}

// The imager is where the triangulation puts it, beside the laser along the camera's y
// (acquire::SensorDesign's baseline): another place is refused, naming the line and the key.
TEST(Simulator, ImagerOffTheBaselineIsRefused) {
    const CellEdit edit(HOTGAUGE_SOURCE_DIR "/config/cell.yaml", "camera_center_mm: [0, 300, 0]",
                        "imager");
    ASSERT_FALSE(edit.line.empty());
    auto with_value = [&](const std::string& v) { return edit.with("camera_center_mm: " + v); };
    auto wide = with_value("[0, 350, 0]");
    ASSERT_TRUE(wide) << wide.error().message;
    EXPECT_EQ(wide->sensor.baseline_mm, 350.0);
    EXPECT_EQ(wide->sensor.imager_mm(), Eigen::Vector3d(0.0, 350.0, 0.0));
    EXPECT_EQ(sim::sensor_model(wide->sensor).baseline_mm, 350.0);
    for (const std::string bad : {"[5, 300, 0]", "[0, 300, 2]", "[0, -300, 0]"}) {
        auto r = with_value(bad);
        ASSERT_FALSE(r) << bad;
        EXPECT_NE(r.error().message.find("cell.yaml:" + edit.line + ": sensor.camera_center_mm"),
                  std::string::npos)
            << r.error().message;
    }
}

TEST(Simulator, BadFaceRequestIsAnError) {
    const Fixture fx = load();
    sim::SimOptions opt;
    opt.faces = {"front"};
    auto sim = sim::simulate(fx.recipe, fx.cell, opt);
    ASSERT_FALSE(sim);
}
