#include "hotgauge/vcell/gv_device.hpp"

#include <arpa/inet.h>
#include <arv.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <deque>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "log.hpp"

namespace hotgauge::vcell {
namespace {

// GigE Vision 2.x control protocol (GVCP, UDP port 3956): command and acknowledge codes, status
// codes and bootstrap registers used here.
constexpr std::uint16_t kGvcpPort = 3956;
constexpr std::uint8_t kCommandKey = 0x42;
constexpr std::uint8_t kFlagAckRequired = 0x01;
constexpr std::uint8_t kFlagExtendedIds = 0x10;
constexpr std::uint16_t kDiscoveryCmd = 0x0002, kDiscoveryAck = 0x0003;
constexpr std::uint16_t kPacketResendCmd = 0x0040;
constexpr std::uint16_t kReadRegCmd = 0x0080, kReadRegAck = 0x0081;
constexpr std::uint16_t kWriteRegCmd = 0x0082, kWriteRegAck = 0x0083;
constexpr std::uint16_t kReadMemCmd = 0x0084, kReadMemAck = 0x0085;
constexpr std::uint16_t kWriteMemCmd = 0x0086, kWriteMemAck = 0x0087;
constexpr std::uint16_t kStatusNotImplemented = 0x8001, kStatusInvalidParameter = 0x8002;
constexpr std::uint16_t kStatusAccessDenied = 0x8006;
constexpr std::uint32_t kDiscoveryDataSize = 0xf8;
constexpr std::uint32_t kGvcpCapabilityRegister = 0x0934;
constexpr std::uint32_t kCapabilityWriteMemory = 1u << 1, kCapabilityPacketResend = 1u << 2;
constexpr std::uint32_t kStreamPacketSizeRegister = 0x0d04;
constexpr std::size_t kMaxReadMemory = 536;  // GVCP's limit per READMEM
// Stream protocol (GVSP): packet formats, image payload type, and the IP + UDP + GVSP header
// bytes that the packet size register includes.
constexpr std::uint8_t kGvspLeader = 0x01, kGvspTrailer = 0x02, kGvspPayload = 0x03;
constexpr std::uint8_t kGvspMultipart = 0x07;
constexpr std::uint16_t kPayloadImage = 0x0001, kPayloadMultipart = 0x000a;
constexpr std::uint16_t kPartData2dImage = 0x0001;
constexpr int kGvspOverheadBytes = 20 + 8 + 8;
// Extended ids: IP + UDP + the 20-byte extended header + the 8-byte part header of each packet.
constexpr int kGvspMultipartOverheadBytes = 20 + 8 + 20 + 8;

void put16(std::vector<std::uint8_t>& b, std::uint32_t v) {
    b.push_back(static_cast<std::uint8_t>(v >> 8));
    b.push_back(static_cast<std::uint8_t>(v));
}
void put32(std::vector<std::uint8_t>& b, std::uint32_t v) {
    put16(b, v >> 16);
    put16(b, v & 0xffff);
}
std::uint16_t get16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] << 8 | p[1]); }
std::uint32_t get32(const std::uint8_t* p) {
    return static_cast<std::uint32_t>(p[0]) << 24 | static_cast<std::uint32_t>(p[1]) << 16 |
           static_cast<std::uint32_t>(p[2]) << 8 | p[3];
}

std::vector<std::uint8_t> ack_header(std::uint16_t status, std::uint16_t answer, std::size_t length,
                                     std::uint16_t id) {
    std::vector<std::uint8_t> b;
    b.reserve(8 + length);
    put16(b, status);
    put16(b, answer);
    put16(b, static_cast<std::uint32_t>(length));
    put16(b, id);
    return b;
}

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

std::int64_t real_time_us() { return g_get_real_time(); }

bool same_endpoint(const sockaddr_in& a, const sockaddr_in& b) {
    return a.sin_addr.s_addr == b.sin_addr.s_addr && a.sin_port == b.sin_port;
}

}  // namespace

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

    ~Impl() {
        stop = true;
        if (control.joinable()) control.join();
        if (stream.joinable()) stream.join();
        if (gvcp_fd >= 0) ::close(gvcp_fd);
        if (gvsp_fd >= 0) ::close(gvsp_fd);
        if (camera) g_object_unref(camera);
    }

    void run_control();
    void handle(const std::uint8_t* packet, std::size_t size, const sockaddr_in& from);
    void handle_resend(const std::uint8_t* payload, std::size_t size, std::uint8_t flags);
    void run_stream();
    void send_frame(const FrameRequest& request, std::uint32_t packet_size,
                    const std::vector<std::uint8_t>& data, std::mt19937_64& loss_rng);
};

