// PLC server under load (docs/plc-modbus.md, docs/benchmarks.md): N clients (libmodbus, each on
// its own connection and thread) poll the whole register map at a fixed rate while a PLC client
// cycles parts through the handshake (trigger -> BUSY -> DONE -> ack) and an owner thread
// publishes a result for each. Reports request errors, blocks seen torn or mixed, the longest
// gap between heartbeat changes any client saw, and request latency p50/p99/max.
// In the same run, the same load (same pollers, same PLC client, same duration) also runs
// against a baseline: a minimal server written the way libmodbus's own examples are (one
// thread, select() over the listening and client sockets, modbus_receive + modbus_reply on a
// shared modbus_mapping_t, a measuring thread writing results into the mapping in place with no
// lock). The two take turns in slices of about 5 s (the order alternating), so that a change in
// the machine's load hits both alike. One table compares them, with the p50/p99 latency ratios.
// Exit code 1 on any error or torn block of OUR server (the short ctest asserts that, never
// timings); the baseline's errors and torn blocks are reported, never fail the run.
//   hotgauge_bench_plc [--seconds 30] [--clients 10] [--rate-hz 100] [--measure-ms 50]
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <spdlog/spdlog.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/plc/server.hpp"

using namespace hotgauge::plc;
using Clock = std::chrono::steady_clock;

namespace {

struct Args {
    double seconds = 30;
    int clients = 10;
    double rate_hz = 100;
    int measure_ms = 50;
};

// Every value of a result derives from its part id, so a reader can tell a whole block.
std::int32_t derived_um(std::uint32_t part, int slot) {
    return static_cast<std::int32_t>(part % 50000) * 40000 + slot * 3;
}

PartResult derived_result(std::uint32_t part) {
    PartResult r;
    for (int slot = 1; slot <= kMaxFeatures; ++slot)
        r.features.push_back({"f", slot, derived_um(part, slot) / 1000.0, Verdict::kOk});
    r.overall = Verdict::kOk;
    return r;
}

// "" if the block is whole and consistent, else what is wrong.
std::string check_block(const std::uint16_t* in) {
    if (in[ir::kState] != static_cast<std::uint16_t>(State::kDone)) {
        if (decode_i32(in[ir::feature(1)], in[ir::feature(1) + 1], {}) != kInvalidInt32)
            return "a result outside DONE";
        return "";
    }
    const auto part = decode_u32(in[ir::kPartId], in[ir::kPartId + 1], {});
    for (int slot = 1; slot <= kMaxFeatures; ++slot) {
        const auto a = ir::feature(slot);
        if (decode_i32(in[a], in[a + 1], {}) != derived_um(part, slot) ||
            decode_f32(in[a + 2], in[a + 3], {}) !=
                static_cast<float>(derived_um(part, slot) / 1000.0))
            return "slot " + std::to_string(slot) + " does not belong to part " +
                   std::to_string(part);
    }
    return "";
}

// nullptr (and errno) if the connection failed: counted as an error of the run, not an exit.
modbus_t* connect(int port) {
    modbus_t* ctx = modbus_new_tcp("127.0.0.1", port);
    modbus_set_slave(ctx, 1);
    modbus_set_response_timeout(ctx, 1, 0);
    if (modbus_connect(ctx) != 0) {
        const int e = errno;
        modbus_free(ctx);
        errno = e;
        return nullptr;
    }
    return ctx;
}

struct ClientResult {
    std::vector<double> latency_us;
    long errors = 0, torn = 0;
    double max_heartbeat_gap_ms = 0;
    std::string first_error;
};

// What the clients saw of one server.
struct LoadResult {
    std::vector<double> latency_us;  // sorted
    long errors = 0, torn = 0;
    double max_heartbeat_gap_ms = 0;
    long cycles = 0, plc_errors = 0;
    std::vector<std::string> client_errors;  // first error of each client that had one

