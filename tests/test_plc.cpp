// PLC interface (docs/plc-modbus.md): the register encoding against the docs' worked examples,
// the handshake state machine exhaustively (every command in every state), the docs' tables
// against the code's, and the Modbus TCP server with real clients on 127.0.0.1 (libmodbus as a
// well-behaved client, raw sockets as misbehaving ones): a full cycle, atomic publication under
// concurrent readers, and every kind of bad input with another client working throughout.
// The pyrometer runs over a socat virtual serial pair (Pyrometer.*, an integration ctest).
// No sleeps as waits: every wait is bounded and on a condition.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <modbus/modbus.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <spdlog/sinks/ringbuffer_sink.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/plc/handshake.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/register_map.hpp"
#include "hotgauge/plc/server.hpp"
#include "serial_pair.hpp"
#include "temp_dir.hpp"

using namespace hotgauge::plc;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

// The plc module's log, captured: it must say things once per client, not per packet.
std::shared_ptr<spdlog::sinks::ringbuffer_sink_mt> plc_log_capture() {
    static const auto sink = [] {
        auto ring = std::make_shared<spdlog::sinks::ringbuffer_sink_mt>(4096);
        auto logger = std::make_shared<spdlog::logger>("plc", ring);
        logger->set_level(spdlog::level::info);
        spdlog::register_logger(logger);
        return ring;
    }();
    return sink;
}
const auto g_capture = plc_log_capture();  // before any plc code logs

// Log lines containing `needle` so far (the capture is shared by every test: compare counts).
int count_lines(const std::string& needle) {
    int n = 0;
    for (const auto& line : g_capture->last_formatted())
        if (line.find(needle) != std::string::npos) ++n;
    return n;
}

bool eventually(const std::function<bool()>& done, std::chrono::milliseconds timeout = 5s) {
    const auto deadline = Clock::now() + timeout;
    while (!done()) {
        if (Clock::now() > deadline) return false;
        std::this_thread::sleep_for(2ms);
    }
    return true;
}

std::uint16_t u16(Verdict v) { return static_cast<std::uint16_t>(v); }
std::uint16_t u16(State s) { return static_cast<std::uint16_t>(s); }
std::uint16_t u16(ErrorCode e) { return static_cast<std::uint16_t>(e); }
std::uint16_t u16(Command c) { return static_cast<std::uint16_t>(c); }
std::uint16_t u16(DriftState d) { return static_cast<std::uint16_t>(d); }
std::uint16_t u16(ScanPhase p) { return static_cast<std::uint16_t>(p); }
std::uint16_t u16(CalibrationState c) { return static_cast<std::uint16_t>(c); }

// ---- register encoding: the worked examples of docs/plc-modbus.md ---------------------------

TEST(Encoding, WorkedExamplesBigEndianWords) {
    // 25.400 mm = 25400 µm = 0x00006338
    EXPECT_EQ(to_um(25.4), 25400);
    EXPECT_EQ(encode_i32(25400, WordOrder::kBigEndian),
              (std::array<std::uint16_t, 2>{0x0000, 0x6338}));
    // 138.400 mm = 138400 µm = 0x00021CA0: the high word is not zero
    EXPECT_EQ(encode_i32(to_um(138.4), WordOrder::kBigEndian),
              (std::array<std::uint16_t, 2>{0x0002, 0x1CA0}));
    // -1.500 mm = -1500 µm = 0xFFFFFA24 (two's complement)
    EXPECT_EQ(encode_i32(to_um(-1.5), WordOrder::kBigEndian),
              (std::array<std::uint16_t, 2>{0xFFFF, 0xFA24}));
    // not measured = 0x80000000
    EXPECT_EQ(encode_i32(to_um(std::nullopt), WordOrder::kBigEndian),
              (std::array<std::uint16_t, 2>{0x8000, 0x0000}));
    // 25.4f = 0x41CB3333
    EXPECT_EQ(encode_f32(25.4f, WordOrder::kBigEndian),
              (std::array<std::uint16_t, 2>{0x41CB, 0x3333}));
}

TEST(Encoding, WorkedExamplesLittleEndianWords) {
    EXPECT_EQ(encode_i32(25400, WordOrder::kLittleEndian),
              (std::array<std::uint16_t, 2>{0x6338, 0x0000}));
    EXPECT_EQ(encode_i32(138400, WordOrder::kLittleEndian),
              (std::array<std::uint16_t, 2>{0x1CA0, 0x0002}));
    EXPECT_EQ(encode_f32(25.4f, WordOrder::kLittleEndian),
              (std::array<std::uint16_t, 2>{0x3333, 0x41CB}));
}

TEST(Encoding, RoundTripsBothOrders) {
    for (auto order : {WordOrder::kBigEndian, WordOrder::kLittleEndian})
        for (std::int32_t v : {0, 1, -1, 25400, -1500, 65535, 65536, INT32_MAX, INT32_MIN + 1}) {
            const auto w = encode_i32(v, order);
            EXPECT_EQ(decode_i32(w[0], w[1], order), v);
            const float f = static_cast<float>(v) / 1000.0f;
            const auto fw = encode_f32(f, order);
            EXPECT_EQ(std::bit_cast<std::uint32_t>(decode_f32(fw[0], fw[1], order)),
                      std::bit_cast<std::uint32_t>(f));
        }
}

TEST(Encoding, MicrometreRoundingAndInvalidMarker) {
    EXPECT_EQ(to_um(0.0004), 0);
    EXPECT_EQ(to_um(0.0006), 1);
    EXPECT_EQ(to_um(-0.0006), -1);
    EXPECT_EQ(to_um(2147483.647), INT32_MAX);
    EXPECT_EQ(to_um(2147483.648), kInvalidInt32);   // too large
    EXPECT_EQ(to_um(-2147483.648), kInvalidInt32);  // would be the marker itself
    EXPECT_EQ(to_um(-2147483.647), INT32_MIN + 1);
    EXPECT_EQ(to_um(std::nan("")), kInvalidInt32);
    EXPECT_EQ(to_um(INFINITY), kInvalidInt32);
    EXPECT_EQ(to_decicelsius(1050.0), 10500);
    EXPECT_EQ(to_decicelsius(-12.34), -123);
    EXPECT_EQ(to_decicelsius(std::nullopt), kInvalidInt16);
    EXPECT_EQ(to_decicelsius(4000.0), kInvalidInt16);
}

TEST(Encoding, WordOrderNames) {
    EXPECT_EQ(parse_word_order("big"), WordOrder::kBigEndian);
    EXPECT_EQ(parse_word_order("little"), WordOrder::kLittleEndian);
    EXPECT_FALSE(parse_word_order("middle"));
}

// ---- the docs agree with the code ----------------------------------------------------------

TEST(RegisterMap, DocsContainTheGeneratedTables) {
    std::ifstream in(std::string(HOTGAUGE_SOURCE_DIR) + "/docs/plc-modbus.md");
    ASSERT_TRUE(in) << "docs/plc-modbus.md missing";
    std::stringstream doc;
    doc << in.rdbuf();
    // Each table of `hotgauge plc map` appears verbatim (the docs put headings between them).
    const std::string tables = map_markdown();
    int n = 0;
    for (std::size_t from = 0; from < tables.size(); ++n) {
        const std::size_t to = std::min(tables.find("\n\n", from), tables.size());
        const std::string table = tables.substr(from, to - from + 1);
        EXPECT_NE(doc.str().find(table), std::string::npos)
            << "docs/plc-modbus.md lacks this table of `hotgauge plc map`:\n"
            << table;
        from = to + 2;
    }
    EXPECT_EQ(n, 4);
}

TEST(RegisterMap, LayoutFitsOneReadAndTheMirror) {
    EXPECT_EQ(ir::kCount, 123);
    EXPECT_LE(ir::kCount, MODBUS_MAX_READ_REGISTERS);  // the whole map in one request
    EXPECT_EQ(ir::feature(1), 16);
    EXPECT_EQ(ir::feature(16) + ir::kFeatureStride, ir::kScanPhase);  // v3's addresses kept
    EXPECT_GT(hr::kMirrorBase, hr::kWritableCount);
}

// ---- handshake -------------------------------------------------------------------------------

// A result whose every value derives from `part` (and the slot): a reader can tell a mixed or
// torn block from a whole one. Signs alternate; the high word changes from part to part.
std::int32_t derived_um(std::uint32_t part, int slot) {
    const std::int32_t v = static_cast<std::int32_t>(part % 50000) * 40000 + slot * 3;
    return slot % 2 ? -v : v;
}