void GvDevice::Impl::run_control() {
    std::vector<std::uint8_t> buf(65536);
    while (!stop) {
        pollfd p{gvcp_fd, POLLIN, 0};
        if (::poll(&p, 1, 50) <= 0) continue;
        sockaddr_in from{};
        socklen_t from_len = sizeof from;
        const ssize_t n = ::recvfrom(gvcp_fd, buf.data(), buf.size(), 0,
                                     reinterpret_cast<sockaddr*>(&from), &from_len);
        if (n > 0) handle(buf.data(), static_cast<std::size_t>(n), from);
    }
}

void GvDevice::Impl::handle(const std::uint8_t* packet, std::size_t size, const sockaddr_in& from) {
    if (size < 8 || packet[0] != kCommandKey) return;  // not a GVCP command: ignored, as devices do
    const std::uint8_t flags = packet[1];
    const std::uint16_t command = get16(packet + 2);
    const std::size_t length = get16(packet + 4);
    const std::uint16_t id = get16(packet + 6);
    if (8 + length > size) return;
    const std::uint8_t* payload = packet + 8;
    if (command == kPacketResendCmd) {  // no acknowledge (GigE Vision: PACKETRESEND has none)
        handle_resend(payload, length, flags);
        return;
    }

    std::vector<std::uint8_t> ack;
    std::lock_guard camera_lock(camera_mutex);
    // Control channel privilege: the controller keeps it while it talks within the heartbeat
    // timeout; others may read but not write. Its age on the monotonic clock: a step of the
    // wall clock (a VM resumed, NTP) is no silence of the controller's.
    const std::int64_t now_us = g_get_monotonic_time();
    const bool acquiring_before = arv_fake_camera_get_acquisition_status(camera) != 0;
    bool write_access = true;
    if (has_controller) {
        const auto timeout_ms = arv_fake_camera_get_heartbeat_timeout(camera);
        if (now_us - controller_time_us > static_cast<std::int64_t>(timeout_ms) * 1000) {
            detail::log().warn("{}: controller heartbeat timeout, control released", where);
            has_controller = false;
            arv_fake_camera_set_control_channel_privilege(camera, 0);
        } else {
            write_access = same_endpoint(from, controller);
            if (write_access) controller_time_us = now_us;
        }
    }
    switch (command) {
        case kDiscoveryCmd: {
            ack = ack_header(0, kDiscoveryAck, kDiscoveryDataSize, id);
            ack.resize(8 + kDiscoveryDataSize);
            arv_fake_camera_read_memory(camera, 0, kDiscoveryDataSize, ack.data() + 8);
            break;
        }
        case kReadRegCmd: {
            if (length == 0 || length % 4 != 0) {
                ack = ack_header(kStatusInvalidParameter, kReadRegAck, 0, id);
                break;
            }
            ack = ack_header(0, kReadRegAck, length, id);
            for (std::size_t i = 0; i < length; i += 4) {
                const std::uint32_t address = get32(payload + i);
                std::uint32_t value = 0;
                arv_fake_camera_read_register(camera, address, &value);
                // The resend buffer is ours: say so where clients look for it.
                if (address == kGvcpCapabilityRegister)
                    value |= kCapabilityPacketResend | kCapabilityWriteMemory;
                put32(ack, value);
            }
            break;
        }
        case kWriteRegCmd: {
            if (!write_access) {
                ack = ack_header(kStatusAccessDenied, kWriteRegAck, 0, id);
                break;
            }
            if (length == 0 || length % 8 != 0) {
                ack = ack_header(kStatusInvalidParameter, kWriteRegAck, 0, id);
                break;
            }
            std::uint32_t written = 0;
            for (std::size_t i = 0; i < length; i += 8) {
                arv_fake_camera_write_register(camera, get32(payload + i), get32(payload + i + 4));
                ++written;
            }
            ack = ack_header(0, kWriteRegAck, 4, id);
            put32(ack, written);
            break;
        }
        case kReadMemCmd: {
            if (length < 8) {
                ack = ack_header(kStatusInvalidParameter, kReadMemAck, 0, id);
                break;
            }
            const std::uint32_t address = get32(payload);
            const std::uint32_t count = get32(payload + 4) & 0xffff;
            if (count == 0 || count > kMaxReadMemory || count % 4 != 0) {
                ack = ack_header(kStatusInvalidParameter, kReadMemAck, 0, id);
                break;
            }
            ack = ack_header(0, kReadMemAck, 4 + count, id);
            put32(ack, address);
            ack.resize(ack.size() + count);
            arv_fake_camera_read_memory(camera, address, count, ack.data() + 12);
            break;
        }
        case kWriteMemCmd: {
            if (!write_access) {
                ack = ack_header(kStatusAccessDenied, kWriteMemAck, 0, id);
                break;
            }
            if (length < 8) {
                ack = ack_header(kStatusInvalidParameter, kWriteMemAck, 0, id);
                break;
            }
            const std::uint32_t address = get32(payload);
            std::vector<std::uint8_t> data(payload + 4, payload + length);
            arv_fake_camera_write_memory(camera, address, static_cast<std::uint32_t>(data.size()),
                                         data.data());
            ack = ack_header(0, kWriteMemAck, 4, id);
            put32(ack, address);
            break;
        }
        default:
            ack = ack_header(kStatusNotImplemented, static_cast<std::uint16_t>(command + 1), 0, id);
    }
    if (!acquiring_before && arv_fake_camera_get_acquisition_status(camera) != 0) {
        ++acquisition_starts;
        acquisition_start_ns = real_time_us() * 1000;
    }
    // The first to take the privilege becomes the controller; giving it up ends that.
    const bool privileged = arv_fake_camera_get_control_channel_privilege(camera) != 0;
    if (!has_controller && privileged) {
        has_controller = true;
        controller = from;
        controller_time_us = now_us;
        detail::log().info("{}: controller {}:{}", where, inet_ntoa(from.sin_addr),
                           ntohs(from.sin_port));
    } else if (has_controller && !privileged) {
        has_controller = false;
    }
    if ((flags & kFlagAckRequired) || command == kDiscoveryCmd)
        ::sendto(gvcp_fd, ack.data(), ack.size(), 0, reinterpret_cast<const sockaddr*>(&from),
                 sizeof from);
}

