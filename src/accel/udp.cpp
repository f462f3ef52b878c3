// HGA1 datagrams over UDP (docs/accelerometer.md, "udp").
#include "hotgauge/accel/udp.hpp"

#include <netdb.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cassert>
#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <utility>

#include "log.hpp"
#include "worker.hpp"

namespace hotgauge::accel {

namespace {

// Little-endian field access, independent of the host's byte order.
template <class U>
U get_le(const std::uint8_t* p) {
    U v = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i)
        v = static_cast<U>(v | (static_cast<U>(p[i]) << (8 * i)));
    return v;
}

template <class U>
void put_le(std::vector<std::uint8_t>& out, U v) {
    for (std::size_t i = 0; i < sizeof(U); ++i)
        out.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xffu));
}

std::string errno_text(int err) { return std::strerror(err); }

struct AddrInfo {
    addrinfo* list = nullptr;
    ~AddrInfo() {
        if (list) ::freeaddrinfo(list);
    }
};

core::Result<void> resolve(const HostPort& hp, bool passive, AddrInfo& out,
                           const std::string& what) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_flags = AI_NUMERICSERV | (passive ? AI_PASSIVE : 0);
    const std::string port = std::to_string(hp.port);
    const int rc = ::getaddrinfo(hp.host.c_str(), port.c_str(), &hints, &out.list);
    if (rc != 0 || !out.list)
        return core::make_error(what + ": cannot resolve '" + hp.host + "': " + ::gai_strerror(rc));
    return {};
}

}  // namespace

const char* to_string(DatagramProblem problem) {
    switch (problem) {
        case DatagramProblem::ok:
            return "ok";
        case DatagramProblem::too_short:
            return "shorter than the 28-byte header";
        case DatagramProblem::oversized:
            return "larger than the 12316-byte maximum";
        case DatagramProblem::bad_magic:
            return "bad magic (not HGA1)";
        case DatagramProblem::bad_version:
            return "unsupported version";
        case DatagramProblem::no_samples:
            return "no samples (n = 0)";
        case DatagramProblem::size_mismatch:
            return "size does not match 28 + 12 n";
        case DatagramProblem::zero_period:
            return "sample period 0";
    }
    return "?";
}

std::vector<std::uint8_t> encode_datagram(const AccelDatagram& d) {
    assert(d.accel_mps2.size() % 3 == 0);
    std::vector<std::uint8_t> out;
    out.reserve(kDatagramHeaderBytes + d.accel_mps2.size() * 4);
    for (char c : kDatagramMagic) out.push_back(static_cast<std::uint8_t>(c));
    put_le<std::uint16_t>(out, kDatagramVersion);
    put_le<std::uint16_t>(out, d.sensor_id);
    put_le<std::uint32_t>(out, d.sequence);
    put_le<std::uint64_t>(out, static_cast<std::uint64_t>(d.t0_ns));
    put_le<std::uint32_t>(out, d.period_ns);
    put_le<std::uint16_t>(out, static_cast<std::uint16_t>(d.n_samples()));
    put_le<std::uint16_t>(out, 0);  // reserved
    for (float v : d.accel_mps2) put_le<std::uint32_t>(out, std::bit_cast<std::uint32_t>(v));
    return out;
}

DatagramProblem decode_datagram(std::span<const std::uint8_t> b, AccelDatagram& out) {
    if (b.size() < kDatagramHeaderBytes) return DatagramProblem::too_short;
    if (b.size() > kDatagramMaxBytes) return DatagramProblem::oversized;
    if (std::memcmp(b.data(), kDatagramMagic.data(), kDatagramMagic.size()) != 0)
        return DatagramProblem::bad_magic;
    if (get_le<std::uint16_t>(&b[4]) != kDatagramVersion) return DatagramProblem::bad_version;
    const std::size_t n = get_le<std::uint16_t>(&b[24]);
    if (n == 0) return DatagramProblem::no_samples;
    if (b.size() != kDatagramHeaderBytes + n * kDatagramSampleBytes)
        return DatagramProblem::size_mismatch;
    const std::uint32_t period_ns = get_le<std::uint32_t>(&b[20]);
    if (period_ns == 0) return DatagramProblem::zero_period;
    out.sensor_id = get_le<std::uint16_t>(&b[6]);
    out.sequence = get_le<std::uint32_t>(&b[8]);
    out.t0_ns = static_cast<std::int64_t>(get_le<std::uint64_t>(&b[12]));
    out.period_ns = period_ns;
    out.accel_mps2.resize(n * 3);
    for (std::size_t i = 0; i < n * 3; ++i)
        out.accel_mps2[i] =
            std::bit_cast<float>(get_le<std::uint32_t>(&b[kDatagramHeaderBytes + 4 * i]));
    return DatagramProblem::ok;
}

