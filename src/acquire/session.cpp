#include "hotgauge/acquire/session.hpp"

#include <algorithm>
#include <cmath>

namespace hotgauge::acquire {

core::Result<ExposureTable> ExposureTable::create(std::vector<std::pair<double, double>> points) {
    for (std::size_t i = 0; i < points.size(); ++i) {
        const auto [t, e] = points[i];
        const std::string where = "exposure table point " + std::to_string(i + 1);
        if (!std::isfinite(t) || !std::isfinite(e))
            return core::make_error(where + ": not a number");
        if (e <= 0) return core::make_error(where + ": exposure must be > 0 µs");
        if (i > 0 && t <= points[i - 1].first)
            return core::make_error(where + ": temperatures must increase");
    }
    ExposureTable table;
    table.points_ = std::move(points);
    return table;
}

double ExposureTable::exposure_us(double t) const {
    if (points_.empty()) return 0.0;
    if (t <= points_.front().first) return points_.front().second;
    if (t >= points_.back().first) return points_.back().second;
    const auto hi = std::upper_bound(points_.begin(), points_.end(), t,
                                     [](double v, const auto& p) { return v < p.first; });
    const auto lo = hi - 1;
    const double f = (t - lo->first) / (hi->first - lo->first);
    return lo->second + f * (hi->second - lo->second);
}

std::string scan_start_lost(const AcquisitionStart& start, std::int64_t period_ns,
                            std::int64_t latency_ns) {
    auto ms = [](std::int64_t ns) {
        return std::to_string(std::llround(static_cast<double>(ns) * 1e-6));
    };
    if (start.lost > 0)
        return std::to_string(start.lost) + " incomplete frames before the first complete one";
    if (period_ns > 0 && start.lag_ns > period_ns + latency_ns)
        return "first frame " + ms(start.lag_ns) + " ms after AcquisitionStart (frame period " +
               ms(period_ns) + " ms, start latency allowed " + ms(latency_ns) + " ms)";
    return {};
}

CameraSession::CameraSession(CameraConfig camera, ScanConfig scan, Triangulation triangulation,
                             ExposureTable exposure, ReconnectPolicy policy)
    : camera_config_(std::move(camera)),
      scan_config_(std::move(scan)),
      triangulation_(std::move(triangulation)),
      exposure_(std::move(exposure)),
      policy_(policy) {}

CameraSession::~CameraSession() {
    if (reaper_.joinable()) reaper_.join();
}

std::chrono::milliseconds CameraSession::backoff_remaining() const {
    const auto now = Clock::now();
    if (camera_ || now >= next_attempt_) return std::chrono::milliseconds(0);
    return std::chrono::ceil<std::chrono::milliseconds>(next_attempt_ - now);
}

void CameraSession::lose(const std::string& why) {
    if (reaper_.joinable()) reaper_.join();
    reaper_ = std::thread([camera = std::move(camera_)]() mutable { camera.reset(); });
    ++failures_;
    last_failure_ = why;
    // Backoff: first, first·factor, ... capped; a camera that is back is found within max.
    double ms = static_cast<double>(policy_.first_backoff.count()) *
                std::pow(policy_.factor, std::max(0, failures_ - 1));
    ms = std::min(ms, static_cast<double>(policy_.max_backoff.count()));
    next_attempt_ = Clock::now() + std::chrono::milliseconds(static_cast<long long>(ms));
}

core::Result<void> CameraSession::connect() {
    if (camera_ && !camera_->in_control()) {
        // It died between scans (power cycled, cable pulled, restarted: it no longer knows us,
        // though the heartbeat may not have noticed yet): close it and open it again at once;
        // the backoff is for attempts that fail.
        lose("lost between scans");
        next_attempt_ = Clock::now();
    }
    if (camera_) return {};
    if (const auto wait = backoff_remaining(); wait.count() > 0)
        return core::make_error("camera unavailable (" + last_failure_ + "); next attempt in " +
                                std::to_string(wait.count()) + " ms");
    auto cam = Camera::open(camera_config_);
    if (!cam) {
        lose(cam.error().message);
        return cam.error();
    }
    camera_ = std::move(*cam);
    failures_ = 0;
    if (ever_opened_) ++reopens_;
    ever_opened_ = true;
    return {};
}

core::Result<void> CameraSession::check() {
    if (camera_ && camera_->in_control()) return {};
    if (camera_) lose("lost between scans: no answer to a register read");
    if (const auto wait = backoff_remaining(); wait.count() > 0)
        return core::make_error(last_failure_ + "; next attempt in " +
                                std::to_string(wait.count()) + " ms");
    return connect();
}

core::Result<ScanOutcome> CameraSession::scan(double seconds, std::optional<double> temperature_c,
                                              const std::function<void()>& on_started) {
    if (auto ok = connect(); !ok) return ok.error();
    ScanOutcome out;
    out.camera = camera_->description();
    if (!exposure_.empty() && temperature_c) {
        out.exposure_us = exposure_.exposure_us(*temperature_c);
        if (auto ok = camera_->set_exposure_us(*out.exposure_us); !ok) {
            lose(ok.error().message);
            return ok.error();
        }
    }
    ScanBuilder builder(scan_config_, triangulation_);
    if (auto ok = camera_->start(); !ok) {
        lose(ok.error().message);
        return ok.error();
    }
    if (on_started) on_started();
    const auto t_end = Clock::now() + std::chrono::duration<double>(seconds);
    // A scan whose last wait saw no frame ended with the camera gone or stalled: it fails, as
    // one that lost the camera earlier does; a part of a scan is never passed on as the scan.
    std::string last_error;
    std::int64_t previous_ns = -1, period_ns = 0;  // the shortest step between frames
    while (Clock::now() < t_end) {
        auto frame = camera_->next();
        if (frame) {
            const std::int64_t step = frame->camera_ns - previous_ns;
            if (previous_ns >= 0 && step > 0 && (period_ns == 0 || step < period_ns))
                period_ns = step;
            previous_ns = frame->camera_ns;
            builder.add(*frame);
            last_error.clear();
            continue;
        }
        last_error = frame.error().message;
        if (camera_->lost()) break;
    }
    camera_->stop();
    out.scan = builder.stats();
    out.stream = camera_->stats();
    out.start = camera_->acquisition_start();
    // The lag says something only when the camera runs free: a triggered one waits for its
    // first trigger (an encoder, the PLC), however long that takes.
    out.start_lost = scan_start_lost(out.start, camera_config_.trigger == "free" ? period_ns : 0,
                                     std::int64_t{camera_config_.start_latency_ms} * 1'000'000);
    if (!last_error.empty()) {
        const std::string why = "scan failed after " + std::to_string(out.scan.frames) +
                                " frames: camera lost or stalled: " + last_error;
        lose(last_error);
        return core::make_error(why);
    }
    out.face = builder.take();
    if (out.face.n_profiles() == 0)
        return core::make_error("scan failed: no frame arrived in " + std::to_string(seconds) +
                                " s (" + std::to_string(out.stream.timeouts) + " timeouts, " +
                                std::to_string(out.stream.incomplete) + " incomplete)");
    return out;
}

}  // namespace hotgauge::acquire
