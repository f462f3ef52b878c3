#pragma once
// The PLC handshake (docs/plc-modbus.md "Handshake") and the register image it drives: pure, no
// I/O. Modbus writes to the writable holding block come in, the owner's results and faults come
// in, and the whole register image (input registers, writable holding block) comes out.
//
//   IDLE --trigger--> BUSY --finish--> DONE (results valid, sequence + 1) --ack--> IDLE
//   any --fault(code)--> FAULT --reset--> IDLE          (reset also aborts BUSY, clears DONE)
//
// Results are visible only in DONE, and never change while DONE; everywhere else every feature
// reads invalid and the verdicts read 0 (none), so a stale result is never shown as valid.
#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/plc/register_map.hpp"

namespace hotgauge::plc {

// One feature of a part result, as the PLC sees it. The daemon translates measure's results.
struct FeatureValue {
    std::string name;                         // for logs only
    int slot = 0;                             // register block 1..kMaxFeatures
    std::optional<double> value_mm;           // absent: not measured (verdict must say so)
    Verdict verdict = Verdict::kNotMeasured;  // kOk, kNok, kNotMeasured or kDegraded
    bool required = true;  // not measured, a feature not required leaves the overall verdict
    DriftState drift = DriftState::kNone;
    std::uint8_t reasons = 0;  // reason:: bits 0..7
};

struct PartResult {
    std::vector<FeatureValue> features;       // at most kMaxFeatures, unique slots
    Verdict overall = Verdict::kNotMeasured;  // kOk, kNok, kNotMeasured or kDegraded
    std::optional<double> temperature_c;
    // The results files' sequence number of this part; input 5 shows its low 16 bits, so the
    // PLC's count continues across restarts and names the results-file row. Unset: the last
    // DONE's + 1 (a server without results files, `hotgauge plc serve`).
    std::optional<std::uint64_t> sequence;
    std::uint16_t reasons = 0;  // the part's own reason bits; the features' are added
    std::int64_t time_ns = 0;   // the result's time, Unix ns (the results files' `time`); 0 none
    std::uint16_t recipe_revision = 0;
};

// The cell's live status (inputs 113, 119..122), updated in every state.
struct CellStatus {
    std::uint16_t device_faults = 0;  // cell::DeviceHealth::fault_bits()
    CalibrationState calibration = CalibrationState::kUnknown;
    std::optional<int> calibration_age_days;
    std::optional<double> expected_scan_s, expected_cycle_s;  // absent: not known yet
};

// The overall verdict by the documented rule: any NOK -> NOK; else any not measured -> not
// measured; else degraded if `degraded` or any feature is; else OK (also for no features).
Verdict overall_verdict(const std::vector<FeatureValue>& features, bool degraded);

// Checks slots, verdict values and consistency (a missing value is never OK or NOK; overall OK
// needs every feature OK). Error names the feature.
core::Result<void> check_result(const PartResult& r);

// A trigger the PLC gave, for the owner to measure.
struct TriggerRequest {
    std::uint32_t trigger_id = 0;  // counts accepted triggers; finish() must quote it
    std::uint32_t part_id = 0;
    std::uint16_t recipe_slot = 0;
    Face face = Face::kAll;
    std::uint16_t die_id = 0;  // 0: the PLC does not say
};

// What the owner must act on: a trigger to measure, or a reset (abandon the cycle, clear the
// fault).
struct PlcEvent {
    enum class Kind { kTrigger, kReset } kind = Kind::kTrigger;
    TriggerRequest trigger;  // kTrigger only
};

class Handshake {
  public:
    using InputImage = std::array<std::uint16_t, ir::kCount>;

    // `first_sequence`: input 5 before the first DONE (the last result's, after a restart).
    explicit Handshake(WordOrder order = WordOrder::kBigEndian, std::uint16_t first_sequence = 0);

    // Applies a Modbus write of `values` at `address` inside the writable holding block (the
    // caller has checked the range), then takes the command register if it is non-zero: the
    // whole write lands first, so one FC16 of registers 0..5 is a complete trigger.
    std::optional<PlcEvent> write(std::uint16_t address, std::span<const std::uint16_t> values);

    // BUSY for `trigger_id` -> DONE with `result`. Refused (state unchanged) when not BUSY or for
    // another trigger: a late result of an aborted cycle is dropped. An invalid result is a bug
    // in the owner: FAULT with kInternal, and the error.
    core::Result<void> finish(std::uint32_t trigger_id, const PartResult& result);
    // Any state -> FAULT with `code` (0 is taken as kInternal); results are cleared.
    void fault(std::uint16_t code);
    // BUSY for `trigger_id`: its scans are done, the part may move (input 112). Ignored
    // otherwise (a late call for an aborted cycle).
    void scans_done(std::uint32_t trigger_id);
    void set_cell_status(const CellStatus& s);
    void tick_heartbeat();

    State state() const { return state_; }
    std::uint16_t sequence() const { return inputs_[ir::kSequence]; }
    std::uint32_t busy_trigger_id() const { return trigger_id_; }
    WordOrder word_order() const { return order_; }
    const InputImage& inputs() const { return inputs_; }
    std::uint16_t holding(std::uint16_t address) const { return holding_[address]; }

  private:
    ErrorCode refusal(std::uint16_t code) const;
    PlcEvent start_cycle();
    std::optional<PlcEvent> back_to_idle();
    void set_state(State s);
    void set_phase(ScanPhase p);
    void clear_result();
    void put32(std::uint16_t address, std::uint32_t v);

    WordOrder order_;
    State state_ = State::kIdle;
    std::uint32_t trigger_id_ = 0;  // of the current (or last) accepted trigger
    std::array<std::uint16_t, hr::kWritableCount> holding_{};
    InputImage inputs_{};
};

}  // namespace hotgauge::plc
