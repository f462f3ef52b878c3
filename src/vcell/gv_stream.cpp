// The virtual camera's stream channel (GVSP): frames rendered at the camera's pace, cut into
// packets (image or multi-part payloads), sent with the link's deliberate losses, and kept for
// PACKETRESEND. The control channel is in gv_device.cpp.
#include <sys/socket.h>

#include <algorithm>
#include <chrono>
#include <thread>
#include <vector>

#include "gv_device_impl.hpp"

namespace hotgauge::vcell {
namespace {

using detail::put16;
using detail::put32;
using detail::real_time_us;

// The bootstrap register of the stream channel's packet size (GigE Vision 2.x, SCPS).
constexpr std::uint32_t kStreamPacketSizeRegister = 0x0d04;

// Stream protocol (GVSP): packet formats, image payload type, and the IP + UDP + GVSP header
// bytes that the packet size register includes.
constexpr std::uint8_t kGvspLeader = 0x01, kGvspTrailer = 0x02, kGvspPayload = 0x03;
constexpr std::uint8_t kGvspMultipart = 0x07;
constexpr std::uint16_t kPayloadImage = 0x0001, kPayloadMultipart = 0x000a;
constexpr std::uint16_t kPartData2dImage = 0x0001;
constexpr int kGvspOverheadBytes = 20 + 8 + 8;
// Extended ids: IP + UDP + the 20-byte extended header + the 8-byte part header of each packet.
constexpr int kGvspMultipartOverheadBytes = 20 + 8 + 20 + 8;

std::vector<std::uint8_t> gvsp_header(std::uint16_t block_id, std::uint8_t format,
                                      std::uint32_t packet_id) {
    std::vector<std::uint8_t> b;
    put16(b, 0);  // status: success
    put16(b, block_id);
    put32(b, static_cast<std::uint32_t>(format) << 24 | (packet_id & 0xffffff));
    return b;
}

// One image payload (GVSP payload type 0x0001), standard ids: leader, data, trailer.
std::vector<std::vector<std::uint8_t>> image_packets(const FrameRequest& req,
                                                     std::uint32_t packet_size,
                                                     const std::vector<std::uint8_t>& data) {
    const std::size_t chunk = packet_size - kGvspOverheadBytes;
    const auto block = static_cast<std::uint16_t>(req.frame_id);
    std::vector<std::vector<std::uint8_t>> packets;
    std::uint32_t packet_id = 0;
    auto leader = gvsp_header(block, kGvspLeader, packet_id++);
    put16(leader, 0);  // flags
    put16(leader, kPayloadImage);
    const auto ts = static_cast<std::uint64_t>(req.timestamp_ns);
    put32(leader, static_cast<std::uint32_t>(ts >> 32));
    put32(leader, static_cast<std::uint32_t>(ts & 0xffffffffu));
    put32(leader, req.pixel_format);
    put32(leader, static_cast<std::uint32_t>(req.width));
    put32(leader, static_cast<std::uint32_t>(req.height));
    put32(leader, static_cast<std::uint32_t>(req.offset_x));
    put32(leader, static_cast<std::uint32_t>(req.offset_y));
    put16(leader, 0);  // padding x
    put16(leader, 0);  // padding y
    packets.push_back(std::move(leader));
    for (std::size_t offset = 0; offset < data.size(); offset += chunk) {
        auto p = gvsp_header(block, kGvspPayload, packet_id++);
        const std::size_t n = std::min(chunk, data.size() - offset);
        p.insert(p.end(), data.begin() + static_cast<std::ptrdiff_t>(offset),
                 data.begin() + static_cast<std::ptrdiff_t>(offset + n));
        packets.push_back(std::move(p));
    }
    auto trailer = gvsp_header(block, kGvspTrailer, packet_id++);
    put16(trailer, 0);
    put16(trailer, kPayloadImage);
    put32(trailer, static_cast<std::uint32_t>(req.height));
    packets.push_back(std::move(trailer));
    return packets;
}

// GigE Vision 2.1 extended-id header: status, flags, EI bit + format + (leader) part count,
// 64-bit block id, 32-bit packet id.
std::vector<std::uint8_t> gvsp_extended_header(std::uint64_t block_id, std::uint8_t format,
                                               std::uint32_t low_byte, std::uint32_t packet_id) {
    std::vector<std::uint8_t> b;
    put16(b, 0);  // status: success
    put16(b, 0);  // flags
    put32(b, 0x80000000u | static_cast<std::uint32_t>(format) << 24 | (low_byte & 0xff));
    put32(b, static_cast<std::uint32_t>(block_id >> 32));
    put32(b, static_cast<std::uint32_t>(block_id & 0xffffffffu));
    put32(b, packet_id);
    return b;
}

// A multi-part payload (type 0x000A), as 3D sensors send range and intensity: the frame's rows
// split into `n_parts` equal parts, each a 2D image part; extended ids (Aravis reads the part
// count from the leader's low byte, which standard ids would take for the packet id).
std::vector<std::vector<std::uint8_t>> multipart_packets(const FrameRequest& req,
                                                         std::uint32_t packet_size,
                                                         const std::vector<std::uint8_t>& data,
                                                         int n_parts) {
    const std::size_t chunk = packet_size - kGvspMultipartOverheadBytes;
    const std::uint64_t block = req.frame_id;
    const int part_rows = req.height / n_parts;
    const std::size_t part_bytes = static_cast<std::size_t>(req.width) *
                                   static_cast<std::size_t>(part_rows) *
                                   static_cast<std::size_t>(std::max(1, req.bytes_per_pixel));
    std::vector<std::vector<std::uint8_t>> packets;
    std::uint32_t packet_id = 0;
    auto leader =
        gvsp_extended_header(block, kGvspLeader, static_cast<std::uint32_t>(n_parts), packet_id++);
    put16(leader, 0);  // flags
    put16(leader, kPayloadMultipart);
    const auto ts = static_cast<std::uint64_t>(req.timestamp_ns);
    put32(leader, static_cast<std::uint32_t>(ts >> 32));
    put32(leader, static_cast<std::uint32_t>(ts & 0xffffffffu));
    for (int i = 0; i < n_parts; ++i) {  // 48 bytes of part description each
        put16(leader, kPartData2dImage);
        put16(leader, 0);  // part length, high 16 bits
        put32(leader, static_cast<std::uint32_t>(part_bytes));
        put32(leader, req.pixel_format);
        put16(leader, 0);                              // reserved
        leader.push_back(0);                           // source id
        leader.push_back(0);                           // additional zones
        put32(leader, 0);                              // zone directions
        put16(leader, static_cast<std::uint32_t>(i));  // data purpose id: the component
        put16(leader, 0);                              // region id
        put32(leader, static_cast<std::uint32_t>(req.width));
        put32(leader, static_cast<std::uint32_t>(part_rows));
        put32(leader, static_cast<std::uint32_t>(req.offset_x));
        put32(leader, static_cast<std::uint32_t>(req.offset_y));
        put16(leader, 0);  // padding x
        put16(leader, 0);  // padding y
        put32(leader, 0);  // reserved
    }
    packets.push_back(std::move(leader));
    for (int i = 0; i < n_parts; ++i) {
        const std::size_t base = static_cast<std::size_t>(i) * part_bytes;
        for (std::size_t offset = 0; offset < part_bytes && base + offset < data.size();
             offset += chunk) {
            auto p = gvsp_extended_header(block, kGvspMultipart, 0, packet_id++);
            const std::size_t n =
                std::min({chunk, part_bytes - offset, data.size() - base - offset});
            const std::uint64_t at = base + offset;     // where the bytes go in the whole buffer
            p.push_back(static_cast<std::uint8_t>(i));  // part id
            p.push_back(0);                             // zone info
            put16(p, static_cast<std::uint32_t>(at >> 32));
            put32(p, static_cast<std::uint32_t>(at & 0xffffffffu));
            p.insert(p.end(), data.begin() + static_cast<std::ptrdiff_t>(at),
                     data.begin() + static_cast<std::ptrdiff_t>(at + n));
            packets.push_back(std::move(p));
        }
    }
    auto trailer = gvsp_extended_header(block, kGvspTrailer, 0, packet_id++);
    put16(trailer, 0);
    put16(trailer, kPayloadMultipart);
    put32(trailer, 0);
    packets.push_back(std::move(trailer));
    return packets;
}

}  // namespace

void GvDevice::Impl::run_stream() {
    std::mt19937_64 loss_rng(config.loss_seed);
    std::vector<std::uint8_t> data;
    StreamState s;
    while (!stop) {
        const StreamTiming timing = look_at_camera(s);
        if (!timing.streaming) {
            s.streaming_before = false;
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
            continue;
        }
        schedule_frame(s, timing);
        // Until the frame's time, in slices so that stop() is prompt.
        while (!stop && real_time_us() < s.next_us)
            std::this_thread::sleep_for(std::chrono::microseconds(
                std::min<std::int64_t>(20000, s.next_us - real_time_us())));
        if (stop) break;

        FrameRequest req;
        std::uint32_t packet_size = 0;
        if (!read_frame_request(s, req, packet_size)) continue;
        if (!render_frame(s, req, data)) continue;
        if (!frame_goes_out(s, req, timing.period_us)) continue;
        send_frame(req, packet_size, data, loss_rng);
    }
}

// Whether the camera streams (control taken, acquisition on), whether an AcquisitionStart came
// since the last look, and the camera's frame times.
GvDevice::Impl::StreamTiming GvDevice::Impl::look_at_camera(StreamState& s) {
    StreamTiming t;
    std::lock_guard lock(camera_mutex);
    t.streaming = arv_fake_camera_get_control_channel_privilege(camera) != 0 &&
                  arv_fake_camera_get_acquisition_status(camera) != 0;
    t.restarted = s.starts_seen != acquisition_starts;
    s.starts_seen = acquisition_starts;
    if (t.streaming) {
        arv_fake_camera_get_sleep_time_for_next_frame(camera, &t.aligned_us);
        std::uint32_t p = 0;
        arv_fake_camera_read_register(camera, ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US,
                                      &p);
        t.period_us = p > 0 ? p : 1'000'000;
    }
    return t;
}

// Frames follow each other at the period from the first one, like exposures of a camera. One
// rendered late goes out late with its own timestamp (a camera's frame buffer); only when a
// second behind does the device skip ahead, and count it.
void GvDevice::Impl::schedule_frame(StreamState& s, const StreamTiming& t) {
    if (!s.streaming_before || t.restarted) {
        ++s.acquisition;
        s.frame_in_acquisition = 0;
        s.streaming_before = true;
        s.next_us =
            config.renderer_paces ? real_time_us() : static_cast<std::int64_t>(t.aligned_us);
    } else if (config.renderer_paces) {
        s.next_us = real_time_us();
    } else {
        s.next_us += t.period_us;
        if (real_time_us() - s.next_us > 1'000'000) {
            const std::int64_t behind =
                (static_cast<std::int64_t>(t.aligned_us) - s.next_us) / t.period_us;
            s.next_us = static_cast<std::int64_t>(t.aligned_us);
            std::lock_guard lock(stats_mutex);
            stats.skipped += static_cast<std::uint64_t>(std::max<std::int64_t>(0, behind));
        }
    }
}

// The frame the client configured, if one is due now (free run, or a software trigger), and
// where it goes; false: none.
bool GvDevice::Impl::read_frame_request(const StreamState& s, FrameRequest& req,
                                        std::uint32_t& packet_size) {
    std::lock_guard lock(camera_mutex);
    // Stopped, or stopped and started again while this frame waited: not sent; a new
    // acquisition begins with the next turn.
    if (arv_fake_camera_get_acquisition_status(camera) == 0 || s.starts_seen != acquisition_starts)
        return false;
    const bool fire = arv_fake_camera_is_in_free_running_mode(camera) ||
                      (arv_fake_camera_is_in_software_trigger_mode(camera) &&
                       arv_fake_camera_check_and_acknowledge_software_trigger(camera));
    if (!fire) return false;
    auto reg = [&](std::uint32_t address) {
        std::uint32_t v = 0;
        arv_fake_camera_read_register(camera, address, &v);
        return v;
    };
    req.width = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_WIDTH));
    req.height = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_HEIGHT));
    req.offset_x = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_X_OFFSET));
    req.offset_y = static_cast<int>(reg(ARV_FAKE_CAMERA_REGISTER_Y_OFFSET));
    req.pixel_format = reg(ARV_FAKE_CAMERA_REGISTER_PIXEL_FORMAT);
    req.exposure_us = reg(ARV_FAKE_CAMERA_REGISTER_EXPOSURE_TIME_US);
    req.acquisition_start_ns = acquisition_start_ns;
    packet_size = reg(kStreamPacketSizeRegister) & 0xffff;
    GSocketAddress* destination = arv_fake_camera_get_stream_address(camera);
    sockaddr_in native{};
    const bool ok =
        destination && g_socket_address_to_native(destination, &native, sizeof native, nullptr);
    if (destination) g_object_unref(destination);
    if (!ok) return false;
    std::lock_guard resend_lock(resend_mutex);
    stream_destination = native;
    return true;
}

