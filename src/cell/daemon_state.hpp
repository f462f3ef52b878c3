#pragma once
// The daemon's shared state, private to `cell`: a trigger's way through the cell (Job, Captured)
// and Daemon::Impl, whose members say which thread owns them. The daemon by job:
//   daemon_setup.cpp        load and check the setup, describe it, the result hashes
//   daemon_control.cpp      the control thread: PLC events, sequence numbers, reload, health
//   daemon_acquisition.cpp  the acquisition thread: axis, camera, pyrometer, accelerometer
//   daemon_processing.cpp   the processing thread: measure → store → publish
//   daemon.cpp              the lifecycle: start, run, stop
#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "device_watch.hpp"
#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/cell/axis.hpp"
#include "hotgauge/cell/daemon.hpp"
#include "hotgauge/cell/quality_feed.hpp"
#include "hotgauge/cell/status_board.hpp"
#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/pipeline/verify.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/server.hpp"
#include "hotgauge/results/archive.hpp"
#include "hotgauge/results/results_log.hpp"
#include "hotgauge/results/sequence.hpp"
#include "hotgauge/web/server.hpp"
#include "plant_feed.hpp"
#include "queue.hpp"

namespace hotgauge::cell {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

inline constexpr milliseconds kLoopPeriod{
    100};  // control and worker loops: beat at least this often

inline double ms_between(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
}

inline std::uint16_t code(plc::ErrorCode e) { return static_cast<std::uint16_t>(e); }

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
    // Processing, by step (daemon_processing.cpp).
    struct Measured {
        pipeline::PartResult r;
        std::optional<pipeline::Verification> verification;  // a master's check
        const core::MasterCertificate* master = nullptr;     // the slot's master, if it is one
        Clock::time_point checked;                           // measured and checked
        double pipeline_ms = 0;  // the pipeline's work after the margin, and the check
    };
    struct Stored {
        results::ResultEntry entry;  // points into its Measured
        plc::PartResult shown;       // what the registers show
        core::Result<void> stored;   // the commit
        bool archiving = false;      // the raw recording is to be kept
        double store_ms = 0;
    };
    void process(Captured c);
    Measured measure_part(Captured& c) const;
    Stored store_part(const Captured& c, const Measured& m);
    void publish_part(Captured& c, const Measured& m, const Stored& s);
    std::string part_message(const Captured& c, const Measured& m, const Stored& s,
                             const std::string& outcome, std::int64_t published_ns) const;
    pipeline::PartResult measure_captured(Captured& c) const;
    // The registers: the result, or the fault; returns the outcome for the log.
    plc::PartResult shown_to_plc(const Captured& c, const results::ResultEntry& entry) const;
    std::string publish(const Captured& c, const results::ResultEntry& entry,
                        const core::Result<void>& stored, const plc::PartResult& shown,
                        bool& problem);
    void prepare_results(const std::shared_ptr<const Setup>& s);
    PartMetrics part_metrics(const Captured& c, const pipeline::PartResult& r, bool stored) const;
};

}  // namespace hotgauge::cell
