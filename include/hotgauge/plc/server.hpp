#pragma once
// The Modbus TCP server the line PLC (and an HMI, a laptop) talks to (docs/plc-modbus.md).
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/plc/handshake.hpp"

namespace hotgauge::plc {

struct ServerConfig {
    std::string bind_address = "0.0.0.0";      // IPv4; tests use 127.0.0.1
    int port = 502;                            // 0: ephemeral, see Server::port()
    std::vector<int> unit_ids = {0, 1, 255};   // accepted unit identifiers; others get 0x0B
    std::vector<std::string> allowed_clients;  // IPv4 "a.b.c.d" or "a.b.c.d/n"; empty: anyone
    // Every slot taken: a new connection closes the one that never sent a request, else the one
    // idle longest (RST), so the PLC can always get in.
    int max_connections = 8;
    int idle_timeout_ms = 60000;  // no complete request for this long: closed; 0: never
    int heartbeat_period_ms = 100;
    WordOrder word_order = WordOrder::kBigEndian;
    // Not a setting: input 5 before the first DONE, the daemon's last result sequence from its
    // results files (docs/plc-modbus.md "Across a restart").
    std::uint16_t first_sequence = 0;
};

core::Result<void> check_config(const ServerConfig& c);

struct ServerStats {
    std::uint64_t accepted = 0;   // connections
    std::uint64_t refused = 0;    // not on the allow-list
    std::uint64_t evicted = 0;    // closed to make room for a new one (max_connections)
    std::uint64_t timed_out = 0;  // closed for idleness
    std::uint64_t malformed = 0;  // connections closed for a malformed MBAP header
    std::uint64_t requests = 0;
    std::uint64_t exceptions = 0;  // exception responses sent
    int clients = 0;               // connected now
};

// Thread-safety: one server thread owns the sockets and serves every request under `mutex_`,
// so a response is always one consistent snapshot of the register image (a 32-bit value or a
// result block is never torn). The owner's calls (finish, fault, wait_event, state, stats) take
// the same mutex for microseconds and never wait on the network; the server thread never waits
// on the owner: commands reach it through a bounded event queue. All public members may be
// called from any thread.
class Server {
  public:
    // Binds and starts serving; errors name the address and the reason.
    static core::Result<std::unique_ptr<Server>> start(const ServerConfig& config);
    ~Server();
    Server(const Server&) = delete;
    Server& operator=(const Server&) = delete;

    int port() const { return port_; }

    // The next trigger or reset from the PLC, waiting up to `timeout`.
    std::optional<PlcEvent> wait_event(std::chrono::milliseconds timeout);
    // Publishes the result of `trigger_id` (BUSY -> DONE) as one block; see Handshake::finish.
    core::Result<void> finish(std::uint32_t trigger_id, const PartResult& result);
    void fault(std::uint16_t code);
    void scans_done(std::uint32_t trigger_id);  // see Handshake::scans_done
    void set_cell_status(const CellStatus& s);

    State state() const;
    Handshake::InputImage inputs() const;
    ServerStats stats() const;

  private:
    struct Impl;
    explicit Server(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
    int port_ = 0;
};

}  // namespace hotgauge::plc