    double pct(double p) const {
        if (latency_us.empty()) return 0.0;
        const double last = static_cast<double>(latency_us.size() - 1);
        return latency_us[static_cast<std::size_t>(std::min(last, p * last + 0.5))];
    }
    double max() const { return latency_us.empty() ? 0.0 : latency_us.back(); }
};

// The load, identical for both servers: the line PLC cycling parts through the handshake, and
// `a.clients` pollers reading input 0..kCount-1 at `a.rate_hz` for `seconds`. The PLC numbers
// its parts from `first_part`, and first finishes a cycle the previous slice left BUSY or DONE.
LoadResult run_load(int port, const Args& a, double seconds, std::uint32_t first_part) {
    std::atomic<bool> stop{false};
    std::atomic<long> cycles{0}, plc_errors{0};
    std::thread plc([&] {  // the line PLC: trigger, poll until DONE, read, ack
        modbus_t* ctx = connect(port);
        if (!ctx) {
            ++plc_errors;
            return;
        }
        std::uint16_t left = static_cast<std::uint16_t>(State::kBusy);
        while (!stop && left == static_cast<std::uint16_t>(State::kBusy)) {
            if (modbus_read_input_registers(ctx, ir::kState, 1, &left) != 1) ++plc_errors;
            if (left == static_cast<std::uint16_t>(State::kBusy))
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        if (left == static_cast<std::uint16_t>(State::kDone) &&
            modbus_write_register(ctx, 0, 2) != 1)
            ++plc_errors;
        std::uint32_t part = first_part;
        while (!stop) {
            const auto p = encode_u32(part, WordOrder::kBigEndian);
            const std::uint16_t trigger[6] = {1, p[0], p[1], 1, 0, 0};
            if (modbus_write_registers(ctx, 0, 6, trigger) != 6) {
                ++plc_errors;
                continue;
            }
            std::uint16_t state = 0;
            while (!stop && state != static_cast<std::uint16_t>(State::kDone)) {
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
                if (modbus_read_input_registers(ctx, ir::kState, 1, &state) != 1) ++plc_errors;
            }
            if (stop) break;
            if (modbus_write_register(ctx, 0, 2) != 1) ++plc_errors;
            ++cycles;
            ++part;
        }
        modbus_close(ctx);
        modbus_free(ctx);
    });

    std::vector<ClientResult> results(static_cast<std::size_t>(a.clients));
    std::vector<std::thread> threads;
    const auto t_start = Clock::now();
    const auto t_end = t_start + std::chrono::duration<double>(seconds);
    const auto period = std::chrono::duration<double>(1.0 / a.rate_hz);
    for (int c = 0; c < a.clients; ++c)
        threads.emplace_back([&, c] {
            auto& r = results[static_cast<std::size_t>(c)];
            r.latency_us.reserve(static_cast<std::size_t>(seconds * a.rate_hz) + 16);
            modbus_t* ctx = connect(port);
            if (!ctx) {
                ++r.errors;
                r.first_error = std::string("connect: ") + modbus_strerror(errno);
                return;
            }
            std::uint16_t in[ir::kCount];
            std::uint16_t last_beat = 0;
            Clock::time_point last_change{};
            // Clients start spread over one period, as independent pollers would.
            auto next = t_start + std::chrono::duration_cast<Clock::duration>(
                                      period * (static_cast<double>(c) / a.clients));
            for (long k = 0; next < t_end; ++k) {
                std::this_thread::sleep_until(next);
                const auto t0 = Clock::now();
                const int n = modbus_read_input_registers(ctx, 0, ir::kCount, in);
                const auto t1 = Clock::now();
                next =
                    t_start +
                    std::chrono::duration_cast<Clock::duration>(
                        period * (static_cast<double>(k + 1) + static_cast<double>(c) / a.clients));
                if (n != ir::kCount) {
                    if (r.errors++ == 0) r.first_error = modbus_strerror(errno);
                    continue;
                }
                r.latency_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
                if (const auto bad = check_block(in); !bad.empty() && r.torn++ == 0)
                    r.first_error = bad;
                if (last_change == Clock::time_point{} || in[ir::kHeartbeat] != last_beat) {
                    if (last_change != Clock::time_point{})
                        r.max_heartbeat_gap_ms = std::max(
                            r.max_heartbeat_gap_ms,
                            std::chrono::duration<double, std::milli>(t1 - last_change).count());
                    last_beat = in[ir::kHeartbeat];
                    last_change = t1;
                }
            }
            modbus_close(ctx);
            modbus_free(ctx);
        });
    for (auto& t : threads) t.join();
    stop = true;
    plc.join();

    LoadResult out;
    for (const auto& r : results) {
        out.latency_us.insert(out.latency_us.end(), r.latency_us.begin(), r.latency_us.end());
        out.errors += r.errors;
        out.torn += r.torn;
        out.max_heartbeat_gap_ms = std::max(out.max_heartbeat_gap_ms, r.max_heartbeat_gap_ms);
        if (!r.first_error.empty()) out.client_errors.push_back(r.first_error);
    }
    out.cycles = cycles.load();
    out.plc_errors = plc_errors.load();
    return out;
}

// Adds one slice to the total; latencies are sorted by the caller once all slices are in.
void merge(LoadResult& total, const LoadResult& slice) {
    total.latency_us.insert(total.latency_us.end(), slice.latency_us.begin(),
                            slice.latency_us.end());
    total.errors += slice.errors;
    total.torn += slice.torn;
    total.max_heartbeat_gap_ms = std::max(total.max_heartbeat_gap_ms, slice.max_heartbeat_gap_ms);
    total.cycles += slice.cycles;
    total.plc_errors += slice.plc_errors;
    for (const auto& e : slice.client_errors)
        if (std::find(total.client_errors.begin(), total.client_errors.end(), e) ==
            total.client_errors.end())
            total.client_errors.push_back(e);
}

// The baseline: a Modbus TCP server written the way libmodbus 3.1.6's own examples are. One
// thread: modbus_tcp_listen, select() over the listening socket and every client socket,
// modbus_tcp_accept, then modbus_receive + modbus_reply on one shared modbus_mapping_t holding
// the same 6 holding and kCount input registers as ours. After each reply the loop looks at
// the command register to run the handshake, and it bumps the heartbeat. A measuring thread,
// as in a real gauge, writes each result into the mapping in place, register by register,
// under no lock (libmodbus has none to offer: modbus_reply reads the mapping directly), and
// sets the state to DONE last. A reply built while that thread writes can carry half of a
// result, or half of a 32-bit value; the pollers count those as torn or mixed blocks.
// Our stores go through atomic_ref (relaxed; release for the state) so that our side of the
// race is defined behaviour; libmodbus's reads are plain loads, as in any such server.
class LibmodbusBaseline {
  public:
    LibmodbusBaseline(int backlog, int heartbeat_ms, int measure_ms)
        : heartbeat_(heartbeat_ms), measure_(measure_ms) {
        ctx_ = modbus_new_tcp("127.0.0.1", 0);  // port 0: the kernel picks one
        map_ = modbus_mapping_new(0, 0, hr::kWritableCount, ir::kCount);
        if (!ctx_ || !map_) {
            error_ = std::string("libmodbus: ") + modbus_strerror(errno);
            return;
        }
        listen_fd_ = modbus_tcp_listen(ctx_, backlog);
        if (listen_fd_ < 0) {
            error_ = std::string("modbus_tcp_listen: ") + modbus_strerror(errno);
            return;
        }
        sockaddr_in addr{};
        socklen_t len = sizeof addr;
        if (getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
            error_ = std::string("getsockname: ") + std::strerror(errno);
            return;
        }
        port_ = ntohs(addr.sin_port);
        put(ir::kState, static_cast<std::uint16_t>(State::kIdle));
        put(ir::kMapVersionReg, kMapVersion);
        put(ir::kTemperature, static_cast<std::uint16_t>(kInvalidInt16));
        clear_result();
        server_ = std::thread([this] { serve(); });
        measurer_ = std::thread([this] { measure(); });
    }
    ~LibmodbusBaseline() {
        stop_ = true;
        cv_.notify_all();
        if (server_.joinable()) server_.join();
        if (measurer_.joinable()) measurer_.join();
        if (listen_fd_ >= 0) close(listen_fd_);
        if (map_) modbus_mapping_free(map_);
        if (ctx_) modbus_free(ctx_);
    }
    LibmodbusBaseline(const LibmodbusBaseline&) = delete;
    LibmodbusBaseline& operator=(const LibmodbusBaseline&) = delete;

    const std::string& error() const { return error_; }  // "" once serving
    int port() const { return port_; }
    long requests() const { return requests_; }
    long connections() const { return connections_; }
    long failed_replies() const { return failed_replies_; }

  private:
    std::uint16_t get(std::uint16_t a) const {
        return std::atomic_ref<std::uint16_t>(map_->tab_input_registers[a])
            .load(std::memory_order_relaxed);
    }
    void put(std::uint16_t a, std::uint16_t v,
             std::memory_order order = std::memory_order_relaxed) {
        std::atomic_ref<std::uint16_t>(map_->tab_input_registers[a]).store(v, order);
    }
    void put32(std::uint16_t a, std::array<std::uint16_t, 2> v) {
        put(a, v[0]);
        put(static_cast<std::uint16_t>(a + 1), v[1]);
    }
    void clear_result() {
        for (int slot = 1; slot <= kMaxFeatures; ++slot) {
            const auto f = ir::feature(slot);
            put32(static_cast<std::uint16_t>(f + ir::kValueUm),
                  encode_i32(kInvalidInt32, WordOrder::kBigEndian));
            put32(static_cast<std::uint16_t>(f + ir::kValueMm),
                  encode_u32(0x7FC00000u, WordOrder::kBigEndian));  // NaN
            put(static_cast<std::uint16_t>(f + ir::kVerdict), 0);
        }
        put(ir::kOverallVerdict, 0);
        put(ir::kFeatureCount, 0);
    }

    // The handshake, after each modbus_reply (which stored any write into tab_registers).
    void take_command() {
        std::uint16_t* hold = map_->tab_registers;
        put(ir::kPlcHeartbeat, hold[hr::kPlcHeartbeat]);
        const std::uint16_t cmd = hold[hr::kCommand];
        if (cmd == 0) return;
        hold[hr::kCommand] = 0;
        put(ir::kCommandCount, static_cast<std::uint16_t>(get(ir::kCommandCount) + 1));
        const auto state = static_cast<State>(get(ir::kState));
        auto status = ErrorCode::kNone;
        if (cmd == static_cast<std::uint16_t>(Command::kTrigger) && state == State::kIdle) {
            put(ir::kPartId, hold[hr::kPartId]);
            put(ir::kPartId + 1, hold[hr::kPartId + 1]);
            put(ir::kRecipeSlot, hold[hr::kRecipeSlot]);
            put(ir::kFace, hold[hr::kFace]);
            put(ir::kState, static_cast<std::uint16_t>(State::kBusy));
            {
                std::lock_guard lock(m_);  // the trigger queue, not the mapping
                trigger_ = decode_u32(hold[hr::kPartId], hold[hr::kPartId + 1], {});
            }
            cv_.notify_one();
        } else if (cmd == static_cast<std::uint16_t>(Command::kAck) && state == State::kDone) {
            put(ir::kState, static_cast<std::uint16_t>(State::kIdle));
            clear_result();
            put32(ir::kPartId, {0, 0});
        } else {
            status = cmd == static_cast<std::uint16_t>(Command::kTrigger)
                         ? (state == State::kBusy ? ErrorCode::kBusy : ErrorCode::kNotAcknowledged)
                         : ErrorCode::kNothingToAck;
        }
        put(ir::kCommandStatus, static_cast<std::uint16_t>(status));
    }

    void serve() {
        std::vector<int> clients;
        std::uint8_t query[MODBUS_TCP_MAX_ADU_LENGTH];
        const auto beat = std::chrono::milliseconds(heartbeat_);
        auto next_beat = Clock::now() + beat;
        while (!stop_) {
            auto now = Clock::now();
            if (now >= next_beat) {
                put(ir::kHeartbeat, static_cast<std::uint16_t>(get(ir::kHeartbeat) + 1));
                next_beat += beat;
            }
            fd_set rdset;
            FD_ZERO(&rdset);
            FD_SET(listen_fd_, &rdset);
            int fdmax = listen_fd_;
            for (const int fd : clients) {
                FD_SET(fd, &rdset);
                fdmax = std::max(fdmax, fd);
            }
            const auto wait =
                std::chrono::duration_cast<std::chrono::microseconds>(std::clamp<Clock::duration>(
                    next_beat - now, Clock::duration::zero(), std::chrono::milliseconds(20)));
            timeval tv{0, static_cast<suseconds_t>(wait.count())};
            if (select(fdmax + 1, &rdset, nullptr, nullptr, &tv) < 0) {
                if (errno == EINTR) continue;
                std::fprintf(stderr, "baseline select: %s\n", std::strerror(errno));
                break;
            }
            if (FD_ISSET(listen_fd_, &rdset)) {
                int s = listen_fd_;
                if (const int fd = modbus_tcp_accept(ctx_, &s); fd >= 0) {
                    clients.push_back(fd);
                    ++connections_;
                }
            }
            for (auto it = clients.begin(); it != clients.end();) {
                if (!FD_ISSET(*it, &rdset)) {
                    ++it;
                    continue;
                }
                modbus_set_socket(ctx_, *it);
                const int rc = modbus_receive(ctx_, query);
                if (rc > 0) {
                    ++requests_;
                    if (modbus_reply(ctx_, query, rc, map_) < 0) ++failed_replies_;
                    take_command();
                } else if (rc < 0) {  // closed by the client, or garbage
                    close(*it);
                    it = clients.erase(it);
                    continue;
                }
                ++it;
            }
        }
        for (const int fd : clients) close(fd);
    }

    // The measuring side: takes a trigger, "measures", writes the result in place.
    void measure() {
        while (!stop_) {
            std::uint32_t part = 0;
            {
                std::unique_lock lock(m_);
                if (!cv_.wait_for(lock, std::chrono::milliseconds(20),
                                  [&] { return trigger_.has_value() || stop_; }))
                    continue;
                if (stop_) return;
                part = *trigger_;
                trigger_.reset();
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(measure_));
            const PartResult r = derived_result(part);
            for (const auto& f : r.features) {
                const auto base = ir::feature(f.slot);
                const auto um = to_um(f.value_mm);
                put32(static_cast<std::uint16_t>(base + ir::kValueUm),
                      encode_i32(um, WordOrder::kBigEndian));
                put32(static_cast<std::uint16_t>(base + ir::kValueMm),
                      encode_f32(static_cast<float>(*f.value_mm), WordOrder::kBigEndian));
                put(static_cast<std::uint16_t>(base + ir::kVerdict),
                    static_cast<std::uint16_t>(f.verdict));
            }
            put(ir::kOverallVerdict, static_cast<std::uint16_t>(r.overall));
            put(ir::kFeatureCount, static_cast<std::uint16_t>(r.features.size()));
            put(ir::kSequence, static_cast<std::uint16_t>(get(ir::kSequence) + 1));
            put(ir::kState, static_cast<std::uint16_t>(State::kDone), std::memory_order_release);
        }
    }

    int heartbeat_, measure_;
    modbus_t* ctx_ = nullptr;
    modbus_mapping_t* map_ = nullptr;
    int listen_fd_ = -1;
    int port_ = 0;
    std::string error_;
    std::atomic<bool> stop_{false};
    std::atomic<long> requests_{0}, connections_{0}, failed_replies_{0};
    std::mutex m_;
    std::condition_variable cv_;
    std::optional<std::uint32_t> trigger_;
    std::thread server_, measurer_;
};

}  // namespace

int main(int argc, char** argv) {
    Args a;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string k = argv[i];
        const double v = std::atof(argv[i + 1]);
        if (k == "--seconds")
            a.seconds = v;
        else if (k == "--clients")
            a.clients = static_cast<int>(v);
        else if (k == "--rate-hz")
            a.rate_hz = v;
        else if (k == "--measure-ms")
            a.measure_ms = static_cast<int>(v);
        else {
            std::fprintf(stderr, "unknown option %s\n", k.c_str());
            return 2;
        }
    }
    if (argc % 2 == 0 || a.seconds <= 0 || a.clients < 1 || a.rate_hz <= 0) {
        std::fprintf(stderr,
                     "usage: %s [--seconds 30] [--clients 10] [--rate-hz 100] "
                     "[--measure-ms 50]\n",
                     argv[0]);
        return 2;
    }
    spdlog::set_level(spdlog::level::warn);  // connects and triggers are info: not per request
    ServerConfig config;
    config.bind_address = "127.0.0.1";
    config.port = 0;
    config.max_connections = a.clients + 2;
    auto started = Server::start(config);
    if (!started) {
        std::fprintf(stderr, "%s\n", started.error().message.c_str());
        return 1;
    }
    Server& server = **started;
    std::printf(
        "plc bench: %d clients x %.0f Hz reading input 0..%d (%d registers) for %.0f s; "
        "a PLC cycling parts, %d ms per measurement; heartbeat every %d ms\n",
        a.clients, a.rate_hz, ir::kCount - 1, ir::kCount, a.seconds, a.measure_ms,
        config.heartbeat_period_ms);
    std::fflush(stdout);

