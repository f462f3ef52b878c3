// The daemon's acquisition thread (daemon_state.hpp): a job's faces scanned in turn (axis,
// camera), the part's temperature, and the accelerometer's record of them.
#include <spdlog/spdlog.h>

#include <algorithm>

#include "daemon_state.hpp"
#include "hotgauge/core/clock.hpp"

namespace hotgauge::cell {
namespace {

// Recorded past the margins the compensation needs, so that the sample grid's phase never leaves
// a face a fraction of a period short: four periods of a 400 Hz accelerometer.
constexpr double kMarginSlackS = 0.01;
constexpr milliseconds kMaxCameraWait{5'000};

}  // namespace

void Daemon::Impl::prepare_acquisition(const std::shared_ptr<const Setup>& s) {
    if (acq_setup == s) return;
    // A new configuration (start, reload): the camera is opened again with its settings, so
    // that nothing of the old one stays applied.
    acq_setup = s;
    const auto& a = s->config.acquisition;
    session =
        std::make_unique<acquire::CameraSession>(a.camera, a.scan, *s->triangulation, s->exposure);
    axis = s->config.axis.kind == "modbus" ? std::make_unique<ModbusAxis>(s->config.axis) : nullptr;
}

void Daemon::Impl::await_accel_history(double margin_s) const {
    // The record before a scan must be whole too, and the stream may have just started or come
    // back after an outage (a restarted sensor head: its first samples are only milliseconds
    // old). A stream that is silent is not waited for: the part is measured without it
    // (degraded).
    constexpr std::int64_t kInFlightNs = 30'000'000;  // the newest samples may be on their way
    constexpr std::int64_t kSilentNs = 130'000'000;   // no sample for this long: silent
    const auto margin_ns = static_cast<std::int64_t>(margin_s * 1e9);
    const auto deadline = Clock::now() + std::chrono::duration<double>(margin_s + 0.5);
    while (Clock::now() < deadline) {
        if (accel::history_before(*ring, core::realtime_ns(), margin_ns, kInFlightNs, kSilentNs) !=
            accel::HistoryState::arriving)
            return;
        std::this_thread::sleep_for(milliseconds(20));
    }
}

// Between parts: the camera and the axis asked whether they are there, every half second, so
// that one lost while idle shows in the health register long before the next trigger.
void Daemon::Impl::probe_devices() {
    constexpr milliseconds kProbePeriod{500};
    if (Clock::now() - last_probe < kProbePeriod) return;
    last_probe = Clock::now();
    ask(Device::kCamera, [this] { return session->check(); });
    if (axis) ask(Device::kAxis, [this] { return axis->check(); });
}

// One question to device d; while it is pending the watch can tell that it takes too long.
void Daemon::Impl::ask(Device d, const std::function<core::Result<void>()>& question) {
    devices.probe_started(d, core::realtime_ns());
    const auto answer = question();
    devices.answered(d, static_cast<bool>(answer), answer ? "answering" : answer.error().message);
}

void Daemon::Impl::acquisition_loop() {
    while (!workers_stop) {
        acq_beat = steady_ns();
        auto job = jobs.pop(kLoopPeriod);
        if (!job) {
            probe_devices();
            continue;
        }
        Captured c = acquire_part(std::move(*job));
        acq_beat = steady_ns();
        if (!captured.try_push(std::move(c)))  // cannot happen: one part at a time
            spdlog::error("processing queue full: a part is lost (bug)");
    }
}

Captured Daemon::Impl::acquire_part(Job next) {
    Captured c;
    c.job = std::move(next);
    const Job& job = c.job;
    const Setup& s = *job.setup;
    prepare_acquisition(job.setup);
    c.rec.part_id = std::to_string(job.trigger.part_id);
    c.rec.recipe = job.recipe->name;
    c.rec.captured_at = core::iso8601_utc(core::realtime_ns());
    // The exposure is set from the temperature at the start; the thermal correction uses the
    // reading taken after the scans, when the pyrometer has surely seen this part and not the
    // one before.
    std::optional<double> exposure_temperature;
    if (pyrometer) {
        if (const plc::PyrometerReading t = pyrometer->latest(); t.valid())
            exposure_temperature = t.temperature_c;
    }
    const double margin_s = s.config.accel_margin_s + kMarginSlackS;
    // A camera lost recently is retried after a backoff: a short one is worth waiting for, as
    // the part is here now; a long one fails the part at once with the reason.
    if (const auto wait = session->backoff_remaining(); wait <= kMaxCameraWait)
        std::this_thread::sleep_for(wait);
    std::optional<Failure> failed;
    for (const auto& name : job.faces) {
        if ((failed = cancelled(job))) break;
        failed = scan_face(s, name, margin_s, exposure_temperature, c);
        if (failed) break;
    }
    if (!failed && c.rec.faces.empty())
        failed = Failure{plc::ErrorCode::kMeasurementFailed,
                         c.degraded.empty() ? "no face to scan" : "no face left: " + c.degraded[0]};
    if (failed) {
        c.fault = code(failed->code);
        c.failure = failed->why;
        c.rec.faces.clear();
        return c;
    }
    c.last_profile_ns = c.rec.faces.back().profile_times_ns.back();
    c.scanned = Clock::now();
    c.margin_s = margin_s;
    read_part_temperature(c);
    // The part has been seen by the camera and the pyrometer: it may move on while the
    // pipeline runs (input 112).
    server->scans_done(job.trigger.trigger_id);
    {
        std::lock_guard lock(stats_mutex);
        scan_times.add(Clock::now() - job.triggered);
    }
    last_probe = Clock::now();  // the scans were as good as a probe
    if (accel) attach_accelerometer(c, margin_s);
    return c;
}

// The axis to the face's start; its jolt kept out of the accelerometer's record of the face
// before and of this one.
std::optional<Failure> Daemon::Impl::move_to_face(const Setup& s, const std::string& name,
                                                  double margin_s, const core::Recording& rec) {
    if (!axis) return std::nullopt;
    const auto pos = s.config.axis.faces.find(name);
    if (pos == s.config.axis.faces.end())
        return Failure{plc::ErrorCode::kMeasurementFailed,
                       "axis: no position for face '" + name + "' in the config"};
    // The accelerometer's record of the last face runs a margin past its scan; the move's
    // jolt must stay out of it, and out of the next face's record before it.
    if (accel && !rec.faces.empty()) {
        const std::int64_t t_free =
            rec.faces.back().profile_times_ns.back() + static_cast<std::int64_t>(margin_s * 1e9);
        if (t_free > core::realtime_ns())
            std::this_thread::sleep_for(std::chrono::nanoseconds(t_free - core::realtime_ns()));
    }
    auto moved = axis->move_to(pos->second);
    devices.answered(Device::kAxis, static_cast<bool>(moved),
                     moved ? "moved to face " + name : moved.error().message);
    // An axis that answers but does not arrive in time is a timeout (204); one that is gone
    // or faulted is a lost device (203).
    if (!moved)
        return Failure{axis->timed_out() ? plc::ErrorCode::kTimeout : plc::ErrorCode::kDeviceLost,
                       moved.error().message};
    if (accel && *moved) std::this_thread::sleep_for(std::chrono::duration<double>(margin_s));
    return std::nullopt;
}

// One face into c.rec. A scan that lost its first frames is shifted along the scan (positions
// count from the first frame): it is scanned once more; lost again, the face is left out with
// the reason, so its features are not measured rather than measured shifted.
std::optional<Failure> Daemon::Impl::scan_face(const Setup& s, const std::string& name,
                                               double margin_s,
                                               std::optional<double> exposure_temperature,
                                               Captured& c) {
    auto sc = calib::scan_config(s.calibration, name, s.config.acquisition.scan);
    if (!sc) return Failure{plc::ErrorCode::kMeasurementFailed, sc.error().message};
    session->set_scan_config(std::move(*sc));
    std::string start_lost;
    for (int attempt = 1; attempt <= 2; ++attempt) {
        if (attempt == 2) {
            if (auto no = cancelled(c.job)) return no;
            // The scan before, and its stop, kept out of this one's accelerometer record and
            // out of its first frame.
            std::this_thread::sleep_for(std::chrono::duration<double>(margin_s));
        }
        if (auto failed = move_to_face(s, name, margin_s, c.rec)) return failed;
        acq_beat = steady_ns();
        // The camera first: reopening one that restarted takes about half a second, and the
        // accelerometer's record is to be judged right before the acquisition starts (a sensor
        // head restarted with the camera resumes its stream meanwhile; judged before the reopen,
        // it was still silent and the scan began 69 ms after the stream came back: degraded).
        const int reopens = session->reopens();
        if (auto ok = session->connect(); !ok) {
            devices.answered(Device::kCamera, false, ok.error().message);
            return Failure{plc::ErrorCode::kDeviceLost, "face " + name + ": " + ok.error().message};
        }
        if (session->reopens() != reopens)
            spdlog::info("camera '{}': reopened (last failure: {})", s.config.acquisition.camera.id,
                         session->last_failure());
        if (accel) await_accel_history(margin_s);
        auto out = session->scan(s.config.acquisition.scan_s, exposure_temperature);
        acq_beat = steady_ns();
        devices.answered(Device::kCamera, static_cast<bool>(out),
                         out ? "scanned face " + name : out.error().message);
        if (!out)
            return Failure{plc::ErrorCode::kDeviceLost,
                           "face " + name + ": " + out.error().message};
        plant->scanned(*out);
        if (out->start_lost.empty()) {
            c.rec.faces.push_back(std::move(out->face));
            return std::nullopt;
        }
        start_lost = out->start_lost;
        spdlog::warn("part {} face {}: the scan lost its start ({}); {}", c.rec.part_id, name,
                     start_lost, attempt == 1 ? "scanning it again" : "face left out");
    }
    c.degraded.push_back("face " + name + " not measured: its scan lost its start twice (" +
                         start_lost + ")");
    c.left_out.push_back(name);
    return std::nullopt;
}

// A reading that is not valid right after the scans gets until the accelerometer's margin past
// the last profile, which processing waits for anyway: a sensor that missed its polls for about a
// second just then (the soak saw one, 1.0 s) does not cost the part its temperature.
void Daemon::Impl::read_part_temperature(Captured& c) const {
    if (!pyrometer) return;
    // Not waited for: without an accelerometer nothing waits anyway, and a cold master reads
    // nothing valid (its certificate's temperature is used).
    const bool wait = accel && !c.job.setup->masters.contains(c.job.trigger.recipe_slot);
    const std::int64_t until_ns = c.last_profile_ns + static_cast<std::int64_t>(c.margin_s * 1e9);
    const auto within = std::chrono::nanoseconds(wait ? until_ns - core::realtime_ns() : 0);
    const plc::PyrometerReading t =
        pyrometer->wait_valid(std::chrono::duration_cast<std::chrono::milliseconds>(
            std::max(within, std::chrono::nanoseconds(0))));
    if (t.valid()) {
        c.rec.temperature_c = t.temperature_c;
        return;
    }
    c.degraded.push_back(
        "part temperature unknown: pyrometer " +
        (t.last_error.empty() ? std::string(t.stale ? "stale" : "out of range") : t.last_error));
}

// Every face's window: complete for every face but the last, whose margin runs on while
// processing starts (complete_last_face).
void Daemon::Impl::attach_accelerometer(Captured& c, double margin_s) const {
    for (auto& f : c.rec.faces)
        accel::attach_face_window(*ring, f, static_cast<std::int64_t>(margin_s * 1e9));
}

// The last face's record once it reaches `until_ns` (a bounded wait), copied again: up to its
// last profile for the pose, as the offline tool has it; then up to the margin past it, which
// the compensation of its last profiles needs (docs/compensation.md).
void Daemon::Impl::refresh_last_face(Captured& c, std::int64_t until_ns, double timeout_s) const {
    ring->wait_for(until_ns, milliseconds(static_cast<long long>(1000 * timeout_s)));
    accel::attach_face_window(*ring, c.rec.faces.back(),
                              static_cast<std::int64_t>(c.margin_s * 1e9));
}

}  // namespace hotgauge::cell
