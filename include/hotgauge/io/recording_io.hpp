#pragma once
// Recording format v1 (`hotgauge-recording/1`, docs/recording-format.md) on disk.
#include <filesystem>
#include <functional>
#include <string>

#include "hotgauge/core/recording.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"

namespace hotgauge::io {

inline constexpr const char* kRecordingFormat = "hotgauge-recording/1";

// Reads and checks a recording folder. Every contract violation is an Error naming the file and
// what is wrong; findings that are allowed but suspicious (accelerometer not covering the scan
// with 0.5 s margins, non-finite accelerometer samples) go to Recording::warnings.
core::Result<core::Recording> read_recording(const std::filesystem::path& dir);
// The same, its files (`dir / "part.yaml"`, `dir / face / "profiles.npy"`, ...) from `files`.
core::Result<core::Recording> read_recording(const std::filesystem::path& dir,
                                             const FileSource& files);

// Writes `rec` as a recording folder (created if needed; existing files are overwritten).
// Checks the same invariants the reader checks before writing anything.
core::Result<void> write_recording(const core::Recording& rec, const std::filesystem::path& dir);

// The files write_recording writes, in the order it writes them (part.yaml last), each handed to
// `file` (its path under `dir`, its bytes) as soon as it is made; an Error from `file` ends it.
using RecordingFile =
    std::function<core::Result<void>(const std::filesystem::path& path, std::string&& bytes)>;
core::Result<void> recording_files(const core::Recording& rec, const std::filesystem::path& dir,
                                   const RecordingFile& file);

}  // namespace hotgauge::io