    std::atomic<bool> stop{false};
    std::thread owner([&] {  // the measuring side: takes triggers, publishes results
        while (!stop) {
            const auto e = server.wait_event(std::chrono::milliseconds(20));
            if (!e || e->kind != PlcEvent::Kind::kTrigger) continue;
            std::this_thread::sleep_for(std::chrono::milliseconds(a.measure_ms));
            (void)server.finish(e->trigger.trigger_id, derived_result(e->trigger.part_id));
        }
    });
    // The baseline serves from the start; the two take turns, never load the cores together.
    LibmodbusBaseline baseline(a.clients + 2, config.heartbeat_period_ms, a.measure_ms);
    const bool have_base = baseline.error().empty();
    const int slices = have_base ? std::max(1, static_cast<int>(std::lround(a.seconds / 5.0))) : 1;
    const double slice_s = a.seconds / slices;
    LoadResult ours, base;
    for (int k = 0; k < slices; ++k) {
        const auto run_ours = [&] {
            merge(ours,
                  run_load(server.port(), a, slice_s, static_cast<std::uint32_t>(1 + ours.cycles)));
        };
        const auto run_base = [&] {
            merge(base, run_load(baseline.port(), a, slice_s,
                                 static_cast<std::uint32_t>(1 + base.cycles)));
        };
        if (k % 2 == 0) {
            run_ours();
            if (have_base) run_base();
        } else {
            run_base();
            run_ours();
        }
    }
    std::sort(ours.latency_us.begin(), ours.latency_us.end());
    std::sort(base.latency_us.begin(), base.latency_us.end());
    stop = true;
    owner.join();

