// hotgauge simulate: one simulated part into a recording plus its ground truth.
#include <spdlog/spdlog.h>

#include <chrono>

#include "commands.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::app {
namespace {

struct SimulateArgs {
    std::string recipe = HOTGAUGE_CONFIG_DIR "/parts/hub-a.yaml";
    std::string cell = HOTGAUGE_CONFIG_DIR "/cell.yaml";
    std::string out;
    std::string truth;
    sim::SimOptions opt;
    bool quick = false;
    bool no_vibration = false;
    double vibration_scale = 1.0;
    std::optional<double> noise_mm, spike_fraction, dropout_fraction, max_tilt_deg;
    std::optional<double> yaw_deg;
    std::vector<double> offset_mm;
};

int run(const SimulateArgs& a) {
    auto recipe = io::read_recipe(a.recipe);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return 1;
    }
    auto cell = sim::read_cell_config(a.cell);
    if (!cell) {
        spdlog::error("{}", cell.error().message);
        return 1;
    }
    sim::CellConfig c = a.quick ? sim::quick(*cell) : *cell;
    if (a.no_vibration) c.vibration.enabled = false;
    for (auto& m : c.vibration.modes) m.amplitude_mm *= a.vibration_scale;
    if (a.noise_mm) c.sensor.range_noise_mm = *a.noise_mm;
    if (a.spike_fraction) c.sensor.spike_fraction = *a.spike_fraction;
    if (a.dropout_fraction) c.sensor.dropout_fraction = *a.dropout_fraction;
    if (a.max_tilt_deg) c.placement.max_tilt_deg = *a.max_tilt_deg;
    sim::SimOptions opt = a.opt;
    if (a.yaw_deg || !a.offset_mm.empty()) {
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.rotate(
            Eigen::AngleAxisd(a.yaw_deg.value_or(0.0) * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
        if (a.offset_mm.size() == 2)
            T.translation() = Eigen::Vector3d(a.offset_mm[0], a.offset_mm[1], 0);
        opt.T_world_part = T;
    }

    const auto t0 = std::chrono::steady_clock::now();
    auto sim = sim::simulate(*recipe, c, opt);
    if (!sim) {
        spdlog::error("{}", sim.error().message);
        return 1;
    }
    const double sim_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (auto r = io::write_recording(sim->recording, a.out); !r) {
        spdlog::error("{}", r.error().message);
        return 1;
    }
    const std::string truth_dir = a.truth.empty() ? a.out + ".truth" : a.truth;
    if (auto r = sim::write_truth(sim->truth, truth_dir); !r) {
        spdlog::error("{}", r.error().message);
        return 1;
    }
    std::int64_t points = 0;
    for (const auto& f : sim->recording.faces)
        for (std::size_t i = 0; i < f.profiles_mm.size(); i += 2)
            points += f.profiles_mm[i] == f.profiles_mm[i];
    spdlog::info("simulated {} ({} faces, {} points, {:.1f} °C, growth {:.6f}) in {:.2f} s", a.out,
                 sim->recording.faces.size(), points, opt.temperature_c, sim->truth.growth, sim_s);
    std::printf("recording %s\nground truth %s\n", a.out.c_str(), truth_dir.c_str());
    return 0;
}

}  // namespace

Command add_simulate(CLI::App& app) {
    auto a = std::make_shared<SimulateArgs>();
    auto* s =
        app.add_subcommand("simulate", "simulate one part scan into a recording + ground truth");
    s->add_option("--out,-o", a->out, "recording folder to write")->required();
    s->add_option("--truth", a->truth, "ground-truth folder (default: OUT.truth)");
    s->add_option("--recipe", a->recipe, "part recipe")->capture_default_str();
    s->add_option("--cell", a->cell, "cell configuration")->capture_default_str();
    s->add_option("--seed", a->opt.seed, "random seed")->capture_default_str();
    s->add_option("--temperature", a->opt.temperature_c, "part temperature, °C")
        ->capture_default_str();
    s->add_option("--part-id", a->opt.part_id, "part id")->capture_default_str();
    s->add_option("--captured-at", a->opt.captured_at, "ISO 8601 UTC time (default: now)");
    s->add_option("--t0-ns", a->opt.t0_ns, "clock of the first sample, ns (default: now)");
    s->add_option("--faces", a->opt.faces, "faces to scan (default: all of the cell)");
    s->add_option("--dimension-sigma", a->opt.dimension_sigma_mm,
                  "as-forged deviation of each dimension from nominal, mm")
        ->capture_default_str();
    s->add_option("--yaw", a->yaw_deg, "part yaw on the support, degrees (default: random)");
    s->add_option("--offset", a->offset_mm, "part x y offset on the support, mm")->expected(2);
    s->add_option("--max-tilt", a->max_tilt_deg, "random tilt up to this, degrees");
    s->add_option("--noise", a->noise_mm, "range noise σ, mm");
    s->add_option("--spikes", a->spike_fraction, "spike outlier fraction");
    s->add_option("--dropouts", a->dropout_fraction, "random dropout fraction");
    s->add_option("--vibration-scale", a->vibration_scale, "scale of the press modes")
        ->capture_default_str();
    s->add_flag("--no-vibration", a->no_vibration, "no press vibration");
    s->add_flag("--quick", a->quick, "coarse sensor for tests (W/4, 1 mm profiles)");
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