core::Result<HostPort> parse_host_port(const std::string& text, const std::string& field) {
    const auto bad = [&](const std::string& why) {
        return core::make_error(field + ": " + why + ", expected HOST:PORT, found '" + text + "'");
    };
    const auto colon = text.rfind(':');
    if (colon == std::string::npos) return bad("no port");
    HostPort hp;
    hp.host = text.substr(0, colon);
    if (hp.host.size() >= 2 && hp.host.front() == '[' && hp.host.back() == ']')
        hp.host = hp.host.substr(1, hp.host.size() - 2);
    else if (hp.host.find(':') != std::string::npos)
        return bad("IPv6 addresses need brackets");
    if (hp.host.empty()) return bad("empty host");
    const std::string port = text.substr(colon + 1);
    unsigned value = 0;
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
    if (port.empty() || ec != std::errc() || end != port.data() + port.size() || value > 65535)
        return bad("port is not a number 0..65535");
    hp.port = static_cast<std::uint16_t>(value);
    return hp;
}

// ---------------------------------------------------------------------------------------------
// Receiver

UdpAccelReceiver::UdpAccelReceiver(UdpReceiverConfig config, AccelRing& ring)
    : config_(std::move(config)), ring_(ring), sensor_id_(config_.sensor_id) {}

UdpAccelReceiver::~UdpAccelReceiver() { stop(); }

core::Result<void> UdpAccelReceiver::start() {
    if (thread_.joinable()) return core::make_error("udp receiver: already started");
    auto hp = parse_host_port(config_.bind, "udp.bind");
    if (!hp) return hp.error();
    const std::string where = "udp receiver " + config_.bind;
    AddrInfo ai;
    if (auto r = resolve(*hp, true, ai, where); !r) return r.error();

    fd_ = ::socket(ai.list->ai_family, ai.list->ai_socktype | SOCK_CLOEXEC, ai.list->ai_protocol);
    if (fd_ < 0) return core::make_error(where + ": cannot create socket: " + errno_text(errno));
    const auto fail = [&](const std::string& what) {
        const int err = errno;
        ::close(fd_);
        fd_ = -1;
        return core::make_error(where + ": " + what + ": " + errno_text(err));
    };
    if (config_.receive_buffer_bytes > 0) {  // a request: the kernel caps it at rmem_max
        const int bytes = config_.receive_buffer_bytes;
        (void)::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &bytes, sizeof bytes);
    }
    if (::bind(fd_, ai.list->ai_addr, ai.list->ai_addrlen) != 0) return fail("cannot bind");
    sockaddr_storage bound{};
    socklen_t len = sizeof bound;
    if (::getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &len) != 0)
        return fail("getsockname");
    port_ = bound.ss_family == AF_INET6
                ? ntohs(reinterpret_cast<const sockaddr_in6*>(&bound)->sin6_port)
                : ntohs(reinterpret_cast<const sockaddr_in*>(&bound)->sin_port);
    wake_fd_ = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (wake_fd_ < 0) return fail("eventfd");
    const bool v6 = hp->host.find(':') != std::string::npos;
    where_ = "udp receiver " + (v6 ? "[" + hp->host + "]" : hp->host) + ":" + std::to_string(port_);

    stop_ = false;
    {
        std::lock_guard lock(mutex_);
        state_ = AccelSourceState::running;
        error_.clear();
    }
    detail::log().info("{}: listening (bind {})", where_, config_.bind);
    thread_ = std::thread([this] { run(); });
    return {};
}

void UdpAccelReceiver::stop() {
    detail::stop_worker(thread_, stop_, wake_fd_, fd_);
    std::lock_guard lock(mutex_);
    if (state_ == AccelSourceState::running) state_ = AccelSourceState::stopped;
}

