// Fuzzes the Modbus TCP request path (plc/modbus_tcp.hpp) as the server runs it for one client,
// without sockets: parse_mbap, serve_request on a Handshake, append_response, frame after frame.
//
// Input: the client's byte stream (a sequence of MBAP frames), served until it ends, a frame is
// incomplete or malformed (the server closes the connection there). The word order is little-
// endian when the stream's first byte has bit 7 set. The owner's side (the daemon) is driven by
// each request's transaction id, after the request: bit 0 finishes the BUSY cycle with a result
// of (high byte % 20) features (bits 3-5 pick the values, bits 6-7 the verdicts; over 16
// features the result is invalid, a bug in the owner: FAULT 205), bit 1 faults with the high
// byte as code, bit 2 ticks the heartbeat.
//
// Asserts: no crash, sanitizer report or exception; every response is a well-formed frame for
// its request (exception = function | 0x80 and one code byte; reads return exactly the requested
// registers of the register image; writes echo the request's first five bytes); the handshake
// stays consistent (state register = state, the command register reads back 0, results only in
// DONE, docs/plc-modbus.md "Handshake"); finish works exactly when BUSY with a valid result.
#include <modbus/modbus.h>

#include <cmath>
#include <limits>

#include "fuzz_util.hpp"
#include "hotgauge/plc/modbus_tcp.hpp"
#include "hotgauge/plc/server.hpp"

using namespace hotgauge;
using namespace hotgauge::plc;

namespace {

constexpr double kValues[] = {12.3456,
                              0.0,
                              -2147483.648,
                              2147483.647,
                              1e300,
                              -std::numeric_limits<double>::infinity(),
                              std::numeric_limits<double>::quiet_NaN(),
                              -0.0004};
constexpr Verdict kVerdicts[] = {Verdict::kOk, Verdict::kNok, Verdict::kNotMeasured,
                                 Verdict::kDegraded};

std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }

PartResult owner_result(std::uint16_t t) {
    PartResult r;
    const int n = (t >> 8) % 20;
    for (int i = 0; i < n; ++i) {
        FeatureValue f;
        f.name = "f" + std::to_string(i);
        f.slot = i + 1;
        f.verdict = kVerdicts[((t >> 6) + i) % 4];
        if (f.verdict != Verdict::kNotMeasured) f.value_mm = kValues[((t >> 3) + i) % 8];
        r.features.push_back(f);
    }
    r.overall = overall_verdict(r.features, false);
    if (t & 0x20) r.temperature_c = kValues[(t >> 3) % 8] * 100.0;
    return r;
}

void check_handshake(const Handshake& h) {
    const auto& in = h.inputs();
    const auto s = static_cast<std::uint16_t>(h.state());
    fuzz::check(s >= 1 && s <= 4 && in[ir::kState] == s, "state register");
    fuzz::check(h.holding(hr::kCommand) == 0, "the command register does not read back 0");
    if (h.state() != State::kDone)
        fuzz::check(in[ir::kOverallVerdict] == 0 && in[ir::kFeatureCount] == 0,
                    "a result is visible outside DONE");
}

void check_response(const Handshake& h, std::span<const std::uint8_t> req,
                    const RequestOutcome& out) {
    const auto& r = out.response;
    const std::uint8_t fc = req[0];
    fuzz::check(!r.empty() && r.size() <= 253, "response PDU size");
    if (out.rejection) {
        fuzz::check(r.size() == 2 && r[0] == (fc | 0x80) && !out.event, "exception response");
        return;
    }
    fuzz::check(r[0] == fc, "response function code");
    if (fc == MODBUS_FC_READ_HOLDING_REGISTERS || fc == MODBUS_FC_READ_INPUT_REGISTERS) {
        const unsigned address = be16(&req[1]), count = be16(&req[3]);
        fuzz::check(r.size() == 2 + 2 * count && r[1] == 2 * count, "read response size");
        for (unsigned i = 0; i < count; ++i) {
            const unsigned a = address + i;
            const std::uint16_t want = fc == MODBUS_FC_READ_INPUT_REGISTERS ? h.inputs()[a]
                                       : a < hr::kWritableCount
                                           ? h.holding(static_cast<std::uint16_t>(a))
                                           : h.inputs()[a - hr::kMirrorBase];
            fuzz::check(be16(&r[2 + 2 * i]) == want, "read response differs from the image");
        }
    } else {
        fuzz::check(
            (fc == MODBUS_FC_WRITE_SINGLE_REGISTER || fc == MODBUS_FC_WRITE_MULTIPLE_REGISTERS) &&
                r.size() == 5 && std::equal(r.begin(), r.end(), req.begin()),
            "write response");
    }
}

void owner(Handshake& h, std::uint16_t t) {
    if (t & 1) {
        const PartResult r = owner_result(t);
        const bool busy = h.state() == State::kBusy, valid = check_result(r).ok();
        const auto sequence = h.sequence();
        const auto ok = h.finish(h.busy_trigger_id(), r);
        fuzz::check(ok.ok() == (busy && valid), "finish accepted or refused wrongly");
        if (busy)
            fuzz::check(valid ? h.state() == State::kDone &&
                                    h.sequence() == static_cast<std::uint16_t>(sequence + 1) &&
                                    h.inputs()[ir::kFeatureCount] == r.features.size()
                              : h.state() == State::kFault &&
                                    h.inputs()[ir::kErrorCode] ==
                                        static_cast<std::uint16_t>(ErrorCode::kInternal),
                        "state after finish");
    }
    if (t & 2) h.fault(static_cast<std::uint16_t>(t >> 8));
    if (t & 4) h.tick_heartbeat();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::array<bool, 256> units{};
    for (int u : ServerConfig{}.unit_ids) units[static_cast<std::size_t>(u)] = true;
    Handshake h(size && (data[0] & 0x80) ? WordOrder::kLittleEndian : WordOrder::kBigEndian);
    std::span<const std::uint8_t> rx(data, size);
    std::vector<std::uint8_t> tx;
    for (;;) {
        const MbapFrame f = parse_mbap(rx);
        if (f.status != MbapFrame::Status::kComplete) break;
        fuzz::check(f.bytes <= rx.size() && !f.pdu.empty() && f.pdu.size() + 7 == f.bytes,
                    "frame bounds");
        const RequestOutcome out = serve_request(h, units, f.unit, f.pdu);
        check_response(h, f.pdu, out);
        check_handshake(h);
        tx.clear();
        append_response(tx, f, out.response);
        const MbapFrame back = parse_mbap(tx);
        fuzz::check(back.status == MbapFrame::Status::kComplete && back.bytes == tx.size() &&
                        back.transaction == f.transaction && back.unit == f.unit &&
                        std::equal(back.pdu.begin(), back.pdu.end(), out.response.begin(),
                                   out.response.end()),
                    "response frame");
        owner(h, f.transaction);
        check_handshake(h);
        rx = rx.subspan(f.bytes);
    }
    return 0;
}
