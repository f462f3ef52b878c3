// hotgauge calibrate: the cell's geometry into calibration.yaml (docs/calibration.md).
//   nominal        the design values a cell config asserts, as method `nominal`: what a cell
//                  runs on before it is commissioned; the daemon says so at start.
//   faces          every face's pose, scan direction and travel scale from a scan of an
//                  artifact, and the accelerometer's mount and bias from gravity in it.
//   clock          the camera → accelerometer clock offset from the artifact (spheres and
//                  plate) scanned with the press running, after `faces`.
//   sensor         the head's camera and laser plane from checkerboard views (image mode).
//   hand-eye       a robot-moved head: the camera's pose on the flange from robot and target
//                  poses, by each method side by side (prints; the faces come from `faces`).
//   virtual-truth  a seeded true geometry for the virtual cell, off nominal as a real cell is.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <memory>

#include "commands.hpp"
#include "hotgauge/calib/align.hpp"
#include "hotgauge/calib/artifact.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/calib/clock.hpp"
#include "hotgauge/calib/hand_eye.hpp"
#include "hotgauge/calib/sensor.hpp"
#include "hotgauge/calib/sensor_stage.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/io/yaml_writer.hpp"
#include "hotgauge/report/commissioning.hpp"
#include "hotgauge/sim/geometry.hpp"
#include "hotgauge/sim/simulator.hpp"

