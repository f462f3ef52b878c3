// Modbus TCP server (docs/plc-modbus.md "Server"). libmodbus opens the listening socket; the
// server thread then frames MBAP requests itself, one receive buffer per client on non-blocking
// sockets, so a client that sends half a frame, or nothing, never holds up another: nothing in
// the loop waits on one client. Function codes 03, 04, 06 and 16 are served from the Handshake's
// register image under one mutex per request.
#include "hotgauge/plc/server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <spdlog/fmt/ranges.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <set>
#include <thread>

#include "hotgauge/plc/modbus_tcp.hpp"
#include "log.hpp"

namespace hotgauge::plc {
namespace {

using Clock = std::chrono::steady_clock;
using detail::log;

constexpr std::size_t kRxCapacity = 4 * MODBUS_TCP_MAX_ADU_LENGTH;
constexpr std::size_t kMaxEvents = 64;

struct Cidr {
    std::uint32_t net = 0, mask = 0;
    bool contains(std::uint32_t host) const { return (host & mask) == net; }
};

std::optional<Cidr> parse_cidr(const std::string& s) {
    const auto slash = s.find('/');
    const std::string ip = s.substr(0, slash);
    int bits = 32;
    if (slash != std::string::npos) {
        const char* first = s.data() + slash + 1;
        const char* last = s.data() + s.size();
        const auto [p, ec] = std::from_chars(first, last, bits);
        if (ec != std::errc() || p != last || first == last || bits < 0 || bits > 32)
            return std::nullopt;
    }
    in_addr a{};
    if (inet_pton(AF_INET, ip.c_str(), &a) != 1) return std::nullopt;
    const std::uint32_t mask = bits == 0 ? 0u : ~0u << (32 - bits);
    return Cidr{ntohl(a.s_addr) & mask, mask};
}

// Rejections (modbus_tcp.hpp), each logged once per client and counted.
constexpr std::array<const char*, kRejectionKinds> kRejectionNames = {
    "illegal function (exception 01)", "illegal data address (exception 02)",
    "illegal data value (exception 03)", "unknown unit id (exception 0B)"};

struct Client {
    int fd = -1;
    std::string peer;  // "a.b.c.d:port"
    std::vector<std::uint8_t> rx, tx;
    Clock::time_point last_request;
    std::array<std::uint64_t, kRejectionKinds> rejected{};
    std::uint64_t requests = 0;  // complete requests served
    bool closing = false;
};

// Who gives way when every slot is taken: a connection that never sent a request before one
// that did, then the one idle longest. A PLC polls, so it is never the one chosen while
// anybody is merely holding a socket open.
bool gives_way_before(const Client& a, const Client& b) {
    if ((a.requests == 0) != (b.requests == 0)) return a.requests == 0;
    return a.last_request < b.last_request;
}

// At most one line per `period`; what was held back is counted into the next one.
struct LogBudget {
    Clock::duration period;
    Clock::time_point next{};
    std::uint64_t held_back = 0;
    // True: log now, mentioning `held_back` (then zero it).
    bool take(Clock::time_point now) {
        if (now < next) {
            ++held_back;
            return false;
        }
        next = now + period;
        return true;
    }
};

// Closes with an RST rather than a FIN: a refused client sees "connection reset" at once.
void reset_and_close(int fd) {
    const linger l{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof l);
    ::close(fd);
}

}  // namespace

core::Result<void> check_config(const ServerConfig& c) {
    in_addr a{};
    if (inet_pton(AF_INET, c.bind_address.c_str(), &a) != 1)
        return core::make_error("plc server: bind address '" + c.bind_address +
                                "' is not an IPv4 address");
    if (c.port < 0 || c.port > 65535)
        return core::make_error("plc server: port " + std::to_string(c.port) + " outside 0..65535");
    if (c.unit_ids.empty()) return core::make_error("plc server: no unit id accepted");
    for (int u : c.unit_ids)
        if (u < 0 || u > 255)
            return core::make_error("plc server: unit id " + std::to_string(u) + " outside 0..255");
    for (const auto& s : c.allowed_clients)
        if (!parse_cidr(s))
            return core::make_error("plc server: allowed client '" + s +
                                    "' is not an IPv4 address or a.b.c.d/n block");
    if (c.max_connections < 1)
        return core::make_error("plc server: max_connections must be at least 1");
    if (c.idle_timeout_ms < 0) return core::make_error("plc server: idle_timeout_ms must be >= 0");
    if (c.heartbeat_period_ms < 10)
        return core::make_error("plc server: heartbeat_period_ms must be at least 10");
    return {};
}

struct Server::Impl {
    ServerConfig config;
    std::vector<Cidr> allowed;
    std::array<bool, 256> units{};
    int listen_fd = -1;
    int wake_fd = -1;
    std::thread thread;
    std::atomic<bool> stopping{false};

