#pragma once
// The part sequence numbers handed out, kept durably (docs/results.md "Sequence numbers"): the
// highest number given to a part is written to DIR/.sequence, and synced, before the part is
// measured, so that a number is never used twice: not after a part whose result never reached the
// files (PLC fault 206, a full disk), nor after a crash during a part. The results files say
// which numbers were committed; this file says which were used.
#include <sys/types.h>

#include <cstdint>
#include <filesystem>
#include <utility>

#include "hotgauge/core/result.hpp"

namespace hotgauge::results {

class SequenceReservation {
  public:
    // Opens (or creates, with DIR) DIR/.sequence; a file that does not hold a number is an error
    // naming it.
    static core::Result<SequenceReservation> open(const std::filesystem::path& dir);
    SequenceReservation(SequenceReservation&&) noexcept;
    SequenceReservation& operator=(SequenceReservation&&) noexcept;
    ~SequenceReservation();

    std::uint64_t reserved() const { return reserved_; }  // 0: none yet
    // Records `n` as used (in place, a fixed-width line: no block to allocate on a full disk);
    // durable when it returns.
    core::Result<void> reserve(std::uint64_t n);

  private:
    ssize_t put(std::uint64_t n) const;  // n's line in place, synced
    SequenceReservation(int fd, std::filesystem::path path, std::uint64_t reserved)
        : fd_(fd), path_(std::move(path)), reserved_(reserved) {}
    int fd_ = -1;
    std::filesystem::path path_;
    std::uint64_t reserved_ = 0;
};

}  // namespace hotgauge::results