void UdpAccelReceiver::run() {
    std::vector<std::uint8_t> buf(kDatagramMaxBytes + 1);
    while (!stop_) {
        pollfd fds[2] = {{fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
        // The timeout only bounds a missed wake-up; stop() writes the eventfd.
        const int r = ::poll(fds, 2, 500);
        if (r < 0) {
            if (errno == EINTR) continue;
            const std::string err = where_ + ": poll: " + errno_text(errno);
            detail::log().error("{}", err);
            std::lock_guard lock(mutex_);
            state_ = AccelSourceState::failed;
            error_ = err;
            return;
        }
        if (fds[1].revents != 0) break;
        if ((fds[0].revents & POLLIN) == 0) continue;
        for (;;) {  // drain what is queued
            // MSG_TRUNC: the return value is the datagram's true size even when it is larger.
            const ssize_t n = ::recv(fd_, buf.data(), buf.size(), MSG_TRUNC | MSG_DONTWAIT);
            if (n < 0) {
                if (errno == EINTR) continue;
                if (errno != EAGAIN && errno != EWOULDBLOCK)
                    detail::log().warn("{}: recv: {}", where_, errno_text(errno));
                break;
            }
            const auto size = static_cast<std::size_t>(n);
            handle(std::span<const std::uint8_t>(buf.data(), std::min(size, buf.size())), size);
        }
    }
}

void UdpAccelReceiver::reject(DatagramProblem problem, std::size_t size) {
    const auto bit = 1u << static_cast<unsigned>(problem);
    if ((logged_problems_ & bit) == 0) {  // once per kind; the counters carry the rest
        logged_problems_ |= bit;
        detail::log().warn(
            "{}: malformed datagram of {} bytes: {} (dropped; further ones of this kind are only "
            "counted)",
            where_, size, to_string(problem));
    }
    std::lock_guard lock(mutex_);
    ++stats_.datagrams;
    ++stats_.malformed;
    ++stats_.by_problem[static_cast<std::size_t>(problem)];
    processed_.notify_all();
}

void UdpAccelReceiver::handle(std::span<const std::uint8_t> bytes, std::size_t true_size) {
    const DatagramProblem problem = true_size > kDatagramMaxBytes
                                        ? DatagramProblem::oversized
                                        : decode_datagram(bytes, datagram_);
    if (problem != DatagramProblem::ok) return reject(problem, true_size);
    const AccelDatagram& d = datagram_;
    const std::size_t n = d.n_samples();
    const auto finish = [&](auto&& count) {
        std::lock_guard lock(mutex_);
        ++stats_.datagrams;
        count(stats_);
        processed_.notify_all();
    };

    if (!sensor_id_) sensor_id_ = d.sensor_id;  // latch on the first sensor heard
    if (d.sensor_id != *sensor_id_) {
        if (!logged_foreign_) {
            logged_foreign_ = true;
            detail::log().warn(
                "{}: datagram from sensor {}, listening to sensor {}: dropped (further ones only "
                "counted)",
                where_, d.sensor_id, *sensor_id_);
        }
        return finish([](UdpReceiverStats& s) { ++s.foreign_sensor; });
    }

    const std::int64_t period = static_cast<std::int64_t>(d.period_ns);
    std::uint32_t lost = 0;
    bool resync = false;
    if (have_sequence_ && d.sequence != expected_sequence_) {
        const std::uint32_t ahead = d.sequence - expected_sequence_;  // modulo 2^32
        if (ahead < 0x80000000u) {
            lost = ahead;
        } else if (d.t0_ns > last_t_ns_) {
            resync = true;  // sequence went back but time went on: the sender restarted
        } else {
            if (!logged_reorder_) {
                logged_reorder_ = true;
                detail::log().warn(
                    "{}: datagram {} arrived after {} (late or duplicated): dropped (further "
                    "ones only counted)",
                    where_, d.sequence, expected_sequence_ - 1);
            }
            return finish([](UdpReceiverStats& s) { ++s.reordered; });
        }
    }
    if (!logged_period_ && std::abs(period - ring_.period_ns()) * 100 > ring_.period_ns()) {
        logged_period_ = true;
        detail::log().warn(
            "{}: sensor sample period {} ns differs from the ring's nominal {} ns; gap "
            "estimates use the nominal one",
            where_, period, ring_.period_ns());
    }
    const std::uint32_t previous = expected_sequence_ - 1;
    have_sequence_ = true;
    expected_sequence_ = d.sequence + 1;

    samples_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        samples_[i] = {d.t0_ns + static_cast<std::int64_t>(i) * period, d.accel_mps2[3 * i],
                       d.accel_mps2[3 * i + 1], d.accel_mps2[3 * i + 2]};
    }
    if (lost > 0) ring_.note_loss();
    ring_.push(samples_);
    last_t_ns_ = samples_.back().t_ns;
    if (resync)
        detail::log().info("{}: sender restarted (sequence {} after {})", where_, d.sequence,
                           previous);
    finish([&](UdpReceiverStats& s) {
        ++s.accepted;
        s.samples += n;
        s.lost_datagrams += lost;
        s.loss_events += lost > 0 ? 1 : 0;
        s.resyncs += resync ? 1 : 0;
    });
}

UdpReceiverStats UdpAccelReceiver::stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
}