    mutable std::mutex mutex;  // guards everything below
    std::condition_variable events_cv;
    Handshake handshake;
    std::deque<PlcEvent> events;
    ServerStats stats;

    std::vector<Client> clients;           // server thread only
    std::set<std::string> refused_logged;  // server thread only; bounded, see refuse()
    LogBudget refusal_log{std::chrono::seconds(10)}, eviction_log{std::chrono::seconds(10)};

    explicit Impl(const ServerConfig& c) : config(c), handshake(c.word_order, c.first_sequence) {
        for (const auto& s : c.allowed_clients) allowed.push_back(*parse_cidr(s));
        for (int u : c.unit_ids) units[static_cast<std::size_t>(u)] = true;
    }

    ~Impl() {
        stopping = true;
        if (wake_fd >= 0) {
            const std::uint64_t one = 1;
            [[maybe_unused]] const auto n = ::write(wake_fd, &one, sizeof one);
        }
        if (thread.joinable()) thread.join();
        for (auto& c : clients) ::close(c.fd);
        if (listen_fd >= 0) ::close(listen_fd);
        if (wake_fd >= 0) ::close(wake_fd);
    }

    void run();
    void accept_all();
    void refuse(int fd, const std::string& ip, const char* why);
    void make_room(const std::string& ip);
    void read_from(Client& c);
    void serve_frames(Client& c);
    std::vector<std::uint8_t> serve_pdu(Client& c, std::uint8_t unit,
                                        std::span<const std::uint8_t> pdu);
    void flush(Client& c);
    void close_client(Client& c, const char* why);
};

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Server::~Server() = default;

core::Result<std::unique_ptr<Server>> Server::start(const ServerConfig& config) {
    if (auto ok = check_config(config); !ok) return ok.error();
    auto impl = std::make_unique<Impl>(config);
    const std::string where =
        "plc server: " + config.bind_address + ":" + std::to_string(config.port) + ": ";
    modbus_t* ctx = modbus_new_tcp(config.bind_address.c_str(), config.port);
    if (!ctx) return core::make_error(where + modbus_strerror(errno));
    // A generous backlog: connections over the limit are refused by us (an RST at once), not
    // left to SYN retries in a full kernel queue.
    impl->listen_fd = modbus_tcp_listen(ctx, 128);
    const int listen_errno = errno;
    modbus_free(ctx);  // the listening socket is ours now
    if (impl->listen_fd < 0) return core::make_error(where + std::strerror(listen_errno));
    const int flags = ::fcntl(impl->listen_fd, F_GETFL, 0);
    ::fcntl(impl->listen_fd, F_SETFL, flags | O_NONBLOCK);
    sockaddr_in bound{};
    socklen_t len = sizeof bound;
    if (::getsockname(impl->listen_fd, reinterpret_cast<sockaddr*>(&bound), &len) != 0)
        return core::make_error(where + std::strerror(errno));
    impl->wake_fd = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    if (impl->wake_fd < 0) return core::make_error(where + std::strerror(errno));
    Impl* raw = impl.get();
    impl->thread = std::thread([raw] { raw->run(); });
    std::unique_ptr<Server> server(new Server(std::move(impl)));
    server->port_ = ntohs(bound.sin_port);
    log().info(
        "modbus tcp server on {}:{} (units {}, max {} connections, idle timeout {} ms, "
        "{}-endian words)",
        config.bind_address, server->port_, fmt::join(config.unit_ids, ","), config.max_connections,
        config.idle_timeout_ms, to_string(config.word_order));
    return server;
}

std::optional<PlcEvent> Server::wait_event(std::chrono::milliseconds timeout) {
    std::unique_lock lock(impl_->mutex);
    if (!impl_->events_cv.wait_for(lock, timeout, [&] { return !impl_->events.empty(); }))
        return std::nullopt;
    PlcEvent e = impl_->events.front();
    impl_->events.pop_front();
    return e;
}

core::Result<void> Server::finish(std::uint32_t trigger_id, const PartResult& result) {
    std::lock_guard lock(impl_->mutex);
    auto ok = impl_->handshake.finish(trigger_id, result);
    if (!ok) log().warn("{}", ok.error().message);
    return ok;
}

void Server::fault(std::uint16_t code) {
    std::lock_guard lock(impl_->mutex);
    impl_->handshake.fault(code);
    log().warn("FAULT {} ({})", code, to_string(static_cast<ErrorCode>(code)));
}

void Server::scans_done(std::uint32_t trigger_id) {
    std::lock_guard lock(impl_->mutex);
    impl_->handshake.scans_done(trigger_id);
}

void Server::set_cell_status(const CellStatus& s) {
    std::lock_guard lock(impl_->mutex);
    impl_->handshake.set_cell_status(s);
}

State Server::state() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->handshake.state();
}

