#pragma once
// AccelRing: the time-indexed ring buffer every accelerometer source feeds and the compensation
// stage reads from (docs/accelerometer.md). It keeps the last `capacity_s` seconds of samples and
// remembers what is known about them: gaps (sequence losses reported by the source, time jumps
// of more than 3 sample periods) and how far the writer has got, so that a reader can tell a
// complete window from one that was overwritten, is not written yet, or has holes.
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <span>
#include <vector>

#include "hotgauge/core/recording.hpp"

namespace hotgauge::accel {

// One accelerometer sample: accelerometer axes, m/s², gravity included.
struct AccelSample {
    std::int64_t t_ns = 0;
    float x_mps2 = 0.0f;
    float y_mps2 = 0.0f;
    float z_mps2 = 0.0f;
};

struct AccelRingConfig {
    double capacity_s = 60.0;        // history kept
    double sample_rate_hz = 4000.0;  // nominal rate: sizes the buffer, sets the gap threshold
    double gap_periods = 3.0;        // a time step above this many periods is a gap
};

enum class AccelGapCause {
    sequence_loss,  // the source saw samples go missing (e.g. a skipped datagram sequence number)
    time_jump,      // consecutive samples further apart than gap_periods sample periods
};

// Samples are missing strictly between last_before_ns and first_after_ns (both are stored
// sample times).
struct AccelGap {
    std::int64_t last_before_ns = 0;
    std::int64_t first_after_ns = 0;
    AccelGapCause cause = AccelGapCause::time_jump;
    std::int64_t missing_samples = 0;  // estimate from the nominal period, ≥ 0
};

// What copy_range knows about the half-open window [t0_ns, t1_ns).
struct AccelWindow {
    std::int64_t t0_ns = 0;
    std::int64_t t1_ns = 0;
    std::vector<AccelSample> samples;  // t0_ns ≤ t_ns < t1_ns, strictly increasing
    std::vector<AccelGap> gaps;        // gaps that intersect the window, oldest first
    std::int64_t missing_samples = 0;  // sum over gaps
    // Samples inside the window were overwritten before this copy (ring too small or read late).
    bool start_overwritten = false;
    // The writer had data from t0_ns or earlier and none of the window was overwritten.
    bool start_covered = false;
    // The writer has pushed a sample at or after t1_ns: nothing more will arrive in the window.
    bool end_reached = false;

    bool covered() const { return start_covered && end_reached; }
    bool complete() const { return covered() && gaps.empty(); }
};

struct AccelRingStats {
    std::size_t capacity = 0;                 // samples
    std::size_t size = 0;                     // samples held now
    std::uint64_t stored = 0;                 // samples accepted since construction
    std::uint64_t overwritten = 0;            // samples evicted by newer ones
    std::uint64_t non_monotonic_dropped = 0;  // samples not after the newest one, never stored
    std::uint64_t gaps = 0;                   // gaps recorded since construction
    std::int64_t missing_samples = 0;         // summed estimate over those gaps
    std::optional<std::int64_t> oldest_ns;    // held now
    std::optional<std::int64_t> newest_ns;
};

// Thread safety: one writer (the source's thread calls push/note_loss) and any number of
// readers (copy_range, stats, wait_for) at the same time; every member takes the one mutex, so
// readers copy out and never see a half-written push. Two writers would be memory-safe but
// interleave, and the one behind would lose its samples as non-monotonic: one ring per source.
class AccelRing {
  public:
    explicit AccelRing(const AccelRingConfig& config = {});

    // Appends samples in time order. A sample whose t_ns is not after the newest stored one is
    // dropped and counted (AccelRingStats::non_monotonic_dropped), never stored.
    void push(const AccelSample& sample);
    void push(std::span<const AccelSample> samples);

    // The writer knows samples were lost just before its next push (a skipped sequence number):
    // the step to the next stored sample becomes a gap with cause sequence_loss, however short.
    void note_loss();

    // Copies the samples of [t0_ns, t1_ns) with gaps and coverage flags.
    AccelWindow copy_range(std::int64_t t0_ns, std::int64_t t1_ns) const;

    AccelRingStats stats() const;
    const AccelRingConfig& config() const { return config_; }
    std::int64_t period_ns() const { return period_ns_; }

    // Waits until a sample at or after t_ns has been pushed, or the timeout passes; true when
    // the writer got there. A bounded wait on a condition: tests and readers use it, not sleeps.
    bool wait_for(std::int64_t t_ns, std::chrono::milliseconds timeout) const;

  private:
    void push_locked(const AccelSample& s);
    const AccelSample& at(std::size_t i) const { return buf_[(head_ + i) % buf_.size()]; }
    std::size_t lower_bound_locked(std::int64_t t_ns) const;

    AccelRingConfig config_;
    std::int64_t period_ns_ = 0;
    mutable std::mutex mutex_;
    mutable std::condition_variable pushed_;
    std::vector<AccelSample> buf_;  // capacity slots, buf_[head_] is the oldest
    std::size_t head_ = 0;
    std::size_t size_ = 0;
    std::deque<AccelGap> gaps_;  // those ending inside the held data, oldest first
    bool loss_pending_ = false;
    std::optional<std::int64_t> first_ever_ns_;    // first sample ever stored
    std::optional<std::int64_t> last_evicted_ns_;  // newest sample overwritten so far
    AccelRingStats counts_;                        // counters only; sizes filled in stats()
    bool warned_non_monotonic_ = false;
};

// Before a scan, the record of the last `margin_ns` must be whole. Is it (complete), will it be
// if the reader waits (arriving: a stream that has just started or come back is still filling
// the margin), or has the stream gone silent (no sample in the last `silent_ns`), so that waiting
// is pointless? Samples younger than `in_flight_ns` may still be on their way and are not asked
// for.
enum class HistoryState { complete, arriving, silent };
HistoryState history_before(const AccelRing& ring, std::int64_t now_ns, std::int64_t margin_ns,
                            std::int64_t in_flight_ns, std::int64_t silent_ns);

// A scanned face's accelerometer record, the one way the tool (hotgauge grab) and the daemon
// attach it: the samples from `margin_ns` before its first profile to `margin_ns` after its
// last, as far as they have arrived, replace face.accel_times_ns and face.accel_mps2. Returns
// the window, for what it says of gaps and coverage.
AccelWindow attach_face_window(const AccelRing& ring, core::FaceScan& face, std::int64_t margin_ns);

}  // namespace hotgauge::accel
