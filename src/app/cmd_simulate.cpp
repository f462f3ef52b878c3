// hotgauge simulate: one simulated part into a recording plus its ground truth.
#include <spdlog/spdlog.h>

#include <charconv>
#include <chrono>
#include <cmath>
#include <csignal>
#include <ctime>
#include <filesystem>
#include <map>
#include <random>

#include "commands.hpp"
#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/sim/geometry.hpp"
#include "hotgauge/sim/simulator.hpp"
#include "hotgauge/sim/target.hpp"
#include "hotgauge/vcell/virtual_cell.hpp"

namespace hotgauge::app {
namespace {

struct SimulateArgs {
    std::string recipe = HOTGAUGE_CONFIG_DIR "/parts/hub-a.yaml";
    std::string cell = HOTGAUGE_CONFIG_DIR "/cell.yaml";
    std::string out;
    std::string truth;
    std::string artifact;          // scan this artifact instead of a part
    std::string true_calibration;  // the cell's true geometry (default: the cell config's)
    std::string in_force;          // the calibration the recording is written with
    sim::SimOptions opt;
    bool quick = false;
    bool no_vibration = false;
    double vibration_scale = 1.0;
    std::optional<double> noise_mm, spike_fraction, dropout_fraction, max_tilt_deg;
    std::optional<double> yaw_deg;
    std::vector<double> offset_mm;
    std::vector<std::string> bad;       // "NAME=DELTA" (mm)
    std::vector<std::string> bad_part;  // serve: "N:NAME=DELTA", conveyor part N's bad feature
    // --serve: the virtual cell instead of a recording.
    bool serve = false;
    vcell::VirtualCellConfig vc;
    double line_rate_hz = 1000.0;
    double seconds = 0.0;
    bool multipart = false;
    std::string pyrometer_device;      // "" = no pyrometer
    int sensor_views = 0;              // > 0: the head's checkerboard views instead of a part
    bool sensor_stage = false;         // the head's stage readings instead of a part
    std::uint64_t master_seed = 1000;  // serve: the cold master's seed (--master-part)
    std::string replay;                // serve: replay this recording (docs/virtual-cell.md)
    std::string calibration;           // replay: the receiving daemon's calibration
    double scan_s = 1.3;               // replay: the daemon's camera.scan_s
};

// --bad "NAME=DELTA": a feature's name and the mm its true value moves (e.g. "Diameter 3=+0.7").
core::Result<std::map<std::string, double>> parse_bad(const std::vector<std::string>& bad) {
    std::map<std::string, double> out;
    for (const auto& b : bad) {
        const auto eq = b.rfind('=');
        std::size_t used = 0;
        double delta = 0.0;
        try {
            if (eq != std::string::npos) delta = std::stod(b.substr(eq + 1), &used);
        } catch (const std::exception&) {
            used = 0;
        }
        std::string name = eq == std::string::npos ? "" : b.substr(0, eq);
        while (!name.empty() && name.back() == ' ') name.pop_back();
        if (name.empty() || used == 0 || used != b.size() - eq - 1 || !std::isfinite(delta))
            return core::make_error("simulate --bad '" + b +
                                    "': expected NAME=DELTA in mm, e.g. \"Diameter 3=+0.7\"");
        out[name] = delta;
    }
    return out;
}

// --bad-part "N:NAME=DELTA": conveyor part N's bad features (e.g. "4:Diameter 3=+0.7").
core::Result<std::map<int, std::map<std::string, double>>> parse_bad_parts(
    const std::vector<std::string>& bad_part) {
    std::map<int, std::map<std::string, double>> out;
    for (const auto& b : bad_part) {
        const auto colon = b.find(':');
        int n = 0;
        const char* end = b.data() + (colon == std::string::npos ? 0 : colon);
        const auto [ptr, ec] = std::from_chars(b.data(), end, n);
        if (colon == std::string::npos || ec != std::errc() || ptr != end || n < 1)
            return core::make_error("simulate --bad-part '" + b +
                                    "': expected N:NAME=DELTA with part N >= 1, e.g. "
                                    "\"4:Diameter 3=+0.7\"");
        auto bad = parse_bad({b.substr(colon + 1)});
        if (!bad)
            return core::make_error("simulate --bad-part '" + b + "': " + bad.error().message);
        for (const auto& [name, delta] : *bad) out[n][name] += delta;
    }
    return out;
}

// --replay REC: the recording and the daemon's calibration, or the first problem (named file).
core::Result<vcell::ReplayConfig> load_replay(const SimulateArgs& a) {
    if (a.calibration.empty())
        return core::make_error(
            "simulate --replay: --calibration FILE is required (the daemon's calibration)");
    if (!(a.scan_s > 0.2))
        return core::make_error("simulate --replay: --scan-s must be > 0.2 s (the daemon's scan)");
    vcell::ReplayConfig r;
    r.dir = a.replay;
    r.scan_s = a.scan_s;
    auto rec = io::read_recording(a.replay);
    if (!rec) return core::make_error("simulate --replay: " + rec.error().message);
    r.recording = std::move(*rec);
    auto cal = calib::read_calibration(a.calibration);
    if (!cal) return core::make_error("simulate --replay: " + cal.error().message);
    r.calibration = std::move(*cal);
    return r;
}

// The cell's nominal calibration with the virtual head's true camera and laser plane as its
// sensor: what a sensor calibration is judged against (OUT/sensor-truth.yaml).
calib::Calibration head_truth(const SimulateArgs& a, const sim::CellConfig& cell,
                              const sim::VirtualSensorCamera& head) {
    calib::Calibration truth =
        sim::nominal_calibration(cell, a.cell, core::iso8601_utc(core::realtime_ns()));
    truth.method = "virtual-truth";
    truth.sensor.model = "pinhole";
    truth.sensor.width = head.camera.width;
    truth.sensor.camera = head.camera;
    truth.sensor.plane = head.plane;
    return truth;
}

// The virtual head's checkerboard views for `calibrate sensor` (docs/calibration.md "Sensor"):
// OUT/views.yaml with its images, and OUT/sensor-truth.yaml, the cell's nominal calibration
// with the head's true camera and laser plane as its sensor.
int write_sensor_views(const SimulateArgs& a, const sim::CellConfig& cell) {
    if (a.out.empty()) {
        spdlog::error("simulate --sensor-views: --out DIR is required");
        return 1;
    }
    const sim::VirtualSensorCamera head = sim::design_sensor_camera(cell.sensor);
    calib::SensorViews views;
    const sim::TargetRenderer render(head.camera);
    std::mt19937_64 rng(a.opt.seed);
    for (const auto& T : sim::target_poses(head, views.board, a.sensor_views, a.opt.seed))
        views.views.push_back(
            {render.board(views.board, T, rng), render.laser(views.board, T, head.plane, rng)});
    const calib::Calibration truth = head_truth(a, cell, head);
    const std::filesystem::path out(a.out);
    auto w = calib::write_sensor_views(views, out);
    if (w) w = calib::write_calibration(truth, out / "sensor-truth.yaml");
    if (!w) {
        spdlog::error("{}", w.error().message);
        return 1;
    }
    std::printf("%zu views %s\ntrue sensor %s\n", views.views.size(), (out / "views.yaml").c_str(),
                (out / "sensor-truth.yaml").c_str());
    return 0;
}

// The virtual head's stage readings for `calibrate sensor --stage` (docs/calibration.md "Sensor
// on a stage"): OUT/stage.yaml with its images, and OUT/sensor-truth.yaml as for the views.
int write_sensor_stage(const SimulateArgs& a, const sim::CellConfig& cell) {
    if (a.out.empty()) {
        spdlog::error("simulate --sensor-stage: --out DIR is required");
        return 1;
    }
    const sim::VirtualSensorCamera head = sim::design_sensor_camera(cell.sensor);
    const auto readings =
        sim::stage_readings(head, sim::default_stage_plan(cell.sensor), a.opt.seed);
    const calib::Calibration truth = head_truth(a, cell, head);
    const std::filesystem::path out(a.out);
    auto w = calib::write_sensor_stage(readings, out);
    if (w) w = calib::write_calibration(truth, out / "sensor-truth.yaml");
    if (!w) {
        spdlog::error("{}", w.error().message);
        return 1;
    }
    std::printf("%zu stage readings %s\ntrue sensor %s\n", readings.size(),
                (out / "stage.yaml").c_str(), (out / "sensor-truth.yaml").c_str());
    return 0;
}

// The virtual cell's config from the options: the conveyor's parts (opt, the bad ones, the cold
// master), the line rate, the pyrometer, multi-part frames.
void configure_virtual_cell(SimulateArgs& a, const core::Recipe& recipe,
                            const sim::CellConfig& cell, const sim::SimOptions& opt,
                            std::map<int, std::map<std::string, double>> bad_parts) {
    a.vc.recipe = recipe;
    a.vc.cell = cell;
    a.vc.part = opt;
    a.vc.bad_parts = std::move(bad_parts);
    a.vc.master = opt;  // a cold master: one physical part, below the pyrometer's span
    a.vc.master.seed = a.master_seed;
    a.vc.master.temperature_c = 20.0;
    // The master is a machined reference with the drawing's idealised shape (sharp, vertical, one
    // axis), so that every feature has a certified value (a forging's Height 1 may have no flat
    // part to measure); never bad. docs/virtual-cell.md "The master".
    a.vc.master.forged = false;
    a.vc.master.bad_mm.clear();
    a.vc.line_period_s = 1.0 / a.line_rate_hz;
    if (!a.pyrometer_device.empty()) {
        plc::SerialConfig serial;  // 9600 8N1, slave 1: the defaults
        serial.device = a.pyrometer_device;
        a.vc.pyrometer = serial;
    }
    if (a.multipart) {
        a.vc.peaks.intensity = true;
        a.vc.device.multipart_parts = a.vc.peaks.rows_per_profile();
    }
}

// Until SIGINT or SIGTERM (blocked in `signals`), or `seconds` if > 0.
void wait_for_stop(const sigset_t& signals, double seconds) {
    const auto t_end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (seconds <= 0 || std::chrono::steady_clock::now() < t_end) {
        timespec wait{0, 200'000'000};
        const int sig = sigtimedwait(&signals, nullptr, &wait);
        if (sig == SIGINT || sig == SIGTERM) break;
    }
}

// What the virtual cell sent, at its end.
void print_served(const SimulateArgs& a, const vcell::VirtualCell& vcell) {
    const auto st = vcell.stats();
    std::printf(
        "served %llu frames (%llu skipped, %llu packets, %llu dropped on purpose, %llu resend "
        "requests, %llu "
        "resent, %llu unavailable), %llu acquisitions, %llu accelerometer datagrams (%llu "
        "samples, %llu send errors)\n",
        static_cast<unsigned long long>(st.camera.frames),
        static_cast<unsigned long long>(st.camera.skipped),
        static_cast<unsigned long long>(st.camera.packets),
        static_cast<unsigned long long>(st.camera.dropped),
        static_cast<unsigned long long>(st.camera.resend_requests),
        static_cast<unsigned long long>(st.camera.resent),
        static_cast<unsigned long long>(st.camera.resend_unavailable),
        static_cast<unsigned long long>(st.acquisitions),
        static_cast<unsigned long long>(st.accel_datagrams),
        static_cast<unsigned long long>(st.accel_samples),
        static_cast<unsigned long long>(st.accel_send_errors));
    std::printf(
        "rendering: %llu frames sent later than a frame period after their time (up to "
        "%.1f ms), %llu rendered in vain (their acquisition stopped meanwhile)\n",
        static_cast<unsigned long long>(st.camera.late),
        static_cast<double>(st.camera.max_late_us) * 1e-3,
        static_cast<unsigned long long>(st.camera.stopped_while_rendered));
    if (a.vc.replay) {
        const vcell::EncodeStats e = vcell.replay_stats();
        std::printf(
            "replayed %s: %lld points as peaks exactly, %lld not (up to %.3g um off), "
            "%lld without a return\n",
            a.replay.c_str(), static_cast<long long>(e.exact), static_cast<long long>(e.inexact),
            e.max_error_mm * 1e3, static_cast<long long>(e.no_return));
    }
}

// Serves the virtual cell until SIGINT/SIGTERM (or --seconds), then prints what it sent.
int serve(SimulateArgs a, const core::Recipe& recipe, const sim::CellConfig& cell,
          const sim::SimOptions& opt, std::map<int, std::map<std::string, double>> bad_parts) {
    configure_virtual_cell(a, recipe, cell, opt, std::move(bad_parts));
    if (!a.replay.empty()) {
        auto replay = load_replay(a);
        if (!replay) {
            spdlog::error("{}", replay.error().message);
            return 1;
        }
        a.vc.replay = std::move(*replay);
    }
    // Signals are taken by sigtimedwait below: block them before any thread starts.
    sigset_t signals;
    sigemptyset(&signals);
    sigaddset(&signals, SIGINT);
    sigaddset(&signals, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &signals, nullptr);
    auto cellp = vcell::VirtualCell::start(a.vc);
    if (!cellp) {
        spdlog::error("{}", cellp.error().message);
        return 1;
    }
    auto& vcell = **cellp;
    if (!a.truth.empty()) {
        if (auto r = sim::write_truth(vcell.truth(), a.truth); !r) {
            spdlog::error("{}", r.error().message);
            return 1;
        }
    }
    std::printf("serving virtual camera %s at %s (%s mode, face %s), accelerometer %s, axis %s\n",
                a.vc.device.serial.c_str(), a.vc.device.address.c_str(), a.vc.mode.c_str(),
                a.vc.face.c_str(), a.vc.accel_to.empty() ? "off" : a.vc.accel_to.c_str(),
                vcell.axis_port() < 0
                    ? "off"
                    : (a.vc.axis_bind + ":" + std::to_string(vcell.axis_port())).c_str());
    std::fflush(stdout);
    wait_for_stop(signals, a.seconds);
    print_served(a, vcell);
    return 0;
}

// The cell config, moved to its true geometry when --true-calibration gives one.
core::Result<sim::CellConfig> read_true_cell(const SimulateArgs& a) {
    auto cell = sim::read_cell_config(a.cell);
    if (!cell) return cell.error();
    if (!a.true_calibration.empty()) {
        auto truth = calib::read_calibration(a.true_calibration);
        auto moved = truth ? sim::with_geometry(*cell, *truth, a.true_calibration)
                           : core::Result<sim::CellConfig>(truth.error());
        if (!moved) return moved.error();
        *cell = std::move(*moved);
    }
    return cell;
}

// The cell as simulated: --quick, and the vibration and sensor options.
sim::CellConfig simulated_cell(const SimulateArgs& a, const sim::CellConfig& cell) {
    sim::CellConfig c = a.quick ? sim::quick(cell) : cell;
    if (a.no_vibration) c.vibration.enabled = false;
    for (auto& m : c.vibration.modes) m.amplitude_mm *= a.vibration_scale;
    if (a.noise_mm) c.sensor.range_noise_mm = *a.noise_mm;
    if (a.spike_fraction) c.sensor.spike_fraction = *a.spike_fraction;
    if (a.dropout_fraction) c.sensor.dropout_fraction = *a.dropout_fraction;
    if (a.max_tilt_deg) c.placement.max_tilt_deg = *a.max_tilt_deg;
    return c;
}

// One part (or the artifact) into a recording at --out and its truth beside it.
int write_simulation(const SimulateArgs& a, const core::Recipe& recipe, const sim::CellConfig& c,
                     const sim::SimOptions& opt) {
    const auto t0 = std::chrono::steady_clock::now();
    core::Result<sim::SimResult> sim = core::make_error("");
    if (!a.artifact.empty()) {
        auto artifact = calib::read_artifact(a.artifact);
        if (!artifact) {
            spdlog::error("{}", artifact.error().message);
            return 1;
        }
        sim = sim::simulate_artifact(*artifact, c, opt);
    } else {
        sim = sim::simulate(recipe, c, opt);
    }
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

int run(const SimulateArgs& a) {
    auto recipe = io::read_recipe(a.recipe);
    if (!recipe) {
        spdlog::error("{}", recipe.error().message);
        return 1;
    }
    auto cell = read_true_cell(a);
    if (!cell) {
        spdlog::error("{}", cell.error().message);
        return 1;
    }
    if (a.sensor_views > 0) return write_sensor_views(a, *cell);
    if (a.sensor_stage) return write_sensor_stage(a, *cell);
    const sim::CellConfig c = simulated_cell(a, *cell);
    sim::SimOptions opt = a.opt;
    auto bad = parse_bad(a.bad);
    if (!bad) {
        spdlog::error("{}", bad.error().message);
        return 2;
    }
    opt.bad_mm = std::move(*bad);
    auto bad_parts = parse_bad_parts(a.bad_part);
    if (!bad_parts) {
        spdlog::error("{}", bad_parts.error().message);
        return 2;
    }
    if (!a.serve && !bad_parts->empty()) {
        spdlog::error("simulate: --bad-part is for the virtual cell's conveyor (--serve)");
        return 2;
    }
    if (!a.in_force.empty()) {
        auto in_force = calib::read_calibration(a.in_force);
        if (!in_force) {
            spdlog::error("{}", in_force.error().message);
            return 1;
        }
        opt.in_force = std::move(*in_force);
    }
    if (a.yaw_deg || !a.offset_mm.empty()) {
        Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
        T.rotate(
            Eigen::AngleAxisd(a.yaw_deg.value_or(0.0) * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
        if (a.offset_mm.size() == 2)
            T.translation() = Eigen::Vector3d(a.offset_mm[0], a.offset_mm[1], 0);
        opt.T_world_part = T;
    }

    if (a.serve && !a.artifact.empty()) {
        spdlog::error(
            "simulate: --artifact writes a recording; the virtual cell (--serve) "
            "serves parts");
        return 2;
    }
    if (a.serve) return serve(a, *recipe, c, opt, std::move(*bad_parts));
    if (a.out.empty()) {
        spdlog::error("simulate: --out is required (or --serve)");
        return 2;
    }
    return write_simulation(a, *recipe, c, opt);
}

}  // namespace

// A part's scan into a recording: the files, the part, the cell and its sensor (the virtual
// cell's conveyor parts take the same part options).
void add_part_options(CLI::App* s, SimulateArgs& a) {
    s->add_option("--out,-o", a.out, "recording folder to write");
    s->add_option("--truth", a.truth, "ground-truth folder (default: OUT.truth)");
    s->add_option("--recipe", a.recipe, "part recipe")->capture_default_str();
    s->add_option("--artifact", a.artifact,
                  "scan this calibration artifact (docs/calibration.md) instead of a part");
    s->add_option("--sensor-views", a.sensor_views,
                  "render N checkerboard views of the head for `calibrate sensor` into OUT");
    s->add_flag("--sensor-stage", a.sensor_stage,
                "render the head's readings of a plate on a precision stage for `calibrate "
                "sensor --stage` into OUT");
    s->add_option("--true-calibration", a.true_calibration,
                  "the cell's true geometry, a calibration.yaml (default: the cell config's)");
    s->add_option("--in-force", a.in_force,
                  "the calibration the cell's software records with (default: the truth)");
    s->add_option("--cell", a.cell, "cell configuration")->capture_default_str();
    s->add_option("--seed", a.opt.seed, "random seed")->capture_default_str();
    s->add_option("--temperature", a.opt.temperature_c, "part temperature, °C")
        ->capture_default_str();
    s->add_option("--part-id", a.opt.part_id, "part id")->capture_default_str();
    s->add_option("--captured-at", a.opt.captured_at, "ISO 8601 UTC time (default: now)");
    s->add_option("--t0-ns", a.opt.t0_ns, "clock of the first sample, ns (default: now)");
    s->add_option("--faces", a.opt.faces, "faces to scan (default: all of the cell)");
    s->add_option("--dimension-sigma", a.opt.dimension_sigma_mm,
                  "as-forged deviation of each dimension from nominal, mm")
        ->capture_default_str();
    s->add_flag("--forged", a.opt.forged,
                "the part as it leaves the press: draft, fillets and die shift drawn within the "
                "recipe's forging drawing (docs/simulator.md \"As-forged parts\")");
    s->add_option("--bad", a.bad,
                  "a bad feature: \"NAME=DELTA\" moves its true value by DELTA mm (a height: "
                  "its upper level); repeatable");
    s->add_option("--yaw", a.yaw_deg, "part yaw on the support, degrees (default: random)");
    s->add_option("--offset", a.offset_mm, "part x y offset on the support, mm")->expected(2);
    s->add_option("--max-tilt", a.max_tilt_deg, "random tilt up to this, degrees");
    s->add_option("--noise", a.noise_mm, "range noise σ, mm");
    s->add_option("--spikes", a.spike_fraction, "spike outlier fraction");
    s->add_option("--dropouts", a.dropout_fraction, "random dropout fraction");
    s->add_option("--vibration-scale", a.vibration_scale, "scale of the press modes")
        ->capture_default_str();
    s->add_flag("--no-vibration", a.no_vibration, "no press vibration");
    s->add_flag("--quick", a.quick, "coarse sensor for tests (W/4, 1 mm profiles)");
}

// The virtual cell (docs/virtual-cell.md).
void add_serve_options(CLI::App* s, SimulateArgs& a) {
    s->add_flag("--serve", a.serve,
                "serve the virtual cell: a GigE Vision camera and the accelerometer stream");
    s->add_option("--address", a.vc.device.address, "serve: camera address (127.x.y.z)")
        ->capture_default_str();
    s->add_option("--serial", a.vc.device.serial, "serve: camera serial number")
        ->capture_default_str();
    s->add_option("--face", a.vc.face, "serve: the face being scanned")->capture_default_str();
    s->add_option("--mode", a.vc.mode, "serve: frame mode")
        ->check(CLI::IsMember({"image", "peaks"}))
        ->capture_default_str();
    s->add_option("--accel-to", a.vc.accel_to, "serve: send accelerometer datagrams to HOST:PORT");
    s->add_option("--speed-mm-s", a.vc.speed_mm_s, "serve: scan axis speed")->capture_default_str();
    s->add_option("--line-rate", a.line_rate_hz, "serve: peaks mode profiles per second")
        ->capture_default_str();
    s->add_option("--fractional-bits", a.vc.peaks.fractional_bits,
                  "serve: peaks mode fractional bits")
        ->capture_default_str();
    s->add_option("--peak-row-offset", a.vc.peak_row_offset,
                  "serve: peaks mode first sensor row of the window")
        ->capture_default_str();
    s->add_option("--packet-loss", a.vc.device.packet_loss,
                  "serve: fraction of GVSP packets the link drops (resend recovers them)")
        ->capture_default_str();
    s->add_option("--lose-scan-start", a.vc.device.lose_scan_start,
                  "serve: fault: the first N frames of each acquisition are never sent")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    s->add_option("--lose-scan-start-count", a.vc.device.lose_scan_start_count,
                  "serve: ... only in the first K acquisitions (0: in every one)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    s->add_option("--axis-port", a.vc.axis_port,
                  "serve: the robot/axis controller's Modbus TCP port (0: any, -1: none)")
        ->capture_default_str();
    s->add_option("--truth-dir", a.vc.truth_dir,
                  "serve: write each loaded part's ground truth to DIR/part-NNNN");
    s->add_option("--master-part", a.vc.master_parts,
                  "serve: conveyor part N is the cold master (20 °C, --master-seed); repeatable");
    s->add_option("--bad-part", a.bad_part,
                  "serve: conveyor part N is bad: \"N:NAME=DELTA\" as --bad, for part N alone "
                  "(repeatable)");
    s->add_option("--master-seed", a.master_seed, "serve: the cold master's seed")
        ->capture_default_str();
    s->add_option("--pyrometer-device", a.pyrometer_device,
                  "serve: simulate the pyrometer (Modbus RTU, 9600 8N1, slave 1) on this serial "
                  "device, e.g. one end of a socat pty pair");
    s->add_flag("--intensity", a.vc.peaks.intensity, "serve: peaks mode sends an intensity row");
    s->add_flag("--multipart", a.multipart,
                "serve: peaks mode sends range and intensity as parts of one multi-part buffer");
    s->add_option("--replay", a.replay,
                  "serve: replay this recording (its faces as peak frames, its accelerometer "
                  "record and temperature) instead of simulating parts; needs --calibration");
    s->add_option("--calibration", a.calibration,
                  "replay: the calibration of the daemon that receives it");
    s->add_option("--scan-s", a.scan_s, "replay: the daemon's scan length (camera.scan_s)")
        ->capture_default_str();
    s->add_option("--seconds", a.seconds, "serve: stop after this long (0: at SIGINT/SIGTERM)")
        ->capture_default_str();
}

Command add_simulate(CLI::App& app) {
    auto a = std::make_shared<SimulateArgs>();
    auto* s =
        app.add_subcommand("simulate", "simulate one part scan into a recording + ground truth");
    add_part_options(s, *a);
    add_serve_options(s, *a);
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
