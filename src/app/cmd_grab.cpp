// hotgauge grab: one face from a live GigE Vision camera into a recording (format v1), with the
// daemon's acquisition code (docs/acquisition.md). Commissioning and tests use it.
#include <spdlog/spdlog.h>

#include <chrono>
#include <ctime>
#include <optional>
#include <thread>

#include "commands.hpp"
#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/session.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/recording_io.hpp"

namespace hotgauge::app {
namespace {

struct GrabArgs {
    acquire::CameraConfig camera;
    acquire::ScanConfig scan;
    std::vector<std::string> features;  // NAME=VALUE
    std::string face = "top";
    std::string calibration = HOTGAUGE_CONFIG_DIR "/calibration.yaml";
    std::string out;
    std::string recipe = "hub-a";
    std::string part_id = "GRAB-000001";
    std::optional<double> temperature_c;
    double seconds = 1.0;
    int fractional_bits = 6;
    int peak_row_offset = 0;
    std::string exposure_table;    // "T:E,..." °C:µs; applied when the temperature is known
    std::string accel;             // udp://HOST:PORT | iio:DEVICE_DIR[,BUFFER]; "" = none
    double accel_margin_s = 0.75;  // accelerometer record before and after the scan
};

// --exposure-table "T:E,T:E,...": °C and µs pairs.
core::Result<acquire::ExposureTable> parse_exposure_table(const std::string& text) {
    std::vector<std::pair<double, double>> points;
    std::size_t at = 0;
    while (at < text.size()) {
        const auto end = std::min(text.find(',', at), text.size());
        const std::string item = text.substr(at, end - at);
        double t = 0, e = 0;
        char tail = 0;
        if (std::sscanf(item.c_str(), "%lf:%lf%c", &t, &e, &tail) != 2)
            return core::make_error("'" + item + "': expected TEMPERATURE_C:EXPOSURE_US");
        points.emplace_back(t, e);
        at = end + 1;
    }
    return acquire::ExposureTable::create(std::move(points));
}

// --accel SOURCE → the accelerometer source config; the error names the option.
core::Result<accel::AccelSourceConfig> parse_accel(const std::string& text) {
    accel::AccelSourceConfig c;
    if (text.rfind("udp://", 0) == 0) {
        c.kind = accel::AccelSourceKind::udp;
        c.udp.bind = text.substr(6);
    } else if (text.rfind("iio:", 0) == 0) {
        c.kind = accel::AccelSourceKind::iio;
        const std::string rest = text.substr(4);
        const auto comma = rest.find(',');
        c.iio.device_dir = rest.substr(0, comma);
        c.iio.buffer_path = comma == std::string::npos
                                ? "/dev/" + c.iio.device_dir.filename().string()
                                : rest.substr(comma + 1);
    } else {
        return core::make_error("--accel '" + text +
                                "': expected udp://HOST:PORT or iio:DEVICE_DIR[,BUFFER]");
    }
    if (auto ok = accel::validate(c); !ok)
        return core::make_error("--accel '" + text + "': " + ok.error().message);
    return c;
}

// --feature NAME=VALUE, in order, onto the camera's GenICam features.
core::Result<void> add_features(const std::vector<std::string>& features,
                                acquire::CameraConfig& camera) {
    for (const auto& f : features) {
        const auto eq = f.find('=');
        if (eq == std::string::npos || eq == 0)
            return core::make_error("--feature '" + f + "': expected NAME=VALUE");
        camera.features.emplace_back(f.substr(0, eq), f.substr(eq + 1));
    }
    return {};
}

// The scan settings from the cell's calibration, as the daemon takes them (calib::scan_config:
// the face's geometry, its travel scale, the clock offset), checked; the triangulation from the
// same file's sensor model.
core::Result<acquire::Triangulation> prepare_scan(GrabArgs& a) {
    auto cal = calib::read_calibration(a.calibration);
    if (!cal) return cal.error();
    auto scan = calib::scan_config(*cal, a.face, a.scan);
    if (!scan) return core::make_error(a.calibration + ": " + scan.error().message);
    a.scan = std::move(*scan);
    a.scan.peaks.fractional_bits = a.fractional_bits;
    if (a.scan.frame_mode == "peaks") {
        if (auto ok = acquire::check_peak_format(a.scan.peaks); !ok) return ok.error();
    } else if (auto ok = acquire::check_stripe_config(a.scan.stripe); !ok) {
        return ok.error();
    }
    auto tri = calib::triangulation(cal->sensor);
    if (!tri) return core::make_error(a.calibration + ": " + tri.error().message);
    a.scan.offset_x_px = a.camera.offset_x;
    // Image rows are the region's; peak values count from the first row of the camera's window.
    a.scan.offset_y_px = a.scan.frame_mode == "peaks" ? a.peak_row_offset : a.camera.offset_y;
    return tri;
}

// The accelerometer source recording into `ring` on its own thread, started.
core::Result<std::unique_ptr<accel::AccelSource>> start_accel_source(
    const accel::AccelSourceConfig& config, accel::AccelRing& ring) {
    auto src = accel::make_accel_source(config, ring);
    if (!src) return src.error();
    std::unique_ptr<accel::AccelSource> source = std::move(*src);
    if (auto ok = source->start(); !ok) return ok.error();
    return source;
}

// Positions count from the first frame. A camera's own start latency is measured here at
// commissioning (camera.start_latency_ms); a scan that lost its start is written, flagged.
void log_scan_start(const acquire::ScanOutcome& outcome, const GrabArgs& a) {
    spdlog::info("first frame {:.1f} ms after AcquisitionStart",
                 static_cast<double>(outcome.start.lag_ns) * 1e-6);
    if (!outcome.start_lost.empty())
        spdlog::warn(
            "the scan may have lost its start ({}): its positions would then be shifted "
            "along the scan; grab again, or, if this camera always starts this late, "
            "raise camera.start_latency_ms",
            outcome.start_lost);
    if (outcome.exposure_us)
        spdlog::info("exposure {:.1f} µs for {:.0f} °C (table)", *outcome.exposure_us,
                     *a.temperature_c);
}

// Stops the accelerometer once its record covers the scan and its margins (waiting a bounded
// time for the last datagram), attaches the record to the face, and says how complete it is.
std::string attach_accel_record(const GrabArgs& a, accel::AccelRing& ring,
                                accel::AccelSource& source, core::FaceScan& scanned) {
    const auto margin_ns = static_cast<std::int64_t>(a.accel_margin_s * 1e9);
    // Samples after the margin's end arrive a datagram or so later: wait, bounded.
    ring.wait_for(
        scanned.profile_times_ns.back() + margin_ns,
        std::chrono::milliseconds(static_cast<long long>(1000 + 2000 * a.accel_margin_s)));
    source.stop();
    const accel::AccelWindow w = accel::attach_face_window(ring, scanned, margin_ns);
    const auto status = source.status();
    std::string summary = std::to_string(w.samples.size()) + " accelerometer samples (" +
                          std::to_string(w.gaps.size()) + " gaps, " +
                          std::to_string(w.missing_samples) + " missing" +
                          (w.covered() ? "" : ", margins NOT covered") + ")";
    if (!w.complete())
        spdlog::warn("accelerometer record incomplete around the scan: {} (source: {})", summary,
                     status.error.empty() ? "running" : status.error);
    return summary;
}

void print_grab_summary(const GrabArgs& a, const core::FaceScan& face, const acquire::ScanStats& st,
                        const acquire::StreamStats& cs, const std::string& accel_summary) {
    const auto& times = face.profile_times_ns;
    std::printf(
        "grabbed %s: %lld frames (%lld incomplete, %lld timeouts, %lld refused, %lld stale), "
        "%lld profiles "
        "over %.3f s; points: %lld ok, %lld no return, %lld dark, %lld saturated, %lld double "
        "peak; %s -> %s\n",
        a.face.c_str(), static_cast<long long>(st.frames), static_cast<long long>(cs.incomplete),
        static_cast<long long>(cs.timeouts), static_cast<long long>(st.refused_frames),
        static_cast<long long>(cs.stale), static_cast<long long>(st.profiles),
        static_cast<double>(times.back() - times.front()) * 1e-9, static_cast<long long>(st.ok),
        static_cast<long long>(st.no_return), static_cast<long long>(st.dark),
        static_cast<long long>(st.saturated), static_cast<long long>(st.double_peak),
        accel_summary.c_str(), a.out.c_str());
    std::printf(
        "stream: %llu completed, %llu failures, %llu underruns, %llu missing frames, %llu "
        "missing packets, %llu resend requests, %llu resent packets\n",
        static_cast<unsigned long long>(cs.completed), static_cast<unsigned long long>(cs.failures),
        static_cast<unsigned long long>(cs.underruns),
        static_cast<unsigned long long>(cs.missing_frames),
        static_cast<unsigned long long>(cs.missing_packets),
        static_cast<unsigned long long>(cs.resend_requests),
        static_cast<unsigned long long>(cs.resent_packets));
}

int run(GrabArgs a) {
    if (auto ok = add_features(a.features, a.camera); !ok) {
        spdlog::error("{}", ok.error().message);
        return 2;
    }
    auto tri = prepare_scan(a);
    if (!tri) {
        spdlog::error("{}", tri.error().message);
        return 1;
    }

    // The accelerometer records from before the first profile to after the last (the
    // compensation's margins), on its own thread into the ring.
    std::optional<accel::AccelSourceConfig> accel_config;
    if (!a.accel.empty()) {
        auto c = parse_accel(a.accel);
        if (!c) {
            spdlog::error("{}", c.error().message);
            return 2;
        }
        accel_config = *c;
    }
    accel::AccelRing ring(
        accel::AccelRingConfig{.capacity_s = a.seconds + 4 * a.accel_margin_s + 10.0,
                               .sample_rate_hz = 4000.0,
                               .gap_periods = 3.0});
    std::unique_ptr<accel::AccelSource> accel_source;
    if (accel_config) {
        auto src = start_accel_source(*accel_config, ring);
        if (!src) {
            spdlog::error("{}", src.error().message);
            return 1;
        }
        accel_source = std::move(*src);
    }

    auto table = parse_exposure_table(a.exposure_table);
    if (!table) {
        spdlog::error("--exposure-table: {}", table.error().message);
        return 2;
    }
    if (!table->empty() && !a.temperature_c)
        spdlog::warn("--exposure-table without --temperature: the exposure is left as configured");
    acquire::CameraSession session(a.camera, a.scan, *tri, *table);
    if (auto ok = session.connect(); !ok) {
        spdlog::error("{}", ok.error().message);
        return 1;
    }
    if (accel_source) std::this_thread::sleep_for(std::chrono::duration<double>(a.accel_margin_s));
    spdlog::info("grabbing {} s", a.seconds);
    auto outcome = session.scan(a.seconds, a.temperature_c);
    if (!outcome) {
        spdlog::error("{}", outcome.error().message);
        return 1;
    }
    log_scan_start(*outcome, a);
    core::Recording rec;
    rec.part_id = a.part_id;
    rec.recipe = a.recipe;
    rec.captured_at = core::iso8601_utc(core::realtime_ns());
    rec.temperature_c = a.temperature_c;
    rec.faces.push_back(std::move(outcome->face));
    const std::string accel_summary =
        accel_source ? attach_accel_record(a, ring, *accel_source, rec.faces[0])
                     : "no accelerometer (K = 0)";
    if (auto ok = io::write_recording(rec, a.out); !ok) {
        spdlog::error("{}", ok.error().message);
        return 1;
    }
    print_grab_summary(a, rec.faces[0], outcome->scan, outcome->stream, accel_summary);
    return 0;
}

}  // namespace

Command add_grab(CLI::App& app) {
    auto a = std::make_shared<GrabArgs>();
    auto* s = app.add_subcommand("grab", "record one face from a live camera (GigE Vision)");
    s->add_option("--camera", a->camera.id, "camera id, serial or IP (Aravis)")->required();
    s->add_option("--seconds", a->seconds, "scan duration")->capture_default_str();
    s->add_option("--out", a->out, "recording folder to write")->required();
    s->add_option("--face", a->face, "face name (geometry from the calibration)")
        ->capture_default_str();
    s->add_option("--calibration", a->calibration,
                  "the cell's calibration: face geometry, clock offset, sensor model")
        ->capture_default_str();
    s->add_option("--mode", a->scan.frame_mode, "frame mode")
        ->check(CLI::IsMember({"image", "peaks"}))
        ->capture_default_str();
    s->add_option("--width", a->camera.width, "region width (0: as is)");
    s->add_option("--height", a->camera.height, "region height (0: as is)");
    s->add_option("--offset-x", a->camera.offset_x, "region offset x, pixels");
    s->add_option("--offset-y", a->camera.offset_y, "region offset y, pixels");
    s->add_option("--pixel-format", a->camera.pixel_format, "Mono8, Mono16 (default: as is)");
    s->add_option("--frame-rate", a->camera.frame_rate_hz, "free-run frame rate, Hz");
    s->add_option("--exposure-us", a->camera.exposure_us, "exposure time, µs");
    s->add_option("--exposure-table", a->exposure_table,
                  "exposure from the part temperature: T_C:EXPOSURE_US,... (needs --temperature)");
    s->add_option("--feature", a->features, "GenICam feature NAME=VALUE (repeatable, in order)");
    s->add_option("--timeout-ms", a->camera.timeout_ms, "frame timeout")->capture_default_str();
    s->add_option("--speed-mm-s", a->scan.speed_mm_s, "scan axis speed")->capture_default_str();
    s->add_option("--max-value", a->scan.stripe.max_value, "image mode: full-scale pixel value")
        ->capture_default_str();
    s->add_option("--fractional-bits", a->fractional_bits, "peaks mode: fractional bits")
        ->capture_default_str();
    s->add_option("--profiles-per-frame", a->scan.peaks.profiles_per_frame,
                  "peaks mode: profiles per frame")
        ->capture_default_str();
    s->add_flag("--intensity", a->scan.peaks.intensity,
                "peaks mode: an intensity row (or part) follows each profile's peak row");
    s->add_option("--peak-row-offset", a->peak_row_offset,
                  "peaks mode: first sensor row of the camera's window")
        ->capture_default_str();
    s->add_option("--accel", a->accel,
                  "accelerometer: udp://HOST:PORT (bind) or iio:DEVICE_DIR[,BUFFER]; default none");
    s->add_option("--accel-margin-s", a->accel_margin_s,
                  "accelerometer record before and after the scan, s")
        ->capture_default_str();
    s->add_option("--part-id", a->part_id, "part id for part.yaml")->capture_default_str();
    s->add_option("--recipe", a->recipe, "recipe name for part.yaml")->capture_default_str();
    s->add_option("--temperature", a->temperature_c, "part temperature, °C (default: unknown)");
    return [a] { return run(*a); };
}

}  // namespace hotgauge::app
