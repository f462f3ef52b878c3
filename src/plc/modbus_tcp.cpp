// MBAP framing and request serving (docs/plc-modbus.md "Server"), moved out of server.cpp so
// that it can be fuzzed without sockets (tests/fuzz/fuzz_modbus.cpp).
#include "hotgauge/plc/modbus_tcp.hpp"

#include <modbus/modbus.h>

namespace hotgauge::plc {
namespace {

std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }

void put16(std::vector<std::uint8_t>& out, std::uint16_t v) {
    out.push_back(static_cast<std::uint8_t>(v >> 8));
    out.push_back(static_cast<std::uint8_t>(v & 0xFF));
}

RequestOutcome reject(Rejection kind, std::uint8_t function, std::string detail) {
    static constexpr std::array<std::uint8_t, kRejectionKinds> kCode = {
        MODBUS_EXCEPTION_ILLEGAL_FUNCTION, MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS,
        MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE, MODBUS_EXCEPTION_GATEWAY_TARGET};
    return {{static_cast<std::uint8_t>(function | 0x80), kCode[kind]}, kind, std::move(detail), {}};
}

}  // namespace

MbapFrame parse_mbap(std::span<const std::uint8_t> rx) {
    MbapFrame f;
    if (rx.size() < kMbapSize) return f;
    const std::uint8_t* h = rx.data();
    f.transaction = be16(h);
    f.protocol = be16(h + 2);
    f.length = be16(h + 4);
    f.unit = h[6];
    if (f.protocol != 0 || f.length < 2 || f.length > kMaxLengthField) {
        f.status = MbapFrame::Status::kMalformed;
        return f;
    }
    f.bytes = 6u + f.length;
    if (rx.size() < f.bytes) return f;
    f.pdu = rx.subspan(kMbapSize, f.length - 1u);
    f.status = MbapFrame::Status::kComplete;
    return f;
}

RequestOutcome serve_request(Handshake& handshake, const std::array<bool, 256>& units,
                             std::uint8_t unit, std::span<const std::uint8_t> request) {
    const std::uint8_t* pdu = request.data();
    const std::size_t size = request.size();
    const std::uint8_t fc = pdu[0];
    if (!units[unit]) return reject(kWrongUnit, fc, "unit " + std::to_string(unit));
    const auto where = [&](const char* what, unsigned address, unsigned count) {
        return std::string(what) + " at " + std::to_string(address) + " x " + std::to_string(count);
    };
    switch (fc) {
        case MODBUS_FC_READ_HOLDING_REGISTERS:
        case MODBUS_FC_READ_INPUT_REGISTERS: {
            if (size != 5)
                return reject(kIllegalValue, fc, "request of " + std::to_string(size) + " bytes");
            const unsigned address = be16(pdu + 1), count = be16(pdu + 3);
            const char* what =
                fc == MODBUS_FC_READ_HOLDING_REGISTERS ? "read holding" : "read input";
            if (count < 1 || count > MODBUS_MAX_READ_REGISTERS)
                return reject(kIllegalValue, fc, where(what, address, count));
            const unsigned end = address + count;
            const auto& in = handshake.inputs();
            RequestOutcome out{{fc, static_cast<std::uint8_t>(2 * count)}, {}, {}, {}};
            if (fc == MODBUS_FC_READ_INPUT_REGISTERS) {
                if (end > ir::kCount)
                    return reject(kIllegalAddress, fc, where(what, address, count));
                for (unsigned a = address; a < end; ++a) put16(out.response, in[a]);
            } else if (end <= hr::kWritableCount) {
                for (unsigned a = address; a < end; ++a)
                    put16(out.response, handshake.holding(static_cast<std::uint16_t>(a)));
            } else if (address >= hr::kMirrorBase && end <= hr::kMirrorBase + ir::kCount) {
                for (unsigned a = address; a < end; ++a)
                    put16(out.response, in[a - hr::kMirrorBase]);
            } else {
                return reject(kIllegalAddress, fc, where(what, address, count));
            }
            return out;
        }
        case MODBUS_FC_WRITE_SINGLE_REGISTER:
        case MODBUS_FC_WRITE_MULTIPLE_REGISTERS: {
            const bool single = fc == MODBUS_FC_WRITE_SINGLE_REGISTER;
            if (size < 5 || (!single && size < 6))
                return reject(kIllegalValue, fc, "request of " + std::to_string(size) + " bytes");
            const unsigned address = be16(pdu + 1);
            const unsigned count = single ? 1u : be16(pdu + 3);
            if (single ? size != 5
                       : (count < 1 || count > MODBUS_MAX_WRITE_REGISTERS || pdu[5] != 2 * count ||
                          size != 6 + 2 * count))
                return reject(kIllegalValue, fc, where("write", address, count));
            if (address + count > hr::kWritableCount)
                return reject(kIllegalAddress, fc, where("write", address, count));
            std::array<std::uint16_t, hr::kWritableCount> values{};
            const std::uint8_t* data = single ? pdu + 3 : pdu + 6;
            for (unsigned i = 0; i < count; ++i) values[i] = be16(data + 2 * i);
            // FC06 echoes the request; FC16 answers function, address, quantity: both are the
            // request's first five bytes.
            return {{pdu, pdu + 5},
                    {},
                    {},
                    handshake.write(static_cast<std::uint16_t>(address), {values.data(), count})};
        }
        default:
            return reject(kIllegalFunction, fc, "function " + std::to_string(fc));
    }
}

void append_response(std::vector<std::uint8_t>& tx, const MbapFrame& frame,
                     std::span<const std::uint8_t> pdu) {
    put16(tx, frame.transaction);
    put16(tx, 0);
    put16(tx, static_cast<std::uint16_t>(pdu.size() + 1));
    tx.push_back(frame.unit);
    tx.insert(tx.end(), pdu.begin(), pdu.end());
}

}  // namespace hotgauge::plc
