#pragma once
// The results on their way to the plant (docs/plant-data.md "Nothing lost"): a bounded queue of
// messages on disk, in order. A message is durable (written and fsync'ed) before append()
// returns, and leaves the spool only when the broker has acknowledged it (pop()), so a crash, a
// restart or a broker that is down for hours loses nothing and repeats nothing already
// acknowledged.
//
// On disk, in the spool's folder:
//   spool.jsonl   the messages, one per line, in the order they were appended
//   spool.cursor  the byte offset in spool.jsonl up to which messages are acknowledged
//   spool.last    the last message appended, kept when spool.jsonl is emptied (last_appended())
// When every message is acknowledged the file is emptied. A last line without its newline (the
// power went during an append) is cut off at open(), and logged.
//
// Thread safety: one appender and one consumer at the same time (the processing thread and the
// publisher's thread); every member takes the one mutex.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "hotgauge/core/result.hpp"

namespace hotgauge::plant {

struct SpoolConfig {
    std::filesystem::path dir;               // created if missing
    std::uint64_t max_bytes = 256ull << 20;  // messages waiting, at most (the bound)
};

struct SpoolState {
    std::uint64_t depth = 0;  // messages waiting for the broker's acknowledgement
    std::uint64_t bytes = 0;  // their size
    // Appends refused since open(): the spool was full, a write failed, or not one line.
    std::uint64_t refused = 0;
    bool full = false;  // the last append was refused for want of room
    std::string error;  // the last write error, "" after a good append
};

class Spool {
  public:
    // Opens (creating) the folder and recovers its state; the error names the file and problem.
    static core::Result<std::unique_ptr<Spool>> open(const SpoolConfig& config);
    ~Spool();
    Spool(const Spool&) = delete;
    Spool& operator=(const Spool&) = delete;

    // Appends one message (one line: no '\n' in it), durable when it returns. Refused, with the
    // reason, when the spool would grow past max_bytes or the write fails; what is already
    // spooled is untouched.
    core::Result<void> append(std::string_view message);
    // The oldest message not yet acknowledged.
    std::optional<std::string> front() const;
    // The front message was acknowledged: it leaves the spool, durably.
    core::Result<void> pop();
    // The newest message ever appended (acknowledged or not), for a writer that must know where
    // to go on after a crash; nullopt for a spool never appended to.
    std::optional<std::string> last_appended() const;
    // For a spool never appended to: `message` is taken as its newest (kept in spool.last), so
    // that a writer starting to use it knows after a crash where it began.
    core::Result<void> start_after(std::string_view message);
    SpoolState state() const;
    const std::filesystem::path& dir() const;

  private:
    struct Impl;
    explicit Spool(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace hotgauge::plant
