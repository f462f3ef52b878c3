#pragma once
// How the daemon keeps cell::DeviceHealth current in every state (docs/operations.md "Device
// health"). The camera and the axis belong to the acquisition thread, which asks them between
// parts (probe_started / answered); a question without an answer for kNoAnswer counts as a
// fault at once, before the transport's own retries give up. The accelerometer, the pyrometer
// and the results disk are read where they are.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/cell/health.hpp"
#include "hotgauge/plc/handshake.hpp"
#include "hotgauge/plc/pyrometer.hpp"

namespace hotgauge::cell {

class DeviceWatch {
  public:
    // A healthy camera or axis answers a register read on the cell network in milliseconds.
    static constexpr std::int64_t kNoAnswerNs = 600'000'000;

    // Acquisition thread: asking device d (the camera or the axis), and its answer; a part's
    // scan or move that succeeded or failed is an answer as good as a probe's.
    void probe_started(Device d, std::int64_t now_ns);
    void answered(Device d, bool ok, std::string detail);
    // The last answer, or "no answer for N ms" while a question is pending too long.
    DeviceStatus status(Device d, bool configured, std::int64_t now_ns) const;

  private:
    struct Probe {
        std::optional<std::int64_t> asked_ns;  // pending since
        bool answered = false, ok = false;
        std::string detail;
    };
    mutable std::mutex mutex_;
    Probe probes_[kDeviceCount];
};

// Samples arriving: the newest is at most `silent_ns` old.
DeviceStatus accelerometer_status(const accel::AccelRing& ring, std::int64_t now_ns,
                                  std::int64_t silent_ns);
// The serial link answers (a reading out of range, a cold support, is no fault).
DeviceStatus pyrometer_status(const plc::Pyrometer& pyrometer);
// The results folder is there, writable, with at least `min_free_mb` free, and the last
// append (if any failed) is named.
DeviceStatus disk_status(const std::filesystem::path& dir, int min_free_mb,
                         const std::string& last_store_error);

// The calibration's state and age for the PLC, from its date and the configured interval.
plc::CellStatus calibration_status(const std::string& calibrated_at, bool geometry_measured,
                                   int interval_days, std::int64_t now_ns);

}  // namespace hotgauge::cell
