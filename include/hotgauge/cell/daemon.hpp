#pragma once
// The cell (docs/operations.md "How the daemon works"): what `hotgauged` runs. A PLC trigger
// (part id, recipe slot, face) becomes scans of the faces the recipe needs, a recording, the
// pipeline `hotgauge measure` runs, a row in the results files, and the result in the PLC's
// registers; or, when that cannot be done, a fault code with the reason. Every trigger gets a
// sequence number and exactly one outcome: measured, or failed with a reason (never dropped,
// never reported twice).
//
// Threads, each with one job, and bounded queues between them:
//   control      (the caller of run()): PLC events, signals, reload, watchdog, status
//   PLC server   (plc::Server's own): answers the PLC; never waits on the others
//   acquisition  axis moves and camera scans for one trigger → captured part
//   processing   pipeline::run → raw archive → results files → registers / fault
//   accelerometer, pyrometer (their sources' own threads)
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "hotgauge/acquire/session.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/calib/calibration.hpp"
#include "hotgauge/cell/config.hpp"
#include "hotgauge/cell/health.hpp"
#include "hotgauge/core/master.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/match/model.hpp"

namespace hotgauge::cell {

// Everything a configuration needs before the first part, built at start and again at reload:
// the config, the cell's calibrated geometry, the recipes and their part models (built or loaded),
// the sensor model and the exposure table. Immutable once built; parts in flight keep theirs.
struct Setup {
    DaemonConfig config;
    calib::Calibration calibration;
    std::map<int, core::Recipe> recipes;                        // by PLC recipe slot
    std::map<int, std::shared_ptr<const match::Model>> models;  // by slot
    std::map<int, core::MasterCertificate> masters;             // master slots
    // By slot: a hash over everything that decides a result there (the daemon config, the
    // calibration, the recipe, a saved model, a master certificate, the software version), with
    // every result: a changed tolerance is a changed hash.
    std::map<int, std::string> result_hash;
    std::map<int, std::uint16_t> recipe_revision;  // by slot: PLC input 118
    std::optional<acquire::Triangulation> triangulation;
    acquire::ExposureTable exposure;
};

// Reads the config and everything it names; the first error names file:line:key or the file.
core::Result<std::shared_ptr<const Setup>> load_setup(const std::filesystem::path& config_file);
// A few lines for `--check-config` and the start-up log.
std::string describe(const Setup& setup);

// What the daemon tells its supervisor (systemd: sd_notify) and its log.
struct Supervisor {
    std::function<void()> ready;                       // READY=1
    std::function<void(const std::string&)> status;    // STATUS=...
    std::function<void()> watchdog;                    // WATCHDOG=1: the loops are healthy
    std::function<void(const std::string&)> stopping;  // STOPPING=1
};

// What the last part took (the latency benchmark, tests).
struct PartTiming {
    std::uint64_t sequence = 0;
    std::int64_t last_profile_ns = 0;  // camera time of the last profile of the last face
    std::int64_t published_ns = 0;     // the result was valid in the registers (or the fault)
    double accel_wait_ms = 0;          // scans done -> the accelerometer's margin arrived
    double pipeline_ms = 0;            // the pipeline's work after the margin
    double store_ms = 0;
};

struct DaemonStats {
    std::uint64_t triggers = 0, measured = 0, failed = 0, reloads = 0, rejected_reloads = 0;
    std::uint64_t next_sequence = 0;
    std::optional<PartTiming> last;
    std::string state;    // as in STATUS=
    DeviceHealth health;  // as at the PLC's input 113, updated every control loop
};

class Daemon {
  public:
    // Starts the accelerometer, pyrometer, PLC server and the camera session, then the worker
    // threads. A camera that is not there yet is not an error (the first part retries it);
    // a PLC port that cannot be bound is.
    static core::Result<std::unique_ptr<Daemon>> start(std::shared_ptr<const Setup> setup,
                                                       Supervisor supervisor = {});
    ~Daemon();  // request_stop() + the bounded shutdown, if run() did not do it
    Daemon(const Daemon&) = delete;
    Daemon& operator=(const Daemon&) = delete;

    // The control loop; returns after request_stop() once the part in progress is finished or
    // failed (bounded: the current face's scan plus the pipeline).
    void run();
    // Safe from any thread (a signal thread).
    void request_stop();
    void request_reload();  // applied between parts

    int plc_port() const;
    DaemonStats stats() const;

  private:
    struct Impl;
    explicit Daemon(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::cell
