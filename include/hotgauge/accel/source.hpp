#pragma once
// Accelerometer sources: adapters that turn the outside world (UDP datagrams, a Linux IIO
// buffer, a recording on disk) into AccelRing samples (docs/accelerometer.md). One config
// struct for the module, one small interface, one factory.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::accel {

enum class AccelSourceKind { udp, iio, recording };

struct UdpReceiverConfig {
    // HOST:PORT to bind ("[::1]:PORT" for IPv6); port 0 = an ephemeral port, see port().
    std::string bind = "0.0.0.0:47355";
    // Accept only this sensor id; unset = latch on the first sensor heard.
    std::optional<std::uint16_t> sensor_id;
    int receive_buffer_bytes = 4 << 20;  // SO_RCVBUF request; the kernel may cap it
};

struct IioSourceConfig {
    std::filesystem::path device_dir;   // sysfs, e.g. /sys/bus/iio/devices/iio:device0
    std::filesystem::path buffer_path;  // e.g. /dev/iio:device0, or a regular file of records
    // Enable the channels and the buffer through sysfs at start, disable the buffer at stop.
    bool enable_buffer = true;
    int buffer_length = 4096;  // kernel buffer, in scans (sysfs buffer/length)
    // Without a timestamp channel: time of the first record; unset = CLOCK_REALTIME at start.
    std::optional<std::int64_t> start_time_ns;
};

struct RecordingReplayConfig {
    std::filesystem::path path;  // recording folder (docs/recording-format.md)
    std::string face;            // face whose accelerometer stream is replayed
    bool realtime = false;       // pace by the sample timestamps; false = as fast as possible
};

struct AccelSourceConfig {
    AccelSourceKind kind = AccelSourceKind::udp;
    UdpReceiverConfig udp;
    IioSourceConfig iio;
    RecordingReplayConfig recording;
};

enum class AccelSourceState {
    stopped,   // not started, or stopped
    running,   // the thread is delivering samples
    finished,  // a finite input is exhausted (recording replayed, end of a record file)
    failed,    // the source gave up; AccelSourceStatus::error says why
};

struct AccelSourceStatus {
    AccelSourceState state = AccelSourceState::stopped;
    std::string error;               // why it failed; empty otherwise
    std::uint64_t samples = 0;       // handed to the ring
    std::uint64_t loss_events = 0;   // losses the source detected (skipped sequence numbers)
    std::uint64_t rejected = 0;      // input discarded: malformed or reordered datagrams, ...
    std::vector<std::string> notes;  // how the data is interpreted, e.g. synthesised timestamps
};

// A running accelerometer feed. start() returns start-up failures (cannot bind, bad sysfs tree,
// unreadable recording) as an Error naming the address or file; once running, problems of the
// data are counted in status(), never thrown. stop() is idempotent and returns in bounded time;
// the destructor stops. The ring passed to the factory must outlive the source.
// Thread safety: start/stop from one controlling thread; status() from any thread.
class AccelSource {
  public:
    virtual ~AccelSource() = default;
    virtual core::Result<void> start() = 0;
    virtual void stop() = 0;
    virtual AccelSourceStatus status() const = 0;
};

const char* to_string(AccelSourceKind kind);
// "udp", "iio", "recording"; otherwise an Error naming the field `kind`.
core::Result<AccelSourceKind> parse_accel_source_kind(std::string_view text);

// Checks the fields the chosen kind uses; an Error names the field ("udp.bind: ...").
core::Result<void> validate(const AccelSourceConfig& config);

// A validated, not yet started source of the configured kind, feeding `ring`.
core::Result<std::unique_ptr<AccelSource>> make_accel_source(const AccelSourceConfig& config,
                                                             AccelRing& ring);

}  // namespace hotgauge::accel
