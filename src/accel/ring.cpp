#include "hotgauge/accel/ring.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#include "log.hpp"

namespace hotgauge::accel {

namespace {

std::size_t capacity_of(const AccelRingConfig& c) {
    assert(c.capacity_s > 0.0 && c.sample_rate_hz > 0.0 && c.gap_periods >= 1.0);
    const double n = std::ceil(c.capacity_s * c.sample_rate_hz);
    return n >= 1.0 ? static_cast<std::size_t>(n) : 1;
}

}  // namespace

AccelRing::AccelRing(const AccelRingConfig& config)
    : config_(config),
      period_ns_(std::max<std::int64_t>(1, std::llround(1e9 / config.sample_rate_hz))),
      buf_(capacity_of(config)) {}

void AccelRing::push(const AccelSample& sample) { push(std::span<const AccelSample>(&sample, 1)); }

void AccelRing::push(std::span<const AccelSample> samples) {
    {
        std::lock_guard lock(mutex_);
        for (const auto& s : samples) push_locked(s);
    }
    pushed_.notify_all();
}

void AccelRing::note_loss() {
    std::lock_guard lock(mutex_);
    loss_pending_ = true;
}

void AccelRing::push_locked(const AccelSample& s) {
    if (size_ > 0) {
        const std::int64_t newest = at(size_ - 1).t_ns;
        if (s.t_ns <= newest) {
            ++counts_.non_monotonic_dropped;
            if (!warned_non_monotonic_) {  // once: the count carries the rest
                warned_non_monotonic_ = true;
                detail::log().warn(
                    "accelerometer sample at {} ns is not after the newest one ({} ns): dropped "
                    "(further ones are only counted)",
                    s.t_ns, newest);
            }
            return;
        }
        const std::int64_t dt = s.t_ns - newest;
        const bool jump =
            static_cast<double>(dt) > config_.gap_periods * static_cast<double>(period_ns_);
        if (loss_pending_ || jump) {
            AccelGap g;
            g.last_before_ns = newest;
            g.first_after_ns = s.t_ns;
            g.cause = loss_pending_ ? AccelGapCause::sequence_loss : AccelGapCause::time_jump;
            g.missing_samples = std::max<std::int64_t>(
                0, std::llround(static_cast<double>(dt) / static_cast<double>(period_ns_)) - 1);
            gaps_.push_back(g);
            ++counts_.gaps;
            counts_.missing_samples += g.missing_samples;
        }
    }
    loss_pending_ = false;
    if (!first_ever_ns_) first_ever_ns_ = s.t_ns;

    if (size_ == buf_.size()) {  // full: overwrite the oldest
        last_evicted_ns_ = buf_[head_].t_ns;
        buf_[head_] = s;
        head_ = (head_ + 1) % buf_.size();
        ++counts_.overwritten;
        // Gaps wholly before the held data are no longer of interest.
        const std::int64_t oldest = at(0).t_ns;
        while (!gaps_.empty() && gaps_.front().first_after_ns < oldest) gaps_.pop_front();
    } else {
        buf_[(head_ + size_) % buf_.size()] = s;
        ++size_;
    }
    ++counts_.stored;
}

std::size_t AccelRing::lower_bound_locked(std::int64_t t_ns) const {
    std::size_t lo = 0, hi = size_;
    while (lo < hi) {
        const std::size_t mid = lo + (hi - lo) / 2;
        if (at(mid).t_ns < t_ns)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

AccelWindow AccelRing::copy_range(std::int64_t t0_ns, std::int64_t t1_ns) const {
    AccelWindow w;
    w.t0_ns = t0_ns;
    w.t1_ns = t1_ns;
    std::lock_guard lock(mutex_);
    if (t1_ns > t0_ns) {
        const std::size_t i0 = lower_bound_locked(t0_ns);
        const std::size_t i1 = lower_bound_locked(t1_ns);
        w.samples.reserve(i1 - i0);
        for (std::size_t i = i0; i < i1; ++i) w.samples.push_back(at(i));
        for (const auto& g : gaps_) {
            if (g.last_before_ns < t1_ns && g.first_after_ns > t0_ns) {
                w.gaps.push_back(g);
                w.missing_samples += g.missing_samples;
            }
        }
    }
    w.start_overwritten = last_evicted_ns_ && *last_evicted_ns_ >= t0_ns;
    w.start_covered = first_ever_ns_ && *first_ever_ns_ <= t0_ns && !w.start_overwritten;
    w.end_reached = size_ > 0 && at(size_ - 1).t_ns >= t1_ns;
    return w;
}

AccelRingStats AccelRing::stats() const {
    std::lock_guard lock(mutex_);
    AccelRingStats s = counts_;
    s.capacity = buf_.size();
    s.size = size_;
    if (size_ > 0) {
        s.oldest_ns = at(0).t_ns;
        s.newest_ns = at(size_ - 1).t_ns;
    }
    return s;
}

bool AccelRing::wait_for(std::int64_t t_ns, std::chrono::milliseconds timeout) const {
    std::unique_lock lock(mutex_);
    return pushed_.wait_for(lock, timeout, [&] { return size_ > 0 && at(size_ - 1).t_ns >= t_ns; });
}

HistoryState history_before(const AccelRing& ring, std::int64_t now_ns, std::int64_t margin_ns,
                            std::int64_t in_flight_ns, std::int64_t silent_ns) {
    const std::optional<std::int64_t> newest = ring.stats().newest_ns;
    if (!newest || *newest < now_ns - silent_ns) return HistoryState::silent;
    const std::int64_t t = now_ns - in_flight_ns;
    return ring.copy_range(t - margin_ns, t).complete() ? HistoryState::complete
                                                        : HistoryState::arriving;
}

AccelWindow attach_face_window(const AccelRing& ring, core::FaceScan& face,
                               std::int64_t margin_ns) {
    AccelWindow w = ring.copy_range(face.profile_times_ns.front() - margin_ns,
                                    face.profile_times_ns.back() + margin_ns);
    face.accel_times_ns.clear();
    face.accel_mps2.clear();
    face.accel_times_ns.reserve(w.samples.size());
    face.accel_mps2.reserve(3 * w.samples.size());
    for (const auto& smp : w.samples) {
        face.accel_times_ns.push_back(smp.t_ns);
        face.accel_mps2.insert(face.accel_mps2.end(), {smp.x_mps2, smp.y_mps2, smp.z_mps2});
    }
    return w;
}

}  // namespace hotgauge::accel