void GvDevice::Impl::handle_resend(const std::uint8_t* payload, std::size_t size,
                                   std::uint8_t flags) {
    std::uint64_t block = 0;
    std::uint32_t first = 0, last = 0;
    if (flags & kFlagExtendedIds) {
        if (size < 20) return;
        first = get32(payload + 4);
        last = get32(payload + 8);
        block = static_cast<std::uint64_t>(get32(payload + 12)) << 32 | get32(payload + 16);
    } else {
        if (size < 12) return;
        block = get32(payload) & 0xffff;
        first = get32(payload + 4) & 0xffffff;
        last = get32(payload + 8) & 0xffffff;
    }
    std::uint64_t resent = 0, unavailable = 0;
    {
        std::lock_guard lock(resend_mutex);
        const SentFrame* frame = nullptr;
        for (const auto& f : sent)
            if (f.block_id == block) frame = &f;
        for (std::uint64_t p = first; p <= last && p < first + 100000; ++p) {
            if (!frame || p >= frame->packets.size()) {
                ++unavailable;
                continue;
            }
            const auto& bytes = frame->packets[p];
            ::sendto(gvsp_fd, bytes.data(), bytes.size(), 0,
                     reinterpret_cast<const sockaddr*>(&stream_destination),
                     sizeof stream_destination);
            ++resent;
        }
    }
    std::lock_guard lock(stats_mutex);
    ++stats.resend_requests;
    stats.resent += resent;
    stats.resend_unavailable += unavailable;
}