namespace hotgauge::app {
namespace {

struct CalibrateArgs {
    std::string cell = HOTGAUGE_CONFIG_DIR "/cell.yaml";
    std::string out;
    std::string artifact, recording;
    std::string calibration = HOTGAUGE_CONFIG_DIR "/calibration.yaml";  // in force
    std::string report;  // calibrate faces --report DIR
    std::string stage;   // calibrate sensor --stage STAGE.yaml
    std::uint64_t seed = 1;
};

int fail(const core::Error& e) {
    spdlog::error("{}", e.message);
    return 1;
}

// DIR/commissioning.html, accepted or refused.
core::Result<void> write_commissioning_report(const calib::Commissioning& c,
                                              const CalibrateArgs& a) {
    std::error_code ec;
    std::filesystem::create_directories(a.report, ec);
    if (ec) return core::make_error(a.report + ": cannot create the folder: " + ec.message());
    const std::string file = a.report + "/commissioning.html";
    if (auto w = io::write_text(file, report::commissioning_html(c, a.recording, a.artifact)); !w)
        return w;
    spdlog::info("commissioning report {}", file);
    return {};
}

int run_faces(const CalibrateArgs& a) {
    auto artifact = calib::read_artifact(a.artifact);
    if (!artifact) return fail(artifact.error());
    auto base = calib::read_calibration(a.calibration);
    if (!base) return fail(base.error());
    auto rec = io::read_recording(a.recording);
    if (!rec) return fail(rec.error());
    calib::Commissioning result = calib::commission_faces(*artifact, *rec, *base);
    if (!a.report.empty())
        if (auto w = write_commissioning_report(result, a); !w) return fail(w.error());
    if (!result.calibration) {
        spdlog::error("calibration refused, {} stays in force: {}", a.calibration, result.refused);
        return 1;
    }
    calib::Calibration* c = &*result.calibration;
    c->source = a.artifact + " scanned in " + a.recording;
    if (auto w = calib::write_calibration(*c, a.out); !w) return fail(w.error());
    std::printf("%-8s %8s %7s %9s %-23s %-26s %10s %9s\n", "face", "rms mm", "spheres", "off by mm",
                "σ position x y z mm", "σ rotation x y z °", "travel", "σ ppm");
    for (const auto& f : c->faces) {
        auto r = [&](const std::string& key) { return c->residuals.at(f.name + "." + key); };
        std::printf("%-8s %8.4f %7g %9.3f %.4f %.4f %.4f   %.5f %.5f %.5f %10.6f %9.1f\n",
                    f.name.c_str(), r("rms_mm"), r("spheres"), r("start_error_mm"),
                    r("sigma_position_x_mm"), r("sigma_position_y_mm"), r("sigma_position_z_mm"),
                    r("sigma_rotation_x_deg"), r("sigma_rotation_y_deg"), r("sigma_rotation_z_deg"),
                    f.travel_scale, r("sigma_travel_ppm"));
    }
    if (c->residuals.at("accel.mount_measured") > 0.0)
        std::printf("accelerometer: gravity residual %.5f m/s², bias [%.4f, %.4f, %.4f] m/s²\n",
                    c->residuals.at("accel.gravity_rms_mps2"), c->accel_bias_mps2.x(),
                    c->accel_bias_mps2.y(), c->accel_bias_mps2.z());
    else
        std::printf(
            "accelerometer: mount NOT MEASURED, the recorded mounts are kept: the faces' "
            "gravity readings leave %.4f m/s² that one head with one bias cannot explain "
            "(limit %.4f; an accelerometer per face?)\n",
            c->residuals.at("accel.gravity_rms_mps2"),
            calib::AlignLimits{}.max_gravity_residual_mps2);
    std::printf("calibration %s\n", a.out.c_str());
    return 0;
}

int run_clock(const CalibrateArgs& a) {
    auto artifact = calib::read_artifact(a.artifact);
    if (!artifact) return fail(artifact.error());
    auto c = calib::read_calibration(a.calibration);
    if (!c) return fail(c.error());
    auto rec = io::read_recording(a.recording);
    if (!rec) return fail(rec.error());
    if (auto g = calib::apply_geometry(*c, a.calibration, *rec); !g) return fail(g.error());
    auto clock = calib::estimate_clock_offset(*rec, *artifact);
    if (!clock) {
        spdlog::error("clock offset not measured, {} unchanged: {}", a.calibration,
                      clock.error().message);
        return 1;
    }
    c->clock_offset_ns = clock->offset_ns;
    c->calibrated_at = core::iso8601_utc(core::realtime_ns());
    c->residuals["clock.u_us"] = clock->u_ns * 1e-3;
    c->residuals["clock.fit_rms_mm"] = clock->residual_mm;
    c->residuals["clock.motion_rms_mm"] = clock->motion_mm;
    c->source += "; clock from " + a.recording;
    if (auto w = calib::write_calibration(*c, a.out); !w) return fail(w.error());
    std::printf(
        "clock offset %.1f µs (u %.1f µs): fit %.4f mm RMS, head moved %.4f mm RMS, "
        "%d profiles\ncalibration %s\n",
        static_cast<double>(clock->offset_ns) * 1e-3, clock->u_ns * 1e-3, clock->residual_mm,
        clock->motion_mm, clock->profiles, a.out.c_str());
    return 0;
}

int run_hand_eye(const CalibrateArgs& a) {
    auto samples = calib::read_hand_eye_poses(a.recording);
    if (!samples) return fail(samples.error());
    auto solutions = calib::solve_hand_eye(*samples);
    if (!solutions) return fail(solutions.error());
    std::printf(
        "%zu poses; flange → camera (X) by each method, and the spread of the target's "
        "base pose through X:\n",
        samples->size());
    for (const auto& s : *solutions) {
        const Eigen::Vector3d t = s.T_flange_camera.translation();
        const Eigen::AngleAxisd r(s.T_flange_camera.linear());
        const Eigen::Vector3d rv = r.axis() * r.angle() * 180.0 / M_PI;
        std::printf(
            "%-13s t [%.4f, %.4f, %.4f] mm, rotation vector [%.5f, %.5f, %.5f]°; spread "
            "%.5f° / %.4f mm\n",
            s.method.c_str(), t.x(), t.y(), t.z(), rv.x(), rv.y(), rv.z(), s.rotation_rms_deg,
            s.translation_rms_mm);
    }
    return 0;
}

// calibrate sensor --stage: the pixel → mm map from a plate on a precision stage.
int run_sensor_stage(const CalibrateArgs& a, const calib::Calibration& base) {
    auto readings = calib::read_sensor_stage(a.stage);
    if (!readings) return fail(readings.error());
    auto fit = calib::calibrate_sensor_stage(*readings);
    if (!fit) {
        spdlog::error("sensor calibration refused, {} stays in force: {}", a.calibration,
                      fit.error().message);
        return 1;
    }
    calib::Calibration c = base;
    c.sensor = calib::SensorModel{};
    c.sensor.model = "stage";
    c.sensor.width = fit->model.width_px;
    c.sensor.map = fit->model;
    c.method = "sensor";
    c.source = a.stage;
    c.calibrated_at = core::iso8601_utc(core::realtime_ns());
    c.residuals = {{"sensor.stage_readings", static_cast<double>(fit->readings)},
                   {"sensor.stage_points", static_cast<double>(fit->samples)},
                   {"sensor.stage_z_rms_mm", fit->rms_z_mm},
                   {"sensor.stage_x_rms_mm", fit->rms_x_mm}};
    if (auto w = calib::write_calibration(c, a.out); !w) return fail(w.error());
    std::printf(
        "%d stage readings, %d stripe points: the map's residual z %.2f µm, x %.2f µm RMS\n"
        "%s: sensor calibrated; align the faces again (calibrate faces), the profiles' "
        "frame is the stage's\n",
        fit->readings, fit->samples, fit->rms_z_mm * 1e3, fit->rms_x_mm * 1e3, a.out.c_str());
    return 0;
}

// The head's camera and laser plane from checkerboard views into the calibration in force's
// sensor (method `sensor`: the faces are to be aligned again, in the new sensor's frame), or the
// stage's map (run_sensor_stage).
int run_sensor(const CalibrateArgs& a) {
    constexpr double kMaxReprojectionPx = 0.3;
    auto base = calib::read_calibration(a.calibration);
    if (!base) return fail(base.error());
    if (!a.stage.empty()) {
        if (!a.recording.empty())
            return fail(core::make_error("calibrate sensor: a views file or --stage, not both"));
        return run_sensor_stage(a, *base);
    }
    if (a.recording.empty())
        return fail(
            core::make_error("calibrate sensor: a views file (image mode) or --stage "
                             "STAGE.yaml (a plate on a stage)"));
    auto views = calib::read_sensor_views(a.recording);
    if (!views) return fail(views.error());
    auto cal = calib::calibrate_sensor(views->views, views->board);
    if (!cal) return fail(cal.error());
    if (cal->reprojection_rms_px > kMaxReprojectionPx)
        return fail(core::make_error("sensor calibration refused: reprojection RMS " +
                                     std::to_string(cal->reprojection_rms_px) + " px exceeds " +
                                     std::to_string(kMaxReprojectionPx) + " px; " + a.calibration +
                                     " stays in force"));
    auto fit = calib::fit_triangulation(*cal);
    if (!fit) return fail(fit.error());
    calib::Calibration c = *base;
    c.sensor.model = "pinhole";
    c.sensor.width = cal->camera.width;
    c.sensor.camera = cal->camera;
    c.sensor.plane = cal->plane;
    c.method = "sensor";
    c.source = a.recording;
    c.calibrated_at = core::iso8601_utc(core::realtime_ns());
    c.residuals = {{"sensor.reprojection_rms_px", cal->reprojection_rms_px},
                   {"sensor.plane_rms_mm", cal->plane_rms_mm},
                   {"sensor.views", static_cast<double>(cal->views)},
                   {"sensor.model_z_rms_mm", fit->rms_z_mm},
                   {"sensor.model_x_rms_mm", fit->rms_x_mm}};
    if (auto w = calib::write_calibration(c, a.out); !w) return fail(w.error());
    const calib::PinholeCamera& k = cal->camera;
    std::printf(
        "%d views: reprojection %.4f px; fx %.3f fy %.3f cx %.3f cy %.3f px, k1 %.5f k2 %.5f; "
        "laser plane RMS %.4f mm over %d points; calibrated model z %.2f µm, x %.2f µm RMS\n"
        "%s: sensor calibrated; align the faces again (calibrate faces), the profiles' frame "
        "is the new sensor's\n",
        cal->views, cal->reprojection_rms_px, k.fx, k.fy, k.cx, k.cy, k.distortion[0],
        k.distortion[1], cal->plane_rms_mm, cal->laser_points, fit->rms_z_mm * 1e3,
        fit->rms_x_mm * 1e3, a.out.c_str());
    return 0;
}

int run_virtual_truth(const CalibrateArgs& a) {
    auto cell = sim::read_cell_config(a.cell);
    if (!cell) return fail(cell.error());
    const auto nominal =
        sim::nominal_calibration(*cell, a.cell, core::iso8601_utc(core::realtime_ns()));
    const auto truth = sim::perturbed_calibration(nominal, a.seed);
    if (auto w = calib::write_calibration(truth, a.out); !w) return fail(w.error());
    std::printf("virtual cell's true geometry %s (%s)\n", a.out.c_str(), truth.source.c_str());
    return 0;
}

int run_nominal(const CalibrateArgs& a) {
    auto cell = sim::read_cell_config(a.cell);
    if (!cell) {
        spdlog::error("{}", cell.error().message);
        return 1;
    }
    const auto c = sim::nominal_calibration(*cell, a.cell, core::iso8601_utc(core::realtime_ns()));
    if (auto w = calib::write_calibration(c, a.out); !w) {
        spdlog::error("{}", w.error().message);
        return 1;
    }
    spdlog::info("{}: nominal geometry of {} ({} faces): design values, not measured", a.out,
                 a.cell, c.faces.size());
    return 0;
}

}  // namespace

Command add_calibrate(CLI::App& app) {
    auto a = std::make_shared<CalibrateArgs>();
    auto* s = app.add_subcommand("calibrate", "the cell's geometry (docs/calibration.md)");
    s->require_subcommand(1);
    auto* nominal =
        s->add_subcommand("nominal", "a cell config's design geometry as calibration.yaml");
    nominal->add_option("--cell", a->cell, "cell config")->capture_default_str();
    nominal->add_option("--out,-o", a->out, "calibration file to write")->required();
    auto* faces = s->add_subcommand(
        "faces", "face poses, travel and accelerometer from a scan of an artifact");
    faces->add_option("--artifact", a->artifact, "artifact file (spheres, planes)")->required();
    faces->add_option("recording", a->recording, "the artifact's recording")->required();
    faces
        ->add_option("--calibration", a->calibration,
                     "the calibration in force (sensor model, clock offset)")
        ->capture_default_str();
    faces->add_option("--out,-o", a->out, "calibration file to write")->required();
    faces->add_option("--report", a->report,
                      "write DIR/commissioning.html: per face the balls, σ, residual map, "
                      "before/after (also when refused)");
    auto* clock = s->add_subcommand(
        "clock", "the camera → accelerometer clock offset from the artifact under press vibration");
    clock->add_option("--artifact", a->artifact, "artifact file (its spheres and planes)")
        ->required();
    clock->add_option("recording", a->recording, "the artifact scanned with the press running")
        ->required();
    clock->add_option("--calibration", a->calibration, "the calibration from `calibrate faces`")
        ->required();
    clock->add_option("--out,-o", a->out, "calibration file to write")->required();
    auto* hand_eye = s->add_subcommand(
        "hand-eye", "the camera's pose on a robot flange from robot and target poses (AX = XB)");
    hand_eye->add_option("poses", a->recording, "poses file (hotgauge-hand-eye-poses-1)")
        ->required();
    auto* sensor = s->add_subcommand(
        "sensor",
        "the head's pixel → mm map: from a plate on a precision stage (--stage), or its camera and "
        "laser plane from checkerboard views (image mode)");
    sensor->add_option("views", a->recording, "views file (hotgauge-sensor-views-1)");
    sensor->add_option("--stage", a->stage,
                       "stage file (hotgauge-sensor-stage-1): laser images of a flat plate at "
                       "known heights and tilts");
    sensor->add_option("--calibration", a->calibration, "the calibration in force")
        ->capture_default_str();
    sensor->add_option("--out,-o", a->out, "calibration file to write")->required();
    auto* truth = s->add_subcommand(
        "virtual-truth", "a seeded true geometry for the virtual cell (issue 16 perturbations)");
    truth->add_option("--cell", a->cell, "cell config")->capture_default_str();
    truth->add_option("--seed", a->seed, "random seed")->capture_default_str();
    truth->add_option("--out,-o", a->out, "calibration file to write")->required();
    return [a, nominal, faces, clock, hand_eye, sensor] {
        if (nominal->parsed()) return run_nominal(*a);
        if (sensor->parsed()) return run_sensor(*a);
        if (faces->parsed()) return run_faces(*a);
        if (clock->parsed()) return run_clock(*a);
        if (hand_eye->parsed()) return run_hand_eye(*a);
        return run_virtual_truth(*a);
    };
}

}  // namespace hotgauge::app