Handshake::InputImage Server::inputs() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->handshake.inputs();
}

ServerStats Server::stats() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->stats;
}

void Server::Impl::run() {
    const auto period = std::chrono::milliseconds(config.heartbeat_period_ms);
    const auto idle = std::chrono::milliseconds(config.idle_timeout_ms);
    auto next_beat = Clock::now() + period;
    std::vector<pollfd> fds;
    while (!stopping) {
        auto now = Clock::now();
        auto wake_at = next_beat;
        if (config.idle_timeout_ms > 0)
            for (const auto& c : clients) wake_at = std::min(wake_at, c.last_request + idle);
        const auto wait_ms = std::chrono::ceil<std::chrono::milliseconds>(
            std::max(wake_at - now, Clock::duration{}));
        fds.clear();
        fds.push_back({wake_fd, POLLIN, 0});
        fds.push_back({listen_fd, POLLIN, 0});
        for (const auto& c : clients) {
            short ev = 0;
            if (c.rx.size() < kRxCapacity) ev |= POLLIN;
            if (!c.tx.empty()) ev |= POLLOUT;
            fds.push_back({c.fd, ev, 0});
        }
        const int n = ::poll(fds.data(), fds.size(), static_cast<int>(wait_ms.count()));
        if (n < 0 && errno != EINTR) {
            log().error("poll: {}", std::strerror(errno));
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (stopping) break;
        if (n > 0) {
            for (std::size_t i = 0; i < clients.size(); ++i) {
                Client& c = clients[i];
                const short re = fds[i + 2].revents;
                if (re & POLLOUT) flush(c);
                if (re & (POLLIN | POLLHUP | POLLERR)) read_from(c);
                if (re & POLLNVAL) close_client(c, "invalid socket");
                if (!c.closing) serve_frames(c);
            }
            if (fds[1].revents & POLLIN) accept_all();
            if (fds[0].revents & POLLIN) {
                std::uint64_t v;
                [[maybe_unused]] const auto r = ::read(wake_fd, &v, sizeof v);
            }
        }
        now = Clock::now();
        if (now >= next_beat) {
            std::lock_guard lock(mutex);
            handshake.tick_heartbeat();
            next_beat += period;
            if (next_beat <= now) next_beat = now + period;  // late (suspended): no burst
        }
        if (config.idle_timeout_ms > 0)
            for (auto& c : clients)
                if (!c.closing && now - c.last_request >= idle) {
                    {
                        std::lock_guard lock(mutex);
                        ++stats.timed_out;
                    }
                    close_client(c, "idle timeout");
                }
        const auto before = clients.size();
        std::erase_if(clients, [](const Client& c) { return c.closing; });
        if (clients.size() != before) {
            std::lock_guard lock(mutex);
            stats.clients = static_cast<int>(clients.size());
        }
    }
}

void Server::Impl::refuse(int fd, const std::string& ip, const char* why) {
    reset_and_close(fd);
    {
        std::lock_guard lock(mutex);
        ++stats.refused;
    }
    // Once per address, and at most one line per 10 s however many addresses try.
    if (refused_logged.size() >= 1024 || refused_logged.count(std::string(why) + ip)) return;
    if (!refusal_log.take(Clock::now())) return;
    refused_logged.insert(std::string(why) + ip);
    log().warn(
        "refused a connection from {}: {} (logged once per address, at most every 10 s; "
        "{} refusals not logged before this one)",
        ip, why, std::exchange(refusal_log.held_back, 0));
}

// Every slot taken: the connection that gives way (gives_way_before) is closed for `ip`, so a
// PLC can always get in (docs/plc-modbus.md "Connections").
void Server::Impl::make_room(const std::string& ip) {
    auto victim = clients.end();
    for (auto it = clients.begin(); it != clients.end(); ++it)
        if (!it->closing && (victim == clients.end() || gives_way_before(*it, *victim)))
            victim = it;
    if (victim == clients.end()) return;
    const auto idle_ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - victim->last_request)
            .count();
    {
        std::lock_guard lock(mutex);
        ++stats.evicted;
    }
    if (eviction_log.take(Clock::now()))
        log().warn(
            "{} connections (the limit): closed {} ({} requests, idle {} ms) for a new one from "
            "{}; {} such closes not logged before this one",
            config.max_connections, victim->peer, victim->requests, idle_ms, ip,
            std::exchange(eviction_log.held_back, 0));
    reset_and_close(victim->fd);
    victim->closing = true;
    std::erase_if(clients, [](const Client& c) { return c.closing; });
}