    for (const auto& e : ours.client_errors) std::printf("client error: %s\n", e.c_str());
    const auto st = server.stats();
    const double expected = a.seconds * a.rate_hz * a.clients;
    std::printf(
        "requests: %zu answered of %.0f scheduled (%.1f%%), errors %ld, torn or mixed "
        "blocks %ld\n",
        ours.latency_us.size(), expected,
        100.0 * static_cast<double>(ours.latency_us.size()) / expected, ours.errors, ours.torn);
    std::printf("latency per request: p50 %.0f us, p99 %.0f us, max %.0f us\n", ours.pct(0.50),
                ours.pct(0.99), ours.max());
    std::printf(
        "heartbeat: longest gap between changes seen by a client %.0f ms (period %d ms; "
        "a gap includes up to one poll period)\n",
        ours.max_heartbeat_gap_ms, config.heartbeat_period_ms);
    std::printf(
        "PLC: %ld parts cycled, %ld errors; server: %llu requests, %llu exceptions, "
        "%llu connections\n",
        ours.cycles, ours.plc_errors, static_cast<unsigned long long>(st.requests),
        static_cast<unsigned long long>(st.exceptions),
        static_cast<unsigned long long>(st.accepted));
    const bool stalled = ours.max_heartbeat_gap_ms > 5.0 * config.heartbeat_period_ms;
    if (stalled) std::printf("heartbeat STALLED (gap above 5 periods)\n");
    const bool ok = ours.errors == 0 && ours.torn == 0 && ours.plc_errors == 0 && ours.cycles > 0 &&
                    st.exceptions == 0;

