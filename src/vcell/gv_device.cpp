// The virtual camera's control channel (GVCP) and its start: discovery, register and memory
// access to Aravis's fake camera, the controller's privilege and heartbeat, and PACKETRESEND
// from the resend buffer. The stream channel is in gv_stream.cpp.
#include "hotgauge/vcell/gv_device.hpp"

#include <poll.h>
#include <sys/socket.h>

#include <cerrno>
#include <cstring>
#include <string>
#include <vector>

#include "gv_device_impl.hpp"
#include "log.hpp"

namespace hotgauge::vcell {
namespace {

using detail::get16;
using detail::get32;
using detail::put16;
using detail::put32;
using detail::real_time_us;

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
constexpr std::size_t kMaxReadMemory = 536;  // GVCP's limit per READMEM

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

bool same_endpoint(const sockaddr_in& a, const sockaddr_in& b) {
    return a.sin_addr.s_addr == b.sin_addr.s_addr && a.sin_port == b.sin_port;
}

// A GVCP command (GigE Vision 2.x command header: key, flags, command, length, request id) and
// its payload, which lies inside the datagram received.
struct GvcpCommand {
    std::uint16_t command = 0;
    std::uint16_t id = 0;
    const std::uint8_t* payload = nullptr;
    std::size_t length = 0;
};

// The acknowledges, one per command; the caller holds the camera's lock.
std::vector<std::uint8_t> discovery_ack(ArvFakeCamera* camera, const GvcpCommand& c) {
    auto ack = ack_header(0, kDiscoveryAck, kDiscoveryDataSize, c.id);
    ack.resize(8 + kDiscoveryDataSize);
    arv_fake_camera_read_memory(camera, 0, kDiscoveryDataSize, ack.data() + 8);
    return ack;
}

std::vector<std::uint8_t> read_register_ack(ArvFakeCamera* camera, const GvcpCommand& c) {
    if (c.length == 0 || c.length % 4 != 0)
        return ack_header(kStatusInvalidParameter, kReadRegAck, 0, c.id);
    auto ack = ack_header(0, kReadRegAck, c.length, c.id);
    for (std::size_t i = 0; i < c.length; i += 4) {
        const std::uint32_t address = get32(c.payload + i);
        std::uint32_t value = 0;
        arv_fake_camera_read_register(camera, address, &value);
        // The resend buffer is ours: say so where clients look for it.
        if (address == kGvcpCapabilityRegister)
            value |= kCapabilityPacketResend | kCapabilityWriteMemory;
        put32(ack, value);
    }
    return ack;
}

std::vector<std::uint8_t> write_register_ack(ArvFakeCamera* camera, const GvcpCommand& c,
                                             bool write_access) {
    if (!write_access) return ack_header(kStatusAccessDenied, kWriteRegAck, 0, c.id);
    if (c.length == 0 || c.length % 8 != 0)
        return ack_header(kStatusInvalidParameter, kWriteRegAck, 0, c.id);
    std::uint32_t written = 0;
    for (std::size_t i = 0; i < c.length; i += 8) {
        arv_fake_camera_write_register(camera, get32(c.payload + i), get32(c.payload + i + 4));
        ++written;
    }
    auto ack = ack_header(0, kWriteRegAck, 4, c.id);
    put32(ack, written);
    return ack;
}

std::vector<std::uint8_t> read_memory_ack(ArvFakeCamera* camera, const GvcpCommand& c) {
    if (c.length < 8) return ack_header(kStatusInvalidParameter, kReadMemAck, 0, c.id);
    const std::uint32_t address = get32(c.payload);
    const std::uint32_t count = get32(c.payload + 4) & 0xffff;
    if (count == 0 || count > kMaxReadMemory || count % 4 != 0)
        return ack_header(kStatusInvalidParameter, kReadMemAck, 0, c.id);
    auto ack = ack_header(0, kReadMemAck, 4 + count, c.id);
    put32(ack, address);
    ack.resize(ack.size() + count);
    arv_fake_camera_read_memory(camera, address, count, ack.data() + 12);
    return ack;
}

std::vector<std::uint8_t> write_memory_ack(ArvFakeCamera* camera, const GvcpCommand& c,
                                           bool write_access) {
    if (!write_access) return ack_header(kStatusAccessDenied, kWriteMemAck, 0, c.id);
    if (c.length < 8) return ack_header(kStatusInvalidParameter, kWriteMemAck, 0, c.id);
    const std::uint32_t address = get32(c.payload);
    std::vector<std::uint8_t> data(c.payload + 4, c.payload + c.length);
    arv_fake_camera_write_memory(camera, address, static_cast<std::uint32_t>(data.size()),
                                 data.data());
    auto ack = ack_header(0, kWriteMemAck, 4, c.id);
    put32(ack, address);
    return ack;
}

// The camera's answer to a command (other than PACKETRESEND); others are not implemented.
std::vector<std::uint8_t> acknowledge(ArvFakeCamera* camera, const GvcpCommand& c,
                                      bool write_access) {
    switch (c.command) {
        case kDiscoveryCmd:
            return discovery_ack(camera, c);
        case kReadRegCmd:
            return read_register_ack(camera, c);
        case kWriteRegCmd:
            return write_register_ack(camera, c, write_access);
        case kReadMemCmd:
            return read_memory_ack(camera, c);
        case kWriteMemCmd:
            return write_memory_ack(camera, c, write_access);
        default:
            return ack_header(kStatusNotImplemented, static_cast<std::uint16_t>(c.command + 1), 0,
                              c.id);
    }
}

}  // namespace

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
    GvcpCommand c;
    c.command = get16(packet + 2);
    c.length = get16(packet + 4);
    c.id = get16(packet + 6);
    if (8 + c.length > size) return;
    c.payload = packet + 8;
    if (c.command == kPacketResendCmd) {  // no acknowledge (GigE Vision: PACKETRESEND has none)
        handle_resend(c.payload, c.length, flags);
        return;
    }

    std::lock_guard camera_lock(camera_mutex);
    const std::int64_t now_us = g_get_monotonic_time();
    const bool acquiring_before = arv_fake_camera_get_acquisition_status(camera) != 0;
    const bool write_access = controller_write_access(from, now_us);
    const std::vector<std::uint8_t> ack = acknowledge(camera, c, write_access);
    note_camera_changes(acquiring_before, from, now_us);
    if ((flags & kFlagAckRequired) || c.command == kDiscoveryCmd)
        ::sendto(gvcp_fd, ack.data(), ack.size(), 0, reinterpret_cast<const sockaddr*>(&from),
                 sizeof from);
}

// Control channel privilege: the controller keeps it while it talks within the heartbeat
// timeout; others may read but not write. Its age on the monotonic clock (`now_us`): a step of
// the wall clock (a VM resumed, NTP) is no silence of the controller's. The caller holds
// camera_mutex.
bool GvDevice::Impl::controller_write_access(const sockaddr_in& from, std::int64_t now_us) {
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
    return write_access;
}

// After a command from `from`: an AcquisitionStart it made, and the controller it made or
// unmade. The caller holds camera_mutex.
void GvDevice::Impl::note_camera_changes(bool acquiring_before, const sockaddr_in& from,
                                         std::int64_t now_us) {
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
