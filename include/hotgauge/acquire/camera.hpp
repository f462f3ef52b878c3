#pragma once
// A GigE Vision (or USB3 Vision) camera through Aravis 0.8 (docs/acquisition.md): open by id,
// serial or IP, configure from plain settings plus a list of GenICam features, stream frames into
// a buffer pool, and report every incomplete or missing buffer. The only file that includes
// Aravis. Thread-safety: one thread uses a Camera; lost() may be read from any thread.
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::acquire {

struct CameraConfig {
    std::string id;  // Aravis device id, serial number or IP address; "" = the first found
    // GenICam features applied in order after the settings below ("ExposureAuto", "Off"), so a
    // Photonfocus, an AT C6 or an area camera is configured without code.
    std::vector<std::pair<std::string, std::string>> features;
    int width = 0, height = 0, offset_x = 0, offset_y = 0;  // region; 0 = as the camera has it
    std::string pixel_format;                               // "Mono8", "Mono16"; "" = as is
    double frame_rate_hz = 0;                               // free-run rate; 0 = as is
    double exposure_us = 0;                                 // 0 = as is
    std::string trigger = "free";  // free (internal rate) | software | external (TriggerSource)
    std::string trigger_source = "Line1";
    int packet_size = 0;  // GigE Vision packet size, bytes; 0 = negotiated by Aravis
    bool packet_resend = true;
    int n_buffers = 16;     // buffer pool
    int timeout_ms = 1000;  // no frame for this long while streaming: a timeout
    int max_timeouts = 3;   // consecutive timeouts before the camera counts as lost
    // GigE Vision: another application holds the control channel (a crashed process, until its
    // heartbeat expires, 3 s by default): try to take it for this long before giving up.
    int control_wait_ms = 5000;
    // The first frame's first packet arrives within one frame period plus this after
    // AcquisitionStart; later, its first frames were lost (see AcquisitionStart).
    int start_latency_ms = 30;
};

// What the stream delivered; never silently zero-filled.
struct StreamStats {
    std::int64_t frames = 0;      // complete buffers handed out
    std::int64_t incomplete = 0;  // buffers with missing packets or another error status
    std::int64_t timeouts = 0;    // waits that saw no buffer
    std::int64_t stale = 0;       // buffers of the acquisition before (begun before its start)
    std::uint64_t completed = 0, failures = 0, underruns = 0;  // Aravis stream statistics
    // GigE Vision streams: frames the receiver saw no packet of, packets missing after resend,
    // packets asked for again and packets received again.
    std::uint64_t missing_frames = 0, missing_packets = 0, resend_requests = 0, resent_packets = 0;
};

// How the last acquisition began. A scan's positions count from its first frame (the axis starts
// with it), so a scan whose first frames were lost is shifted along the scan: whoever uses the
// scan must know. Frames lost later only leave a gap, their neighbours keep their positions.
struct AcquisitionStart {
    // AcquisitionStart sent → the first buffer's leader received (host clock); -1: none.
    std::int64_t lag_ns = -1;
    // Incomplete buffers before the first complete one. (Frames lost whole show in lag_ns.)
    std::int64_t lost = 0;
};

// One part of a multi-part buffer (GigE Vision 2.1: range and intensity of a 3D sensor as
// separate parts), read through Aravis's buffer-part API.
struct FramePart {
    int component = 0;  // the part's data purpose / component id
    int width = 0, height = 0;
    int bytes_per_pixel = 1;
    std::size_t offset = 0, size = 0;  // where its bytes are in Frame::data
};

// One received buffer, copied out of the pool.
struct Frame {
    std::int64_t camera_ns = 0;  // the camera's timestamp
    std::int64_t system_ns = 0;  // host clock (CLOCK_REALTIME) when the buffer arrived
    std::uint64_t frame_id = 0;
    int width = 0, height = 0;
    int bytes_per_pixel = 1;
    std::vector<std::uint8_t> data;  // width × height × bytes_per_pixel, row-major
    // Multi-part buffers: the parts, their bytes one after the other in `data`; width and height
    // above are then those of part 0. Empty for a plain image.
    std::vector<FramePart> parts;
};

class Camera {
  public:
    // Opens and configures the camera; the error names the device and the setting that failed.
    static core::Result<std::unique_ptr<Camera>> open(const CameraConfig& config);
    ~Camera();
    Camera(const Camera&) = delete;
    Camera& operator=(const Camera&) = delete;

    core::Result<void> start();
    void stop();
    // The next complete frame, or an error: "timeout" (none within timeout_ms; counted) or
    // "camera lost" (control lost, or max_timeouts in a row). Incomplete buffers are counted and
    // skipped, never returned.
    core::Result<Frame> next();
    core::Result<void> software_trigger();
    core::Result<void> set_exposure_us(double exposure_us);
    bool lost() const;
    // Asks the device (one register read): false when lost, or when a GigE Vision device no
    // longer grants us its control channel (it restarted). Between scans only.
    bool in_control() const;
    const StreamStats& stats() const { return stats_; }
    const AcquisitionStart& acquisition_start() const { return start_; }
    std::string description() const;  // vendor, model, serial, address

  private:
    struct Impl;
    explicit Camera(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
    StreamStats stats_;
    AcquisitionStart start_;
};

}  // namespace hotgauge::acquire
