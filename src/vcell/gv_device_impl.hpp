#pragma once
// Private to the vcell module: the GigE Vision device's state, shared by its control channel
// (GVCP, gv_device.cpp) and its stream channel (GVSP, gv_stream.cpp).
// Thread safety: `camera` and the acquisition counters under camera_mutex, the resend buffer and
// the stream destination under resend_mutex, stats under stats_mutex; the controller fields are
// the control thread's, StreamState the stream thread's.
#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <deque>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/vcell/gv_device.hpp"

namespace hotgauge::vcell {
namespace detail {

// Big-endian fields, as GVCP and GVSP send them.
inline void put16(std::vector<std::uint8_t>& b, std::uint32_t v) {
    b.push_back(static_cast<std::uint8_t>(v >> 8));
    b.push_back(static_cast<std::uint8_t>(v));
}
inline void put32(std::vector<std::uint8_t>& b, std::uint32_t v) {
    put16(b, v >> 16);
    put16(b, v & 0xffff);
}
inline std::uint16_t get16(const std::uint8_t* p) {
    return static_cast<std::uint16_t>(p[0] << 8 | p[1]);
}
inline std::uint32_t get32(const std::uint8_t* p) {
    return static_cast<std::uint32_t>(p[0]) << 24 | static_cast<std::uint32_t>(p[1]) << 16 |
           static_cast<std::uint32_t>(p[2]) << 8 | p[3];
}

inline std::int64_t real_time_us() { return g_get_real_time(); }

}  // namespace detail

struct GvDevice::Impl {
    GvDeviceConfig config;
    Renderer renderer;
    std::string where;  // "virtual camera SERIAL at ADDRESS"
    ArvFakeCamera* camera = nullptr;
    std::mutex camera_mutex;  // ArvFakeCamera is not thread-safe: every call holds this
    int gvcp_fd = -1, gvsp_fd = -1;
    std::thread control, stream;
    std::atomic<bool> stop{false};

    // AcquisitionStart commands received: a stop and a start between two frames are still a new
    // acquisition (its frame 0 starts the axis again). Written and read under camera_mutex.
    std::uint64_t acquisition_starts = 0;
    std::int64_t acquisition_start_ns = 0;  // realtime of the last AcquisitionStart

    // Control thread only.
    bool has_controller = false;
    sockaddr_in controller{};
    std::int64_t controller_time_us = 0;

    // Resend buffer: the packets of recent frames, and where the stream went.
    std::mutex resend_mutex;
    struct SentFrame {
        std::uint16_t block_id;
        std::vector<std::vector<std::uint8_t>> packets;  // by packet id
    };
    std::deque<SentFrame> sent;
    sockaddr_in stream_destination{};

    mutable std::mutex stats_mutex;
    GvDeviceStats stats;

    // Stream thread only: where the stream is in its acquisitions and frame times.
    struct StreamState {
        std::uint64_t acquisition = 0;
        std::int64_t frame_in_acquisition = 0;
        std::uint32_t frame_id = 0;  // the last block id used
        bool streaming_before = false;
        std::uint64_t starts_seen = 0;  // acquisition_starts when last looked at
        std::int64_t next_us = 0;       // this frame's time, µs
    };
    // One look at the camera by the stream thread: streaming or not, and its frame times.
    struct StreamTiming {
        bool streaming = false, restarted = false;
        guint64 aligned_us = 0;  // the fake camera's next frame time on its period grid
        std::int64_t period_us = 0;
    };

    ~Impl() {
        stop = true;
        if (control.joinable()) control.join();
        if (stream.joinable()) stream.join();
        if (gvcp_fd >= 0) ::close(gvcp_fd);
        if (gvsp_fd >= 0) ::close(gvsp_fd);
        if (camera) g_object_unref(camera);
    }

    // Control channel (gv_device.cpp).
    void run_control();
    void handle(const std::uint8_t* packet, std::size_t size, const sockaddr_in& from);
    bool controller_write_access(const sockaddr_in& from, std::int64_t now_us);
    void note_camera_changes(bool acquiring_before, const sockaddr_in& from, std::int64_t now_us);
    void handle_resend(const std::uint8_t* payload, std::size_t size, std::uint8_t flags);

    // Stream channel (gv_stream.cpp).
    void run_stream();
    StreamTiming look_at_camera(StreamState& s);
    void schedule_frame(StreamState& s, const StreamTiming& timing);
    bool read_frame_request(const StreamState& s, FrameRequest& req, std::uint32_t& packet_size);
    bool render_frame(StreamState& s, FrameRequest& req, std::vector<std::uint8_t>& data);
    bool frame_goes_out(const StreamState& s, const FrameRequest& req, std::int64_t period_us);
    void send_frame(const FrameRequest& request, std::uint32_t packet_size,
                    const std::vector<std::uint8_t>& data, std::mt19937_64& loss_rng);
};

}  // namespace hotgauge::vcell