PartResult derived_result(std::uint32_t part, int n = kMaxFeatures) {
    PartResult r;
    for (int slot = 1; slot <= n; ++slot)
        r.features.push_back(
            {"f" + std::to_string(slot), slot, derived_um(part, slot) / 1000.0, Verdict::kOk});
    r.overall = Verdict::kOk;
    r.temperature_c = 1000.0 + part % 100;
    return r;
}

std::vector<std::uint16_t> trigger_write(std::uint32_t part, std::uint16_t slot = 1,
                                         std::uint16_t face = 0,
                                         WordOrder order = WordOrder::kBigEndian) {
    const auto p = encode_u32(part, order);
    return {u16(Command::kTrigger), p[0], p[1], slot, face, 0};
}

std::optional<PlcEvent> command(Handshake& h, std::uint16_t code) {
    const std::uint16_t v = code;
    return h.write(hr::kCommand, {&v, 1});
}

bool result_cleared(const Handshake& h) {
    const auto& in = h.inputs();
    if (in[ir::kOverallVerdict] != 0 || in[ir::kFeatureCount] != 0) return false;
    if (in[ir::kTemperature] != 0x8000) return false;
    for (int slot = 1; slot <= kMaxFeatures; ++slot) {
        const auto a = ir::feature(slot);
        if (decode_i32(in[a], in[a + 1], h.word_order()) != kInvalidInt32) return false;
        if (!std::isnan(decode_f32(in[a + 2], in[a + 3], h.word_order()))) return false;
        if (in[a + ir::kVerdict] != 0) return false;
    }
    return true;
}

// A handshake brought to `s` the way the PLC and the owner would, with valid trigger parameters
// (part 42, recipe slot 1, all faces) in the writable block.
Handshake in_state(State s) {
    Handshake h;
    const std::vector<std::uint16_t> params = {0, 42, 1, 0};
    h.write(hr::kPartId, params);
    if (s == State::kIdle) return h;
    const auto w = trigger_write(42);
    const auto e = h.write(0, w);
    if (s == State::kBusy) return h;
    if (s == State::kDone) {
        EXPECT_TRUE(h.finish(e->trigger.trigger_id, derived_result(42)));
        return h;
    }
    h.fault(u16(ErrorCode::kMeasurementFailed));
    return h;
}

TEST(Handshake, StartsIdleWithNothingShown) {
    Handshake h;
    EXPECT_EQ(h.state(), State::kIdle);
    EXPECT_EQ(h.inputs()[ir::kState], u16(State::kIdle));
    EXPECT_EQ(h.inputs()[ir::kMapVersionReg], kMapVersion);
    EXPECT_TRUE(result_cleared(h));
}

struct Expect {
    State next;
    ErrorCode status;
    std::optional<PlcEvent::Kind> event;
};

TEST(Handshake, EveryCommandInEveryState) {
    constexpr std::uint16_t kUnknown = 7;
    const std::vector<State> states = {State::kIdle, State::kBusy, State::kDone, State::kFault};
    const std::vector<std::uint16_t> commands = {u16(Command::kTrigger), u16(Command::kAck),
                                                 u16(Command::kReset), kUnknown};
    using K = PlcEvent::Kind;
    // rows: state; columns: trigger, ack, reset, unknown (docs/plc-modbus.md "Handshake")
    const std::map<State, std::vector<Expect>> table = {
        {State::kIdle,
         {{State::kBusy, ErrorCode::kNone, K::kTrigger},
          {State::kIdle, ErrorCode::kNothingToAck, {}},
          {State::kIdle, ErrorCode::kNone, {}},
          {State::kIdle, ErrorCode::kUnknownCommand, {}}}},
        {State::kBusy,
         {{State::kBusy, ErrorCode::kBusy, {}},
          {State::kBusy, ErrorCode::kNothingToAck, {}},
          {State::kIdle, ErrorCode::kNone, K::kReset},
          {State::kBusy, ErrorCode::kUnknownCommand, {}}}},
        {State::kDone,
         {{State::kDone, ErrorCode::kNotAcknowledged, {}},
          {State::kIdle, ErrorCode::kNone, {}},
          {State::kIdle, ErrorCode::kNone, {}},
          {State::kDone, ErrorCode::kUnknownCommand, {}}}},
        {State::kFault,
         {{State::kFault, ErrorCode::kInFault, {}},
          {State::kFault, ErrorCode::kInFault, {}},
          {State::kIdle, ErrorCode::kNone, K::kReset},
          {State::kFault, ErrorCode::kUnknownCommand, {}}}},
    };
    for (State s : states)
        for (std::size_t c = 0; c < commands.size(); ++c) {
            SCOPED_TRACE(std::string(to_string(s)) + " + command " + std::to_string(commands[c]));
            Handshake h = in_state(s);
            const auto before = h.inputs();
            const Expect& x = table.at(s)[c];
            const auto e = command(h, commands[c]);
            EXPECT_EQ(h.state(), x.next);
            EXPECT_EQ(h.inputs()[ir::kState], u16(x.next));
            EXPECT_EQ(h.inputs()[ir::kCommandStatus], u16(x.status));
            EXPECT_EQ(h.inputs()[ir::kCommandCount], before[ir::kCommandCount] + 1);
            EXPECT_EQ(h.holding(hr::kCommand), 0) << "a taken command reads back 0";
            ASSERT_EQ(e.has_value(), x.event.has_value());
            if (e) {
                EXPECT_EQ(e->kind, *x.event);
            }
            // Results only in DONE; a refused command in DONE changes nothing of them.
            EXPECT_EQ(result_cleared(h), x.next != State::kDone);
            if (x.next == State::kDone) {
                for (std::uint16_t a = ir::kSequence; a < ir::kCount; ++a)
                    EXPECT_EQ(h.inputs()[a], before[a]) << "register " << a;
            }
            // The fault code stays until the reset; IDLE shows none.
            const std::uint16_t fault_code =
                x.next == State::kFault ? u16(ErrorCode::kMeasurementFailed) : 0;
            EXPECT_EQ(h.inputs()[ir::kErrorCode], fault_code);
            if (x.next == State::kIdle) {
                EXPECT_EQ(decode_u32(h.inputs()[ir::kPartId], h.inputs()[ir::kPartId + 1], {}), 0u);
            }
        }
}

TEST(Handshake, CommandZeroIsANoOp) {
    for (State s : {State::kIdle, State::kBusy, State::kDone, State::kFault}) {
        Handshake h = in_state(s);
        const auto before = h.inputs();
        EXPECT_FALSE(command(h, 0));
        EXPECT_EQ(h.inputs(), before);
    }
}

TEST(Handshake, TriggerTakesItsParametersFromTheSameWrite) {
    for (auto order : {WordOrder::kBigEndian, WordOrder::kLittleEndian}) {
        Handshake h(order);
        const auto e = h.write(0, trigger_write(0x12345678, 3, 2, order));
        ASSERT_TRUE(e);
        EXPECT_EQ(e->trigger.part_id, 0x12345678u);
        EXPECT_EQ(e->trigger.recipe_slot, 3);
        EXPECT_EQ(e->trigger.face, Face::kBottom);
        EXPECT_EQ(e->trigger.trigger_id, 1u);
        const auto& in = h.inputs();
        EXPECT_EQ(decode_u32(in[ir::kPartId], in[ir::kPartId + 1], order), 0x12345678u);
        EXPECT_EQ(in[ir::kRecipeSlot], 3);
        EXPECT_EQ(in[ir::kFace], 2);
    }
}

TEST(Handshake, TriggerParametersAreChecked) {
    Handshake h;
    EXPECT_FALSE(h.write(0, trigger_write(1, 1, kMaxFace + 1)));
    EXPECT_EQ(h.inputs()[ir::kCommandStatus], u16(ErrorCode::kBadFace));
    EXPECT_FALSE(h.write(0, trigger_write(1, 0, 0)));
    EXPECT_EQ(h.inputs()[ir::kCommandStatus], u16(ErrorCode::kBadRecipeSlot));
    EXPECT_EQ(h.state(), State::kIdle);
    EXPECT_TRUE(h.write(0, trigger_write(1, 1, kMaxFace)));
    EXPECT_EQ(h.inputs()[ir::kCommandStatus], 0);
}

