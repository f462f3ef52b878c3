#pragma once
// Where the daemon's log goes (docs/operations.md "Logs"): under systemd (stderr connected to
// the journal, $JOURNAL_STREAM) every message goes to journald with its priority, and part
// records carry the structured fields PART_ID, RECIPE, VERDICT, SEQ (journalctl SEQ=42);
// elsewhere to stderr.
#include <cstdint>
#include <string>

#include "hotgauge/plc/register_map.hpp"

namespace hotgauge::cell {

// True when stderr is the journal's stream (systemd sets $JOURNAL_STREAM to its device:inode).
bool stderr_is_journal();

// Makes the default spdlog logger (and so every module's) write to the journal or to stderr.
void init_logging(const std::string& identifier);

struct PartRecord {
    std::uint64_t sequence = 0;
    std::string part_id, recipe, verdict;
    std::string message;   // the human line
    bool problem = false;  // logged as a warning (not measured, fault, degraded)
};

// The VERDICT field of a part record (docs/operations.md "Logs"): FAULT when the part was not
// measured by a fault (the PLC saw a fault code), else the published verdict in capitals: OK,
// NOK, NOT_MEASURED, DEGRADED.
std::string verdict_field(bool fault, plc::Verdict published);

// One line per part, with the structured fields when journald is the log.
void log_part(const PartRecord& record);

}  // namespace hotgauge::cell
