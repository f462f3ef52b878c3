#include "device_watch.hpp"

#include <sys/statvfs.h>
#include <unistd.h>

#include "hotgauge/core/clock.hpp"

namespace hotgauge::cell {

namespace {

std::string ms_text(std::int64_t ns) { return std::to_string(ns / 1'000'000) + " ms"; }

}  // namespace

void DeviceWatch::probe_started(Device d, std::int64_t now_ns) {
    std::lock_guard lock(mutex_);
    probes_[static_cast<int>(d)].asked_ns = now_ns;
}

void DeviceWatch::answered(Device d, bool ok, std::string detail) {
    std::lock_guard lock(mutex_);
    Probe& p = probes_[static_cast<int>(d)];
    p.asked_ns.reset();
    p.answered = true;
    p.ok = ok;
    p.detail = std::move(detail);
}

DeviceStatus DeviceWatch::status(Device d, bool configured, std::int64_t now_ns) const {
    if (!configured) return {false, false, "not configured"};
    std::lock_guard lock(mutex_);
    const Probe& p = probes_[static_cast<int>(d)];
    if (p.asked_ns && now_ns - *p.asked_ns > kNoAnswerNs)
        return {true, false, "no answer for " + ms_text(now_ns - *p.asked_ns)};
    if (!p.answered) return {true, false, "not asked yet"};
    return {true, p.ok, p.detail};
}

DeviceStatus accelerometer_status(const accel::AccelRing& ring, std::int64_t now_ns,
                                  std::int64_t silent_ns) {
    const accel::AccelRingStats st = ring.stats();
    if (!st.newest_ns) return {true, false, "no sample received yet"};
    const std::int64_t age = now_ns - *st.newest_ns;
    if (age > silent_ns) return {true, false, "silent: last sample " + ms_text(age) + " ago"};
    return {true, true,
            "streaming, last sample " + ms_text(std::max<std::int64_t>(age, 0)) + " ago"};
}

DeviceStatus pyrometer_status(const plc::Pyrometer& pyrometer) {
    const plc::PyrometerReading r = pyrometer.latest();
    if (!r.last_error.empty()) return {true, false, r.last_error};
    if (r.stale)
        return {
            true, false,
            r.age_ms < 0 ? "no answer yet" : "no answer for " + std::to_string(r.age_ms) + " ms"};
    if (r.out_of_range) return {true, true, "answering; no part in its span"};
    return {true, true, "answering"};
}

DeviceStatus disk_status(const std::filesystem::path& dir, int min_free_mb,
                         const std::string& last_store_error) {
    struct statvfs fs {};
    if (statvfs(dir.c_str(), &fs) != 0) return {true, false, dir.string() + ": not found"};
    if (access(dir.c_str(), W_OK) != 0) return {true, false, dir.string() + ": not writable"};
    const auto free_mb = static_cast<std::int64_t>(fs.f_bavail) *
                         static_cast<std::int64_t>(fs.f_frsize) / (1024 * 1024);
    const std::string free = std::to_string(free_mb) + " MB free";
    if (free_mb < min_free_mb)
        return {true, false, free + ", below " + std::to_string(min_free_mb) + " MB"};
    if (!last_store_error.empty()) return {true, false, "last write failed: " + last_store_error};
    return {true, true, free};
}

plc::CellStatus calibration_status(const std::string& calibrated_at, bool geometry_measured,
                                   int interval_days, std::int64_t now_ns) {
    plc::CellStatus s;
    const auto at = core::parse_iso8601_utc(calibrated_at);
    if (at) s.calibration_age_days = static_cast<int>((now_ns - *at) / (86'400LL * 1'000'000'000));
    if (!geometry_measured)
        s.calibration = plc::CalibrationState::kNotMeasured;
    else if (!at || *s.calibration_age_days < 0)
        s.calibration = plc::CalibrationState::kUnknown;
    else
        s.calibration = *s.calibration_age_days > interval_days ? plc::CalibrationState::kDue
                                                                : plc::CalibrationState::kValid;
    return s;
}

}  // namespace hotgauge::cell
