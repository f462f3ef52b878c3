#include "hotgauge/plc/register_map.hpp"

#include <bit>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

namespace hotgauge::plc {

const char* to_string(State s) {
    switch (s) {
        case State::kIdle:
            return "IDLE";
        case State::kBusy:
            return "BUSY";
        case State::kDone:
            return "DONE";
        case State::kFault:
            return "FAULT";
    }
    return "?";
}

const char* to_string(Verdict v) {
    switch (v) {
        case Verdict::kNone:
            return "none";
        case Verdict::kOk:
            return "OK";
        case Verdict::kNok:
            return "NOK";
        case Verdict::kNotMeasured:
            return "not measured";
        case Verdict::kDegraded:
            return "degraded";
    }
    return "?";
}

const char* to_string(ErrorCode e) {
    switch (e) {
        case ErrorCode::kNone:
            return "none";
        case ErrorCode::kBusy:
            return "busy";
        case ErrorCode::kNotAcknowledged:
            return "not acknowledged";
        case ErrorCode::kInFault:
            return "in fault";
        case ErrorCode::kNothingToAck:
            return "nothing to acknowledge";
        case ErrorCode::kUnknownCommand:
            return "unknown command";
        case ErrorCode::kBadFace:
            return "bad face";
        case ErrorCode::kBadRecipeSlot:
            return "bad recipe slot";
        case ErrorCode::kMeasurementFailed:
            return "measurement failed";
        case ErrorCode::kUnknownRecipe:
            return "unknown recipe";
        case ErrorCode::kDeviceLost:
            return "device lost";
        case ErrorCode::kTimeout:
            return "timeout";
        case ErrorCode::kInternal:
            return "internal error";
        case ErrorCode::kNotStored:
            return "result not stored";
    }
    return "?";
}

const char* to_string(WordOrder w) { return w == WordOrder::kBigEndian ? "big" : "little"; }

std::optional<WordOrder> parse_word_order(std::string_view s) {
    if (s == "big") return WordOrder::kBigEndian;
    if (s == "little") return WordOrder::kLittleEndian;
    return std::nullopt;
}

std::array<std::uint16_t, 2> encode_u32(std::uint32_t v, WordOrder order) {
    const auto hi = static_cast<std::uint16_t>(v >> 16);
    const auto lo = static_cast<std::uint16_t>(v & 0xFFFFu);
    if (order == WordOrder::kBigEndian) return {hi, lo};
    return {lo, hi};
}

std::uint32_t decode_u32(std::uint16_t first, std::uint16_t second, WordOrder order) {
    const std::uint32_t hi = order == WordOrder::kBigEndian ? first : second;
    const std::uint32_t lo = order == WordOrder::kBigEndian ? second : first;
    return (hi << 16) | lo;
}

std::array<std::uint16_t, 2> encode_i32(std::int32_t v, WordOrder order) {
    return encode_u32(std::bit_cast<std::uint32_t>(v), order);
}

std::int32_t decode_i32(std::uint16_t first, std::uint16_t second, WordOrder order) {
    return std::bit_cast<std::int32_t>(decode_u32(first, second, order));
}

std::array<std::uint16_t, 2> encode_f32(float v, WordOrder order) {
    return encode_u32(std::bit_cast<std::uint32_t>(v), order);
}

float decode_f32(std::uint16_t first, std::uint16_t second, WordOrder order) {
    return std::bit_cast<float>(decode_u32(first, second, order));
}

std::int32_t to_um(std::optional<double> value_mm) {
    if (!value_mm || !std::isfinite(*value_mm)) return kInvalidInt32;
    const double um = std::round(*value_mm * 1000.0);
    // The marker INT32_MIN is excluded from the value range.
    if (um <= static_cast<double>(std::numeric_limits<std::int32_t>::min()) ||
        um > static_cast<double>(std::numeric_limits<std::int32_t>::max()))
        return kInvalidInt32;
    return static_cast<std::int32_t>(um);
}

std::int16_t to_decicelsius(std::optional<double> temperature_c) {
    if (!temperature_c || !std::isfinite(*temperature_c)) return kInvalidInt16;
    const double d = std::round(*temperature_c * 10.0);
    if (d <= static_cast<double>(std::numeric_limits<std::int16_t>::min()) ||
        d > static_cast<double>(std::numeric_limits<std::int16_t>::max()))
        return kInvalidInt16;
    return static_cast<std::int16_t>(d);
}

namespace {

struct Row {
    std::uint16_t address;
    int words;
    const char* type;
    const char* name;
    const char* meaning;
};

// PLC -> hotgauge, holding registers (read/write).
const std::vector<Row>& plc_rows() {
    static const std::vector<Row> rows = {
        {hr::kCommand, 1, "uint16", "command",
         "1 trigger, 2 ack, 3 reset; 0 no-op. Taken on write, then reads back 0"},
        {hr::kPartId, 2, "uint32", "part id", "part to measure, echoed in the results"},
        {hr::kRecipeSlot, 1, "uint16", "recipe slot", "recipe to measure with, 1..65535"},
        {hr::kFace, 1, "uint16", "face", "0 all faces, 1 top, 2 bottom, 3 side1, 4 side2"},
        {hr::kPlcHeartbeat, 1, "uint16", "PLC heartbeat", "any changing value; echoed at input 10"},
        {hr::kDieId, 1, "uint16", "die id",
         "the die that forged the part, 0 unknown; drift is watched per die"},
    };
    return rows;
}

// hotgauge -> PLC, input registers (read-only), mirrored in holding registers.
const std::vector<Row>& status_rows() {
    static const std::vector<Row> rows = {
        {ir::kHeartbeat, 1, "uint16", "heartbeat", "+1 every 100 ms (configurable), wraps"},
        {ir::kState, 1, "uint16", "state", "1 IDLE, 2 BUSY, 3 DONE, 4 FAULT"},
        {ir::kErrorCode, 1, "uint16", "error code", "fault code (2xx) while FAULT, else 0"},
        {ir::kCommandStatus, 1, "uint16", "command status",
         "0 last command accepted, else why it was refused (1xx)"},
        {ir::kCommandCount, 1, "uint16", "command count",
         "+1 per command taken (accepted or refused), wraps"},
        {ir::kSequence, 1, "uint16", "result sequence",
         "the results files' sequence number of the result shown (low 16 bits); changes on "
         "every DONE, continues across restarts"},
        {ir::kPartId, 2, "uint32", "part id", "echo of the cycle's part id (0 when IDLE)"},
        {ir::kRecipeSlot, 1, "uint16", "recipe slot", "echo of the cycle's recipe slot"},
        {ir::kFace, 1, "uint16", "face", "echo of the cycle's face"},
        {ir::kPlcHeartbeat, 1, "uint16", "PLC heartbeat echo", "last value written at holding 5"},
        {ir::kOverallVerdict, 1, "uint16", "overall verdict",
         "0 none, 1 OK, 2 NOK, 3 not measured, 4 degraded"},
        {ir::kFeatureCount, 1, "uint16", "feature count", "features in the result, 0 when none"},
        {ir::kTemperature, 1, "int16", "part temperature",
         "0.1 °C (10500 = 1050.0 °C); -32768 unknown"},
        {ir::kMapVersionReg, 1, "uint16", "map version", "4 for this map"},
        {ir::kDriftCount, 1, "uint16", "drift warnings",
         "features of the result whose die is drifting (drift 2 or 3), 0 when none"},
    };
    return rows;
}

// hotgauge -> PLC after the feature blocks (map version 4), mirrored like the others.
const std::vector<Row>& cell_rows() {
    static const std::vector<Row> rows = {
        {ir::kScanPhase, 1, "uint16", "scan phase",
         "0 no cycle, 1 scanning: the part must stay, 2 scans done: the part may move; live"},
        {ir::kDeviceHealth, 1, "uint16", "device health",
         "a bit per device not working: 0 camera, 1 accelerometer, 2 pyrometer, 3 axis, "
         "4 results disk, 5 plant link (MQTT); 0 all well; live"},
        {ir::kReasons, 1, "uint16", "reasons",
         "reason bits of the result (below), 0 when OK or no result"},
        {ir::kResultTime, 2, "uint32", "result time",
         "Unix seconds (UTC) of the result, as the results files' `time`; 0 no result"},
        {ir::kResultTimeMs, 1, "uint16", "result time ms", "its milliseconds, 0..999"},
        {ir::kRecipeRevision, 1, "uint16", "recipe revision",
         "checksum of the result's recipe file, as `hotgauge plc map --recipe` prints it"},
        {ir::kCalibrationState, 1, "uint16", "calibration state",
         "0 unknown, 1 valid, 2 due (older than its interval), 3 geometry not measured; live"},
        {ir::kCalibrationAge, 1, "uint16", "calibration age",
         "days since the calibration, 65535 unknown; live"},
        {ir::kExpectedScanMs, 1, "uint16", "expected scan time",
         "ms from trigger to scan phase 2 (median of recent cycles), 0 not known yet; live"},
        {ir::kExpectedCycleMs, 1, "uint16", "expected cycle time",
         "ms from trigger to DONE (median of recent cycles), 0 not known yet; live"},
    };
    return rows;
}

std::string range(std::uint32_t first, int words) {
    if (words == 1) return std::to_string(first);
    return std::to_string(first) + "–" + std::to_string(first + static_cast<unsigned>(words) - 1);
}

void input_rows(std::ostream& o, const std::vector<Row>& rows) {
    o << "| Input (0-based) | 3xxxx | Holding mirror (0-based) | 4xxxx | Type | Name | Meaning |\n";
    o << "| --- | --- | --- | --- | --- | --- | --- |\n";
    for (const auto& r : rows)
        o << "| " << range(r.address, r.words) << " | " << range(30001u + r.address, r.words)
          << " | " << range(hr::kMirrorBase + r.address, r.words) << " | "
          << range(40001u + hr::kMirrorBase + r.address, r.words) << " | " << r.type << " | "
          << r.name << " | " << r.meaning << " |\n";
}

}  // namespace

std::string map_markdown() {
    std::ostringstream o;
    o << "| Holding (0-based) | 4xxxx | Type | Name | Meaning |\n";
    o << "| --- | --- | --- | --- | --- |\n";
    for (const auto& r : plc_rows())
        o << "| " << range(r.address, r.words) << " | " << range(40001u + r.address, r.words)
          << " | " << r.type << " | " << r.name << " | " << r.meaning << " |\n";
    o << "\n";
    input_rows(o, status_rows());
    o << "\n";
    o << "| Feature slot | Input (0-based): µm int32 / mm float32 / verdict / drift and reasons | "
         "3xxxx | "
         "Holding mirror 4xxxx |\n";
    o << "| --- | --- | --- | --- |\n";
    auto triple = [](std::uint32_t base) {
        return range(base + ir::kValueUm, 2) + " / " + range(base + ir::kValueMm, 2) + " / " +
               std::to_string(base + ir::kVerdict) + " / " + std::to_string(base + ir::kDrift);
    };
    for (int slot = 1; slot <= kMaxFeatures; ++slot) {
        const std::uint32_t a = ir::feature(slot);
        o << "| " << slot << " | " << triple(a) << " | " << triple(30001u + a) << " | "
          << triple(40001u + hr::kMirrorBase + a) << " |\n";
    }
    o << "\n";
    input_rows(o, cell_rows());
    return o.str();
}

}  // namespace hotgauge::plc
