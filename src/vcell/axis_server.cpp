#include "hotgauge/vcell/axis_server.hpp"

#include <arpa/inet.h>
#include <modbus.h>
#include <netinet/in.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <thread>
#include <vector>

#include "log.hpp"

namespace hotgauge::vcell {
namespace {

constexpr int kTarget = 0, kCommand = 1, kCurrent = 2, kState = 3, kFaces = 4, kMoves = 5;
constexpr int kPartRequest = 6, kPartLoaded = 7;
constexpr int kRegisters = 8;
constexpr std::uint16_t kInPosition = 0, kMoving = 1, kFault = 2;

}  // namespace

struct AxisServer::Impl {
    AxisServerConfig config;
    std::function<void(int)> on_arrival;
    std::function<void(int)> on_part_request;
    modbus_t* ctx = nullptr;
    modbus_mapping_t* map = nullptr;
    int listen_fd = -1;
    int port = 0;
    std::thread thread;
    std::atomic<bool> stop{false};
    std::atomic<int> face{1};
    std::atomic<int> part_loaded{0};  // register 7, copied into the map by the server thread

    ~Impl() {
        stop = true;
        if (thread.joinable()) thread.join();
        if (listen_fd >= 0) ::close(listen_fd);
        if (map) modbus_mapping_free(map);
        if (ctx) modbus_free(ctx);
    }

    void run();
};

void AxisServer::Impl::run() {
    std::vector<int> clients;
    std::vector<std::uint8_t> query(MODBUS_TCP_MAX_ADU_LENGTH);
    using Clock = std::chrono::steady_clock;
    Clock::time_point arrive_at{};
    int moving_to = 0;
    while (!stop) {
        fd_set fds;
        FD_ZERO(&fds);
        FD_SET(listen_fd, &fds);
        int top = listen_fd;
        for (int c : clients) {
            FD_SET(c, &fds);
            top = std::max(top, c);
        }
        timeval tv{0, 10'000};
        const int n = ::select(top + 1, &fds, nullptr, nullptr, &tv);
        // The map belongs to this thread: other threads' writes reach it through the atomic,
        // before this round's replies.
        map->tab_registers[kPartLoaded] = static_cast<std::uint16_t>(part_loaded.load());
        if (n > 0 && FD_ISSET(listen_fd, &fds)) {
            const int c = ::accept(listen_fd, nullptr, nullptr);
            if (c >= 0) clients.push_back(c);
        }
        for (std::size_t i = 0; n > 0 && i < clients.size();) {
            const int c = clients[i];
            if (!FD_ISSET(c, &fds)) {
                ++i;
                continue;
            }
            modbus_set_socket(ctx, c);
            const int len = modbus_receive(ctx, query.data());
            if (len > 0) {
                modbus_reply(ctx, query.data(), len, map);
                ++i;
            } else if (len < 0) {
                ::close(c);
                clients.erase(clients.begin() + static_cast<std::ptrdiff_t>(i));
            } else {
                ++i;  // not for us (another unit id): ignored
            }
        }
        std::uint16_t* r = map->tab_registers;
        if (r[kCommand] == 1) {  // take the command
            r[kCommand] = 0;
            const int target = r[kTarget];
            if (target < 1 || target > config.n_faces) {
                r[kState] = kFault;
                detail::log().warn("axis: target face {} is not 1..{}", target, config.n_faces);
            } else {
                moving_to = target;
                face = 0;
                r[kCurrent] = 0;
                r[kState] = kMoving;
                arrive_at = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(config.move_time_s));
            }
        }
        if (r[kPartRequest] != 0) {  // take the request; the owner loads the part
            const int part = r[kPartRequest];
            r[kPartRequest] = 0;
            part_loaded = 0;
            r[kPartLoaded] = 0;
            if (on_part_request) on_part_request(part);
        }
        if (moving_to != 0 && Clock::now() >= arrive_at) {
            if (on_arrival) on_arrival(moving_to);
            face = moving_to;
            r[kCurrent] = static_cast<std::uint16_t>(moving_to);
            r[kState] = kInPosition;
            r[kMoves] = static_cast<std::uint16_t>(r[kMoves] + 1);
            moving_to = 0;
        }
    }
    for (int c : clients) ::close(c);
}

AxisServer::AxisServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
AxisServer::~AxisServer() = default;
int AxisServer::port() const { return impl_->port; }
int AxisServer::current_face() const { return impl_->face; }
void AxisServer::set_part_loaded(int part) { impl_->part_loaded = part; }

core::Result<std::unique_ptr<AxisServer>> AxisServer::start(
    const AxisServerConfig& config, std::function<void(int)> on_arrival,
    std::function<void(int)> on_part_request) {
    if (config.n_faces < 1 || config.initial_face < 1 || config.initial_face > config.n_faces)
        return core::make_error("axis: initial face must be in 1..n_faces");
    auto impl = std::make_unique<Impl>();
    impl->config = config;
    impl->on_arrival = std::move(on_arrival);
    impl->on_part_request = std::move(on_part_request);
    const std::string where = "axis server " + config.bind + ":" + std::to_string(config.port);
    impl->ctx = modbus_new_tcp(config.bind.c_str(), config.port);
    impl->map = modbus_mapping_new(0, 0, kRegisters, 0);
    if (!impl->ctx || !impl->map) return core::make_error(where + ": out of memory");
    impl->listen_fd = modbus_tcp_listen(impl->ctx, 8);
    if (impl->listen_fd < 0) return core::make_error(where + ": " + modbus_strerror(errno));
    sockaddr_in sa{};
    socklen_t len = sizeof sa;
    ::getsockname(impl->listen_fd, reinterpret_cast<sockaddr*>(&sa), &len);
    impl->port = ntohs(sa.sin_port);
    // A client that sends half a request must not stall the axis for long.
    modbus_set_indication_timeout(impl->ctx, 0, 200'000);
    std::uint16_t* r = impl->map->tab_registers;
    r[kTarget] = r[kCurrent] = static_cast<std::uint16_t>(config.initial_face);
    r[kFaces] = static_cast<std::uint16_t>(config.n_faces);
    impl->face = config.initial_face;
    Impl* raw = impl.get();
    impl->thread = std::thread([raw] { raw->run(); });
    detail::log().info("axis server on {}:{} ({} faces)", config.bind, impl->port, config.n_faces);
    return std::unique_ptr<AxisServer>(new AxisServer(std::move(impl)));
}

}  // namespace hotgauge::vcell