void GvDevice::Impl::run_stream() {
    std::mt19937_64 loss_rng(config.loss_seed);
    std::vector<std::uint8_t> data;
    std::uint64_t acquisition = 0;
    std::int64_t frame_in_acquisition = 0;
    std::uint32_t frame_id = 0;
    bool streaming_before = false;
    std::uint64_t starts_seen = 0;
    std::int64_t next_us = 0;  // this frame's time, µs
    while (!stop) {
        guint64 aligned_us = 0;  // the fake camera's next frame time on its period grid
        std::int64_t period_us = 0;
        bool streaming = false, restarted = false;
        {
            std::lock_guard lock(camera_mutex);
            streaming = arv_fake_camera_get_control_channel_privilege(camera) != 0 &&
                        arv_fake_camera_get_acquisition_status(camera) != 0;
            restarted = starts_seen != acquisition_starts;
            starts_seen = acquisition_starts;
            if (streaming) {
                arv_fake_camera_get_sleep_time_for_next_frame(camera, &aligned_us);
                std::uint32_t p = 0;
                arv_fake_camera_read_register(
                    camera, ARV_FAKE_CAMERA_REGISTER_ACQUISITION_FRAME_PERIOD_US, &p);
                period_us = p > 0 ? p : 1'000'000;
            }
        }
        if (!streaming) {
            streaming_before = false;
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
            continue;
        }
        // Frames follow each other at the period from the first one, like exposures of a
        // camera. One rendered late goes out late with its own timestamp (a camera's frame
        // buffer); only when a second behind does the device skip ahead, and count it.
        if (!streaming_before || restarted) {
            ++acquisition;
            frame_in_acquisition = 0;
            streaming_before = true;
            next_us =
                config.renderer_paces ? real_time_us() : static_cast<std::int64_t>(aligned_us);
        } else if (config.renderer_paces) {
            next_us = real_time_us();
        } else {
            next_us += period_us;
            if (real_time_us() - next_us > 1'000'000) {
                const std::int64_t behind =
                    (static_cast<std::int64_t>(aligned_us) - next_us) / period_us;
                next_us = static_cast<std::int64_t>(aligned_us);
                std::lock_guard lock(stats_mutex);
                stats.skipped += static_cast<std::uint64_t>(std::max<std::int64_t>(0, behind));
            }
        }
        // Until the frame's time, in slices so that stop() is prompt.
        while (!stop && real_time_us() < next_us)
            std::this_thread::sleep_for(
                std::chrono::microseconds(std::min<std::int64_t>(20000, next_us - real_time_us())));
        if (stop) break;

        FrameRequest req;
        std::uint32_t packet_size = 0;
        {
            std::lock_guard lock(camera_mutex);
            // Stopped, or stopped and started again while this frame waited: not sent; a new
            // acquisition begins with the next turn.
            if (arv_fake_camera_get_acquisition_status(camera) == 0 ||
                starts_seen != acquisition_starts)
                continue;
            const bool fire = arv_fake_camera_is_in_free_running_mode(camera) ||
                              (arv_fake_camera_is_in_software_trigger_mode(camera) &&
                               arv_fake_camera_check_and_acknowledge_software_trigger(camera));
            if (!fire) continue;
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
            const bool ok = destination && g_socket_address_to_native(destination, &native,
                                                                      sizeof native, nullptr);
            if (destination) g_object_unref(destination);
            if (!ok) continue;
            std::lock_guard resend_lock(resend_mutex);
            stream_destination = native;
        }
        req.bytes_per_pixel =
            static_cast<int>(ARV_PIXEL_FORMAT_BIT_PER_PIXEL(req.pixel_format) / 8);
        const std::uint32_t previous_id = frame_id;
        frame_id = frame_id % 65535 + 1;  // 16-bit block ids; 0 is reserved
        req.frame_id = frame_id;
        req.timestamp_ns = next_us * 1000;
        req.acquisition = acquisition;
        req.frame_in_acquisition = frame_in_acquisition++;
        data.assign(static_cast<std::size_t>(req.width) * static_cast<std::size_t>(req.height) *
                        static_cast<std::size_t>(std::max(1, req.bytes_per_pixel)),
                    0);
        if (renderer) renderer(req, data);
        if (!req.send) {  // no frame: its block id is not used
            frame_id = previous_id;
            continue;
        }
        {
            // Stopped, or stopped and started again, while it was rendered: dropped, as a
            // camera drops the frame in progress (it belongs to no acquisition now).
            std::lock_guard lock(camera_mutex);
            if (arv_fake_camera_get_acquisition_status(camera) == 0 ||
                starts_seen != acquisition_starts) {
                std::lock_guard stats_lock(stats_mutex);
                ++stats.stopped_while_rendered;
                continue;
            }
        }
        if (const std::int64_t late_us = real_time_us() - next_us - period_us; late_us > 0) {
            std::lock_guard lock(stats_mutex);
            ++stats.late;
            stats.max_late_us = std::max(stats.max_late_us, late_us);
        }
        const bool lose_start =
            req.frame_in_acquisition < config.lose_scan_start &&
            (config.lose_scan_start_count == 0 ||
             acquisition <= static_cast<std::uint64_t>(config.lose_scan_start_count));
        if (lose_start) {
            std::lock_guard lock(stats_mutex);
            ++stats.start_frames_lost;
            continue;
        }
        send_frame(req, packet_size, data, loss_rng);
    }
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

GvDevice::GvDevice(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GvDevice::~GvDevice() = default;

GvDeviceStats GvDevice::stats() const {
    std::lock_guard lock(impl_->stats_mutex);
    return impl_->stats;
}

const GvDeviceConfig& GvDevice::config() const { return impl_->config; }

core::Result<std::unique_ptr<GvDevice>> GvDevice::start(const GvDeviceConfig& config,
                                                        Renderer renderer) {
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->renderer = std::move(renderer);
    impl->where = "virtual camera " + config.serial + " at " + config.address;
    if (config.packet_loss < 0 || config.packet_loss >= 1)
        return core::make_error(impl->where + ": packet loss must be in [0, 1)");
    if (config.lose_scan_start < 0 || config.lose_scan_start_count < 0)
        return core::make_error(impl->where + ": lose_scan_start and its count must be >= 0");
    in_addr address{};
    if (::inet_pton(AF_INET, config.address.c_str(), &address) != 1)
        return core::make_error(impl->where + ": not an IPv4 address");

    auto bind_udp = [&](std::uint16_t port) -> core::Result<int> {
        const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        if (fd < 0) return core::make_error(impl->where + ": socket: " + std::strerror(errno));
        sockaddr_in sa{};
        sa.sin_family = AF_INET;
        sa.sin_addr = address;
        sa.sin_port = htons(port);
        if (::bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0) {
            const int err = errno;
            ::close(fd);
            return core::make_error(impl->where + ":" + std::to_string(port) + ": " +
                                    std::strerror(err) +
                                    (err == EADDRINUSE ? " (another GigE Vision device?)" : ""));
        }
        return fd;
    };
    auto gvcp = bind_udp(kGvcpPort);
    if (!gvcp) return gvcp.error();
    impl->gvcp_fd = *gvcp;
    auto gvsp = bind_udp(0);
    if (!gvsp) return gvsp.error();
    impl->gvsp_fd = *gvsp;
    // Room for a burst of full frames: the stream sends a frame's packets back to back.
    const int buffer_bytes = 8 << 20;
    ::setsockopt(impl->gvsp_fd, SOL_SOCKET, SO_SNDBUF, &buffer_bytes, sizeof buffer_bytes);

    impl->camera = arv_fake_camera_new_full(
        config.serial.c_str(), config.genicam_file.empty() ? nullptr : config.genicam_file.c_str());
    if (!impl->camera) return core::make_error(impl->where + ": Aravis fake camera not created");
    GInetAddress* inet = g_inet_address_new_from_string(config.address.c_str());
    arv_fake_camera_set_inet_address(impl->camera, inet);
    g_object_unref(inet);

    Impl* raw = impl.get();
    impl->control = std::thread([raw] { raw->run_control(); });
    impl->stream = std::thread([raw] { raw->run_stream(); });
    detail::log().info("{}: GVCP {}:{} up (packet loss {:.2f} %)", impl->where, config.address,
                       kGvcpPort, 100.0 * config.packet_loss);
    if (config.lose_scan_start > 0)
        detail::log().warn("{}: fault injected: the first {} frames of {} acquisitions are lost",
                           impl->where, config.lose_scan_start,
                           config.lose_scan_start_count == 0
                               ? std::string("all")
                               : "the first " + std::to_string(config.lose_scan_start_count));
    return std::unique_ptr<GvDevice>(new GvDevice(std::move(impl)));
}

}  // namespace hotgauge::vcell
