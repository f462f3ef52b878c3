// PLC server under load (docs/plc-modbus.md, docs/benchmarks.md): N clients (libmodbus, each on
// its own connection and thread) poll the whole register map at a fixed rate while a PLC client
// cycles parts through the handshake (trigger -> BUSY -> DONE -> ack) and an owner thread
// publishes a result for each. Reports request errors, blocks seen torn or mixed, the longest
// gap between heartbeat changes any client saw, and request latency p50/p99/max.
// Exit code 1 on any error or torn block (the short ctest asserts that, never timings).
//   hotgauge_bench_plc [--seconds 30] [--clients 10] [--rate-hz 100] [--measure-ms 50]
#include <modbus/modbus.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
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

modbus_t* connect(int port) {
    modbus_t* ctx = modbus_new_tcp("127.0.0.1", port);
    modbus_set_slave(ctx, 1);
    modbus_set_response_timeout(ctx, 1, 0);
    if (modbus_connect(ctx) != 0) {
        std::fprintf(stderr, "connect: %s\n", modbus_strerror(errno));
        std::exit(1);
    }
    return ctx;
}

struct ClientResult {
    std::vector<double> latency_us;
    long errors = 0, torn = 0;
    double max_heartbeat_gap_ms = 0;
    std::string first_error;
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
    std::atomic<long> cycles{0}, plc_errors{0};
    std::thread plc([&] {  // the line PLC: trigger, poll until DONE, read, ack
        modbus_t* ctx = connect(server.port());
        std::uint32_t part = 1;
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
    const auto t_end = t_start + std::chrono::duration<double>(a.seconds);
    const auto period = std::chrono::duration<double>(1.0 / a.rate_hz);
    for (int c = 0; c < a.clients; ++c)
        threads.emplace_back([&, c] {
            auto& r = results[static_cast<std::size_t>(c)];
            r.latency_us.reserve(static_cast<std::size_t>(a.seconds * a.rate_hz) + 16);
            modbus_t* ctx = connect(server.port());
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
    owner.join();

    std::vector<double> all;
    long errors = 0, torn = 0;
    double gap = 0;
    for (const auto& r : results) {
        all.insert(all.end(), r.latency_us.begin(), r.latency_us.end());
        errors += r.errors;
        torn += r.torn;
        gap = std::max(gap, r.max_heartbeat_gap_ms);
        if (!r.first_error.empty()) std::printf("client error: %s\n", r.first_error.c_str());
    }
    std::sort(all.begin(), all.end());
    const auto pct = [&](double p) {
        if (all.empty()) return 0.0;
        const double last = static_cast<double>(all.size() - 1);
        return all[static_cast<std::size_t>(std::min(last, p * last + 0.5))];
    };
    const auto st = server.stats();
    const double expected = a.seconds * a.rate_hz * a.clients;
    std::printf(
        "requests: %zu answered of %.0f scheduled (%.1f%%), errors %ld, torn or mixed "
        "blocks %ld\n",
        all.size(), expected, 100.0 * static_cast<double>(all.size()) / expected, errors, torn);
    std::printf("latency per request: p50 %.0f us, p99 %.0f us, max %.0f us\n", pct(0.50),
                pct(0.99), all.empty() ? 0.0 : all.back());
    std::printf(
        "heartbeat: longest gap between changes seen by a client %.0f ms (period %d ms; "
        "a gap includes up to one poll period)\n",
        gap, config.heartbeat_period_ms);
    std::printf(
        "PLC: %ld parts cycled, %ld errors; server: %llu requests, %llu exceptions, "
        "%llu connections\n",
        cycles.load(), plc_errors.load(), static_cast<unsigned long long>(st.requests),
        static_cast<unsigned long long>(st.exceptions),
        static_cast<unsigned long long>(st.accepted));
    const bool stalled = gap > 5.0 * config.heartbeat_period_ms;
    if (stalled) std::printf("heartbeat STALLED (gap above 5 periods)\n");
    const bool ok = errors == 0 && torn == 0 && plc_errors == 0 && cycles > 0 && st.exceptions == 0;
    std::printf("%s\n", ok ? "PASS: zero errors" : "FAIL");
    return ok ? 0 : 1;
}