// Numbers the frame and has it rendered into `data`; false: the renderer has no frame.
bool GvDevice::Impl::render_frame(StreamState& s, FrameRequest& req,
                                  std::vector<std::uint8_t>& data) {
    req.bytes_per_pixel = static_cast<int>(ARV_PIXEL_FORMAT_BIT_PER_PIXEL(req.pixel_format) / 8);
    const std::uint32_t previous_id = s.frame_id;
    s.frame_id = s.frame_id % 65535 + 1;  // 16-bit block ids; 0 is reserved
    req.frame_id = s.frame_id;
    req.timestamp_ns = s.next_us * 1000;
    req.acquisition = s.acquisition;
    req.frame_in_acquisition = s.frame_in_acquisition++;
    data.assign(static_cast<std::size_t>(req.width) * static_cast<std::size_t>(req.height) *
                    static_cast<std::size_t>(std::max(1, req.bytes_per_pixel)),
                0);
    if (renderer) renderer(req, data);
    if (!req.send) {  // no frame: its block id is not used
        s.frame_id = previous_id;
        return false;
    }
    return true;
}

// Whether a rendered frame is sent: not when its acquisition ended meanwhile, nor when the
// injected fault loses it; counts those, and frames that are late.
bool GvDevice::Impl::frame_goes_out(const StreamState& s, const FrameRequest& req,
                                    std::int64_t period_us) {
    {
        // Stopped, or stopped and started again, while it was rendered: dropped, as a
        // camera drops the frame in progress (it belongs to no acquisition now).
        std::lock_guard lock(camera_mutex);
        if (arv_fake_camera_get_acquisition_status(camera) == 0 ||
            s.starts_seen != acquisition_starts) {
            std::lock_guard stats_lock(stats_mutex);
            ++stats.stopped_while_rendered;
            return false;
        }
    }
    if (const std::int64_t late_us = real_time_us() - s.next_us - period_us; late_us > 0) {
        std::lock_guard lock(stats_mutex);
        ++stats.late;
        stats.max_late_us = std::max(stats.max_late_us, late_us);
    }
    const bool lose_start =
        req.frame_in_acquisition < config.lose_scan_start &&
        (config.lose_scan_start_count == 0 ||
         s.acquisition <= static_cast<std::uint64_t>(config.lose_scan_start_count));
    if (lose_start) {
        std::lock_guard lock(stats_mutex);
        ++stats.start_frames_lost;
        return false;
    }
    return true;
}

