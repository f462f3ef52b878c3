#pragma once
// The part sequence numbers handed out, kept durably (docs/results.md "Sequence numbers"): the
// highest number given to a part is written to DIR/.sequence, and synced, before the part is
// measured, so that a number is never used twice: not after a part whose result never reached the
// files (PLC fault 206, a full disk), nor after a crash during a part. The results files say
// which numbers were committed; this file says which were used, by which part (the PLC's part id
// and recipe slot), and whether that part's cycle ended: a restart tells from it the part a crash
// interrupted (docs/results.md "One commit per part").
//
// The file: one fixed-width line "<number, 20> <part id, 10> <slot, 5> <R|D|S>\n": R from the
// number's use until the PLC took the part's result, D once it did, S once the daemon stopped
// cleanly. (A line of only the number, as before, reads as S.)
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

    struct Use {
        std::uint64_t sequence = 0;  // 0: none yet
        std::uint32_t part_id = 0;   // 0: not known
        std::uint16_t slot = 0;
        char state = 'S';  // R: in its cycle; D: the PLC took its result; S: stopped cleanly
        bool unfinished() const { return state == 'R'; }
    };
    std::uint64_t reserved() const { return last_.sequence; }
    const Use& last() const { return last_; }
    // Records `n` as used by part `part_id` (in place, a fixed-width line: no block to allocate
    // on a full disk); durable when it returns.
    core::Result<void> reserve(std::uint64_t n, std::uint32_t part_id = 0, std::uint16_t slot = 0);
    // The PLC took the last part's result (or reset its cycle): its cycle is over.
    core::Result<void> taken();
    // The daemon stops cleanly: said in the file (durably) for the next start.
    core::Result<void> stopped();

  private:
    ssize_t put(const Use& use) const;  // the line in place, synced
    core::Result<void> keep(const Use& use);
    SequenceReservation(int fd, std::filesystem::path path) : fd_(fd), path_(std::move(path)) {}
    int fd_ = -1;
    std::filesystem::path path_;
    Use last_;
};

}  // namespace hotgauge::results
