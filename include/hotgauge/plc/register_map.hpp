#pragma once
// The Modbus register map of the PLC interface (docs/plc-modbus.md), as constants and as data:
// the docs' tables are printed from `map_markdown()` (`hotgauge plc map`) and a test checks that
// the docs contain them verbatim, so code and docs cannot drift apart.
//
// Addresses are 0-based PDU addresses (what goes on the wire); the docs also give the
// 40001/30001-style numbers. Every 32-bit value spans two registers in the configured word order;
// the bytes inside a register are big-endian as Modbus defines.
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace hotgauge::plc {

// 2: per-feature verdict 4 degraded (a value the data cannot vouch for), docs/plc-modbus.md.
// 3: die id (holding 6), the drift warning per feature and its count (input 15).
// 4: the cell's status after the feature blocks (scan phase, device health, reasons, result time,
//    recipe revision, calibration, expected times, inputs 112..122) and each feature's reason
//    bits in the high byte of its block's sixth register.
inline constexpr std::uint16_t kMapVersion = 4;
inline constexpr int kMaxFeatures = 16;

// Holding registers: 0..6 are written by the PLC (the only writable block); the input registers
// are mirrored read-only at kMirrorBase + address for PLCs that only read holding registers.
namespace hr {
inline constexpr std::uint16_t kCommand = 0;     // Command; reads back 0 once taken
inline constexpr std::uint16_t kPartId = 1;      // uint32, 2 registers
inline constexpr std::uint16_t kRecipeSlot = 3;  // 1..65535
inline constexpr std::uint16_t kFace = 4;        // Face
inline constexpr std::uint16_t kPlcHeartbeat = 5;
inline constexpr std::uint16_t kDieId = 6;  // which die forged the part: drift is watched per die
inline constexpr std::uint16_t kWritableCount = 7;
inline constexpr std::uint16_t kMirrorBase = 100;
}  // namespace hr

// Input registers (read-only): status, then one block per feature slot.
namespace ir {
inline constexpr std::uint16_t kHeartbeat = 0;      // +1 every heartbeat period, wraps
inline constexpr std::uint16_t kState = 1;          // State
inline constexpr std::uint16_t kErrorCode = 2;      // fault code while FAULT, else 0
inline constexpr std::uint16_t kCommandStatus = 3;  // 0 accepted, else why the last was refused
inline constexpr std::uint16_t kCommandCount = 4;   // commands taken (accepted or refused), wraps
inline constexpr std::uint16_t kSequence = 5;       // +1 on every DONE, wraps
inline constexpr std::uint16_t kPartId = 6;         // uint32 echo of the cycle's part id
inline constexpr std::uint16_t kRecipeSlot = 8;
inline constexpr std::uint16_t kFace = 9;
inline constexpr std::uint16_t kPlcHeartbeat = 10;  // echo of the PLC's heartbeat
inline constexpr std::uint16_t kOverallVerdict = 11;
inline constexpr std::uint16_t kFeatureCount = 12;  // features in the result, 0 when none
inline constexpr std::uint16_t kTemperature = 13;   // int16, 0.1 °C; kInvalidInt16 if unknown
inline constexpr std::uint16_t kMapVersionReg = 14;
inline constexpr std::uint16_t kDriftCount = 15;  // features of the result in DRIFT_UP/DOWN
inline constexpr std::uint16_t kFeatureBase = 16;
inline constexpr std::uint16_t kFeatureStride = 6;
// Offsets inside one feature block.
inline constexpr std::uint16_t kValueUm = 0;  // int32 µm, kInvalidInt32 if not measured
inline constexpr std::uint16_t kValueMm = 2;  // float32 mm, NaN if not measured
inline constexpr std::uint16_t kVerdict = 4;  // Verdict
inline constexpr std::uint16_t kDrift = 5;    // low byte DriftState, high byte reason bits
inline constexpr int kReasonShift = 8;        // a feature's reason bits: (register >> 8)
inline constexpr std::uint16_t kFeatureEnd = kFeatureBase + kMaxFeatures * kFeatureStride;  // 112
// The cell's status after the feature blocks (map version 4). Live: updated in every state.
inline constexpr std::uint16_t kScanPhase = 112;     // ScanPhase: the part may move at 2
inline constexpr std::uint16_t kDeviceHealth = 113;  // bit per device (cell::Device) not working
// Of the result (DONE only, else 0):
inline constexpr std::uint16_t kReasons = 114;         // reason bits of the part (Reason)
inline constexpr std::uint16_t kResultTime = 115;      // uint32 Unix seconds (UTC), 2 registers
inline constexpr std::uint16_t kResultTimeMs = 117;    // milliseconds of the result time
inline constexpr std::uint16_t kRecipeRevision = 118;  // 16-bit checksum of the recipe file
// Live again:
inline constexpr std::uint16_t kCalibrationState = 119;  // CalibrationState
inline constexpr std::uint16_t kCalibrationAge = 120;    // days since calibrated, 0xFFFF unknown
inline constexpr std::uint16_t kExpectedScanMs = 121;    // trigger -> scans done, ms; 0 unknown
inline constexpr std::uint16_t kExpectedCycleMs = 122;   // trigger -> DONE, ms; 0 unknown
inline constexpr std::uint16_t kCount = 123;
static_assert(kScanPhase == kFeatureEnd && kCount <= 125, "one read request holds the whole map");

// First register of feature `slot` (1-based).
constexpr std::uint16_t feature(int slot) {
    return static_cast<std::uint16_t>(kFeatureBase + (slot - 1) * kFeatureStride);
}
}  // namespace ir

enum class State : std::uint16_t { kIdle = 1, kBusy = 2, kDone = 3, kFault = 4 };
enum class Command : std::uint16_t { kNone = 0, kTrigger = 1, kAck = 2, kReset = 3 };
// Per feature: kNone (no result), kOk, kNok, kNotMeasured, kDegraded (measured only with
// profiles the compensation could not follow: the value is given, it sorts nothing). Overall:
// NOK when a feature is NOK, else not measured, else degraded when a feature is (or the cell
// flagged the data), else OK.
enum class Verdict : std::uint16_t {
    kNone = 0,
    kOk = 1,
    kNok = 2,
    kNotMeasured = 3,
    kDegraded = 4
};
// Per feature, the drift warning of its die (docs/quality.md "In the daemon"): kNone while the
// baseline is collected (or no value), kWatching, kUp / kDown while the EWMA is beyond its limit.
enum class DriftState : std::uint16_t { kNone = 0, kWatching = 1, kUp = 2, kDown = 3 };
// Where the cycle is (input 112): the part must stay on the support while scanning; from
// kScansDone on (before the result, which takes the pipeline's time) it may move.
enum class ScanPhase : std::uint16_t { kNone = 0, kScanning = 1, kScansDone = 2 };
// Why a feature or the part is not simply OK (docs/plc-modbus.md "Reason bits"): one set of
// bits for both. A feature carries bits 0..5 and 7 in its block's high byte; the part's register
// (input 114) is the OR of its features' bits and the part's own (6, and 1, 4, 5 from the cell).
namespace reason {
inline constexpr std::uint16_t kNotMeasured = 1u << 0;         // no value
inline constexpr std::uint16_t kDegraded = 1u << 1;            // untrusted data: sorts nothing
inline constexpr std::uint16_t kOutsideTolerance = 1u << 2;    // deviation beyond its limits
inline constexpr std::uint16_t kLowCoverage = 1u << 3;         // an edge seen on a partial arc
inline constexpr std::uint16_t kTemperatureUnknown = 1u << 4;  // no cold value: no temperature
inline constexpr std::uint16_t kFaceMissing = 1u << 5;         // a face it needs was not scanned
inline constexpr std::uint16_t kNotCompensated = 1u << 6;      // no accelerometer configured
inline constexpr std::uint16_t kMasterCheckFailed = 1u << 7;   // off its master certificate
}  // namespace reason
// The calibration the cell measures with (input 119): kDue once older than the configured
// interval; kNotMeasured when its faces' geometry is design values (method nominal or sensor).
enum class CalibrationState : std::uint16_t {
    kUnknown = 0,  // no readable calibration date
    kValid = 1,
    kDue = 2,
    kNotMeasured = 3
};
enum class Face : std::uint16_t { kAll = 0, kTop = 1, kBottom = 2, kSide1 = 3, kSide2 = 4 };
inline constexpr std::uint16_t kMaxFace = 4;

// Command refusals (command status register) are 1xx; faults (error code register) are 2xx.
enum class ErrorCode : std::uint16_t {
    kNone = 0,
    kBusy = 101,             // trigger while BUSY
    kNotAcknowledged = 102,  // trigger while DONE: ack the result first
    kInFault = 103,          // trigger or ack while FAULT: reset first
    kNothingToAck = 104,     // ack while IDLE or BUSY
    kUnknownCommand = 105,
    kBadFace = 106,        // face register above 4
    kBadRecipeSlot = 107,  // recipe slot 0
    kMeasurementFailed = 201,
    kUnknownRecipe = 202,  // no recipe in that slot
    kDeviceLost = 203,     // camera, accelerometer or pyrometer gone
    kTimeout = 204,        // the cycle took too long
    kInternal = 205,       // a bug: an invalid result was published
    kNotStored = 206,      // the results files could not be written (disk full): not published
};

enum class WordOrder { kBigEndian, kLittleEndian };  // high word first / low word first

const char* to_string(State s);
const char* to_string(Verdict v);
const char* to_string(ErrorCode e);
const char* to_string(WordOrder w);
std::optional<WordOrder> parse_word_order(std::string_view s);  // "big" or "little"

inline constexpr std::int32_t kInvalidInt32 = INT32_MIN;  // 0x80000000, as profile sensors do
inline constexpr std::int16_t kInvalidInt16 = INT16_MIN;  // 0x8000

// A 32-bit value as two registers, in the order they appear at increasing addresses.
std::array<std::uint16_t, 2> encode_u32(std::uint32_t v, WordOrder order);
std::uint32_t decode_u32(std::uint16_t first, std::uint16_t second, WordOrder order);
std::array<std::uint16_t, 2> encode_i32(std::int32_t v, WordOrder order);
std::int32_t decode_i32(std::uint16_t first, std::uint16_t second, WordOrder order);
std::array<std::uint16_t, 2> encode_f32(float v, WordOrder order);
float decode_f32(std::uint16_t first, std::uint16_t second, WordOrder order);

// A length in mm as int32 µm (rounded half away from zero); kInvalidInt32 when absent,
// not finite or out of range (the marker itself is never a value).
std::int32_t to_um(std::optional<double> value_mm);
// A temperature as int16 in 0.1 °C; kInvalidInt16 when absent or out of range.
std::int16_t to_decicelsius(std::optional<double> temperature_c);

// The register tables of docs/plc-modbus.md, generated from the constants above.
std::string map_markdown();

}  // namespace hotgauge::plc