void GvDevice::Impl::send_frame(const FrameRequest& req, std::uint32_t packet_size,
                                const std::vector<std::uint8_t>& data, std::mt19937_64& loss_rng) {
    if (packet_size < 576 || packet_size > 16000) packet_size = 1500;
    const auto block = static_cast<std::uint16_t>(req.frame_id);
    SentFrame frame{block, config.multipart_parts >= 2
                               ? multipart_packets(req, packet_size, data, config.multipart_parts)
                               : image_packets(req, packet_size, data)};

    std::uint64_t dropped = 0;
    std::bernoulli_distribution drop(config.packet_loss);
    sockaddr_in destination{};
    {
        std::lock_guard lock(resend_mutex);
        destination = stream_destination;
    }
    for (const auto& p : frame.packets) {
        if (config.packet_loss > 0 && drop(loss_rng)) {
            ++dropped;
            continue;
        }
        ::sendto(gvsp_fd, p.data(), p.size(), 0, reinterpret_cast<const sockaddr*>(&destination),
                 sizeof destination);
    }
    const std::uint64_t n_packets = frame.packets.size();
    {
        std::lock_guard lock(resend_mutex);
        sent.push_back(std::move(frame));
        while (sent.size() > static_cast<std::size_t>(std::max(1, config.resend_buffer_frames)))
            sent.pop_front();
    }
    std::lock_guard lock(stats_mutex);
    ++stats.frames;
    stats.packets += n_packets;
    stats.dropped += dropped;
}

}  // namespace hotgauge::vcell
