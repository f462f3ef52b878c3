#pragma once
// A camera that may come and go (docs/acquisition.md "Sessions"): opened on demand, its exposure
// set from the part temperature before each scan (paper §3.1), and, when it is lost (cable pulled,
// power cycled), the scan in progress fails with the reason and the camera is reopened later with
// exponential backoff. The process keeps running; the daemon and `hotgauge grab` both scan
// through this class.
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::acquire {

// Exposure from the part temperature: hotter parts glow brighter and the stripe must not drown
// in it, so the exposure falls with temperature. Points (°C, µs) with increasing temperature;
// linear in between, the end values beyond.
class ExposureTable {
  public:
    // Errors name the offending point ("exposure table point 2: ...").
    static core::Result<ExposureTable> create(std::vector<std::pair<double, double>> points);
    ExposureTable() = default;  // empty: the camera's exposure is left as configured
    bool empty() const { return points_.empty(); }
    double exposure_us(double temperature_c) const;
    const std::vector<std::pair<double, double>>& points() const { return points_; }

  private:
    std::vector<std::pair<double, double>> points_;
};

struct ReconnectPolicy {
    std::chrono::milliseconds first_backoff{250};
    std::chrono::milliseconds max_backoff{30'000};
    double factor = 2.0;
};

struct ScanOutcome {
    core::FaceScan face;
    ScanStats scan;
    StreamStats stream;
    std::optional<double> exposure_us;  // set from the table for this scan
    std::string camera;                 // description of the camera that scanned
    AcquisitionStart start;             // how the acquisition began
    // Not empty: the scan's first frames were lost, so its positions are shifted; why.
    std::string start_lost;
};

// Why a scan's start was lost (its positions shifted), or "" when its first frame followed
// AcquisitionStart within one frame period plus `latency_ns` and nothing was lost before it.
// `period_ns` ≤ 0: unknown (a one-frame scan), only the counted losses decide.
std::string scan_start_lost(const AcquisitionStart& start, std::int64_t period_ns,
                            std::int64_t latency_ns);

// Thread safety: one thread drives a session.
class CameraSession {
  public:
    using Clock = std::chrono::steady_clock;
    CameraSession(CameraConfig camera, ScanConfig scan, Triangulation triangulation,
                  ExposureTable exposure = {}, ReconnectPolicy policy = {});
    ~CameraSession();
    CameraSession(const CameraSession&) = delete;
    CameraSession& operator=(const CameraSession&) = delete;

    // Opens the camera unless it is open. While the backoff after a failure runs, fails at once
    // with "camera unavailable ... next attempt in N ms" without touching the network.
    core::Result<void> connect();
    // Between scans (the daemon asks while idle): whether the camera is there and still grants
    // us control (one register read). One that does not is closed; one that is closed is opened
    // again once its backoff allows. The error says why it is not there.
    core::Result<void> check();
    // One face: exposure for the temperature, then frames for `seconds`. `on_started` runs once
    // acquisition has started (the accelerometer window, the axis). A lost camera fails the scan
    // with the reason (nothing partial is returned) and closes it; the next connect() reopens.
    core::Result<ScanOutcome> scan(double seconds, std::optional<double> temperature_c,
                                   const std::function<void()>& on_started = {});

    // The face geometry and scan settings of the next scan (the daemon scans face after face).
    void set_scan_config(ScanConfig scan) { scan_config_ = std::move(scan); }
    const ScanConfig& scan_config() const { return scan_config_; }
    bool connected() const { return camera_ != nullptr; }
    int failures_in_a_row() const { return failures_; }
    // Opens after a loss so far, and why the last one was lost ("lost between scans", the
    // scan's error): the daemon logs each reopen.
    int reopens() const { return reopens_; }
    const std::string& last_failure() const { return last_failure_; }
    // Time until the next open attempt is allowed (0 when allowed now).
    std::chrono::milliseconds backoff_remaining() const;

  private:
    void lose(const std::string& why);

    CameraConfig camera_config_;
    ScanConfig scan_config_;
    Triangulation triangulation_;
    ExposureTable exposure_;
    ReconnectPolicy policy_;
    std::unique_ptr<Camera> camera_;
    // A lost camera is closed on this thread: Aravis's goodbye to a dead device takes seconds,
    // which the failed scan's report must not wait for. Joined before the next close and at
    // destruction.
    std::thread reaper_;
    int failures_ = 0;
    int reopens_ = 0;
    bool ever_opened_ = false;
    Clock::time_point next_attempt_{};
    std::string last_failure_;
};

}  // namespace hotgauge::acquire
