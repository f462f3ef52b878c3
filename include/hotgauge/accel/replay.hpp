#pragma once
// The `recording` accelerometer source: replays the accelerometer stream of one face of a
// recording (docs/recording-format.md) into the ring, as fast as possible or paced in real
// time by its timestamps. Sample times are those of the recording, unchanged.
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>
#include <vector>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::accel {

// Thread safety: start/stop from one thread; status from any.
class RecordingAccelSource final : public AccelSource {
  public:
    RecordingAccelSource(RecordingReplayConfig config, AccelRing& ring);
    ~RecordingAccelSource() override;
    RecordingAccelSource(const RecordingAccelSource&) = delete;
    RecordingAccelSource& operator=(const RecordingAccelSource&) = delete;

    // Reads the recording (io::read_recording); an Error names the file or the missing face.
    core::Result<void> start() override;
    void stop() override;
    AccelSourceStatus status() const override;

  private:
    void run();

    RecordingReplayConfig config_;
    AccelRing& ring_;
    std::vector<AccelSample> samples_;  // the face's stream, fixed while running
    std::thread thread_;

    mutable std::mutex mutex_;  // guards everything below
    std::condition_variable wake_;
    bool stop_ = false;
    AccelSourceStatus status_;
};

}  // namespace hotgauge::accel
