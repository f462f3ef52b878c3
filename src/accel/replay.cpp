// Replay of a recording's accelerometer stream (docs/accelerometer.md, "recording").
#include "hotgauge/accel/replay.hpp"

#include <algorithm>
#include <chrono>
#include <span>
#include <string>
#include <utility>

#include "hotgauge/io/recording_io.hpp"
#include "log.hpp"

namespace hotgauge::accel {

RecordingAccelSource::RecordingAccelSource(RecordingReplayConfig config, AccelRing& ring)
    : config_(std::move(config)), ring_(ring) {}

RecordingAccelSource::~RecordingAccelSource() { stop(); }

core::Result<void> RecordingAccelSource::start() {
    if (thread_.joinable()) return core::make_error("recording source: already started");
    auto rec = io::read_recording(config_.path);
    if (!rec) return rec.error();
    const core::FaceScan* face = rec->face(config_.face);
    if (!face) {
        std::string faces;
        for (const auto& f : rec->faces) faces += (faces.empty() ? "" : ", ") + f.name;
        return core::make_error("recording.face: no face '" + config_.face + "' in " +
                                (config_.path / "part.yaml").string() + " (faces: " + faces + ")");
    }
    const std::size_t k = face->accel_times_ns.size();
    samples_.resize(k);
    for (std::size_t j = 0; j < k; ++j)
        samples_[j] = {face->accel_times_ns[j], face->accel_mps2[3 * j],
                       face->accel_mps2[3 * j + 1], face->accel_mps2[3 * j + 2]};

    AccelSourceStatus st;
    st.state = AccelSourceState::running;
    st.notes.push_back("replaying " + std::to_string(k) + " samples of face '" + config_.face +
                       "' of " + config_.path.string() +
                       (config_.realtime ? ", paced in real time" : ", as fast as possible"));
    for (const auto& w : rec->warnings) st.notes.push_back(w);
    detail::log().info("{}", st.notes.front());
    {
        std::lock_guard lock(mutex_);
        stop_ = false;
        status_ = std::move(st);
    }
    thread_ = std::thread([this] { run(); });
    return {};
}

void RecordingAccelSource::stop() {
    if (thread_.joinable()) {
        {
            std::lock_guard lock(mutex_);
            stop_ = true;
        }
        wake_.notify_all();
        thread_.join();
    }
    std::lock_guard lock(mutex_);
    if (status_.state == AccelSourceState::running) status_.state = AccelSourceState::stopped;
}

void RecordingAccelSource::run() {
    using clock = std::chrono::steady_clock;
    constexpr std::size_t kChunk = 4096;  // samples per push when not paced
    const auto start = clock::now();
    const std::int64_t t_first = samples_.empty() ? 0 : samples_.front().t_ns;
    std::size_t next = 0;
    while (next < samples_.size()) {
        std::size_t end = std::min(samples_.size(), next + kChunk);
        if (config_.realtime) {
            // Push what is due; then sleep until the next sample is, or stop() wakes us.
            const std::int64_t elapsed_ns =
                std::chrono::duration_cast<std::chrono::nanoseconds>(clock::now() - start).count();
            end = next;
            while (end < samples_.size() && samples_[end].t_ns - t_first <= elapsed_ns) ++end;
            if (end == next) {
                const auto due = start + std::chrono::nanoseconds(samples_[next].t_ns - t_first);
                std::unique_lock lock(mutex_);
                if (wake_.wait_until(lock, due, [&] { return stop_; })) break;
                continue;
            }
        }
        ring_.push(std::span<const AccelSample>(samples_.data() + next, end - next));
        std::lock_guard lock(mutex_);
        status_.samples += end - next;
        next = end;
        if (stop_) break;
    }
    std::lock_guard lock(mutex_);
    if (next == samples_.size()) status_.state = AccelSourceState::finished;
}

AccelSourceStatus RecordingAccelSource::status() const {
    std::lock_guard lock(mutex_);
    return status_;
}

}  // namespace hotgauge::accel