void Server::Impl::accept_all() {
    for (;;) {
        sockaddr_in sa{};
        socklen_t len = sizeof sa;
        const int fd = ::accept4(listen_fd, reinterpret_cast<sockaddr*>(&sa), &len,
                                 SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd < 0) {
            if (errno == EINTR || errno == ECONNABORTED) continue;
            if (errno != EAGAIN && errno != EWOULDBLOCK)
                log().warn("accept: {}", std::strerror(errno));
            return;
        }
        char ip[INET_ADDRSTRLEN] = "?";
        ::inet_ntop(AF_INET, &sa.sin_addr, ip, sizeof ip);
        const std::uint32_t host = ntohl(sa.sin_addr.s_addr);
        if (!allowed.empty() && std::none_of(allowed.begin(), allowed.end(),
                                             [&](const Cidr& c) { return c.contains(host); })) {
            refuse(fd, ip, "not on the allow-list");
            continue;
        }
        if (clients.size() >= static_cast<std::size_t>(config.max_connections)) make_room(ip);
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        Client c;
        c.fd = fd;
        c.peer = std::string(ip) + ":" + std::to_string(ntohs(sa.sin_port));
        c.last_request = Clock::now();
        c.rx.reserve(kRxCapacity);
        log().info("client {} connected", c.peer);
        clients.push_back(std::move(c));
        std::lock_guard lock(mutex);
        ++stats.accepted;
        stats.clients = static_cast<int>(clients.size());
    }
}

