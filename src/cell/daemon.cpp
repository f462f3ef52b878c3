#include "hotgauge/cell/daemon.hpp"

#include <malloc.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <deque>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "device_watch.hpp"
#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/cell/axis.hpp"
#include "hotgauge/cell/journal.hpp"
#include "hotgauge/cell/quality_feed.hpp"
#include "hotgauge/cell/status_board.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/io/certificate.hpp"
#include "hotgauge/io/model_io.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/measure/features.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/pipeline/verify.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/server.hpp"
#include "hotgauge/results/archive.hpp"
#include "hotgauge/results/results_log.hpp"
#include "hotgauge/results/sequence.hpp"
#include "hotgauge/web/server.hpp"
#include "plant_feed.hpp"
#include "plc_result.hpp"
#include "queue.hpp"

namespace hotgauge::cell {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

constexpr milliseconds kLoopPeriod{100};  // control and worker loops: beat at least this often
// Recorded past the margins the compensation needs, so that the sample grid's phase never leaves
// a face a fraction of a period short: four periods of a 400 Hz accelerometer.
constexpr double kMarginSlackS = 0.01;
constexpr milliseconds kMaxCameraWait{5'000};

double ms_between(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

std::uint16_t code(plc::ErrorCode e) { return static_cast<std::uint16_t>(e); }

// The PLC's face register → the cell's face name (docs/plc-modbus.md).
const char* face_name(plc::Face f) {
    switch (f) {
        case plc::Face::kTop:
            return "top";
        case plc::Face::kBottom:
            return "bottom";
        case plc::Face::kSide1:
            return "side1";
        case plc::Face::kSide2:
            return "side2";
        case plc::Face::kAll:
            break;
    }
    return "";
}

// The faces to scan: all faces the recipe's features need, in the configured order; or the one
// face the PLC asked for.
std::vector<std::string> faces_to_scan(const Setup& s, const core::Recipe& recipe, plc::Face f) {
    if (f != plc::Face::kAll) return {face_name(f)};
    std::set<std::string> needed;
    for (const auto& feature : recipe.features)
        needed.insert(feature.faces.begin(), feature.faces.end());
    std::vector<std::string> out;
    for (const auto& name : s.config.faces)
        if (needed.count(name)) out.push_back(name);
    return out;
}

// Setup::result_hash: per slot, the files that decide its results and the software version.
std::map<int, std::string> result_hashes(const Setup& s) {
    std::map<int, std::string> out;
    for (const auto& [slot, recipe_file] : s.config.recipes) {
        std::vector<std::filesystem::path> files{s.config.file, s.config.calibration_file,
                                                 recipe_file};
        for (const auto* more : {&s.config.models, &s.config.masters})
            if (auto it = more->find(slot); it != more->end()) files.push_back(it->second);
        if (const auto& mesh = s.recipes.at(slot).mesh_file; !mesh.empty()) files.push_back(mesh);
        out[slot] = files_hash(files, HOTGAUGE_VERSION);
    }
    return out;
}

}  // namespace

core::Result<std::shared_ptr<const Setup>> load_setup(const fs::path& config_file) {
    auto config = read_daemon_config(config_file);
    if (!config) return config.error();
    auto s = std::make_shared<Setup>();
    s->config = std::move(*config);
    auto calibration = calib::read_calibration(s->config.calibration_file);
    if (!calibration) return calibration.error();
    s->calibration = std::move(*calibration);
    for (const auto& name : s->config.faces)
        if (!s->calibration.face(name))
            return core::make_error(s->config.file.string() + ": faces: '" + name +
                                    "' is not a face of " + s->config.calibration_file.string());
    for (const auto& [slot, path] : s->config.recipes) {
        auto recipe = io::read_recipe(path);
        if (!recipe) return recipe.error();
        if (auto ok = check_recipe_for_cell(*recipe, path, &s->config.faces); !ok)
            return core::make_error("recipe slot " + std::to_string(slot) + ": " +
                                    ok.error().message);
        const auto file = s->config.models.find(slot);
        auto model = pipeline::part_model(
            *recipe, {.model_file = file == s->config.models.end() ? fs::path() : file->second});
        if (!model)
            return core::make_error("recipe slot " + std::to_string(slot) + ": " +
                                    model.error().message);
        s->models.emplace(slot, std::make_shared<const match::Model>(std::move(*model)));
        s->recipes.emplace(slot, std::move(*recipe));
    }
    for (const auto& [slot, path] : s->config.masters) {
        auto cert = io::read_certificate(path);
        if (!cert) return cert.error();
        if (cert->recipe != s->recipes.at(slot).name)
            return core::make_error(path.string() + ": master of recipe '" + cert->recipe +
                                    "', recipe slot " + std::to_string(slot) + " is '" +
                                    s->recipes.at(slot).name + "'");
        const core::Recipe& recipe = s->recipes.at(slot);
        for (const auto& cf : cert->features)
            if (std::none_of(recipe.features.begin(), recipe.features.end(),
                             [&](const auto& f) { return f.name == cf.name; }))
                return core::make_error(path.string() + ": certified feature '" + cf.name +
                                        "' is not in recipe " + recipe.name + " (slot " +
                                        std::to_string(slot) + ")");
        s->masters.emplace(slot, std::move(*cert));
    }
    s->result_hash = result_hashes(*s);
    for (const auto& [slot, file] : s->config.recipes)
        s->recipe_revision[slot] = recipe_revision(file);
    auto tri = calib::triangulation(s->calibration.sensor);
    if (!tri)
        return core::make_error(s->config.calibration_file.string() + ": " + tri.error().message);
    s->triangulation.emplace(std::move(*tri));
    auto table = acquire::ExposureTable::create(s->config.acquisition.exposure_table);
    if (!table)
        return core::make_error(s->config.file.string() +
                                ": camera.exposure_table: " + table.error().message);
    s->exposure = std::move(*table);
    return std::shared_ptr<const Setup>(std::move(s));
}

std::string describe(const Setup& s) {
    std::ostringstream o;
    const auto& c = s.config;
    o << "config " << c.file.string() << " (hash " << c.hash << ")\n";
    const calib::Calibration& cal = s.calibration;
    o << "  calibration " << c.calibration_file.string() << ": " << cal.method << ", "
      << cal.calibrated_at << " from " << cal.source
      << (cal.measured() ? "" : " (design values, NOT MEASURED: commission the cell)") << "\n";
    o << "  faces";
    for (const auto& f : c.faces) o << " " << f;
    o << "\n";
    for (const auto& [slot, r] : s.recipes) {
        o << "  recipe slot " << slot << ": " << r.name << " (" << r.features.size()
          << " features), model " << s.models.at(slot)->refs.size() << " references";
        if (auto m = s.masters.find(slot); m != s.masters.end())
            o << "; master " << m->second.master << " (certified " << m->second.certified_at << ", "
              << m->second.features.size() << " features)";
        o << "\n";
    }
    o << "  camera " << c.acquisition.camera.id << " (" << c.acquisition.scan.frame_mode
      << " mode), " << c.acquisition.scan_s << " s per face\n";
    o << "  accelerometer "
      << (c.accelerometer ? (c.accelerometer->kind == accel::AccelSourceKind::udp
                                 ? "udp " + c.accelerometer->udp.bind
                                 : "iio " + c.accelerometer->iio.device_dir.string())
                          : std::string("none (no compensation)"))
      << "\n";
    o << "  axis " << c.axis.kind << (c.axis.kind == "modbus" ? " " + c.axis.address : "") << "\n";
    o << "  PLC Modbus TCP " << c.plc.bind_address << ":" << c.plc.port << "\n";
    o << "  pyrometer " << (c.pyrometer ? c.pyrometer->serial.device : "none") << "\n";
    o << "  results " << c.results.dir.string() << ", archive " << c.archive.dir.string() << "\n";
    return o.str();
}

// One trigger on its way through the cell.
struct Job {
    std::uint64_t sequence = 0;
    Clock::time_point triggered;
    plc::TriggerRequest trigger;
    std::shared_ptr<const Setup> setup;
    const core::Recipe* recipe = nullptr;
    std::vector<std::string> faces;
    std::optional<std::uint64_t> remeasure_of;  // the number its first measurement lost
};

// A part a crash or a FAULT 206 left unfinished (docs/results.md "One commit per part"): when the
// PLC triggers it again, a committed result is shown again, else it is measured under a new number
// that names the lost one.
struct Unfinished {
    std::uint64_t sequence = 0;
    std::uint32_t part_id = 0;
    std::uint16_t slot = 0;
    std::string committed_line;  // its results line, when it committed
};

// Why a part could not be scanned: the PLC's fault code and the reason.
struct Failure {
    plc::ErrorCode code;
    std::string why;
};

// What acquisition hands to processing: the recording, or why there is none.
struct Captured {
    Job job;
    core::Recording rec;
    std::uint16_t fault = 0;  // plc::ErrorCode when the part could not be scanned
    std::string failure;
    std::int64_t last_profile_ns = 0;
    Clock::time_point scanned;          // when the scans were done
    double margin_s = 0;                // the accelerometer record wanted past the last profile
    double accel_wait_ms = 0;           // from `scanned` until that record was there
    double after_margin_ms = 0;         // the pipeline's work after it (the last face's share)
    std::vector<std::string> degraded;  // found while scanning (temperature unknown, ...)
    std::vector<std::string> left_out;  // faces whose scans lost their start twice
};

// The last cycles' durations, for the PLC's expected times: their median.
class CycleTimes {
  public:
    void add(Clock::duration d) {
        if (seconds_.size() == kKept) seconds_.pop_front();
        seconds_.push_back(std::chrono::duration<double>(d).count());
    }
    std::optional<double> median() const {
        if (seconds_.empty()) return std::nullopt;
        std::vector<double> v(seconds_.begin(), seconds_.end());
        std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
        return v[v.size() / 2];
    }

  private:
    static constexpr std::size_t kKept = 15;
    std::deque<double> seconds_;
};

struct Daemon::Impl {
    std::shared_ptr<const Setup> setup;  // control thread; jobs carry their own
    Supervisor sup;
    std::unique_ptr<accel::AccelRing> ring;
    std::unique_ptr<accel::AccelSource> accel;
    std::unique_ptr<plc::Pyrometer> pyrometer;
    std::unique_ptr<plc::Server> server;
    std::unique_ptr<StatusBoard> board;  // what the status page shows; any thread
    std::unique_ptr<web::Server> web;    // the status page, when configured
    std::unique_ptr<PlantFeed> plant;    // MQTT and metrics; any thread

    detail::BoundedQueue<Job> jobs{1};
    detail::BoundedQueue<Captured> captured{2};
    std::thread acquisition_thread, processing_thread;
    std::atomic<bool> stop{false}, reload{false}, workers_stop{false};
    std::atomic<std::uint64_t> in_flight{0};              // jobs not yet finished
    std::atomic<std::uint64_t> abandoned{0};              // sequence the PLC reset; 0 = none
    std::atomic<std::int64_t> acq_beat{0}, proc_beat{0};  // steady ns of the last loop step
    bool shut_down = false;

    mutable std::mutex stats_mutex;
    DaemonStats stats;
    CycleTimes scan_times, cycle_times;  // trigger -> scans done / DONE; under stats_mutex
    std::string store_error;             // the last failed append, "" after a good one; ditto
    DeviceWatch devices;                 // the camera's and the axis's answers
    Clock::time_point last_probe{};      // acquisition thread

    // Acquisition thread only.
    std::shared_ptr<const Setup> acq_setup;
    std::unique_ptr<acquire::CameraSession> session;
    std::unique_ptr<ModbusAxis> axis;
    // Processing thread only.
    std::shared_ptr<const Setup> proc_setup;
    std::optional<results::ResultsLog> log;
    std::optional<results::RawArchive> archive;
    std::optional<QualityFeed> quality;  // drift watch, the day's lot report
    std::string log_error;               // why the results files could not be opened
    // Control thread only: the sequence numbers used, kept in the results folder
    // (docs/results.md "Sequence numbers"), or why they cannot be.
    std::optional<results::SequenceReservation> sequences;
    std::string sequences_error;
    void open_sequences(const fs::path& dir);
    core::Result<std::uint64_t> take_sequence(std::uint32_t part_id, std::uint16_t slot);
    void refuse(const plc::TriggerRequest& t, const std::string& recipe, const std::string& reason,
                plc::ErrorCode error);
    std::optional<Unfinished> unfinished;         // under stats_mutex
    std::atomic<std::uint64_t> committed_seq{0};  // the last sequence whose result committed
    std::uint64_t taken_failed = 0;               // control thread: taken() failed for it
    std::uint64_t open_cycle = 0;  // control thread: the number whose cycle this run opened
    void mark_taken(plc::State st);
    void find_unfinished(const fs::path& dir);
    bool show_again(const plc::TriggerRequest& t, const Unfinished& u);

    static std::int64_t steady_ns() {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
            .count();
    }
    // systemd's STATUS=: the state, and a rejected reload until a reload succeeds (the journal
    // has the whole message; `systemctl status` shows this line).
    std::string reload_note;  // under stats_mutex
    void publish_status() {
        std::string text;
        {
            std::lock_guard lock(stats_mutex);
            text = reload_note.empty() ? stats.state : stats.state + " — " + reload_note;
        }
        if (sup.status) sup.status(text);
    }
    void set_state(const std::string& s) {
        {
            std::lock_guard lock(stats_mutex);
            if (stats.state == s) return;
            stats.state = s;
        }
        board->set_state(s);
        plant->state(s);
        publish_status();
    }

    void control_loop();
    void update_health();
    void probe_devices();
    void ask(Device d, const std::function<core::Result<void>()>& question);
    void on_event(const plc::PlcEvent& ev);
    void apply_reload();
    bool healthy() const;
    void shutdown();
    void start_status_page();

    void acquisition_loop();
    Captured acquire_part(Job job);
    std::optional<Failure> scan_face(const Setup& s, const std::string& name, double margin_s,
                                     std::optional<double> exposure_temperature, Captured& c);
    // The cycle is not to go on: the PLC reset it, or the daemon is stopping.
    std::optional<Failure> cancelled(const Job& job) const {
        if (abandoned != job.sequence && !stop) return std::nullopt;
        return Failure{plc::ErrorCode::kMeasurementFailed,
                       stop ? "daemon stopping (SIGTERM)" : "cycle reset by the PLC"};
    }
    std::optional<Failure> move_to_face(const Setup& s, const std::string& name, double margin_s,
                                        const core::Recording& rec);
    void read_part_temperature(Captured& c) const;
    void attach_accelerometer(Captured& c, double margin_s) const;
    void refresh_last_face(Captured& c, std::int64_t until_ns, double timeout_s) const;
    void prepare_acquisition(const std::shared_ptr<const Setup>& s);
    void await_accel_history(double margin_s) const;
    void processing_loop();
    void process(Captured c);
    pipeline::PartResult measure_captured(Captured& c) const;
    // The registers: the result, or the fault; returns the outcome for the log.
    plc::PartResult shown_to_plc(const Captured& c, const results::ResultEntry& entry) const;
    std::string publish(const Captured& c, const results::ResultEntry& entry,
                        const core::Result<void>& stored, const plc::PartResult& shown,
                        bool& problem);
    void prepare_results(const std::shared_ptr<const Setup>& s);
    PartMetrics part_metrics(const Captured& c, const pipeline::PartResult& r, bool stored) const;
};

// ---- control -------------------------------------------------------------------------------

namespace {

// What PlantFeed was started with, to tell a reload that changes it (it needs a restart).
std::string plant_settings(const DaemonConfig& c) {
    std::string s = c.metrics.bind_address + ":" + std::to_string(c.metrics.port) +
                    (c.metrics.enabled ? "+" : "-");
    if (const auto& m = c.mqtt)
        s += "|" + m->host + ":" + std::to_string(m->port) + "/" + m->site + "/" + m->cell + "/" +
             m->client_id + "/" + m->username + "/" + m->password_file.string() + "/" +
             m->tls.ca_file.string() + "/" + m->tls.cert_file.string() + "/" +
             m->spool.dir.string() + "/" + std::to_string(m->spool.max_bytes) + "/" +
             std::to_string(m->keepalive_s);
    return s;
}

}  // namespace

void Daemon::Impl::control_loop() {
    set_state("idle: waiting for a trigger");
    while (!stop) {
        if (auto ev = server->wait_event(kLoopPeriod)) on_event(*ev);
        if (reload && in_flight == 0) apply_reload();
        if (healthy() && sup.watchdog) sup.watchdog();
        update_health();
        if (in_flight == 0) {
            const auto st = server->state();
            mark_taken(st);
            set_state(st == plc::State::kFault ? "fault: waiting for the PLC's reset"
                                               : "idle: waiting for a trigger");
        }
    }
}

// The devices' health into the PLC's registers and the stats, every control loop; a device that
// changes between working and not is logged once each way.
void Daemon::Impl::update_health() {
    constexpr std::int64_t kAccelSilentNs = 500'000'000;
    const Setup& s = *setup;
    const std::int64_t now = core::realtime_ns();
    DeviceHealth h;
    h.updated_ns = now;
    h[Device::kCamera] = devices.status(Device::kCamera, true, now);
    h[Device::kAxis] = devices.status(Device::kAxis, s.config.axis.kind == "modbus", now);
    h[Device::kAccelerometer] = ring ? accelerometer_status(*ring, now, kAccelSilentNs)
                                     : DeviceStatus{false, false, "not configured"};
    h[Device::kPyrometer] =
        pyrometer ? pyrometer_status(*pyrometer) : DeviceStatus{false, false, "not configured"};
    std::string last_store_error;
    {
        std::lock_guard lock(stats_mutex);
        last_store_error = store_error;
    }
    h[Device::kResultsDisk] =
        disk_status(s.config.results.dir, s.config.results_min_free_mb, last_store_error);
    h[Device::kPlantLink] = plant->link_status();
    plc::CellStatus cs = calibration_status(s.calibration.calibrated_at, s.calibration.measured(),
                                            s.config.calibration_interval_days, now);
    cs.device_faults = h.fault_bits();
    DeviceHealth before;
    {
        std::lock_guard lock(stats_mutex);
        cs.expected_scan_s = scan_times.median();
        cs.expected_cycle_s = cycle_times.median();
        before = std::exchange(stats.health, h);
    }
    server->set_cell_status(cs);
    board->set_health(h);
    plant->health(h);
    const bool first = before.updated_ns == 0;  // then only what is not working is news
    for (int d = 0; d < kDeviceCount; ++d) {
        const DeviceStatus &was = before.devices[d], &is = h.devices[d];
        if (!is.configured || (first ? is.ok : was.ok == is.ok)) continue;
        const std::string what = "device health: " + std::string(to_string(Device(d))) +
                                 (is.ok ? " working again: " : " NOT working: ") + is.detail;
        if (is.ok)
            spdlog::info("{}", what);
        else
            spdlog::warn("{}", what);
        board->event(what, !is.ok);  // the status page's recent events
    }
}

void Daemon::Impl::on_event(const plc::PlcEvent& ev) {
    if (ev.kind == plc::PlcEvent::Kind::kReset) {
        if (in_flight > 0) {
            std::lock_guard lock(stats_mutex);
            abandoned = stats.next_sequence - 1;
            spdlog::warn("PLC reset during part sequence {}: the cycle is abandoned",
                         abandoned.load());
        }
        return;
    }
    const plc::TriggerRequest& t = ev.trigger;
    const auto r = setup->recipes.find(t.recipe_slot);
    if (r == setup->recipes.end())
        return refuse(t, "slot " + std::to_string(t.recipe_slot),
                      "no recipe in slot " + std::to_string(t.recipe_slot),
                      plc::ErrorCode::kUnknownRecipe);
    std::optional<Unfinished> before;
    {
        std::lock_guard lock(stats_mutex);
        before.swap(unfinished);  // only the next trigger can be that part again
    }
    const bool same_part =
        before && t.part_id != 0 && before->part_id == t.part_id && before->slot == t.recipe_slot;
    if (same_part && !before->committed_line.empty() && show_again(t, *before)) return;
    const auto sequence = take_sequence(t.part_id, t.recipe_slot);
    if (!sequence) {  // a number not kept is not used; the part triggered again is still that one
        std::lock_guard lock(stats_mutex);
        if (!unfinished) unfinished = std::move(before);
    }
    if (!sequence)
        return refuse(t, r->second.name,
                      "no sequence number can be kept: " + sequence.error().message,
                      plc::ErrorCode::kNotStored);
    Job job;
    job.trigger = t;
    job.setup = setup;
    job.triggered = Clock::now();
    job.sequence = *sequence;
    open_cycle = job.sequence;
    if (same_part && before->committed_line.empty()) job.remeasure_of = before->sequence;
    {
        std::lock_guard lock(stats_mutex);
        ++stats.triggers;
    }
    job.recipe = &r->second;
    job.faces = faces_to_scan(*setup, r->second, t.face);
    ++in_flight;
    set_state("busy: part " + std::to_string(t.part_id) + " (seq " + std::to_string(job.sequence) +
              ")");
    if (!jobs.try_push(std::move(job))) {  // the handshake allows one cycle at a time
        --in_flight;
        spdlog::error("trigger while a part is queued: PLC fault 205");
        server->fault(code(plc::ErrorCode::kInternal));
    }
}

// A trigger refused before it becomes a part: no sequence number, no row; the PLC and the
// journal get the reason.
void Daemon::Impl::refuse(const plc::TriggerRequest& t, const std::string& recipe,
                          const std::string& reason, plc::ErrorCode error) {
    const std::string why = "part " + std::to_string(t.part_id) + ": " + reason + ": PLC fault " +
                            std::to_string(code(error));
    log_part({0, std::to_string(t.part_id), recipe, "FAULT", why, true});
    board->event(why, true);
    server->fault(code(error));
    plant->refused(code(error));
    std::lock_guard lock(stats_mutex);
    ++stats.triggers;
    ++stats.failed;
}

// The PLC took the committed result of the last part numbered (acknowledged DONE, or reset a
// FAULT or its cycle): its cycle is over, and a restart now has nothing to show again. A part
// whose result never committed stays in its cycle until measured again.
void Daemon::Impl::mark_taken(plc::State st) {
    if (st != plc::State::kIdle || !sequences || !sequences->last().unfinished()) return;
    const std::uint64_t n = sequences->reserved();
    // Only a cycle this run opened (or showed again): a number the last run left open stays so
    // until its part is triggered again.
    if (open_cycle != n || committed_seq != n || taken_failed == n) return;
    if (auto ok = sequences->taken(); !ok) {
        taken_failed = n;  // said once; the next part's number rewrites the line
        spdlog::warn("{}", ok.error().message);
    }
}

// The part the last run had numbered when it died (no clean stop after it), and whether its
// result committed (it is then the results files' last line).
void Daemon::Impl::find_unfinished(const fs::path& dir) {
    if (!sequences) return;
    const auto& last = sequences->last();
    if (!last.unfinished() || last.sequence == 0 || last.part_id == 0) return;  // 0: no id
    Unfinished u{last.sequence, last.part_id, last.slot, {}};
    const auto lines = results::last_result_lines(dir, 1);
    if (!lines.empty()) {
        const auto j = nlohmann::json::parse(lines.back(), nullptr, false);
        if (j.is_object() && j.value("sequence", std::uint64_t{0}) == last.sequence)
            u.committed_line = lines.back();
    }
    spdlog::warn(
        "the last run stopped during or after part {} (seq {}), whose result {}; if the "
        "PLC triggers it again, {}",
        u.part_id, u.sequence, u.committed_line.empty() ? "never committed" : "committed",
        u.committed_line.empty() ? "it is measured under a new number"
                                 : "that result is shown again");
    std::lock_guard lock(stats_mutex);
    unfinished = std::move(u);
}

// A part whose result committed before a crash, triggered again: the PLC is shown that result
// (its sequence, values and verdicts, as kept in the line), nothing is measured or written.
// False, and the part is measured, when that result was a fault (the PLC triggers again to have
// it measured) or the line does not say what the PLC was shown (written before this was kept).
bool Daemon::Impl::show_again(const plc::TriggerRequest& t, const Unfinished& u) {
    auto shown = plc_from_json(u.committed_line);
    if (!shown || shown->fault) {
        spdlog::warn("part {} seq {}: its committed result {}; measured again", t.part_id,
                     u.sequence,
                     shown ? "was FAULT " + std::to_string(shown->fault)
                           : "cannot be shown again (" + shown.error().message + ")");
        return false;
    }
    open_cycle = u.sequence;  // taken once the PLC acknowledges it
    std::string outcome;
    if (auto ok = server->finish(t.trigger_id, shown->result); !ok) {
        outcome = "not published: " + ok.error().message;
    } else {
        outcome = plc::to_string(shown->result.overall);
    }
    const auto j = nlohmann::json::parse(u.committed_line);
    const std::string recipe = j.at("part").value("recipe", std::string());
    log_part({u.sequence, std::to_string(t.part_id), recipe, plc::to_string(shown->result.overall),
              "part " + std::to_string(t.part_id) + " seq " + std::to_string(u.sequence) +
                  " triggered again after a restart: its result had committed before the "
                  "restart and is shown again, not measured again: " +
                  outcome,
              false});
    std::lock_guard lock(stats_mutex);
    ++stats.triggers;
    return true;
}

// The numbers used in `dir`: numbering goes on past them and past the files' last one.
void Daemon::Impl::open_sequences(const fs::path& dir) {
    auto r = results::SequenceReservation::open(dir);
    if (!r) {
        sequences.reset();
        sequences_error = r.error().message;
        spdlog::error("{}: parts fault 206 until it can be written", sequences_error);
        return;
    }
    const std::uint64_t there = std::max(results::last_sequence(dir), r->reserved());
    sequences.emplace(std::move(*r));
    sequences_error.clear();
    std::lock_guard lock(stats_mutex);
    stats.next_sequence = std::max(stats.next_sequence, there + 1);
}

// The next part's number, kept before it is used: a part whose result never reaches the files,
// or a crash during it, must not give it to the next part too. A number that could not be kept
// is not taken.
core::Result<std::uint64_t> Daemon::Impl::take_sequence(std::uint32_t part_id, std::uint16_t slot) {
    if (!sequences) open_sequences(setup->config.results.dir);  // the folder may be back
    if (!sequences) return core::make_error(sequences_error);
    std::uint64_t n = 0;
    {
        std::lock_guard lock(stats_mutex);
        n = stats.next_sequence;
    }
    if (auto kept = sequences->reserve(n, part_id, slot); !kept) return kept.error();
    std::lock_guard lock(stats_mutex);
    stats.next_sequence = n + 1;
    return n;
}

void Daemon::Impl::apply_reload() {
    reload = false;
    const fs::path file = setup->config.file;
    spdlog::info("reloading {}", file.string());
    auto next = load_setup(file);
    if (!next) {
        spdlog::error("reload REJECTED, the running configuration is kept: {}",
                      next.error().message);
        {
            std::lock_guard lock(stats_mutex);
            ++stats.rejected_reloads;
            reload_note = "reload rejected at " + core::iso8601_utc(core::realtime_ns()) + ": " +
                          next.error().message;
        }
        publish_status();
        return;
    }
    const auto& a = setup->config;
    const auto& b = (*next)->config;
    // These run for the whole life of the process; a change needs a restart.
    if (a.plc.port != b.plc.port || a.plc.bind_address != b.plc.bind_address)
        spdlog::warn("reload: the PLC server's address changes only at a restart");
    if (a.accelerometer.has_value() != b.accelerometer.has_value() ||
        (a.pyrometer.has_value() != b.pyrometer.has_value()))
        spdlog::warn("reload: accelerometer and pyrometer sources change only at a restart");
    if (a.status_page.enabled != b.status_page.enabled ||
        a.status_page.port != b.status_page.port ||
        a.status_page.bind_address != b.status_page.bind_address)
        spdlog::warn("reload: the status page's address changes only at a restart");
    if (plant_settings(a) != plant_settings(b))
        spdlog::warn("reload: the MQTT broker and the metrics endpoint change only at a restart");
    if (a.results.dir != b.results.dir) open_sequences(b.results.dir);  // numbering goes on
    setup = std::move(*next);
    spdlog::info("reloaded: config hash {}\n{}", setup->config.hash, describe(*setup));
    {
        std::lock_guard lock(stats_mutex);
        ++stats.reloads;
        reload_note.clear();
    }
    publish_status();
}

bool Daemon::Impl::healthy() const {
    // A worker that has not come round its loop for longer than its longest step (a face's scan
    // and an axis move, or the pipeline) is stuck: the watchdog then lets systemd restart us.
    const auto& c = setup->config;
    const double limit_s = c.acquisition.scan_s + c.axis.timeout_ms * 1e-3 +
                           c.acquisition.camera.timeout_ms * 1e-3 * 10 + 30.0;
    const auto limit_ns = static_cast<std::int64_t>(limit_s * 1e9);
    const std::int64_t now = steady_ns();
    return now - acq_beat < limit_ns && now - proc_beat < limit_ns;
}

void Daemon::Impl::shutdown() {
    if (shut_down) return;
    shut_down = true;
    if (sup.stopping) sup.stopping("stopping");
    // Workers finish (or fail, and report) the part in progress, then leave.
    const auto deadline = Clock::now() + std::chrono::seconds(60);
    while (in_flight > 0 && Clock::now() < deadline) {
        if (auto ev = server->wait_event(kLoopPeriod);
            ev && ev.value().kind == plc::PlcEvent::Kind::kTrigger)
            server->fault(code(plc::ErrorCode::kDeviceLost));  // no new part while stopping
    }
    workers_stop = true;
    if (acquisition_thread.joinable()) acquisition_thread.join();
    if (processing_thread.joinable()) processing_thread.join();
    if (accel) accel->stop();
    // A result the PLC has not taken yet (or a part to measure again) stays open for the next
    // start, clean stop or not.
    mark_taken(server->state());
    if (sequences && in_flight == 0 && sequences->last().state == 'D')
        if (auto ok = sequences->stopped(); !ok) spdlog::warn("{}", ok.error().message);
    web.reset();    // the page shows the state up to the last part
    plant.reset();  // the broker is told "offline"; what is spooled stays for the next start
}

// The page is a window on the cell, not part of measuring: if it cannot listen, the cell runs
// without it and says so (log and page of faults), rather than stopping the line.
void Daemon::Impl::start_status_page() {
    const HttpEndpointConfig& sp = setup->config.status_page;
    if (!sp.enabled) return;
    web::ServerConfig wc;
    wc.bind_address = sp.bind_address;
    wc.port = sp.port;
    wc.roots = board->roots();
    auto started = web::Server::start(wc, [this] {
        web::CellView v = board->view();
        v.plc_state = plc::to_string(server->state());
        return v;
    });
    if (!started) {
        spdlog::error("{}: the cell runs without it", started.error().message);
        board->event(started.error().message, true);
        return;
    }
    web = std::move(*started);
    spdlog::info("status page on {}", web->url());
}

// ---- acquisition ---------------------------------------------------------------------------

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
    const calib::FaceGeometry* face = s.calibration.face(name);
    if (!face)
        return Failure{plc::ErrorCode::kMeasurementFailed,
                       "no face '" + name + "' in the calibration"};
    acquire::ScanConfig sc = s.config.acquisition.scan;
    sc.face = name;
    sc.T_world_camera = face->T_world_camera;
    sc.scan_direction = face->scan_direction;
    sc.R_camera_accel = face->R_camera_accel;
    sc.speed_mm_s *= face->travel_scale;  // the true travel per commanded mm, as calibrated
    sc.clock_offset_ns = s.calibration.clock_offset_ns;
    session->set_scan_config(sc);
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
            out->face.travel_scale =
                face->travel_scale;  // applied above: a recalibration replaces it
            out->face.clock_offset_ns = sc.clock_offset_ns;
            out->face.geometry_from_calibration = true;
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

// ---- processing ----------------------------------------------------------------------------

void Daemon::Impl::prepare_results(const std::shared_ptr<const Setup>& s) {
    if (proc_setup && proc_setup->config.results.dir == s->config.results.dir &&
        proc_setup->config.archive.dir == s->config.archive.dir &&
        proc_setup->config.archive.quota_bytes == s->config.archive.quota_bytes &&
        proc_setup->config.archive.every_nth_ok == s->config.archive.every_nth_ok &&
        proc_setup->config.quality.drift_baseline == s->config.quality.drift_baseline &&
        proc_setup->config.quality.lot_report == s->config.quality.lot_report &&
        proc_setup->config.quality.lot_report_every_s == s->config.quality.lot_report_every_s &&
        log) {
        proc_setup = s;
        return;
    }
    proc_setup = s;
    log.reset();
    archive.reset();
    auto l = results::ResultsLog::open(s->config.results);
    if (!l) {
        log_error = l.error().message;
    } else {
        log.emplace(std::move(*l));
        log_error.clear();
    }
    if (auto a = results::RawArchive::open(s->config.archive); a) {
        archive.emplace(std::move(*a));
        archive->complete(
            results::last_result_lines(s->config.results.dir, results::ResultsLog::kRecoverLines));
    } else
        spdlog::error("raw archive: {}", a.error().message);
    quality.emplace(s->config.results.dir, s->config.quality);
    quality->load(core::realtime_ns());
}

namespace {

// glibc keeps what a part freed (its profiles, clouds and archive buffers: hundreds of MB) for
// reuse, so the idle RSS swung 60–260 MB from part to part in the soak, which would hide a
// leak. Given back after each part. (A sample taken right after DONE can still catch the
// archive of a degraded part being written: the 1 000-part soak's idle medians were 87–105 MB.)
void release_freed_memory() {
#if defined(__GLIBC__)
    malloc_trim(0);
#endif
}

}  // namespace

void Daemon::Impl::processing_loop() {
    while (!workers_stop || captured.size() > 0) {
        proc_beat = steady_ns();
        auto c = captured.pop(kLoopPeriod);
        if (!c) continue;
        process(std::move(*c));
        proc_beat = steady_ns();
        --in_flight;
        release_freed_memory();
    }
}

// The pipeline in its two steps (pipeline::PartRun): every face but the last while the last
// face's accelerometer margin runs, then the last face.
pipeline::PartResult Daemon::Impl::measure_captured(Captured& c) const {
    const Job& job = c.job;
    pipeline::PartResult r;
    if (c.fault) {
        r.part_id = c.rec.part_id;
        r.recipe = c.rec.recipe;
        r.captured_at = c.rec.captured_at;
        r.measurement = measure::unmeasured(*job.recipe, c.rec, c.failure);
        r.measurement.temperature_c = c.rec.temperature_c;
        r.warnings.push_back(c.failure);
        return r;
    }
    const PipelineSettings& ps = job.setup->config.pipeline;
    pipeline::PipelineOptions opt;
    opt.model = job.setup->models.at(job.trigger.recipe_slot).get();
    // No accelerometer configured (source: none): nothing to compensate with, as with
    // `hotgauge measure --no-compensation` (a warning, not every feature degraded).
    opt.compensate = accel != nullptr && ps.compensate;
    opt.compensation.highpass_hz = ps.highpass_hz;
    opt.match.threads = ps.threads;
    opt.measure.threads = ps.threads;
    if (accel) refresh_last_face(c, c.last_profile_ns + ring->period_ns(), 0.2);
    pipeline::PartRun run(c.rec, *job.recipe, opt);
    run.measure_all_but_last();
    if (accel) {
        refresh_last_face(c, c.last_profile_ns + static_cast<std::int64_t>(c.margin_s * 1e9),
                          0.5 + c.margin_s);
        c.accel_wait_ms = ms_between(c.scanned, Clock::now());
    }
    const auto t0 = Clock::now();
    r = run.finish();
    if (!c.left_out.empty()) {  // the pose was found without them: nothing sorts the part
        std::string faces;
        for (const auto& f : c.left_out) faces += (faces.empty() ? "" : ", ") + f;
        measure::degrade_measured(r.measurement, "the pose was found without face " + faces +
                                                     " (its scans lost their start)");
    }
    c.after_margin_ms = ms_between(t0, Clock::now());
    if (!accel) r.warnings.push_back("no accelerometer configured: vibration not compensated");
    if (accel && !ps.compensate)
        r.warnings.push_back("pipeline.compensation is false: vibration not compensated");
    for (const auto& why : c.degraded) {
        r.degraded = true;
        r.degraded_reasons.push_back(why);
    }
    if (c.accel_wait_ms > 0) r.stage_ms.emplace(r.stage_ms.begin(), "accel_wait", c.accel_wait_ms);
    return r;
}

// What the PLC is shown for a measured part: values, verdicts, reasons, the drift watch's state.
plc::PartResult Daemon::Impl::shown_to_plc(const Captured& c,
                                           const results::ResultEntry& entry) const {
    const Job& job = c.job;
    plc::PartResult shown = to_plc(*entry.result, entry.verification);
    set_drift(shown, entry.drift);
    shown.sequence = job.sequence;
    shown.time_ns = entry.time_ns;
    if (auto rev = job.setup->recipe_revision.find(job.trigger.recipe_slot);
        rev != job.setup->recipe_revision.end())
        shown.recipe_revision = rev->second;
    if (!c.left_out.empty()) shown.reasons |= plc::reason::kFaceMissing;
    if (!accel || !job.setup->config.pipeline.compensate)
        shown.reasons |= plc::reason::kNotCompensated;
    return shown;
}

std::string Daemon::Impl::publish(const Captured& c, const results::ResultEntry& entry,
                                  const core::Result<void>& stored, const plc::PartResult& shown,
                                  bool& problem) {
    const Job& job = c.job;
    const pipeline::PartResult& r = *entry.result;
    const pipeline::Verification* check = entry.verification;
    problem = true;
    if (abandoned == job.sequence) {
        // The PLC reset this cycle and has moved on: neither a result nor a fault of it may
        // reach the registers now.
        return (c.fault ? std::string("NOT_MEASURED (") + c.failure + ")"
                        : verdict_text(r, check)) +
               ", not published: the PLC reset the cycle";
    }
    if (!stored) {
        server->fault(code(plc::ErrorCode::kNotStored));
        return "FAULT 206 (result not stored: " + stored.error().message + ")";
    }
    if (c.fault) {
        server->fault(c.fault);
        return "FAULT " + std::to_string(c.fault) + " (" +
               plc::to_string(static_cast<plc::ErrorCode>(c.fault)) + "): " + c.failure;
    }
    if (auto ok = server->finish(job.trigger.trigger_id, shown); !ok)
        return verdict_text(r, check) + ", not published: " + ok.error().message;
    problem = r.measurement.verdict != measure::Verdict::kOk || r.degraded;
    {
        std::lock_guard lock(stats_mutex);
        cycle_times.add(Clock::now() - job.triggered);
    }
    return verdict_text(r, check);
}

PartMetrics Daemon::Impl::part_metrics(const Captured& c, const pipeline::PartResult& r,
                                       bool stored) const {
    PartMetrics m;
    if (stored) m.verdict = measure::to_string(r.measurement.verdict);
    m.fault = !stored ? code(plc::ErrorCode::kNotStored) : c.fault;
    if (c.scanned != Clock::time_point{})
        m.scan_s = std::chrono::duration<double>(c.scanned - c.job.triggered).count();
    m.cycle_s = std::chrono::duration<double>(Clock::now() - c.job.triggered).count();
    m.stage_ms = r.stage_ms;
    return m;
}

void Daemon::Impl::process(Captured c) {
    const Job& job = c.job;
    prepare_results(job.setup);
    const auto master = job.setup->masters.find(job.trigger.recipe_slot);
    const bool is_master = master != job.setup->masters.end();
    if (is_master && !c.rec.temperature_c) {  // a cold master: the pyrometer reads nothing
        c.rec.temperature_c = master->second.temperature_c;
        std::erase_if(c.degraded, [](const std::string& why) {
            return why.rfind("part temperature unknown", 0) == 0;
        });
    }
    pipeline::PartResult r = measure_captured(c);
    const auto t_measured = Clock::now();
    // A master's overall verdict is the verification's (docs/verification.md).
    std::optional<pipeline::Verification> verification;
    if (is_master && !c.fault) {
        if (auto v = pipeline::verify(r, master->second)) {
            verification = std::move(*v);
            r.measurement.verdict = verification->passed         ? measure::Verdict::kOk
                                    : verification->inconclusive ? measure::Verdict::kDegraded
                                                                 : measure::Verdict::kNok;
        } else {
            r.warnings.push_back("master check: " + v.error().message);
            r.measurement.verdict = measure::Verdict::kNotMeasured;
        }
    }
    // The pipeline's work after the margin: the last face's share and the master check (the
    // rest overlapped the margin).
    const auto t1 = Clock::now();
    const double pipeline_ms = c.after_margin_ms + ms_between(t_measured, t1);

    const std::int64_t t_result = core::realtime_ns();
    results::ResultEntry entry;
    entry.time_ns = t_result;
    entry.sequence = job.sequence;
    entry.result = &r;
    entry.verification = verification ? &*verification : nullptr;
    entry.software_version = HOTGAUGE_VERSION;
    entry.config_hash = job.setup->config.hash;
    entry.die_id = job.trigger.die_id;
    entry.remeasure_of = job.remeasure_of;
    if (auto h = job.setup->result_hash.find(job.trigger.recipe_slot);
        h != job.setup->result_hash.end())
        entry.result_hash = h->second;
    if (quality && !is_master && !c.fault) entry.drift = quality->observe(entry.die_id, r);
    // The raw recording is written after the registers (it is large, and the PLC is waiting);
    // the results line names the folder it goes to, and a failure to write it is logged.
    const plc::PartResult shown = shown_to_plc(c, entry);
    entry.plc = plc_json(shown, c.fault);  // kept in the commit, to be shown again after a crash
    const bool archiving = !c.fault && archive && archive->wants(r, job.sequence);
    if (archiving)
        entry.archived_as = archive->folder(c.rec.part_id, job.sequence, t_result).string();
    const core::Result<void> stored =
        log ? log->append(entry) : core::Result<void>(core::make_error(log_error));
    const double store_ms = ms_between(t1, Clock::now());
    {
        std::lock_guard lock(stats_mutex);
        store_error = stored ? "" : stored.error().message;
    }
    if (stored) committed_seq = job.sequence;
    if (!stored) {
        spdlog::error("seq {}: results NOT stored: {}; the result is only in this log: {}",
                      job.sequence, stored.error().message, pipeline::to_json(r));
        std::lock_guard lock(stats_mutex);  // triggered again, it is measured again, said so
        if (job.trigger.part_id != 0)
            unfinished = Unfinished{job.sequence, job.trigger.part_id, job.trigger.recipe_slot, {}};
    }

    // Registers last: a result the PLC can acknowledge is already on disk.
    bool problem = true;
    const std::string outcome = publish(c, entry, stored, shown, problem);
    const std::int64_t published = core::realtime_ns();
    if (stored) log->sync_csv();  // off the PLC's wait: the row derived from the commit
    if (archiving && stored) {    // the archive follows from the commit
        if (auto where = archive->store(c.rec, job.sequence, t_result); !where) {
            spdlog::error("seq {}: raw archive: {} (the results line names {})", job.sequence,
                          where.error().message, *entry.archived_as);
            archive->not_archived(log->last_line(), "writing it failed: " + where.error().message);
        }
    }
    {
        std::lock_guard lock(stats_mutex);
        stats.last = PartTiming{job.sequence,    c.last_profile_ns, published,
                                c.accel_wait_ms, pipeline_ms,       store_ms};
        ++(c.fault || !stored ? stats.failed : stats.measured);
    }
    std::ostringstream msg;
    msg << "part " << r.part_id << " seq " << job.sequence << " recipe " << r.recipe << ": "
        << outcome;
    if (is_master)
        msg << "; master " << master->second.master << " check "
            << (verification ? (verification->passed ? "passed" : "FAILED") : "not made");
    if (c.last_profile_ns)
        msg << "; " << (published - c.last_profile_ns) / 1'000'000
            << " ms after the last profile (accelerometer margin " << std::lround(c.accel_wait_ms)
            << " ms, then pipeline " << std::lround(pipeline_ms) << " ms, files "
            << std::lround(store_ms) << " ms)";
    for (const auto& why : r.degraded_reasons) msg << "; degraded: " << why;
    if (stored && log->csv_error().empty()) msg << "; " << log->last_csv().string();
    if (stored && !log->csv_error().empty())
        msg << "; " << log->last_jsonl().string() << " (its CSV row is owed: " << log->csv_error()
            << ")";
    log_part({job.sequence, r.part_id, r.recipe,
              verdict_field(c.fault != 0 || !stored,
                            to_plc(r, verification ? &*verification : nullptr).overall),
              msg.str(), problem});
    // Last: the stats and the log above are the part's outcome, the pages can wait.
    PartNews news{stored ? log->last_line() : results::jsonl_line(entry),
                  outcome,
                  msg.str(),
                  problem,
                  web ? &c.rec : nullptr,
                  {},
                  std::nullopt};
    if (stored) news.files = {log->last_csv(), log->last_jsonl()};
    if (archiving && stored) news.archived = fs::path(*entry.archived_as);
    if (quality && stored) quality->stored(news.jsonl_line, t_result);
    if (stored) plant->result(news.jsonl_line, job.sequence);  // the plant gets what committed
    plant->part(part_metrics(c, r, static_cast<bool>(stored)));
    board->part(news);
}

// ---- Daemon --------------------------------------------------------------------------------

Daemon::Daemon(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Daemon::~Daemon() {
    impl_->stop = true;
    impl_->shutdown();
}

core::Result<std::unique_ptr<Daemon>> Daemon::start(std::shared_ptr<const Setup> setup,
                                                    Supervisor supervisor) {
    auto impl = std::make_unique<Impl>();
    impl->setup = setup;
    impl->sup = std::move(supervisor);
    const DaemonConfig& c = setup->config;
    impl->board = std::make_unique<StatusBoard>(c.results.dir, c.archive.dir);
    // Numbering goes on after the highest number used (.sequence) or committed (the files); the
    // PLC's input 5 starts at the last committed one.
    const std::uint64_t committed = results::last_sequence(c.results.dir);
    impl->committed_seq = committed;
    impl->stats.next_sequence = committed + 1;
    impl->open_sequences(c.results.dir);
    impl->find_unfinished(c.results.dir);
    // What a crash left half done (a CSV row, an archive folder) is completed before the PLC is
    // served (docs/results.md "One commit per part"); the plant spool's share when it starts.
    impl->prepare_results(setup);
    if (!impl->log) spdlog::error("results: {}", impl->log_error);
    if (c.accelerometer) {
        // Room for a whole part: every face, the moves and the margins, twice over.
        const double part_s = static_cast<double>(c.faces.size()) *
                                  (c.acquisition.scan_s + c.axis.timeout_ms * 1e-3) +
                              4 * c.accel_margin_s;
        impl->ring = std::make_unique<accel::AccelRing>(
            accel::AccelRingConfig{.capacity_s = 2 * part_s + 10.0,
                                   .sample_rate_hz = c.accel_rate_hz,
                                   .gap_periods = 3.0});
        auto src = accel::make_accel_source(*c.accelerometer, *impl->ring);
        if (!src) return core::make_error("accelerometer: " + src.error().message);
        impl->accel = std::move(*src);
        if (auto ok = impl->accel->start(); !ok)
            return core::make_error("accelerometer: " + ok.error().message);
    }
    if (c.pyrometer) {
        auto p = plc::Pyrometer::start(*c.pyrometer);
        if (!p) return core::make_error("pyrometer: " + p.error().message);
        impl->pyrometer = std::move(*p);
    }
    plc::ServerConfig plc = c.plc;  // the PLC's count goes on from the results files
    plc.first_sequence = static_cast<std::uint16_t>(committed & 0xFFFF);
    auto server = plc::Server::start(plc);
    if (!server) return server.error();
    impl->server = std::move(*server);
    // The camera: opened now so that the first part does not wait; if it is not there, the
    // first trigger tries again (and fails that part with the reason if it still is not).
    impl->prepare_acquisition(setup);
    if (impl->axis)  // its health known from the start, as the camera's
        impl->ask(Device::kAxis, [raw = impl.get()] { return raw->axis->check(); });
    const auto opening = Clock::now();
    const auto opened = impl->session->connect();
    impl->devices.answered(Device::kCamera, static_cast<bool>(opened),
                           opened ? "opened" : opened.error().message);
    if (!opened)
        spdlog::warn("camera {}: {} (retried at the first trigger)", c.acquisition.camera.id,
                     opened.error().message);
    else if (const auto took = std::chrono::duration_cast<milliseconds>(Clock::now() - opening);
             took > milliseconds(500))  // after a crash: the old control channel had to expire
        spdlog::info("camera {}: opened in {} ms", c.acquisition.camera.id, took.count());
    impl->start_status_page();
    impl->plant = std::make_unique<PlantFeed>(c, impl->ring.get());
    impl->acq_beat = impl->proc_beat = Impl::steady_ns();
    Impl* raw = impl.get();
    impl->acquisition_thread = std::thread([raw] { raw->acquisition_loop(); });
    impl->processing_thread = std::thread([raw] { raw->processing_loop(); });
    spdlog::info("hotgauged {} up: PLC on port {}, next sequence {}\n{}", HOTGAUGE_VERSION,
                 impl->server->port(), impl->stats.next_sequence, describe(*setup));
    if (impl->sup.ready) impl->sup.ready();
    return std::unique_ptr<Daemon>(new Daemon(std::move(impl)));
}

void Daemon::run() {
    impl_->control_loop();
    impl_->shutdown();
}

void Daemon::request_stop() { impl_->stop = true; }
void Daemon::request_reload() { impl_->reload = true; }
int Daemon::plc_port() const { return impl_->server->port(); }

DaemonStats Daemon::stats() const {
    std::lock_guard lock(impl_->stats_mutex);
    return impl_->stats;
}

}  // namespace hotgauge::cell
