#pragma once
// The wall clock the cell runs on (CLOCK_REALTIME: camera frames, accelerometer samples and
// results share it, recording-format-v1), and the recording's timestamp text.
#include <cstdint>
#include <optional>
#include <string>

namespace hotgauge::core {

// Now, in ns since the Unix epoch.
std::int64_t realtime_ns();

// "2026-11-22T07:15:03Z": ISO 8601 UTC to the second, as part.yaml's captured_at.
std::string iso8601_utc(std::int64_t t_ns);
// Its reverse, for a text that begins "YYYY-MM-DDTHH:MM:SS" (a trailing "Z", fraction or
// nothing; read as UTC); nullopt when it does not.
std::optional<std::int64_t> parse_iso8601_utc(const std::string& text);

}  // namespace hotgauge::core
