#include "hotgauge/plc/handshake.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

namespace hotgauge::plc {

Verdict overall_verdict(const std::vector<FeatureValue>& features, bool degraded) {
    const auto any = [&](Verdict v) {
        return std::any_of(features.begin(), features.end(), [v](const FeatureValue& f) {
            return f.verdict == v && (f.required || v != Verdict::kNotMeasured);
        });
    };
    if (any(Verdict::kNok)) return Verdict::kNok;
    if (any(Verdict::kNotMeasured)) return Verdict::kNotMeasured;
    return degraded || any(Verdict::kDegraded) ? Verdict::kDegraded : Verdict::kOk;
}

core::Result<void> check_result(const PartResult& r) {
    if (r.features.size() > static_cast<std::size_t>(kMaxFeatures))
        return core::make_error("result: " + std::to_string(r.features.size()) +
                                " features, the register map holds " +
                                std::to_string(kMaxFeatures));
    std::array<bool, kMaxFeatures + 1> used{};
    for (const auto& f : r.features) {
        const std::string what =
            "result feature '" + f.name + "' (slot " + std::to_string(f.slot) + ")";
        if (f.slot < 1 || f.slot > kMaxFeatures)
            return core::make_error(what + ": slot outside 1.." + std::to_string(kMaxFeatures));
        if (used[static_cast<std::size_t>(f.slot)])
            return core::make_error(what + ": slot used twice");
        used[static_cast<std::size_t>(f.slot)] = true;
        if (f.verdict != Verdict::kOk && f.verdict != Verdict::kNok &&
            f.verdict != Verdict::kNotMeasured && f.verdict != Verdict::kDegraded)
            return core::make_error(what + ": verdict must be OK, NOK, not measured or degraded");
        if (to_um(f.value_mm) == kInvalidInt32 && f.verdict != Verdict::kNotMeasured)
            return core::make_error(what + ": no valid value but verdict " + to_string(f.verdict));
    }
    if (r.overall == Verdict::kNone)
        return core::make_error(
            "result: overall verdict must be OK, NOK, not measured or degraded");
    // OK overall: every feature OK, but a feature not required may be not measured.
    if (r.overall == Verdict::kOk &&
        !std::all_of(r.features.begin(), r.features.end(), [](const FeatureValue& f) {
            return f.verdict == Verdict::kOk || (!f.required && f.verdict == Verdict::kNotMeasured);
        }))
        return core::make_error("result: overall OK but a feature is not OK");
    return {};
}

Handshake::Handshake(WordOrder order, std::uint16_t first_sequence) : order_(order) {
    inputs_[ir::kMapVersionReg] = kMapVersion;
    inputs_[ir::kSequence] = first_sequence;
    inputs_[ir::kCalibrationAge] = 0xFFFF;
    set_state(State::kIdle);
    clear_result();
}

void Handshake::put32(std::uint16_t address, std::uint32_t v) {
    const auto w = encode_u32(v, order_);
    inputs_[address] = w[0];
    inputs_[address + 1] = w[1];
}

void Handshake::set_state(State s) {
    state_ = s;
    inputs_[ir::kState] = static_cast<std::uint16_t>(s);
}

void Handshake::clear_result() {
    inputs_[ir::kOverallVerdict] = static_cast<std::uint16_t>(Verdict::kNone);
    inputs_[ir::kReasons] = 0;
    put32(ir::kResultTime, 0);
    inputs_[ir::kResultTimeMs] = 0;
    inputs_[ir::kRecipeRevision] = 0;
    inputs_[ir::kFeatureCount] = 0;
    inputs_[ir::kDriftCount] = 0;
    inputs_[ir::kTemperature] = std::bit_cast<std::uint16_t>(kInvalidInt16);
    const auto invalid = encode_i32(kInvalidInt32, order_);
    const auto nan = encode_f32(std::nanf(""), order_);
    for (int slot = 1; slot <= kMaxFeatures; ++slot) {
        const std::uint16_t a = ir::feature(slot);
        inputs_[a + ir::kValueUm] = invalid[0];
        inputs_[a + ir::kValueUm + 1] = invalid[1];
        inputs_[a + ir::kValueMm] = nan[0];
        inputs_[a + ir::kValueMm + 1] = nan[1];
        inputs_[a + ir::kVerdict] = static_cast<std::uint16_t>(Verdict::kNone);
        inputs_[a + ir::kDrift] = static_cast<std::uint16_t>(DriftState::kNone);
    }
}

std::optional<PlcEvent> Handshake::write(std::uint16_t address,
                                         std::span<const std::uint16_t> values) {
    for (std::size_t i = 0; i < values.size(); ++i) holding_[address + i] = values[i];
    inputs_[ir::kPlcHeartbeat] = holding_[hr::kPlcHeartbeat];
    const std::uint16_t code = holding_[hr::kCommand];
    if (code == 0) return std::nullopt;
    holding_[hr::kCommand] = 0;  // taken: reads back 0
    ++inputs_[ir::kCommandCount];
    const ErrorCode why = refusal(code);
    inputs_[ir::kCommandStatus] = static_cast<std::uint16_t>(why);
    if (why != ErrorCode::kNone) return std::nullopt;
    if (static_cast<Command>(code) == Command::kTrigger) return start_cycle();
    return back_to_idle();
}

ErrorCode Handshake::refusal(std::uint16_t code) const {
    switch (static_cast<Command>(code)) {
        case Command::kTrigger:
            if (state_ == State::kBusy) return ErrorCode::kBusy;
            if (state_ == State::kDone) return ErrorCode::kNotAcknowledged;
            if (state_ == State::kFault) return ErrorCode::kInFault;
            if (holding_[hr::kFace] > kMaxFace) return ErrorCode::kBadFace;
            if (holding_[hr::kRecipeSlot] == 0) return ErrorCode::kBadRecipeSlot;
            return ErrorCode::kNone;
        case Command::kAck:
            if (state_ == State::kFault) return ErrorCode::kInFault;
            if (state_ != State::kDone) return ErrorCode::kNothingToAck;
            return ErrorCode::kNone;
        case Command::kReset:
            return ErrorCode::kNone;
        case Command::kNone:
            break;
    }
    return ErrorCode::kUnknownCommand;
}

PlcEvent Handshake::start_cycle() {
    PlcEvent e;
    e.kind = PlcEvent::Kind::kTrigger;
    e.trigger.trigger_id = ++trigger_id_;
    e.trigger.part_id = decode_u32(holding_[hr::kPartId], holding_[hr::kPartId + 1], order_);
    e.trigger.recipe_slot = holding_[hr::kRecipeSlot];
    e.trigger.face = static_cast<Face>(holding_[hr::kFace]);
    e.trigger.die_id = holding_[hr::kDieId];
    clear_result();
    put32(ir::kPartId, e.trigger.part_id);
    inputs_[ir::kRecipeSlot] = e.trigger.recipe_slot;
    inputs_[ir::kFace] = holding_[hr::kFace];
    set_phase(ScanPhase::kScanning);
    set_state(State::kBusy);
    return e;
}

// Ack in DONE, or reset anywhere: IDLE with nothing shown. The owner hears of a reset that
// abandons a cycle (BUSY) or clears a fault.
std::optional<PlcEvent> Handshake::back_to_idle() {
    const State was = state_;
    clear_result();
    put32(ir::kPartId, 0);
    inputs_[ir::kRecipeSlot] = 0;
    inputs_[ir::kFace] = 0;
    inputs_[ir::kErrorCode] = 0;
    set_phase(ScanPhase::kNone);
    set_state(State::kIdle);
    if (was == State::kBusy || was == State::kFault) return PlcEvent{PlcEvent::Kind::kReset, {}};
    return std::nullopt;
}

core::Result<void> Handshake::finish(std::uint32_t trigger_id, const PartResult& result) {
    if (state_ != State::kBusy)
        return core::make_error(std::string("result for trigger ") + std::to_string(trigger_id) +
                                " dropped: state is " + to_string(state_) + ", not BUSY");
    if (trigger_id != trigger_id_)
        return core::make_error("stale result for trigger " + std::to_string(trigger_id) +
                                " dropped: BUSY with trigger " + std::to_string(trigger_id_));
    if (auto ok = check_result(result); !ok) {
        fault(static_cast<std::uint16_t>(ErrorCode::kInternal));
        return ok;
    }
    std::uint16_t drifting = 0;
    std::uint16_t reasons = result.reasons;
    for (const auto& f : result.features) {
        const std::uint16_t a = ir::feature(f.slot);
        const std::int32_t um = to_um(f.value_mm);
        const auto v = encode_i32(um, order_);
        const float mm = um == kInvalidInt32 ? std::nanf("") : static_cast<float>(*f.value_mm);
        const auto m = encode_f32(mm, order_);
        inputs_[a + ir::kValueUm] = v[0];
        inputs_[a + ir::kValueUm + 1] = v[1];
        inputs_[a + ir::kValueMm] = m[0];
        inputs_[a + ir::kValueMm + 1] = m[1];
        inputs_[a + ir::kVerdict] = static_cast<std::uint16_t>(f.verdict);
        inputs_[a + ir::kDrift] = static_cast<std::uint16_t>(
            static_cast<std::uint16_t>(f.drift) | (std::uint16_t{f.reasons} << ir::kReasonShift));
        if (f.drift == DriftState::kUp || f.drift == DriftState::kDown) ++drifting;
        reasons |= f.reasons;
    }
    inputs_[ir::kReasons] = reasons;
    if (result.time_ns > 0) {
        put32(ir::kResultTime, static_cast<std::uint32_t>(result.time_ns / 1'000'000'000));
        inputs_[ir::kResultTimeMs] = static_cast<std::uint16_t>(result.time_ns / 1'000'000 % 1000);
    }
    inputs_[ir::kRecipeRevision] = result.recipe_revision;
    set_phase(ScanPhase::kScansDone);
    inputs_[ir::kDriftCount] = drifting;
    inputs_[ir::kFeatureCount] = static_cast<std::uint16_t>(result.features.size());
    inputs_[ir::kOverallVerdict] = static_cast<std::uint16_t>(result.overall);
    inputs_[ir::kTemperature] = std::bit_cast<std::uint16_t>(to_decicelsius(result.temperature_c));
    inputs_[ir::kSequence] = result.sequence
                                 ? static_cast<std::uint16_t>(*result.sequence & 0xFFFF)
                                 : static_cast<std::uint16_t>(inputs_[ir::kSequence] + 1);
    set_state(State::kDone);
    return {};
}

void Handshake::fault(std::uint16_t code) {
    if (code == 0) code = static_cast<std::uint16_t>(ErrorCode::kInternal);
    clear_result();
    inputs_[ir::kErrorCode] = code;
    set_phase(ScanPhase::kNone);
    set_state(State::kFault);
}

void Handshake::scans_done(std::uint32_t trigger_id) {
    if (state_ == State::kBusy && trigger_id == trigger_id_) set_phase(ScanPhase::kScansDone);
}

void Handshake::set_cell_status(const CellStatus& s) {
    const auto ms = [](std::optional<double> seconds) -> std::uint16_t {
        if (!seconds || !std::isfinite(*seconds) || *seconds <= 0) return 0;
        return static_cast<std::uint16_t>(std::clamp(std::lround(*seconds * 1000.0), 1L, 65535L));
    };
    inputs_[ir::kDeviceHealth] = s.device_faults;
    inputs_[ir::kCalibrationState] = static_cast<std::uint16_t>(s.calibration);
    inputs_[ir::kCalibrationAge] =
        s.calibration_age_days
            ? static_cast<std::uint16_t>(std::clamp(*s.calibration_age_days, 0, 65534))
            : std::uint16_t{0xFFFF};
    inputs_[ir::kExpectedScanMs] = ms(s.expected_scan_s);
    inputs_[ir::kExpectedCycleMs] = ms(s.expected_cycle_s);
}

void Handshake::set_phase(ScanPhase p) { inputs_[ir::kScanPhase] = static_cast<std::uint16_t>(p); }

void Handshake::tick_heartbeat() { ++inputs_[ir::kHeartbeat]; }

}  // namespace hotgauge::plc
