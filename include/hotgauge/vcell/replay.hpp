#pragma once
// An archived recording served again as the cell's sensors (docs/virtual-cell.md "Replay"): each
// face's profiles as the peak frames a profile camera would have sent, the accelerometer record as
// HGA1 datagrams. Pure functions: the virtual cell times and sends what they return.
//
// The frames are the inverse of what the receiver does (acquire::ScanBuilder): a peaks frame of
// profiles_per_frame profiles stamped t on the camera's clock becomes profiles at
// t + clock_offset_ns + k · line period, point i from column i + offset_x at the decoded row
// + offset_y through the calibration's triangulation. So a recording taken through that format,
// calibration and camera region comes back bit for bit.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/acquire/triangulation.hpp"
#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/vcell/gv_device.hpp"

namespace hotgauge::vcell {

// How the receiver turns peak rows into profile points: the camera region's offsets (full-sensor
// pixels) and the peak format; the triangulation is the calibration's.
struct PeakEncoding {
    acquire::PeakFormat format;
    int offset_x_px = 0, offset_y_px = 0;
};

// What encoding cost: points that decode to exactly the recorded floats, and the others (a
// recording taken in image mode or another format) with their largest error.
struct EncodeStats {
    std::int64_t exact = 0, inexact = 0, no_return = 0;
    double max_error_mm = 0.0;  // over the inexact points, |Δx| and |Δz|
};

// One recorded profile (`width` points of x, z; NaN = no return) into its peak rows
// (format.rows_per_profile() rows of `width` words): the row word whose decoded, triangulated point
// is the recorded one (searched around the triangulation's inverse), else the nearest; intensity
// at its maximum, second peak and width rows 0.
void encode_profile(std::span<const float> xz, const acquire::Triangulation& triangulation,
                    const PeakEncoding& encoding, std::uint16_t* rows, EncodeStats& stats);

// One frame of a face: its camera timestamp and its first profile.
struct ReplayFrame {
    std::int64_t camera_ns = 0;
    std::size_t first_profile = 0;
};

// The face's profiles in frames of `profiles_per_frame`, camera_ns = profile time −
// clock_offset_ns. Error (naming `where`, the face's folder) when the profiles do not come in
// such frames: a count that is not a multiple, or profiles within a frame not `line_period_ns`
// apart.
core::Result<std::vector<ReplayFrame>> replay_frames(const core::FaceScan& face,
                                                     int profiles_per_frame,
                                                     std::int64_t line_period_ns,
                                                     std::int64_t clock_offset_ns,
                                                     const std::string& where);

// One HGA1 datagram of recorded samples: evenly spaced, at most max_samples.
struct AccelBatch {
    std::size_t first = 0, count = 0;
    std::int64_t t_ns = 0;  // the first sample's recorded time
    std::uint32_t period_ns = 0;
};
// The face's accelerometer record cut into datagrams: a new one wherever the spacing changes (a
// gap in the record stays a gap), so that t_ns + q · period_ns are the recorded times exactly.
std::vector<AccelBatch> accel_batches(const core::FaceScan& face, std::size_t max_samples);

struct PlayerConfig {
    std::filesystem::path dir;  // the recording's folder, for messages
    core::Recording recording;
    std::int64_t clock_offset_ns = 0;   // the calibration's camera → accelerometer clock
    double scan_s = 1.3;                // the receiver's scan length (hotgauged camera.scan_s)
    double line_period_s = 1e-3;        // between the profiles of one frame
    PeakEncoding encoding;              // format (profiles per frame from each request)
    std::size_t datagram_samples = 20;  // at most this many samples per datagram
};

// Plays one recording: per acquisition, the frames of the face the axis is at, and the same
// face's accelerometer record, both shifted by one offset to now (fixed at the first frame; later
// when the record sent before still reaches that far, see start_accel).
// Frames 0..N−2 go out within the first scan_s − 0.15 s of the acquisition and the last one
// 0.15 s after scan_s: a receiver that scans scan_s gets exactly the N recorded frames.
// Thread safety: render() on the device's stream thread, due() on another.
class RecordingPlayer {
  public:
    // `triangulation`: the calibration's, as the receiver has it.
    RecordingPlayer(PlayerConfig config, acquire::Triangulation triangulation)
        : c_(std::move(config)), triangulation_(std::move(triangulation)) {}

    // A device renderer (GvDeviceConfig::renderer_paces): waits until the frame is due (or
    // `stop`), then fills it; no frame (req.send = false) when the face is not in the recording,
    // its frames do not fit the request, or all were sent (logged once per acquisition).
    void render(FrameRequest& req, std::span<std::uint8_t> data, const std::string& face,
                const std::atomic<bool>& stop);
    // The accelerometer datagrams due by now_ns: the playing face's samples whose shifted time
    // has come, in order; (t_ns shifted, period, x y z per sample).
    struct Datagram {
        std::int64_t t_ns = 0;
        std::uint32_t period_ns = 0;
        std::vector<float> samples;
    };
    std::vector<Datagram> due(std::int64_t now_ns);
    EncodeStats stats() const;
    const core::Recording& recording() const { return c_.recording; }

  private:
    bool start_acquisition(const FrameRequest& req, const std::string& face);
    void encode_frame(const ReplayFrame& f, const FrameRequest& req, std::span<std::uint8_t> data);
    void start_accel(const ReplayFrame& first);

    PlayerConfig c_;
    acquire::Triangulation triangulation_;
    // Stream thread only.
    std::uint64_t acquisition_ = 0;
    const core::FaceScan* face_ = nullptr;  // null: nothing to send in this acquisition
    std::vector<ReplayFrame> frames_;
    std::size_t sent_ = 0;
    std::int64_t shift_ns_ = 0;
    bool warned_still_scanning_ = false;
    std::vector<std::uint16_t> words_;
    // Shared with due().
    mutable std::mutex mutex_;
    const core::FaceScan* accel_face_ = nullptr;
    std::vector<AccelBatch> batches_;
    std::size_t next_batch_ = 0;
    std::int64_t accel_shift_ns_ = 0;
    std::int64_t accel_lead_ns_ = 0;  // samples go out this long before their time
    std::int64_t last_sent_ns_ = 0;   // the last sample sent, shifted
    bool sent_any_ = false;
    EncodeStats stats_;
};

}  // namespace hotgauge::vcell
