#pragma once
// A part's result as the PLC sees it (docs/plc-modbus.md): cold values, verdicts, reason bits,
// the drift watch's state, and a master check's overall verdict.
#include <string>
#include <utility>
#include <vector>

#include "hotgauge/pipeline/pipeline.hpp"
#include "hotgauge/pipeline/verify.hpp"
#include "hotgauge/plc/handshake.hpp"

namespace hotgauge::cell {

// The reason bits of one feature (plc::reason), from what the measurement recorded; `check`: the
// master check it belongs to, or null.
std::uint8_t feature_reasons(const measure::FeatureResult& f, const pipeline::Verification* check);

// Values, verdicts and reason bits; the part's own reasons: degraded data, temperature unknown.
// The cell adds what only it knows (a face left out, no accelerometer).
plc::PartResult to_plc(const pipeline::PartResult& r, const pipeline::Verification* check);

// The drift watch's state of each feature (results::ResultEntry::drift) into the registers.
void set_drift(plc::PartResult& p, const std::vector<std::pair<std::string, std::string>>& drift);

// What the PLC is shown for a part, kept in its results line ("plc", docs/results.md) so that it
// can be shown again after a crash took it from the registers: the result (or the fault, non-zero)
// as a JSON object's text, and back. The sequence and the time are the line's own.
std::string plc_json(const plc::PartResult& p, std::uint16_t fault);
struct PlcShown {
    plc::PartResult result;
    std::uint16_t fault = 0;
};
core::Result<PlcShown> plc_from_json(const std::string& results_line);

// "OK", "NOK", ... as the PLC's overall verdict reads.
std::string verdict_text(const pipeline::PartResult& r, const pipeline::Verification* check);

}  // namespace hotgauge::cell