AccelSourceStatus UdpAccelReceiver::status() const {
    std::lock_guard lock(mutex_);
    AccelSourceStatus s;
    s.state = state_;
    s.error = error_;
    s.samples = stats_.samples;
    s.loss_events = stats_.loss_events;
    s.rejected = stats_.malformed + stats_.reordered + stats_.foreign_sensor;
    if (port_ != 0) s.notes.push_back("listening on UDP port " + std::to_string(port_));
    return s;
}

bool UdpAccelReceiver::wait_processed(std::uint64_t datagrams,
                                      std::chrono::milliseconds timeout) const {
    std::unique_lock lock(mutex_);
    return processed_.wait_for(lock, timeout, [&] { return stats_.datagrams >= datagrams; });
}

// ---------------------------------------------------------------------------------------------
// Sender

core::Result<UdpAccelSender> UdpAccelSender::open(const std::string& host_port,
                                                  std::uint16_t sensor_id) {
    auto hp = parse_host_port(host_port, "udp sender");
    if (!hp) return hp.error();
    const std::string where = "udp sender to " + host_port;
    AddrInfo ai;
    if (auto r = resolve(*hp, false, ai, where); !r) return r.error();
    const int fd =
        ::socket(ai.list->ai_family, ai.list->ai_socktype | SOCK_CLOEXEC, ai.list->ai_protocol);
    if (fd < 0) return core::make_error(where + ": cannot create socket: " + errno_text(errno));
    if (::connect(fd, ai.list->ai_addr, ai.list->ai_addrlen) != 0) {
        const int err = errno;
        ::close(fd);
        return core::make_error(where + ": connect: " + errno_text(err));
    }
    return UdpAccelSender(fd, sensor_id);
}

UdpAccelSender::UdpAccelSender(UdpAccelSender&& o) noexcept
    : fd_(std::exchange(o.fd_, -1)), sensor_id_(o.sensor_id_), sequence_(o.sequence_) {}

UdpAccelSender& UdpAccelSender::operator=(UdpAccelSender&& o) noexcept {
    if (this != &o) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = std::exchange(o.fd_, -1);
        sensor_id_ = o.sensor_id_;
        sequence_ = o.sequence_;
    }
    return *this;
}

UdpAccelSender::~UdpAccelSender() {
    if (fd_ >= 0) ::close(fd_);
}

core::Result<void> UdpAccelSender::send(std::int64_t t0_ns, std::uint32_t period_ns,
                                        std::span<const float> accel_mps2) {
    const std::size_t n = accel_mps2.size() / 3;
    if (accel_mps2.size() % 3 != 0 || n == 0 || n > kDatagramMaxSamples)
        return core::make_error("udp sender: " + std::to_string(accel_mps2.size()) +
                                " values are not 1.." + std::to_string(kDatagramMaxSamples) +
                                " samples of x, y, z");
    AccelDatagram d;
    d.sensor_id = sensor_id_;
    d.sequence = sequence_;
    d.t0_ns = t0_ns;
    d.period_ns = period_ns;
    d.accel_mps2.assign(accel_mps2.begin(), accel_mps2.end());
    auto r = send_bytes(encode_datagram(d));
    ++sequence_;  // a failed send is a lost datagram, as on the wire
    return r;
}

core::Result<void> UdpAccelSender::send_bytes(std::span<const std::uint8_t> bytes) {
    for (;;) {
        if (::send(fd_, bytes.data(), bytes.size(), 0) >= 0) return {};
        if (errno == EINTR) continue;
        // Nobody listening (ICMP port unreachable on a connected socket): the datagram is lost,
        // as UDP datagrams are; not the sender's failure.
        if (errno == ECONNREFUSED) return {};
        return core::make_error("udp sender: send: " + errno_text(errno));
    }
}

}  // namespace hotgauge::accel