TEST(Handshake, PlcHeartbeatIsEchoedAndOursCounts) {
    Handshake h;
    const std::uint16_t beat = 4711;
    h.write(hr::kPlcHeartbeat, {&beat, 1});
    EXPECT_EQ(h.inputs()[ir::kPlcHeartbeat], 4711);
    EXPECT_EQ(h.holding(hr::kPlcHeartbeat), 4711);
    for (int i = 0; i < 70000; ++i) h.tick_heartbeat();
    EXPECT_EQ(h.inputs()[ir::kHeartbeat], 70000 % 65536);
}

TEST(Handshake, DonePublishesTheWholeResult) {
    for (auto order : {WordOrder::kBigEndian, WordOrder::kLittleEndian}) {
        Handshake h(order);
        const auto e = h.write(0, trigger_write(77, 1, 0, order));
        PartResult r = derived_result(77, 13);
        r.features[2].value_mm.reset();  // slot 3 not measured
        r.features[2].verdict = Verdict::kNotMeasured;
        r.overall = overall_verdict(r.features, false);
        ASSERT_TRUE(h.finish(e->trigger.trigger_id, r));
        const auto& in = h.inputs();
        EXPECT_EQ(in[ir::kState], u16(State::kDone));
        EXPECT_EQ(in[ir::kSequence], 1);
        EXPECT_EQ(in[ir::kOverallVerdict], u16(Verdict::kNotMeasured));
        EXPECT_EQ(in[ir::kFeatureCount], 13);
        EXPECT_EQ(std::bit_cast<std::int16_t>(in[ir::kTemperature]), 10770);
        for (int slot = 1; slot <= kMaxFeatures; ++slot) {
            const auto a = ir::feature(slot);
            const auto um = decode_i32(in[a], in[a + 1], order);
            const float mm = decode_f32(in[a + 2], in[a + 3], order);
            if (slot == 3 || slot > 13) {
                EXPECT_EQ(um, kInvalidInt32);
                EXPECT_TRUE(std::isnan(mm));
                EXPECT_EQ(in[a + 4], u16(slot == 3 ? Verdict::kNotMeasured : Verdict::kNone));
            } else {
                EXPECT_EQ(um, derived_um(77, slot));
                EXPECT_EQ(mm, static_cast<float>(derived_um(77, slot) / 1000.0));
                EXPECT_EQ(in[a + 4], u16(Verdict::kOk));
            }
        }
    }
}

TEST(Handshake, FinishOnlyForTheBusyTrigger) {
    Handshake h;
    EXPECT_FALSE(h.finish(0, derived_result(1))) << "not BUSY";
    const auto e1 = h.write(0, trigger_write(1));
    const std::uint16_t reset = u16(Command::kReset);
    h.write(0, {&reset, 1});  // abandons trigger 1
    const auto e2 = h.write(0, trigger_write(2));
    ASSERT_TRUE(e1 && e2);
    EXPECT_NE(e1->trigger.trigger_id, e2->trigger.trigger_id);
    EXPECT_FALSE(h.finish(e1->trigger.trigger_id, derived_result(1))) << "a late result";
    EXPECT_EQ(h.state(), State::kBusy);
    EXPECT_TRUE(result_cleared(h));
    ASSERT_TRUE(h.finish(e2->trigger.trigger_id, derived_result(2)));
    const auto done = h.inputs();
    EXPECT_FALSE(h.finish(e2->trigger.trigger_id, derived_result(3))) << "DONE is frozen";
    EXPECT_EQ(h.inputs(), done);
}

TEST(Handshake, SequenceCountsDonesAndWraps) {
    Handshake h;
    for (std::uint32_t i = 1; i <= 65537; ++i) {
        const auto e = h.write(0, trigger_write(i));
        ASSERT_TRUE(e);
        ASSERT_TRUE(h.finish(e->trigger.trigger_id, derived_result(i, 1)));
        ASSERT_EQ(h.sequence(), static_cast<std::uint16_t>(i));
        ASSERT_FALSE(command(h, u16(Command::kAck)));
        ASSERT_EQ(h.state(), State::kIdle);
    }
    EXPECT_EQ(h.sequence(), 1);
}

// Issue 18, finding 4: after a restart input 5 went 47 -> 1 while the results files went on
// 47 -> 48. It shows the results files' sequence number of the result (low 16 bits), and
// before the first DONE the last one the files hold.
TEST(Handshake, SequenceIsTheResultsFilesNumberAcrossARestart) {
    Handshake h(WordOrder::kBigEndian, 47);
    EXPECT_EQ(h.sequence(), 47) << "before the first DONE: the last result's";
    auto e = h.write(0, trigger_write(1));
    ASSERT_TRUE(e);
    PartResult r = derived_result(1, 1);
    r.sequence = 48;
    ASSERT_TRUE(h.finish(e->trigger.trigger_id, r));
    EXPECT_EQ(h.sequence(), 48);
    ASSERT_FALSE(command(h, u16(Command::kAck)));
    e = h.write(0, trigger_write(2));  // a cycle that ended in FAULT took 49 in the files
    ASSERT_TRUE(e);
    r.sequence = (std::uint64_t{1} << 32) + 65536 + 50;  // only the low 16 bits are shown
    ASSERT_TRUE(h.finish(e->trigger.trigger_id, r));
    EXPECT_EQ(h.sequence(), 50);
}

TEST(Handshake, FaultFromEveryStateClearsResults) {
    for (State s : {State::kIdle, State::kBusy, State::kDone, State::kFault}) {
        Handshake h = in_state(s);
        h.fault(u16(ErrorCode::kDeviceLost));
        EXPECT_EQ(h.state(), State::kFault);
        EXPECT_EQ(h.inputs()[ir::kErrorCode], u16(ErrorCode::kDeviceLost));
        EXPECT_TRUE(result_cleared(h));
    }
    Handshake h;
    h.fault(0);
    EXPECT_EQ(h.inputs()[ir::kErrorCode], u16(ErrorCode::kInternal)) << "0 is not a fault code";
}

TEST(Handshake, InvalidResultIsAnInternalFault) {
    const auto expect_rejected = [](PartResult r, const std::string& why) {
        SCOPED_TRACE(why);
        EXPECT_FALSE(check_result(r));
        Handshake h;
        const auto e = h.write(0, trigger_write(5));
        EXPECT_FALSE(h.finish(e->trigger.trigger_id, r));
        EXPECT_EQ(h.state(), State::kFault);
        EXPECT_EQ(h.inputs()[ir::kErrorCode], u16(ErrorCode::kInternal));
        EXPECT_TRUE(result_cleared(h));
    };
    auto r = derived_result(5, 3);
    r.features[1].slot = 1;
    expect_rejected(r, "duplicate slot");
    r = derived_result(5, 3);
    r.features[0].slot = kMaxFeatures + 1;
    expect_rejected(r, "slot out of range");
    r = derived_result(5, 3);
    r.features[0].value_mm.reset();
    r.overall = Verdict::kNotMeasured;
    expect_rejected(r, "no value but OK");
    r = derived_result(5, 3);
    r.features[0].verdict = Verdict::kNok;
    expect_rejected(r, "overall OK with a NOK feature");
    r = derived_result(5, 3);
    r.overall = Verdict::kNone;
    expect_rejected(r, "no overall verdict");
    r = derived_result(5, 3);
    r.features[0].verdict = Verdict::kDegraded;
    r.features[0].value_mm.reset();
    r.overall = Verdict::kDegraded;
    expect_rejected(r, "degraded without a value");
    r = derived_result(5, 3);
    r.features[0].verdict = Verdict::kDegraded;
    expect_rejected(r, "overall OK with a degraded feature");
    r = derived_result(5, 3);  // a feature not required, not measured: the others' OK stands
    r.features[1].verdict = Verdict::kNotMeasured;
    r.features[1].value_mm.reset();
    expect_rejected(r, "overall OK with a required feature not measured");
    r.features[1].required = false;
    EXPECT_TRUE(check_result(r)) << "overall OK, a feature not required not measured";
    r.overall = Verdict::kDegraded;  // map version 2: a feature may be degraded, with its value
    EXPECT_TRUE(check_result(r));
    r = derived_result(5, kMaxFeatures);
    r.features.push_back({"extra", 1, 1.0, Verdict::kOk});
    expect_rejected(r, "too many features");
}

