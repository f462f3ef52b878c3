#pragma once
// Serving Modbus TCP requests (docs/plc-modbus.md "Server"): MBAP framing, and function codes 03,
// 04, 06 and 16 on the Handshake's register image. Pure: no sockets, locks or logging. The server
// calls these for each client's receive buffer under its mutex; tests/fuzz/fuzz_modbus.cpp feeds
// them byte streams directly.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "hotgauge/plc/handshake.hpp"

namespace hotgauge::plc {

inline constexpr std::size_t kMbapSize = 7;          // transaction, protocol, length (2 each), unit
inline constexpr std::size_t kMaxLengthField = 254;  // unit id + a PDU of at most 253 bytes

// The first MBAP frame of a receive buffer.
struct MbapFrame {
    enum class Status {
        kComplete,    // `pdu` holds the request; the frame is `bytes` long
        kIncomplete,  // the rest is still on its way (or fewer than kMbapSize bytes)
        kMalformed,   // protocol not 0 or length out of 2..kMaxLengthField: the stream is lost
    } status = Status::kIncomplete;
    std::uint16_t transaction = 0, protocol = 0, length = 0;
    std::uint8_t unit = 0;
    std::span<const std::uint8_t> pdu;  // function code first, at least one byte
    std::size_t bytes = 0;              // 6 + length
};
MbapFrame parse_mbap(std::span<const std::uint8_t> rx);

// Why a request got an exception response; counted and logged per client by the server.
enum Rejection { kIllegalFunction, kIllegalAddress, kIllegalValue, kWrongUnit, kRejectionKinds };

struct RequestOutcome {
    std::vector<std::uint8_t> response;  // the response PDU, function code first
    std::optional<Rejection> rejection;  // set: `response` is an exception response
    std::string detail;                  // what was rejected, for the log
    std::optional<PlcEvent> event;       // a trigger or reset that a write gave
};

// Serves the request `pdu` (function code first, at least one byte) addressed to `unit`;
// `units[u]`: unit id u is answered (others get exception 0B).
RequestOutcome serve_request(Handshake& handshake, const std::array<bool, 256>& units,
                             std::uint8_t unit, std::span<const std::uint8_t> pdu);

// Appends the response frame of `frame`'s request: its MBAP header, then `pdu`.
void append_response(std::vector<std::uint8_t>& tx, const MbapFrame& frame,
                     std::span<const std::uint8_t> pdu);

}  // namespace hotgauge::plc