void Server::Impl::read_from(Client& c) {
    while (c.rx.size() < kRxCapacity) {
        std::uint8_t buf[kRxCapacity];
        const ssize_t n = ::recv(c.fd, buf, kRxCapacity - c.rx.size(), MSG_DONTWAIT);
        if (n > 0) {
            c.rx.insert(c.rx.end(), buf, buf + n);
            continue;
        }
        if (n == 0) {
            close_client(c, c.rx.empty() ? "disconnected" : "disconnected mid-request");
            return;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN && errno != EWOULDBLOCK) close_client(c, std::strerror(errno));
        return;
    }
}

void Server::Impl::serve_frames(Client& c) {
    std::size_t used = 0;
    // One response in flight at a time: a client that does not read its responses stops being
    // read (TCP flow control) instead of growing our buffer.
    while (c.tx.empty() && !c.closing && c.rx.size() - used >= kMbapSize) {
        const MbapFrame f = parse_mbap(std::span(c.rx).subspan(used));
        if (f.status == MbapFrame::Status::kMalformed) {
            // A byte stream cannot be resynchronised after a bad header: drop the connection.
            log().warn("client {}: malformed MBAP header (protocol {}, length {}): closing", c.peer,
                       f.protocol, f.length);
            {
                std::lock_guard lock(mutex);
                ++stats.malformed;
            }
            close_client(c, "malformed frame");
            break;
        }
        if (f.status == MbapFrame::Status::kIncomplete) break;  // the rest is on its way
        const auto pdu = serve_pdu(c, f.unit, f.pdu);
        used += f.bytes;
        c.last_request = Clock::now();
        ++c.requests;
        append_response(c.tx, f, pdu);
        flush(c);
    }
    c.rx.erase(c.rx.begin(), c.rx.begin() + static_cast<std::ptrdiff_t>(used));
}

std::vector<std::uint8_t> Server::Impl::serve_pdu(Client& c, std::uint8_t unit,
                                                  std::span<const std::uint8_t> pdu) {
    std::lock_guard lock(mutex);
    ++stats.requests;
    RequestOutcome out = serve_request(handshake, units, unit, pdu);
    if (out.rejection) {
        if (c.rejected[*out.rejection]++ == 0)
            log().warn("client {}: {}: {}; further ones from this client are counted, not logged",
                       c.peer, kRejectionNames[*out.rejection], out.detail);
        ++stats.exceptions;
    }
    if (const auto& event = out.event) {
        if (events.size() == kMaxEvents) {
            log().warn(
                "event queue full: the owner does not take PLC commands; dropping the oldest");
            events.pop_front();
        }
        if (event->kind == PlcEvent::Kind::kTrigger)
            log().debug("trigger {} from {}: part {}, recipe slot {}, face {}",
                        event->trigger.trigger_id, c.peer, event->trigger.part_id,
                        event->trigger.recipe_slot, static_cast<int>(event->trigger.face));
        else
            log().debug("reset from {}", c.peer);
        events.push_back(*event);
        events_cv.notify_one();
    }
    return std::move(out.response);
}

void Server::Impl::flush(Client& c) {
    while (!c.tx.empty()) {
        const ssize_t n = ::send(c.fd, c.tx.data(), c.tx.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        if (n > 0) {
            c.tx.erase(c.tx.begin(), c.tx.begin() + n);
            continue;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return;
        close_client(c, n < 0 ? std::strerror(errno) : "send failed");
        return;
    }
}

void Server::Impl::close_client(Client& c, const char* why) {
    if (c.closing) return;
    c.closing = true;
    ::close(c.fd);
    std::uint64_t total = 0;
    for (auto r : c.rejected) total += r;
    if (total > 0)
        log().info(
            "client {} closed ({}); rejected requests: {} illegal function, {} illegal "
            "address, {} illegal value, {} unknown unit",
            c.peer, why, c.rejected[kIllegalFunction], c.rejected[kIllegalAddress],
            c.rejected[kIllegalValue], c.rejected[kWrongUnit]);
    else
        log().info("client {} closed ({})", c.peer, why);
}

}  // namespace hotgauge::plc