TEST(Handshake, OverallVerdictRule) {
    std::vector<FeatureValue> f = {{"a", 1, 1.0, Verdict::kOk}, {"b", 2, 2.0, Verdict::kOk}};
    EXPECT_EQ(overall_verdict(f, false), Verdict::kOk);
    EXPECT_EQ(overall_verdict(f, true), Verdict::kDegraded);
    f[1].verdict = Verdict::kDegraded;  // a degraded feature degrades the part by itself
    EXPECT_EQ(overall_verdict(f, false), Verdict::kDegraded);
    f[0].verdict = Verdict::kNotMeasured;
    EXPECT_EQ(overall_verdict(f, false), Verdict::kNotMeasured);
    f[0].verdict = Verdict::kOk;
    f[1].verdict = Verdict::kNotMeasured;
    EXPECT_EQ(overall_verdict(f, true), Verdict::kNotMeasured);
    f[0].verdict = Verdict::kNok;
    EXPECT_EQ(overall_verdict(f, false), Verdict::kNok);
    // A feature not required: its not-measured leaves the verdict to the others; its NOK counts.
    f[0].verdict = Verdict::kOk;
    f[1].required = false;
    EXPECT_EQ(overall_verdict(f, false), Verdict::kOk);
    EXPECT_EQ(overall_verdict(f, true), Verdict::kDegraded);
    f[1].verdict = Verdict::kNok;
    EXPECT_EQ(overall_verdict(f, false), Verdict::kNok);
}

// ---- server: clients --------------------------------------------------------------------------

// A well-behaved client: libmodbus over TCP.
class MbClient {
  public:
    explicit MbClient(int port, int unit = 1) {
        ctx_ = modbus_new_tcp("127.0.0.1", port);
        modbus_set_slave(ctx_, unit);
        modbus_set_response_timeout(ctx_, 2, 0);
        connected_ = modbus_connect(ctx_) == 0;
    }
    ~MbClient() {
        modbus_close(ctx_);
        modbus_free(ctx_);
    }
    MbClient(const MbClient&) = delete;
    MbClient& operator=(const MbClient&) = delete;
    bool connected() const { return connected_; }
    modbus_t* ctx() { return ctx_; }
    // "127.0.0.1:port" as the server sees (and logs) this client.
    std::string local_address() const {
        sockaddr_in a{};
        socklen_t len = sizeof a;
        ::getsockname(modbus_get_socket(ctx_), reinterpret_cast<sockaddr*>(&a), &len);
        return "127.0.0.1:" + std::to_string(ntohs(a.sin_port));
    }
    void set_unit(int unit) { modbus_set_slave(ctx_, unit); }

    // Input registers (or holding, with `holding`); nullopt and errno on failure.
    std::optional<std::vector<std::uint16_t>> read(int address, int count, bool holding = false) {
        std::vector<std::uint16_t> v(static_cast<std::size_t>(count));
        const int n = holding ? modbus_read_registers(ctx_, address, count, v.data())
                              : modbus_read_input_registers(ctx_, address, count, v.data());
        if (n != count) return std::nullopt;
        return v;
    }
    bool write(int address, const std::vector<std::uint16_t>& v) {
        return modbus_write_registers(ctx_, address, static_cast<int>(v.size()), v.data()) ==
               static_cast<int>(v.size());
    }
    std::optional<std::uint16_t> state() {
        auto r = read(ir::kState, 1);
        if (!r) return std::nullopt;
        return (*r)[0];
    }

  private:
    modbus_t* ctx_ = nullptr;
    bool connected_ = false;
};

// A client that can misbehave: raw bytes on a TCP socket.
class RawClient {
  public:
    explicit RawClient(int port) {
        fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(static_cast<std::uint16_t>(port));
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
    }
    ~RawClient() { close(); }
    RawClient(const RawClient&) = delete;
    RawClient& operator=(const RawClient&) = delete;
    bool connected() const { return connected_; }
    int fd() const { return fd_; }
    void close() {
        if (fd_ >= 0) ::close(fd_);
        fd_ = -1;
    }
    bool send(const std::vector<std::uint8_t>& bytes) {
        return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) ==
               static_cast<ssize_t>(bytes.size());
    }
    // Exactly n bytes within `timeout`; fewer if the peer closed or time ran out.
    std::vector<std::uint8_t> recv(std::size_t n, std::chrono::milliseconds timeout = 3s) {
        std::vector<std::uint8_t> out;
        const auto deadline = Clock::now() + timeout;
        while (out.size() < n) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
            if (left.count() <= 0) break;
            pollfd p{fd_, POLLIN, 0};
            if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) break;
            std::uint8_t buf[512];
            const ssize_t k = ::recv(fd_, buf, std::min(sizeof buf, n - out.size()), 0);
            if (k <= 0) {
                peer_closed_ = true;
                break;
            }
            out.insert(out.end(), buf, buf + k);
        }
        return out;
    }
    // One Modbus TCP response: its PDU (function, data...), or empty.
    std::vector<std::uint8_t> response(std::chrono::milliseconds timeout = 3s) {
        const auto h = recv(7, timeout);
        if (h.size() < 7) return {};
        const std::size_t len = static_cast<std::size_t>((h[4] << 8) | h[5]);
        last_transaction_ = static_cast<std::uint16_t>((h[0] << 8) | h[1]);
        last_unit_ = h[6];
        return recv(len - 1, timeout);
    }
    // True once the server closed (FIN or RST) within `timeout`.
    bool closed_by_server(std::chrono::milliseconds timeout = 3s) {
        recv(1u << 16, timeout);
        return peer_closed_;
    }
    std::uint16_t last_transaction() const { return last_transaction_; }
    std::uint8_t last_unit() const { return last_unit_; }

  private:
    int fd_ = -1;
    bool connected_ = false;
    bool peer_closed_ = false;
    std::uint16_t last_transaction_ = 0;
    std::uint8_t last_unit_ = 0;
};

// A Modbus TCP frame: MBAP header (length from the PDU unless given) + PDU.
std::vector<std::uint8_t> frame(std::vector<std::uint8_t> pdu, std::uint8_t unit = 1,
                                std::uint16_t transaction = 0x1234, std::uint16_t protocol = 0,
                                std::optional<std::uint16_t> length = std::nullopt) {
    const std::uint16_t len = length.value_or(static_cast<std::uint16_t>(pdu.size() + 1));
    std::vector<std::uint8_t> f;
    f.reserve(7 + pdu.size());
    f = {static_cast<std::uint8_t>(transaction >> 8),
         static_cast<std::uint8_t>(transaction & 0xFF),
         static_cast<std::uint8_t>(protocol >> 8),
         static_cast<std::uint8_t>(protocol & 0xFF),
         static_cast<std::uint8_t>(len >> 8),
         static_cast<std::uint8_t>(len & 0xFF),
         unit};
    f.insert(f.end(), pdu.begin(), pdu.end());
    return f;
}

std::vector<std::uint8_t> read_pdu(std::uint8_t fc, std::uint16_t address, std::uint16_t count) {
    return {fc, static_cast<std::uint8_t>(address >> 8), static_cast<std::uint8_t>(address & 0xFF),
            static_cast<std::uint8_t>(count >> 8), static_cast<std::uint8_t>(count & 0xFF)};
}

ServerConfig loopback(int max_connections = 8, int idle_timeout_ms = 10000) {
    ServerConfig c;
    c.bind_address = "127.0.0.1";
    c.port = 0;
    c.max_connections = max_connections;
    c.idle_timeout_ms = idle_timeout_ms;
    return c;
}

std::unique_ptr<Server> start(const ServerConfig& c) {
    auto s = Server::start(c);
    EXPECT_TRUE(s) << (s ? "" : s.error().message);
    return s ? std::move(*s) : nullptr;
}

// A healthy client proves it is unaffected: `n` full-map reads, each answered and consistent.
void expect_healthy(MbClient& c, int n = 20) {
    for (int i = 0; i < n; ++i) {
        const auto t0 = Clock::now();
        const auto r = c.read(0, ir::kCount);
        ASSERT_TRUE(r) << "read " << i << ": " << modbus_strerror(errno);
        EXPECT_EQ((*r)[ir::kMapVersionReg], kMapVersion);
        EXPECT_LT(Clock::now() - t0, 1s) << "a read was held up";
    }
}

// ---- server: the handshake with a real client ------------------------------------------------

