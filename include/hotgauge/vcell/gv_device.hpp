#pragma once
// A GigE Vision device on a loopback address (docs/virtual-cell.md): Aravis's fake camera
// (ArvFakeCamera: its GenICam description and register model, public API of libaravis 0.8) behind
// our own GVCP control channel and GVSP stream. Written here rather than taken whole from
// ArvGvFakeCamera because a measuring cell needs what that one does not do: packet resend (a
// resend buffer of recent frames answering PACKETRESEND commands), deterministic packet loss on
// the link, and frames rendered by a callback that knows the frame's timestamp.
// Any GigE Vision client reaches it: Aravis (`hotgauge grab --camera 127.0.0.2`), arv-tool.
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>

#include "hotgauge/core/result.hpp"

namespace hotgauge::vcell {

// What the renderer is asked for: the region and format the client configured, the exposure it
// set, and the frame's timestamp (the device clock: CLOCK_REALTIME, ns).
struct FrameRequest {
    std::uint32_t frame_id = 0;             // GVSP block id, 1..65535
    std::int64_t timestamp_ns = 0;          // start of exposure; also in the GVSP leader
    std::uint64_t acquisition = 0;          // +1 at each AcquisitionStart
    std::int64_t frame_in_acquisition = 0;  // 0 for the first frame (render turn) after the start
    int width = 0, height = 0, offset_x = 0, offset_y = 0;
    int bytes_per_pixel = 1;
    std::uint32_t pixel_format = 0;  // PFNC code
    double exposure_us = 0;
    std::int64_t acquisition_start_ns = 0;  // when this acquisition's AcquisitionStart arrived
    // The renderer's answer besides the pixels: it may replace timestamp_ns (a replay sends the
    // recorded time), and clears `send` when it has no frame (a replay past its recording's end):
    // nothing goes out, and no block id is used.
    bool send = true;
};

// Fills `data` (width × height × bytes_per_pixel, row-major, little-endian words) for `request`.
// Called on the device's stream thread.
using Renderer = std::function<void(FrameRequest& request, std::span<std::uint8_t> data)>;

struct GvDeviceConfig {
    std::string address = "127.0.0.1";  // any 127.x.y.z: several devices side by side
    std::string serial = "HG-VCELL";
    std::string genicam_file;       // "" = Aravis's built-in fake camera description
    double packet_loss = 0.0;       // fraction of first transmissions the link drops
    std::uint64_t loss_seed = 1;    // the drops are reproducible
    int resend_buffer_frames = 64;  // frames kept for PACKETRESEND
    // ≥ 2: each frame goes out as a GVSP multi-part payload, its rows split into this many equal
    // parts (range, intensity, ... as 3D sensors send them); the renderer writes them one after
    // the other.
    int multipart_parts = 0;
    // A fault to inject: the first `lose_scan_start` frames of an acquisition are not sent (the
    // axis starts with frame 0 all the same), in the first `lose_scan_start_count` acquisitions,
    // 0 = in every one. A receiver sees a scan whose start is missing.
    int lose_scan_start = 0;
    int lose_scan_start_count = 0;
    // The renderer sets the pace: each frame goes out when the renderer returns, not at the
    // frame period, stamped with the time it was asked for (or the renderer's timestamp). A
    // replay times its recorded frames itself (docs/virtual-cell.md "Replay").
    bool renderer_paces = false;
};

struct GvDeviceStats {
    std::uint64_t frames = 0, packets = 0;
    std::uint64_t skipped = 0;             // frames not rendered: the device fell a second behind
    std::uint64_t dropped = 0;             // first transmissions dropped on purpose
    std::uint64_t start_frames_lost = 0;   // frames not sent: lose_scan_start
    std::uint64_t resend_requests = 0;     // PACKETRESEND commands received
    std::uint64_t resent = 0;              // packets sent again
    std::uint64_t resend_unavailable = 0;  // asked for packets no longer buffered
    // Rendering slower than real time: frames that went out more than a frame period after
    // their timestamp (their content is still that of their time), the largest such delay, and
    // frames rendered in vain because the acquisition stopped meanwhile (a scan's lost tail).
    std::uint64_t late = 0;
    std::int64_t max_late_us = 0;
    std::uint64_t stopped_while_rendered = 0;
};

// Thread safety: stats() from any thread; the renderer runs on the stream thread.
class GvDevice {
  public:
    // Binds GVCP port 3956 on the address and starts the control and stream threads. The error
    // names the address (e.g. already in use by another device).
    static core::Result<std::unique_ptr<GvDevice>> start(const GvDeviceConfig& config,
                                                         Renderer renderer);
    ~GvDevice();  // stops both threads; the device vanishes from the network
    GvDevice(const GvDevice&) = delete;
    GvDevice& operator=(const GvDevice&) = delete;

    GvDeviceStats stats() const;
    const GvDeviceConfig& config() const;

  private:
    struct Impl;
    explicit GvDevice(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::vcell