    std::printf(
        "baseline: libmodbus %s modbus_receive + modbus_reply, one select() thread, shared "
        "modbus_mapping_t written in place by a measuring thread under no lock; same load, "
        "taking turns with ours in %d slice(s) of %.1f s\n",
        LIBMODBUS_VERSION_STRING, slices, slice_s);
    if (!have_base) {
        std::printf("baseline: could not start: %s\n", baseline.error().c_str());
    } else {
        for (const auto& e : base.client_errors)
            std::printf("baseline client error: %s\n", e.c_str());
        std::printf(
            "baseline PLC: %ld parts cycled, %ld errors; server: %ld requests, %ld failed "
            "replies, %ld connections\n",
            base.cycles, base.plc_errors, baseline.requests(), baseline.failed_replies(),
            baseline.connections());
    }
    std::printf("%-34s %9s %7s %11s %7s %7s %7s %10s %6s\n", "server", "answered", "errors",
                "torn/mixed", "p50 us", "p99 us", "max us", "hb gap ms", "parts");
    const auto row = [&](const char* name, const LoadResult& r) {
        std::printf("%-34s %9zu %7ld %11ld %7.0f %7.0f %7.0f %10.0f %6ld\n", name,
                    r.latency_us.size(), r.errors, r.torn, r.pct(0.50), r.pct(0.99), r.max(),
                    r.max_heartbeat_gap_ms, r.cycles);
    };
    row("ours (hotgauge plc::Server)", ours);
    if (have_base) {
        row("libmodbus modbus_reply baseline", base);
        const auto ratio = [](double x, double y) { return y > 0 ? x / y : 0.0; };
        std::printf(
            "latency ratio ours / baseline: p50 %.2f, p99 %.2f (below 1: ours faster); "
            "baseline torn or mixed blocks %ld (reported, not a failure)\n",
            ratio(ours.pct(0.50), base.pct(0.50)), ratio(ours.pct(0.99), base.pct(0.99)),
            base.torn);
    }
    std::printf("%s\n", ok ? "PASS: zero errors" : "FAIL");
    return ok ? 0 : 1;
}