TEST(Server, ConfigIsChecked) {
    auto c = loopback();
    c.bind_address = "localhost";
    EXPECT_FALSE(check_config(c));
    c = loopback();
    c.allowed_clients = {"300.1.1.1"};
    EXPECT_FALSE(check_config(c));
    c.allowed_clients = {"10.0.0.0/33"};
    EXPECT_FALSE(check_config(c));
    c.allowed_clients = {"10.0.0.0/8", "192.168.1.7"};
    EXPECT_TRUE(check_config(c));
    c.unit_ids = {256};
    EXPECT_FALSE(check_config(c));
    c = loopback(0);
    EXPECT_FALSE(Server::start(c));
}

TEST(Server, HeartbeatAdvances) {
    auto c = loopback();
    c.heartbeat_period_ms = 20;
    auto s = start(c);
    ASSERT_TRUE(s);
    EXPECT_GT(s->port(), 0);
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    const auto first = m.read(ir::kHeartbeat, 1);
    ASSERT_TRUE(first);
    EXPECT_TRUE(eventually([&] {
        const auto now = m.read(ir::kHeartbeat, 1);
        return now && static_cast<std::uint16_t>((*now)[0] - (*first)[0]) >= 3;
    }));
}

TEST(Server, FullCycleWithInputsAndMirror) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient plc(s->port());
    ASSERT_TRUE(plc.connected());
    EXPECT_EQ(plc.state(), u16(State::kIdle));
    ASSERT_TRUE(plc.write(0, trigger_write(123456, 1, 0)));
    const auto e = s->wait_event(2s);
    ASSERT_TRUE(e);
    ASSERT_EQ(e->kind, PlcEvent::Kind::kTrigger);
    EXPECT_EQ(e->trigger.part_id, 123456u);
    EXPECT_EQ(plc.state(), u16(State::kBusy));
    const auto cmd = plc.read(hr::kCommand, 1, true);
    ASSERT_TRUE(cmd);
    EXPECT_EQ((*cmd)[0], 0) << "the command register reads back 0 once taken";
    ASSERT_TRUE(s->finish(e->trigger.trigger_id, derived_result(123456)));
    const auto in = plc.read(0, ir::kCount);
    ASSERT_TRUE(in);
    EXPECT_EQ((*in)[ir::kState], u16(State::kDone));
    EXPECT_EQ((*in)[ir::kSequence], 1);
    EXPECT_EQ(decode_u32((*in)[ir::kPartId], (*in)[ir::kPartId + 1], {}), 123456u);
    for (int slot = 1; slot <= kMaxFeatures; ++slot) {
        const auto a = ir::feature(slot);
        EXPECT_EQ(decode_i32((*in)[a], (*in)[a + 1], {}), derived_um(123456, slot));
    }
    // The mirror in holding registers is the same image (the heartbeat may have moved).
    const auto mirror = plc.read(hr::kMirrorBase, ir::kCount, true);
    ASSERT_TRUE(mirror);
    for (std::size_t i = 1; i < ir::kCount; ++i) EXPECT_EQ((*mirror)[i], (*in)[i]) << i;
    ASSERT_TRUE(plc.write(0, {u16(Command::kAck)}));
    EXPECT_EQ(plc.state(), u16(State::kIdle));
    const auto after = plc.read(ir::feature(1), 2);
    ASSERT_TRUE(after);
    EXPECT_EQ(decode_i32((*after)[0], (*after)[1], {}), kInvalidInt32);
    // A single-register write (FC06) works too; the PLC heartbeat is echoed.
    ASSERT_EQ(modbus_write_register(plc.ctx(), hr::kPlcHeartbeat, 999), 1);
    const auto echo = plc.read(ir::kPlcHeartbeat, 1);
    ASSERT_TRUE(echo);
    EXPECT_EQ((*echo)[0], 999);
}

TEST(Server, TriggerWhileBusyIsRefusedWithACode) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient plc(s->port());
    ASSERT_TRUE(plc.write(0, trigger_write(1)));
    ASSERT_TRUE(s->wait_event(2s));
    ASSERT_TRUE(plc.write(0, trigger_write(2)));
    const auto st = plc.read(0, 8);
    ASSERT_TRUE(st);
    EXPECT_EQ((*st)[ir::kState], u16(State::kBusy));
    EXPECT_EQ((*st)[ir::kCommandStatus], u16(ErrorCode::kBusy));
    EXPECT_EQ(decode_u32((*st)[ir::kPartId], (*st)[ir::kPartId + 1], {}), 1u) << "still part 1";
    EXPECT_FALSE(s->wait_event(50ms)) << "the owner hears of accepted commands only";
}

// ---- server: atomic publication ---------------------------------------------------------------

// A PLC cycles parts as fast as it can while two readers (inputs and the holding mirror) read
// the whole map continuously: every block they see is whole (no torn value, no mix of two
// results), and nothing but DONE ever shows a result.
TEST(Server, PublicationIsAtomicUnderConcurrentReaders) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    constexpr std::uint32_t kParts = 150;
    std::atomic<bool> done{false};
    std::atomic<int> failures{0};

    std::thread owner([&] {
        while (!done) {
            const auto e = s->wait_event(20ms);
            if (e && e->kind == PlcEvent::Kind::kTrigger)
                if (!s->finish(e->trigger.trigger_id, derived_result(e->trigger.part_id)))
                    ++failures;
        }
    });
    std::array<std::atomic<int>, 2> done_seen{};
    std::array<std::atomic<int>, 2> reads{};
    std::array<std::string, 2> first_error;
    auto reader = [&](int k) {
        MbClient c(s->port());
        const bool holding = k == 1;
        const int base = holding ? hr::kMirrorBase : 0;
        while (!done) {
            const auto r = c.read(base, ir::kCount, holding);
            if (!r) {
                if (failures++ == 0) first_error[k] = modbus_strerror(errno);
                continue;
            }
            ++reads[k];
            const auto& in = *r;
            std::string bad;
            const auto state = in[ir::kState];
            if (state == u16(State::kDone)) {
                ++done_seen[k];
                const auto part = decode_u32(in[ir::kPartId], in[ir::kPartId + 1], {});
                if (in[ir::kSequence] != part) bad = "sequence does not match the part";
                if (in[ir::kFeatureCount] != kMaxFeatures) bad = "feature count";
                for (int slot = 1; slot <= kMaxFeatures && bad.empty(); ++slot) {
                    const auto a = ir::feature(slot);
                    const auto um = decode_i32(in[a], in[a + 1], {});
                    const float mm = decode_f32(in[a + 2], in[a + 3], {});
                    if (um != derived_um(part, slot) ||
                        mm != static_cast<float>(derived_um(part, slot) / 1000.0) ||
                        in[a + 4] != u16(Verdict::kOk))
                        bad = "slot " + std::to_string(slot) + " of part " + std::to_string(part);
                }
            } else {
                for (int slot = 1; slot <= kMaxFeatures && bad.empty(); ++slot) {
                    const auto a = ir::feature(slot);
                    if (decode_i32(in[a], in[a + 1], {}) != kInvalidInt32 || in[a + 4] != 0)
                        bad = "a result outside DONE (state " + std::to_string(state) + ")";
                }
                if (in[ir::kOverallVerdict] != 0) bad = "an overall verdict outside DONE";
            }
            if (!bad.empty() && failures++ == 0) first_error[k] = bad;
        }
    };
    std::thread r0(reader, 0), r1(reader, 1);
    MbClient plc(s->port());
    for (std::uint32_t part = 1; part <= kParts; ++part) {
        ASSERT_TRUE(plc.write(0, trigger_write(part)));
        ASSERT_TRUE(eventually([&] { return plc.state() == u16(State::kDone); }));
        ASSERT_TRUE(plc.write(0, {u16(Command::kAck)}));
    }
    // Let the readers catch at least a few DONE blocks if the cycle outran them.
    eventually([&] { return done_seen[0] > 0 && done_seen[1] > 0; }, 2s);
    done = true;
    r0.join();
    r1.join();
    owner.join();
    EXPECT_EQ(failures, 0) << first_error[0] << " / " << first_error[1];
    EXPECT_GT(reads[0] + reads[1], 100);
    EXPECT_GT(done_seen[0] + done_seen[1], 0) << "no DONE block was read: nothing was checked";
    EXPECT_EQ(s->inputs()[ir::kSequence], kParts);
}

// ---- server: bad input ----------------------------------------------------------------------

