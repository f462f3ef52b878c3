#pragma once
// The `udp` accelerometer source: HGA1 sample datagrams (byte layout in docs/accelerometer.md),
// their codec, the receiver that feeds an AccelRing, and the sender tests and the virtual cell
// use.
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/core/result.hpp"

namespace hotgauge::accel {

inline constexpr std::array<char, 4> kDatagramMagic = {'H', 'G', 'A', '1'};
inline constexpr std::uint16_t kDatagramVersion = 1;
inline constexpr std::size_t kDatagramHeaderBytes = 28;
inline constexpr std::size_t kDatagramSampleBytes = 12;  // x, y, z float32
inline constexpr std::size_t kDatagramMaxSamples = 1024;
inline constexpr std::size_t kDatagramMaxBytes =
    kDatagramHeaderBytes + kDatagramMaxSamples * kDatagramSampleBytes;

// One datagram: n samples at t0_ns + i·period_ns, accelerometer axes, m/s².
struct AccelDatagram {
    std::uint16_t sensor_id = 0;
    std::uint32_t sequence = 0;  // per datagram, +1 each, wraps at 2^32
    std::int64_t t0_ns = 0;      // time of the first sample
    std::uint32_t period_ns = 0;
    std::vector<float> accel_mps2;  // n·3: x0 y0 z0 x1 ...

    std::size_t n_samples() const { return accel_mps2.size() / 3; }
};

// Why a datagram was rejected (the receiver counts each kind and logs its first occurrence).
enum class DatagramProblem : std::uint8_t {
    ok,
    too_short,      // fewer than kDatagramHeaderBytes
    oversized,      // more than kDatagramMaxBytes
    bad_magic,      // not "HGA1"
    bad_version,    // version ≠ kDatagramVersion
    no_samples,     // n = 0
    size_mismatch,  // size ≠ header + 12·n
    zero_period,    // period_ns = 0
};
inline constexpr std::size_t kDatagramProblemKinds = 8;
const char* to_string(DatagramProblem problem);

// Little-endian encoding; asserts accel_mps2.size() is a multiple of 3 (n may exceed the
// receiver's limits: tests build bad datagrams with it).
std::vector<std::uint8_t> encode_datagram(const AccelDatagram& datagram);
// Validates and decodes; `out` is filled only when the result is ok.
DatagramProblem decode_datagram(std::span<const std::uint8_t> bytes, AccelDatagram& out);

struct UdpReceiverStats {
    std::uint64_t datagrams = 0;       // received, of any kind
    std::uint64_t accepted = 0;        // valid, in order, handed to the ring
    std::uint64_t samples = 0;         // samples handed to the ring
    std::uint64_t lost_datagrams = 0;  // sequence numbers skipped
    std::uint64_t loss_events = 0;     // times the sequence jumped forward
    std::uint64_t reordered = 0;       // behind the expected sequence number: dropped
    std::uint64_t resyncs = 0;         // sender restarts (sequence went back, time went on)
    std::uint64_t foreign_sensor = 0;  // other sensor ids: dropped
    std::uint64_t malformed = 0;       // sum of by_problem
    std::array<std::uint64_t, kDatagramProblemKinds> by_problem{};  // indexed by DatagramProblem
};

// Receives HGA1 datagrams on a UDP socket and pushes their samples into the ring.
// Every datagram is validated; malformed ones are counted per kind (the first of each kind is
// logged), never trusted. Sequence numbers detect loss (AccelRing::note_loss, so the ring
// records a gap) and reordering (late datagrams dropped: the ring only takes increasing times).
// A sequence number going back while t0 moves forward is a restarted sender: resynchronised.
// Thread safety: start/stop from one thread; stats/status/port/wait_processed from any.
class UdpAccelReceiver final : public AccelSource {
  public:
    UdpAccelReceiver(UdpReceiverConfig config, AccelRing& ring);
    ~UdpAccelReceiver() override;
    UdpAccelReceiver(const UdpAccelReceiver&) = delete;
    UdpAccelReceiver& operator=(const UdpAccelReceiver&) = delete;

    // Binds and starts the receiving thread; an Error names the address.
    core::Result<void> start() override;
    void stop() override;
    AccelSourceStatus status() const override;

    std::uint16_t port() const { return port_; }  // the bound port (valid after start)
    UdpReceiverStats stats() const;
    // Waits until `datagrams` datagrams (of any kind) have been processed or the timeout passes.
    bool wait_processed(std::uint64_t datagrams, std::chrono::milliseconds timeout) const;

  private:
    void run();
    void handle(std::span<const std::uint8_t> bytes, std::size_t true_size);
    void reject(DatagramProblem problem, std::size_t size);

    UdpReceiverConfig config_;
    AccelRing& ring_;
    int fd_ = -1;
    int wake_fd_ = -1;  // eventfd: stop() wakes the thread's poll
    std::uint16_t port_ = 0;
    std::string where_;  // "udp receiver HOST:PORT" with the bound port, for messages
    std::thread thread_;
    std::atomic<bool> stop_{false};

    mutable std::mutex mutex_;  // guards everything below
    mutable std::condition_variable processed_;
    UdpReceiverStats stats_;
    AccelSourceState state_ = AccelSourceState::stopped;
    std::string error_;

    // Receiving thread only.
    AccelDatagram datagram_;
    std::vector<AccelSample> samples_;
    bool have_sequence_ = false;
    std::uint32_t expected_sequence_ = 0;
    std::optional<std::uint16_t> sensor_id_;
    std::int64_t last_t_ns_ = 0;         // last sample time handed to the ring
    std::uint32_t logged_problems_ = 0;  // bit per DatagramProblem already logged
    bool logged_reorder_ = false, logged_foreign_ = false, logged_period_ = false;
};

// Sends HGA1 datagrams to HOST:PORT with consecutive sequence numbers.
// Not thread-safe: one thread sends.
class UdpAccelSender {
  public:
    static core::Result<UdpAccelSender> open(const std::string& host_port,
                                             std::uint16_t sensor_id = 0);
    UdpAccelSender(UdpAccelSender&& other) noexcept;
    UdpAccelSender& operator=(UdpAccelSender&& other) noexcept;
    UdpAccelSender(const UdpAccelSender&) = delete;
    UdpAccelSender& operator=(const UdpAccelSender&) = delete;
    ~UdpAccelSender();

    // One datagram of accel_mps2.size()/3 samples (1..kDatagramMaxSamples) at t0_ns + i·period.
    core::Result<void> send(std::int64_t t0_ns, std::uint32_t period_ns,
                            std::span<const float> accel_mps2);
    // Raw bytes, as they are (tests send malformed datagrams with it).
    core::Result<void> send_bytes(std::span<const std::uint8_t> bytes);
    // Skips sequence numbers, as if `n` datagrams had been lost on the way.
    void skip(std::uint32_t n) { sequence_ += n; }
    std::uint32_t next_sequence() const { return sequence_; }
    void set_next_sequence(std::uint32_t s) { sequence_ = s; }

  private:
    UdpAccelSender(int fd, std::uint16_t sensor_id) : fd_(fd), sensor_id_(sensor_id) {}
    int fd_ = -1;
    std::uint16_t sensor_id_ = 0;
    std::uint32_t sequence_ = 0;
};

// "HOST:PORT" or "[V6]:PORT" split; an Error names `field`.
struct HostPort {
    std::string host;
    std::uint16_t port = 0;
};
core::Result<HostPort> parse_host_port(const std::string& text, const std::string& field);

}  // namespace hotgauge::accel
