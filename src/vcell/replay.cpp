#include "hotgauge/vcell/replay.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <thread>

#include "hotgauge/core/clock.hpp"
#include "log.hpp"

namespace hotgauge::vcell {
namespace {

// The receiver's scan ends scan_s after its AcquisitionStart, with the frame that arrives after
// its last look: frames 0..N−2 go out by scan_s − kEdgeS (their delivery's margin), the last at
// scan_s + kEdgeS (the margin of the receiver's start); 0.3 s between them, less than a camera
// timeout (hotgauged: 500 ms).
constexpr double kEdgeS = 0.15;
// A new record starts at least this long after the last sample sent (the receiver's ring takes
// only samples after its newest, and its window must not reach back into the record before).
constexpr std::int64_t kAccelGuardNs = 100'000'000;

// The point the receiver makes of row word w in column u (acquire::decode_peaks, then
// Triangulation::to_camera with the region's offsets): the same calls, so the same floats.
void decode_point(const acquire::Triangulation& t, const PeakEncoding& e, double u, long w,
                  float* xz) {
    const acquire::StripePoint p{
        static_cast<float>(w) * std::ldexp(1.0F, -e.format.fractional_bits), 1.0F,
        acquire::StripeStatus::kOk};
    t.to_camera(std::span(&p, 1), u, e.offset_y_px, xz);
}

// The row word of one recorded point: the triangulation's inverse rounded to the format's
// fraction, then its neighbours, until one decodes to the recorded floats; else the nearest.
std::uint16_t encode_point(const acquire::Triangulation& t, const PeakEncoding& e, double u,
                           float x, float z, EncodeStats& stats) {
    const acquire::ImagePoint ip = t.to_image(x, z);
    const double scale = std::ldexp(1.0, e.format.fractional_bits);
    long best = 0;
    double best_error = std::numeric_limits<double>::infinity();
    if (std::isfinite(ip.v_px)) {
        const long w0 = std::lround((ip.v_px - e.offset_y_px) * scale);
        for (long d : {0L, -1L, 1L, -2L, 2L, -3L, 3L}) {
            const long w = w0 + d;
            if (w < 1 || w > 65535) continue;
            float xz[2];
            decode_point(t, e, u, w, xz);
            if (xz[0] == x && xz[1] == z) {
                ++stats.exact;
                return static_cast<std::uint16_t>(w);
            }
            const double err = std::max(std::abs(double{xz[0]} - x), std::abs(double{xz[1]} - z));
            if (err < best_error) best_error = err, best = w;
        }
    }
    ++stats.inexact;
    stats.max_error_mm = std::max(stats.max_error_mm, best_error);
    return static_cast<std::uint16_t>(best);  // 0 (no return) when nothing decodes near it
}

}  // namespace

void encode_profile(std::span<const float> xz, const acquire::Triangulation& triangulation,
                    const PeakEncoding& encoding, std::uint16_t* rows, EncodeStats& stats) {
    const std::size_t width = xz.size() / 2;
    const acquire::PeakFormat& f = encoding.format;
    std::fill(rows, rows + width * static_cast<std::size_t>(f.rows_per_profile()), 0);
    std::uint16_t* intensity = f.intensity ? rows + (f.second_peak ? 2 : 1) * width : nullptr;
    for (std::size_t i = 0; i < width; ++i) {
        const float x = xz[2 * i], z = xz[2 * i + 1];
        if (std::isnan(x) || std::isnan(z)) {
            ++stats.no_return;
            continue;
        }
        const double u = static_cast<double>(i) + encoding.offset_x_px;
        rows[i] = encode_point(triangulation, encoding, u, x, z, stats);
        if (intensity && rows[i] != 0)
            intensity[i] = static_cast<std::uint16_t>(f.intensity_max_value);
    }
}

core::Result<std::vector<ReplayFrame>> replay_frames(const core::FaceScan& face,
                                                     int profiles_per_frame,
                                                     std::int64_t line_period_ns,
                                                     std::int64_t clock_offset_ns,
                                                     const std::string& where) {
    const auto n = static_cast<std::size_t>(face.n_profiles());
    const auto ppf = static_cast<std::size_t>(std::max(1, profiles_per_frame));
    if (n == 0) return core::make_error(where + ": no profiles to replay");
    if (n % ppf != 0)
        return core::make_error(where + ": " + std::to_string(n) +
                                " profiles are not whole frames of " + std::to_string(ppf) +
                                " profiles (the receiver's profiles per frame)");
    std::vector<ReplayFrame> frames;
    frames.reserve(n / ppf);
    const auto& t = face.profile_times_ns;
    for (std::size_t first = 0; first < n; first += ppf) {
        for (std::size_t k = 1; k < ppf; ++k)
            if (t[first + k] - t[first + k - 1] != line_period_ns)
                return core::make_error(
                    where + "/profile_times.npy: profile " + std::to_string(first + k) + " is " +
                    std::to_string(t[first + k] - t[first + k - 1]) +
                    " ns after the one before, in a frame whose profiles are " +
                    std::to_string(line_period_ns) + " ns apart (the line period)");
        frames.push_back({t[first] - clock_offset_ns, first});
    }
    return frames;
}

std::vector<AccelBatch> accel_batches(const core::FaceScan& face, std::size_t max_samples) {
    std::vector<AccelBatch> out;
    const auto& t = face.accel_times_ns;
    for (std::size_t i = 0; i < t.size();) {
        // A lone sample (the record's last after a gap) keeps the period before it.
        AccelBatch b{i, 1, t[i], out.empty() ? 1U : out.back().period_ns};
        if (i + 1 < t.size() && t[i + 1] - t[i] <= std::numeric_limits<std::uint32_t>::max()) {
            b.period_ns = static_cast<std::uint32_t>(t[i + 1] - t[i]);
            while (b.count < max_samples && i + b.count < t.size() &&
                   t[i + b.count] - t[i + b.count - 1] == b.period_ns)
                ++b.count;
        }
        out.push_back(b);
        i += b.count;
    }
    return out;
}

// ---- RecordingPlayer -------------------------------------------------------------------------

bool RecordingPlayer::start_acquisition(const FrameRequest& req, const std::string& face) {
    acquisition_ = req.acquisition;
    face_ = nullptr;
    sent_ = 0;
    warned_still_scanning_ = false;
    const std::string where = (c_.dir / face).string();
    const auto it = std::find_if(c_.recording.faces.begin(), c_.recording.faces.end(),
                                 [&](const core::FaceScan& f) { return f.name == face; });
    if (it == c_.recording.faces.end()) {
        std::string have;
        for (const auto& f : c_.recording.faces) have += (have.empty() ? "" : ", ") + f.name;
        detail::log().error("{}: face '{}' is not in the recording (it has {}): no frames sent",
                            (c_.dir / "part.yaml").string(), face, have);
        return false;
    }
    const int rpp = c_.encoding.format.rows_per_profile();
    const auto period_ns = static_cast<std::int64_t>(std::llround(c_.line_period_s * 1e9));
    auto frames = req.bytes_per_pixel == 2 && req.height >= rpp
                      ? replay_frames(*it, req.height / rpp, period_ns, c_.clock_offset_ns, where)
                      : core::make_error(where + ": the camera is not set to Mono16 peak frames");
    if (frames && it->width != req.width)
        frames = core::make_error(where + "/profiles.npy: " + std::to_string(it->width) +
                                  " points per profile, the camera's width is " +
                                  std::to_string(req.width));
    if (!frames) {
        detail::log().error("{}: no frames sent", frames.error().message);
        return false;
    }
    face_ = &*it;
    frames_ = std::move(*frames);
    detail::log().info("replay: face {}: {} frames, {} accelerometer samples", face, frames_.size(),
                       it->accel_times_ns.size());
    return true;
}

void RecordingPlayer::render(FrameRequest& req, std::span<std::uint8_t> data,
                             const std::string& face, const std::atomic<bool>& stop) {
    if (req.acquisition != acquisition_) start_acquisition(req, face);
    if (!face_ || sent_ >= frames_.size()) {
        req.send = false;
        // The last frame went out kEdgeS after scan_s: a receiver scanning on after 0.5 s scans
        // longer, and has waited in vain for a frame since.
        const auto late_ns = static_cast<std::int64_t>((c_.scan_s + 0.5) * 1e9);
        if (face_ && !warned_still_scanning_ &&
            core::realtime_ns() > req.acquisition_start_ns + late_ns) {
            warned_still_scanning_ = true;
            detail::log().warn(
                "replay: face {}: the receiver still scans 0.35 s after the recording's last "
                "frame: is --scan-s {} its camera.scan_s?",
                face, c_.scan_s);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
        return;
    }
    // Frames 0..N−2 spread over [5 ms, scan_s − kEdgeS], the last at scan_s + kEdgeS.
    const std::size_t n = frames_.size();
    const auto ns = [](double s) { return static_cast<std::int64_t>(s * 1e9); };
    const std::int64_t spread = std::max<std::int64_t>(0, ns(c_.scan_s - kEdgeS - 0.005));
    const std::int64_t due =
        req.acquisition_start_ns +
        (sent_ + 1 < n ? ns(0.005) + (n > 2 ? spread * static_cast<std::int64_t>(sent_) /
                                                  static_cast<std::int64_t>(n - 2)
                                            : 0)
                       : ns(c_.scan_s + kEdgeS));
    while (!stop && core::realtime_ns() < due)
        std::this_thread::sleep_for(std::chrono::nanoseconds(
            std::min<std::int64_t>(20'000'000, due - core::realtime_ns())));
    const ReplayFrame& f = frames_[sent_];
    if (sent_ == 0) start_accel(f);
    req.timestamp_ns = f.camera_ns + shift_ns_;
    encode_frame(f, req, data);
    ++sent_;
}

// One shift for the frames and the accelerometer record of this scan: the first frame is now,
// unless the record sent before still reaches that far (the face scanned again right after, when
// the receiver found the scan's start lost): then later, so that the new record follows it, and
// the stream runs that much ahead of the clock.
void RecordingPlayer::start_accel(const ReplayFrame& first) {
    const std::int64_t now = core::realtime_ns();
    shift_ns_ = now - first.camera_ns;
    std::lock_guard lock(mutex_);
    if (!face_->accel_times_ns.empty() && sent_any_)
        shift_ns_ =
            std::max(shift_ns_, last_sent_ns_ + kAccelGuardNs - face_->accel_times_ns.front());
    const std::int64_t lead = shift_ns_ - (now - first.camera_ns);
    if (accel_face_ && next_batch_ < batches_.size())
        detail::log().info("replay: face {}'s accelerometer record cut short by a new scan",
                           accel_face_->name);
    if (lead > 0)
        detail::log().info(
            "replay: face {}: its record follows the one sent before: frames and samples {:.1f} "
            "ms ahead of the clock",
            face_->name, static_cast<double>(lead) * 1e-6);
    accel_face_ = face_;
    batches_ = accel_batches(*face_, c_.datagram_samples);
    next_batch_ = 0;
    accel_shift_ns_ = shift_ns_;
    accel_lead_ns_ = lead;
}

void RecordingPlayer::encode_frame(const ReplayFrame& f, const FrameRequest& req,
                                   std::span<std::uint8_t> data) {
    const int rpp = c_.encoding.format.rows_per_profile();
    const int profiles = req.height / rpp;
    const auto w = static_cast<std::size_t>(req.width);
    PeakEncoding e = c_.encoding;
    e.offset_x_px = req.offset_x;
    words_.assign(w * static_cast<std::size_t>(req.height), 0);
    EncodeStats s;
    for (int k = 0; k < profiles; ++k) {
        const std::size_t p = f.first_profile + static_cast<std::size_t>(k);
        encode_profile(std::span(face_->profiles_mm).subspan(p * w * 2, w * 2), triangulation_, e,
                       words_.data() + static_cast<std::size_t>(k * rpp) * w, s);
    }
    std::memcpy(data.data(), words_.data(), std::min(data.size(), words_.size() * 2));
    std::lock_guard lock(mutex_);
    stats_.exact += s.exact;
    stats_.inexact += s.inexact;
    stats_.no_return += s.no_return;
    stats_.max_error_mm = std::max(stats_.max_error_mm, s.max_error_mm);
}

std::vector<RecordingPlayer::Datagram> RecordingPlayer::due(std::int64_t now_ns) {
    std::vector<Datagram> out;
    std::lock_guard lock(mutex_);
    for (; accel_face_ && next_batch_ < batches_.size(); ++next_batch_) {
        const AccelBatch& b = batches_[next_batch_];
        const std::int64_t t_last =
            b.t_ns + static_cast<std::int64_t>(b.count - 1) * b.period_ns + accel_shift_ns_;
        if (t_last > now_ns + accel_lead_ns_) break;
        const float* s = accel_face_->accel_mps2.data() + b.first * 3;
        out.push_back({b.t_ns + accel_shift_ns_, b.period_ns, {s, s + b.count * 3}});
        last_sent_ns_ = t_last;
        sent_any_ = true;
    }
    return out;
}

EncodeStats RecordingPlayer::stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
}

}  // namespace hotgauge::vcell