TEST(BadInput, AddressesOutsideTheMapGetException02LoggedOncePerClient) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    const std::string logged = "client " + m.local_address() + ": illegal data address";
    std::vector<std::uint16_t> buf(ir::kCount);
    const auto illegal_address = [&](int rc) { return rc == -1 && errno == EMBXILADD; };
    for (int i = 0; i < 20; ++i) {
        EXPECT_TRUE(illegal_address(modbus_read_input_registers(m.ctx(), 110, 20, buf.data())));
    }
    EXPECT_TRUE(illegal_address(modbus_read_input_registers(m.ctx(), ir::kCount, 1, buf.data())));
    EXPECT_TRUE(illegal_address(modbus_read_registers(m.ctx(), hr::kWritableCount, 1, buf.data())));
    EXPECT_TRUE(illegal_address(modbus_read_registers(m.ctx(), 0, hr::kWritableCount + 1,
                                                      buf.data())));  // spans the gap
    EXPECT_TRUE(
        illegal_address(modbus_read_registers(m.ctx(), hr::kMirrorBase + ir::kCount - 12, 13,
                                              buf.data())));  // runs past the mirror
    EXPECT_TRUE(illegal_address(modbus_write_register(m.ctx(), hr::kMirrorBase, 1)));
    EXPECT_TRUE(illegal_address(modbus_write_register(m.ctx(), hr::kWritableCount, 1)));
    const std::uint16_t two[2] = {0, 0};
    EXPECT_TRUE(illegal_address(modbus_write_registers(m.ctx(), hr::kWritableCount - 1, 2, two)));
    EXPECT_EQ(s->stats().exceptions, 27u);
    EXPECT_EQ(s->state(), State::kIdle);
    expect_healthy(m, 3);
    EXPECT_EQ(count_lines(logged), 1) << "27 rejected requests from one client log one line";
    MbClient other(s->port());
    EXPECT_TRUE(illegal_address(modbus_read_input_registers(other.ctx(), 200, 1, buf.data())));
    EXPECT_EQ(count_lines("client " + other.local_address() + ": illegal data address"), 1)
        << "another client is logged once too";
}

TEST(BadInput, WrongUnitIdGetsException0B) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port(), 7);
    ASSERT_TRUE(m.connected());
    EXPECT_FALSE(m.read(0, 4));
    EXPECT_EQ(errno, EMBXGTAR);
    EXPECT_FALSE(m.write(0, trigger_write(1)));
    EXPECT_EQ(s->state(), State::kIdle) << "a write for another unit changes nothing";
    m.set_unit(255);
    expect_healthy(m, 2);
    m.set_unit(0);
    expect_healthy(m, 2);
}

TEST(BadInput, IllegalFunctionsGetException01) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port());
    std::uint8_t bits[8];
    EXPECT_EQ(modbus_read_bits(m.ctx(), 0, 8, bits), -1);  // FC01
    EXPECT_EQ(errno, EMBXILFUN);
    EXPECT_EQ(modbus_write_bit(m.ctx(), 0, 1), -1);  // FC05
    EXPECT_EQ(errno, EMBXILFUN);
    RawClient raw(s->port());
    for (const std::uint8_t fc : std::vector<std::uint8_t>{0x00, 0x07, 0x17, 0x2B, 0x7F, 0xFF}) {
        ASSERT_TRUE(raw.send(frame({fc, 0x00, 0x00})));
        const auto r = raw.response();
        ASSERT_EQ(r.size(), 2u) << "function " << int(fc);
        EXPECT_EQ(r[0], fc | 0x80);
        EXPECT_EQ(r[1], MODBUS_EXCEPTION_ILLEGAL_FUNCTION);
        EXPECT_EQ(raw.last_transaction(), 0x1234);
    }
    expect_healthy(m, 2);
}

TEST(BadInput, OversizedOrMalformedRequestsGetException03) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port());
    RawClient raw(s->port());
    const auto expect_03 = [&](const std::vector<std::uint8_t>& pdu, const char* what) {
        SCOPED_TRACE(what);
        ASSERT_TRUE(raw.send(frame(pdu)));
        const auto r = raw.response();
        ASSERT_EQ(r.size(), 2u);
        EXPECT_EQ(r[0], pdu[0] | 0x80);
        EXPECT_EQ(r[1], MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE);
    };
    expect_03(read_pdu(0x04, 0, 126), "read 126 registers");
    expect_03(read_pdu(0x03, 0, 0), "read 0 registers");
    expect_03(read_pdu(0x04, 0, 0xFFFF), "read 65535 registers");
    expect_03({0x04, 0x00, 0x00, 0x00}, "read request one byte short");
    expect_03({0x04, 0x00, 0x00, 0x00, 0x01, 0x00}, "read request one byte long");
    expect_03({0x06, 0x00, 0x00}, "write single without value");
    expect_03({0x10, 0x00, 0x00, 0x00, 0x02, 0x02, 0x00, 0x01}, "byte count 2 for 2 registers");
    expect_03({0x10, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x01}, "data shorter than byte count");
    std::vector<std::uint8_t> big = {0x10, 0x00, 0x00, 0x00, 124, 248};
    big.resize(big.size() + 248, 0);  // a 254-byte PDU does not fit a frame: closed below
    expect_03({0x10, 0x00, 0x00, 0x00, 124, 0xF8, 0x00}, "write 124 registers");
    EXPECT_EQ(s->state(), State::kIdle);
    expect_healthy(m, 3);
    // A request longer than any Modbus frame is a malformed frame: the connection goes.
    ASSERT_TRUE(raw.send(frame(big)));
    EXPECT_TRUE(raw.closed_by_server());
    expect_healthy(m, 3);
}

TEST(BadInput, MalformedMbapHeadersCloseOnlyThatConnection) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    const std::vector<std::vector<std::uint8_t>> bad = {
        frame(read_pdu(0x04, 0, 1), 1, 1, 0x0001),                     // protocol id 1
        frame(read_pdu(0x04, 0, 1), 1, 1, 0, std::uint16_t{0}),        // length 0
        frame(read_pdu(0x04, 0, 1), 1, 1, 0, std::uint16_t{1}),        // length 1: no PDU
        frame(read_pdu(0x04, 0, 1), 1, 1, 0, std::uint16_t{300}),      // longer than any frame
        {0x47, 0x45, 0x54, 0x20, 0x2F, 0x20, 0x48, 0x54, 0x54, 0x50},  // "GET / HTTP"
    };
    for (std::size_t i = 0; i < bad.size(); ++i) {
        SCOPED_TRACE("malformed frame " + std::to_string(i));
        RawClient raw(s->port());
        ASSERT_TRUE(raw.send(bad[i]));
        EXPECT_TRUE(raw.closed_by_server());
        expect_healthy(m, 2);
    }
    EXPECT_EQ(s->stats().malformed, bad.size());
}

TEST(BadInput, PartialFramesAreReassembledAndPipelinedOnesAnswered) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    RawClient raw(s->port());
    const auto f = frame(read_pdu(0x04, ir::kMapVersionReg, 1), 1, 0x0101);
    for (auto b : f) ASSERT_TRUE(raw.send({b}));  // one byte at a time
    auto r = raw.response();
    ASSERT_EQ(r.size(), 4u);
    EXPECT_EQ(r[3], kMapVersion);
    auto two = frame(read_pdu(0x04, ir::kState, 1), 1, 0x0202);
    const auto second = frame(read_pdu(0x04, ir::kMapVersionReg, 1), 1, 0x0303);
    two.insert(two.end(), second.begin(), second.end());
    ASSERT_TRUE(raw.send(two));
    r = raw.response();
    EXPECT_EQ(raw.last_transaction(), 0x0202);
    ASSERT_EQ(r.size(), 4u);
    EXPECT_EQ(r[3], u16(State::kIdle));
    r = raw.response();
    EXPECT_EQ(raw.last_transaction(), 0x0303);
    ASSERT_EQ(r.size(), 4u);
    EXPECT_EQ(r[3], kMapVersion);
}

TEST(BadInput, SilentClientIsClosedAfterTheIdleTimeoutAndBlocksNobody) {
    auto s = start(loopback(8, 300));
    ASSERT_TRUE(s);
    RawClient silent(s->port());
    ASSERT_TRUE(silent.connected());
    RawClient half(s->port());  // sends half a request, then nothing
    const auto f = frame(read_pdu(0x04, 0, 10));
    ASSERT_TRUE(half.send({f.begin(), f.begin() + 9}));
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    const auto t0 = Clock::now();
    // Reading continuously keeps the healthy client alive while the other two time out.
    while (Clock::now() - t0 < 600ms) {
        expect_healthy(m, 1);
        std::this_thread::sleep_for(5ms);
    }
    EXPECT_TRUE(silent.closed_by_server(2s));
    EXPECT_TRUE(half.closed_by_server(2s));
    EXPECT_GE(Clock::now() - t0, 250ms) << "closed before the idle timeout";
    EXPECT_EQ(s->stats().timed_out, 2u);
    expect_healthy(m, 3);
}

TEST(BadInput, ClientDisconnectingMidRequestAffectsNobody) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    const auto f = frame({0x10, 0x00, 0x00, 0x00, 0x06, 0x0C, 0x00, 0x01, 0x00, 0x00, 0x00, 0x05,
                          0x00, 0x01, 0x00, 0x00, 0x00, 0x00});  // a full trigger
    for (std::size_t cut : {3u, 7u, 12u, 17u}) {
        RawClient raw(s->port());
        ASSERT_TRUE(raw.send({f.begin(), f.begin() + static_cast<std::ptrdiff_t>(cut)}));
        expect_healthy(m, 2);
        raw.close();
        expect_healthy(m, 2);
    }
    EXPECT_TRUE(eventually([&] { return s->stats().clients == 1; }));
    EXPECT_EQ(s->state(), State::kIdle) << "half a trigger is no trigger";
    EXPECT_FALSE(s->wait_event(10ms));
}

// Issue 18, finding 6: eight idle connections locked every new client out for the idle
// timeout. Now, with every slot taken, a new connection closes one that never sent a request,
// else the one idle longest: a polling PLC is never the one, and it can always get in.
TEST(BadInput, ConnectionFloodMakesRoomAndNeverLocksThePlcOut) {
    constexpr int kMax = 4;
    auto s = start(loopback(kMax));
    ASSERT_TRUE(s);
    MbClient m(s->port());
    ASSERT_TRUE(m.connected());
    expect_healthy(m, 1);
    const int lines_before = count_lines("connections (the limit): closed");
    std::vector<std::unique_ptr<RawClient>> flood;
    for (int i = 0; i < 40; ++i) flood.push_back(std::make_unique<RawClient>(s->port()));
    // Each one past the limit closes the oldest silent one; the PLC, which polls, stays.
    ASSERT_TRUE(eventually([&] { return s->stats().evicted == 40 - (kMax - 1); }))
        << s->stats().evicted;
    expect_healthy(m, 5);
    std::vector<RawClient*> alive;
    for (auto& r : flood)
        if (!r->closed_by_server(0ms) && !r->closed_by_server(20ms)) alive.push_back(r.get());
    ASSERT_EQ(alive.size(), static_cast<std::size_t>(kMax - 1));
    EXPECT_EQ(alive.back(), flood.back().get()) << "the newest ones stay";
    for (auto* r : alive) {  // and are served
        ASSERT_TRUE(r->send(frame(read_pdu(0x04, ir::kMapVersionReg, 1))));
        const auto resp = r->response();
        ASSERT_EQ(resp.size(), 4u);
        EXPECT_EQ(resp[3], kMapVersion);
    }
    EXPECT_EQ(s->stats().clients, kMax);
    EXPECT_EQ(s->stats().refused, 0u);
    EXPECT_EQ(count_lines("connections (the limit): closed") - lines_before, 1)
        << "a flood logs one line (at most one per 10 s)";

    // Every slot held by a client that asked once and went quiet (a forgotten HMI, a laptop):
    // a new PLC connection still gets in, and the one idle longest gives way.
    flood.clear();
    ASSERT_TRUE(eventually([&] { return s->stats().clients == 1; }));
    std::vector<std::unique_ptr<MbClient>> quiet;
    for (int i = 0; i < kMax - 1; ++i) {
        quiet.push_back(std::make_unique<MbClient>(s->port()));
        expect_healthy(*quiet.back(), 1);
        std::this_thread::sleep_for(5ms);
    }
    expect_healthy(m, 1);  // the first PLC polls again: now quiet[0] is idle longest
    MbClient plc(s->port());
    expect_healthy(plc, 2);
    EXPECT_FALSE(quiet[0]->read(0, 1)) << "the one idle longest was closed";
    expect_healthy(m, 1);
    expect_healthy(*quiet[1], 1);

    // Twenty quick connect/close cycles, then the PLC reconnects: served at once.
    for (int i = 0; i < 20; ++i) RawClient(s->port()).close();
    MbClient after(s->port());
    expect_healthy(after, 2);
}

TEST(BadInput, AllowListRefusesOtherAddresses) {
    auto c = loopback();
    c.allowed_clients = {"10.20.0.0/16", "192.168.0.10"};
    auto s = start(c);
    ASSERT_TRUE(s);
    RawClient raw(s->port());
    EXPECT_TRUE(raw.closed_by_server());
    MbClient m(s->port());
    EXPECT_FALSE(m.read(0, 1));
    EXPECT_TRUE(eventually([&] { return s->stats().refused == 2; }));
    EXPECT_EQ(s->stats().accepted, 0u);
    c.allowed_clients = {"10.20.0.0/16", "127.0.0.0/8"};
    auto s2 = start(c);
    ASSERT_TRUE(s2);
    MbClient ok(s2->port());
    expect_healthy(ok, 2);
}

TEST(BadInput, OwnerThatNeverListensDoesNotStallTheServer) {
    auto s = start(loopback());
    ASSERT_TRUE(s);
    MbClient plc(s->port());
    for (int i = 0; i < 200; ++i) {  // 400 events nobody takes; the queue is bounded
        ASSERT_TRUE(plc.write(0, trigger_write(static_cast<std::uint32_t>(i + 1))));
        ASSERT_TRUE(plc.write(0, {u16(Command::kReset)}));
    }
    expect_healthy(plc, 3);
    int n = 0;
    while (s->wait_event(0ms)) ++n;
    EXPECT_EQ(n, 64) << "the oldest are dropped";
}

// ---- pyrometer --------------------------------------------------------------------------------

TEST(PyrometerConfig, OpeningAMissingDeviceNamesIt) {
    PyrometerConfig c;
    c.serial.device = "/nonexistent/ttyHG0";
    const auto p = Pyrometer::start(c);
    ASSERT_FALSE(p);
    EXPECT_NE(p.error().message.find("/nonexistent/ttyHG0"), std::string::npos);
    c.serial.parity = 'X';
    EXPECT_FALSE(check_config(c));
    c = {};
    c.stale_after_ms = 10;
    EXPECT_FALSE(check_config(c)) << "stale sooner than the poll period";
}

// A virtual serial pair: socat linking two ptys (TMP/a <-> TMP/b).
TEST(Pyrometer, ReadsFlagsOutOfRangeAndStaleAgainstASimulatedSensor) {
    hotgauge::test::SerialPair pair;
    ASSERT_TRUE(pair.ok()) << "socat did not come up";
    SerialConfig sc;
    sc.device = pair.a();
    sc.baud = 19200;
    sc.parity = 'E';
    sc.slave_id = 3;
    auto sim = PyrometerSimulator::start(sc, 5, 0.1);
    ASSERT_TRUE(sim) << sim.error().message;
    (*sim)->set_temperature(1050.0);

    PyrometerConfig pc;
    pc.serial = sc;
    pc.serial.device = pair.b();
    pc.register_address = 5;
    pc.poll_period_ms = 20;
    pc.response_timeout_ms = 100;
    pc.stale_after_ms = 300;
    pc.min_valid_c = 600;
    pc.max_valid_c = 1400;
    auto p = Pyrometer::start(pc);
    ASSERT_TRUE(p) << p.error().message;
    auto& py = **p;
    ASSERT_TRUE(eventually([&] { return py.latest().valid(); })) << py.latest().last_error;
    auto r = py.latest();
    EXPECT_NEAR(*r.temperature_c, 1050.0, 1e-9);
    EXPECT_FALSE(r.stale);
    EXPECT_LE(r.age_ms, 300);

    (*sim)->set_temperature(-12.5);  // signed register
    ASSERT_TRUE(eventually([&] {
        const auto t = py.latest().temperature_c;
        return t && std::abs(*t + 12.5) < 1e-9;
    }));
    r = py.latest();
    EXPECT_TRUE(r.out_of_range);
    EXPECT_FALSE(r.valid());

    (*sim)->set_temperature(1200.0);
    ASSERT_TRUE(eventually([&] { return py.latest().valid(); }));
    (*sim)->set_responding(false);  // the sensor dies: the value ages, then is stale
    ASSERT_TRUE(eventually([&] { return py.latest().stale; }));
    r = py.latest();
    EXPECT_FALSE(r.valid());
    EXPECT_GT(r.errors, 0u);
    EXPECT_FALSE(r.last_error.empty());
    EXPECT_NEAR(*r.temperature_c, 1200.0, 1e-9) << "the last value is kept, flagged stale";
    // The daemon asks once the scans are done, and gives a sensor that missed its polls until
    // the accelerometer's margin has passed: still dead, the answer is the stale reading; back
    // within the wait, a valid one (the soak lost a part's temperature to a 1.0 s outage).
    const auto t0 = std::chrono::steady_clock::now();
    EXPECT_FALSE(py.wait_valid(std::chrono::milliseconds(150)).valid());
    EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(150));
    std::thread revive([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
        (*sim)->set_responding(true);
    });
    r = py.wait_valid(std::chrono::milliseconds(3000));
    revive.join();
    EXPECT_TRUE(r.valid()) << "recovers by itself: " << r.last_error;
    EXPECT_NEAR(*r.temperature_c, 1200.0, 1e-9);
    EXPECT_GE((*sim)->served(), 4u);  // one answer per phase at least
}

TEST(Pyrometer, WrongSlaveIdNeverReads) {
    hotgauge::test::SerialPair pair;
    ASSERT_TRUE(pair.ok()) << "socat did not come up";
    SerialConfig sc;
    sc.device = pair.a();
    sc.slave_id = 1;
    auto sim = PyrometerSimulator::start(sc);
    ASSERT_TRUE(sim) << sim.error().message;
    (*sim)->set_temperature(900.0);
    PyrometerConfig pc;
    pc.serial = sc;
    pc.serial.device = pair.b();
    pc.serial.slave_id = 2;
    pc.poll_period_ms = 20;
    pc.response_timeout_ms = 50;
    pc.stale_after_ms = 100;
    auto p = Pyrometer::start(pc);
    ASSERT_TRUE(p) << p.error().message;
    ASSERT_TRUE(eventually([&] { return (*p)->latest().errors >= 3; }));
    const auto r = (*p)->latest();
    EXPECT_FALSE(r.temperature_c);
    EXPECT_TRUE(r.stale);
    EXPECT_EQ(r.reads, 0u);
    EXPECT_EQ((*sim)->served(), 0u);
}

}  // namespace

// Map version 3: the die id comes with the trigger (holding 6); each feature's drift state is
// the sixth register of its block and input 15 counts the features in drift; an ack clears them.
TEST(Handshake, DieIdAndDriftRegisters) {
    Handshake h;
    auto w = trigger_write(5, 1, 0);
    w.push_back(9);  // die id
    const auto e = h.write(0, w);
    ASSERT_TRUE(e);
    EXPECT_EQ(e->trigger.die_id, 9);
    PartResult r = derived_result(5, 4);
    r.features[0].drift = DriftState::kWatching;
    r.features[1].drift = DriftState::kUp;
    r.features[3].drift = DriftState::kDown;
    ASSERT_TRUE(h.finish(e->trigger.trigger_id, r));
    const auto& in = h.inputs();
    EXPECT_EQ(in[ir::kMapVersionReg], 4);
    EXPECT_EQ(in[ir::kDriftCount], 2);
    EXPECT_EQ(in[ir::feature(1) + ir::kDrift], u16(DriftState::kWatching));
    EXPECT_EQ(in[ir::feature(2) + ir::kDrift], u16(DriftState::kUp));
    EXPECT_EQ(in[ir::feature(3) + ir::kDrift], u16(DriftState::kNone));
    EXPECT_EQ(in[ir::feature(4) + ir::kDrift], u16(DriftState::kDown));
    EXPECT_EQ(ir::feature(1) + ir::kDrift, 21);  // as docs/plc-modbus.md says
    command(h, u16(Command::kAck));
    EXPECT_EQ(h.inputs()[ir::kDriftCount], 0);
    EXPECT_EQ(h.inputs()[ir::feature(2) + ir::kDrift], 0);
}

// Map version 4: the scan phase (the part may move before the result), the live cell status in
// every state, and the result's reason bits, time and recipe revision, cleared with the result.
TEST(Handshake, ScanPhaseFollowsTheCycle) {
    Handshake h;
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kNone));
    const auto e = h.write(0, trigger_write(5, 1, 0));
    ASSERT_TRUE(e);
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kScanning));
    h.scans_done(e->trigger.trigger_id + 1);  // another cycle's: ignored
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kScanning));
    h.scans_done(e->trigger.trigger_id);
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kScansDone));
    EXPECT_EQ(h.state(), State::kBusy);
    ASSERT_TRUE(h.finish(e->trigger.trigger_id, derived_result(5, 4)));
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kScansDone));
    command(h, u16(Command::kAck));
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kNone));
    h.scans_done(e->trigger.trigger_id);  // late: the cycle is over
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kNone));
    const auto f = h.write(0, trigger_write(6, 1, 0));
    ASSERT_TRUE(f);
    h.fault(u16(ErrorCode::kDeviceLost));
    EXPECT_EQ(h.inputs()[ir::kScanPhase], u16(ScanPhase::kNone));
}

TEST(Handshake, ReasonsTimeAndRevisionComeAndGoWithTheResult) {
    Handshake h;
    const auto e = h.write(0, trigger_write(5, 1, 0));
    ASSERT_TRUE(e);
    PartResult r = derived_result(5, 3);
    r.features[1].reasons = reason::kDegraded | reason::kOutsideTolerance;
    r.features[2].reasons = reason::kLowCoverage;
    r.features[1].drift = DriftState::kUp;
    r.reasons = reason::kNotCompensated;
    r.time_ns = 1'796'000'000'123'456'789;  // 2026-11-29T..., .123 s
    r.recipe_revision = 62768;
    ASSERT_TRUE(h.finish(e->trigger.trigger_id, r));
    const auto& in = h.inputs();
    EXPECT_EQ(in[ir::feature(1) + ir::kDrift], 0);
    EXPECT_EQ(in[ir::feature(2) + ir::kDrift], u16(DriftState::kUp) | (0x06 << 8));
    EXPECT_EQ(in[ir::feature(3) + ir::kDrift], 0x08 << 8);
    EXPECT_EQ(in[ir::kReasons], reason::kNotCompensated | reason::kDegraded |
                                    reason::kOutsideTolerance | reason::kLowCoverage);
    EXPECT_EQ(decode_u32(in[ir::kResultTime], in[ir::kResultTime + 1], WordOrder::kBigEndian),
              1'796'000'000u);
    EXPECT_EQ(in[ir::kResultTimeMs], 123);
    EXPECT_EQ(in[ir::kRecipeRevision], 62768);
    command(h, u16(Command::kAck));
    for (auto a : {ir::kReasons, ir::kResultTime, ir::kResultTimeMs, ir::kRecipeRevision})
        EXPECT_EQ(h.inputs()[a], 0) << a;
    EXPECT_EQ(h.inputs()[ir::feature(2) + ir::kDrift], 0);
}

TEST(Handshake, CellStatusIsLiveInEveryState) {
    Handshake h;
    EXPECT_EQ(h.inputs()[ir::kCalibrationAge], 0xFFFF);  // unknown until told
    CellStatus s;
    s.device_faults = 0b10001;  // camera and results disk
    s.calibration = CalibrationState::kDue;
    s.calibration_age_days = 200;
    s.expected_scan_s = 9.8765;
    s.expected_cycle_s = 100.0;  // beyond 65.535 s: saturates
    h.set_cell_status(s);
    h.fault(u16(ErrorCode::kDeviceLost));  // FAULT clears the result, not the status
    const auto& in = h.inputs();
    EXPECT_EQ(in[ir::kDeviceHealth], 0b10001);
    EXPECT_EQ(in[ir::kCalibrationState], u16(CalibrationState::kDue));
    EXPECT_EQ(in[ir::kCalibrationAge], 200);
    EXPECT_EQ(in[ir::kExpectedScanMs], 9877);
    EXPECT_EQ(in[ir::kExpectedCycleMs], 65535);
    h.set_cell_status({});
    EXPECT_EQ(in[ir::kExpectedScanMs], 0);  // not known
    EXPECT_EQ(in[ir::kCalibrationAge], 0xFFFF);
}
