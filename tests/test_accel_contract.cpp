// The one contract of the three accelerometer sources (docs/accelerometer.md, source.hpp), the
// same assertions over each: UDP datagrams on a loopback ephemeral port, a Linux IIO buffer (a
// fake sysfs tree and a FIFO standing in for /dev/iio:deviceN) and a recording replayed. States:
// stopped until started, running while its input is open, finished when a finite input ends;
// stop() bounded and idempotent, and the destructor stops; what lands in the ring: the stream's
// times and values to the bit, its one hole as one gap. No sleeps: every wait is bounded and on a
// condition (the ring's wait_for, or a polled state with a deadline).
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <ostream>
#include <string>
#include <thread>
#include <vector>

#include "accel_test_helpers.hpp"
#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/source.hpp"
#include "hotgauge/accel/udp.hpp"
#include "hotgauge/io/recording_io.hpp"
#include "temp_dir.hpp"

namespace fs = std::filesystem;
using namespace hotgauge::accel;
using namespace std::chrono_literals;

namespace {

using hotgauge::test::TempDir;

// The stream every source carries: 1 kHz from kT0, samples kBefore .. kBefore + kLost − 1
// missing (a hole of kLost samples, round(21 ms / 1 ms) − 1 = 20 by the ring's estimate).
// Values are multiples of 0.5 m/s² from small integers, so that an IIO record (raw integer ×
// scale 0.5) carries them exactly, as a datagram and a recording do.
constexpr std::int64_t kT0 = 1'700'000'000'000'000'000;
constexpr std::int64_t kPeriodNs = 1'000'000;
constexpr int kBefore = 60, kLost = 20, kAfter = 60;
constexpr std::size_t kStreamSamples = kBefore + kAfter;
constexpr int kSamplesPerDatagram = 10;
constexpr auto kStopBound = 1s;  // each thread's poll is woken at once; its timeout is 500 ms

struct RawSample {  // the stream's sample j, as integers (IIO raw counts)
    std::int64_t t_ns;
    std::int32_t x, y, z;
};

constexpr RawSample raw_sample(int j) { return {kT0 + j * kPeriodNs, j, -(j + 2), 19 + j % 7}; }

std::vector<int> stream_indices() {
    std::vector<int> j;
    for (int k = 0; k < kBefore; ++k) j.push_back(k);
    for (int k = kBefore + kLost; k < kBefore + kLost + kAfter; ++k) j.push_back(k);
    return j;
}

AccelSample sample_of(const RawSample& r) {
    return {r.t_ns, 0.5f * static_cast<float>(r.x), 0.5f * static_cast<float>(r.y),
            0.5f * static_cast<float>(r.z)};
}

std::vector<AccelSample> stream() {
    std::vector<AccelSample> s;
    for (int j : stream_indices()) s.push_back(sample_of(raw_sample(j)));
    return s;
}

constexpr std::int64_t kLastNs = raw_sample(kBefore + kLost + kAfter - 1).t_ns;
constexpr std::int64_t kLastBeforeHoleNs = raw_sample(kBefore - 1).t_ns;
constexpr std::int64_t kFirstAfterHoleNs = raw_sample(kBefore + kLost).t_ns;

AccelRingConfig ring_config() {
    AccelRingConfig c;
    c.capacity_s = 10.0;
    c.sample_rate_hz = 1000.0;
    return c;
}

using hotgauge::test::eventually;
using hotgauge::test::expect_samples_eq;
using hotgauge::test::read_line;
using hotgauge::test::write_text;

// ---------------------------------------------------------------------------------------------
// One input per source kind: its configuration, how the stream reaches it, how it ends.

class Feed {
  public:
    virtual ~Feed() = default;
    // The source's configuration. `live`: the input stays open after the stream (a socket, a
    // FIFO whose writer is still there, a paced replay whose next sample is due in an hour);
    // otherwise a finite input ends after it.
    virtual AccelSourceConfig config(bool live) = 0;
    // After start(): sends the stream (a recording has it in its file already).
    virtual void deliver(AccelSource& source) = 0;
    // The input ends: the FIFO's writer closes. Datagrams have no end; a recording's is in it.
    virtual void end_input() {}
    // After stop: what the source still holds of its input ("" = nothing).
    virtual std::string still_held() const { return ""; }
};

// HGA1 datagrams of 10 samples from a sender on loopback; the hole's two datagrams are lost on
// the way (skipped sequence numbers), so the ring's gap is a sequence_loss.
class UdpFeed final : public Feed {
  public:
    explicit UdpFeed(const fs::path&) {}
    AccelSourceConfig config(bool) override {
        AccelSourceConfig c;
        c.kind = AccelSourceKind::udp;
        c.udp.bind = "127.0.0.1:0";
        return c;
    }
    void deliver(AccelSource& source) override {
        port_ = dynamic_cast<UdpAccelReceiver&>(source).port();
        auto sender = UdpAccelSender::open("127.0.0.1:" + std::to_string(port_), 5);
        ASSERT_TRUE(sender.ok()) << sender.error().message;
        const auto indices = stream_indices();
        for (std::size_t i = 0; i < indices.size(); i += kSamplesPerDatagram) {
            if (indices[i] == kBefore + kLost) sender->skip(kLost / kSamplesPerDatagram);
            std::vector<float> xyz;
            for (std::size_t k = i; k < i + kSamplesPerDatagram; ++k) {
                const auto s = sample_of(raw_sample(indices[k]));
                xyz.insert(xyz.end(), {s.x_mps2, s.y_mps2, s.z_mps2});
            }
            ASSERT_TRUE(sender->send(raw_sample(indices[i]).t_ns,
                                     static_cast<std::uint32_t>(kPeriodNs), xyz));
        }
    }
    // The socket is closed: its port binds again.
    std::string still_held() const override {
        const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        if (fd < 0) return std::string("socket: ") + std::strerror(errno);
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(port_);
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        const bool bound = ::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) == 0;
        const int err = errno;
        ::close(fd);
        return bound ? "" : "UDP port " + std::to_string(port_) + ": " + std::strerror(err);
    }

  private:
    std::uint16_t port_ = 0;
};

// A fake sysfs tree (x, y, z le:s32/32>>0 at 0, 4, 8, the timestamp le:s64/64>>0 at 16:
// 24-byte records, scale 0.5) and a FIFO for the buffer device: records written by the test,
// read by the source while the writer holds it open; closing the writer is the end of the input.
// Times come from the timestamp channel, so the hole is a time_jump.
class IioFeed final : public Feed {
  public:
    explicit IioFeed(const fs::path& dir) : dev_(dir / "iio:device0"), fifo_(dir / "iio_device0") {
        const char* axes[] = {"in_accel_x", "in_accel_y", "in_accel_z"};
        for (int k = 0; k < 3; ++k) {
            write_text(dev_ / "scan_elements" / (std::string(axes[k]) + "_en"), "0");
            write_text(dev_ / "scan_elements" / (std::string(axes[k]) + "_index"),
                       std::to_string(k));
            write_text(dev_ / "scan_elements" / (std::string(axes[k]) + "_type"), "le:s32/32>>0");
        }
        write_text(dev_ / "scan_elements/in_timestamp_en", "0");
        write_text(dev_ / "scan_elements/in_timestamp_index", "3");
        write_text(dev_ / "scan_elements/in_timestamp_type", "le:s64/64>>0");
        write_text(dev_ / "in_accel_scale", "0.5");
        write_text(dev_ / "sampling_frequency", "1000");
        write_text(dev_ / "buffer/enable", "0");
        write_text(dev_ / "buffer/length", "0");
        EXPECT_EQ(::mkfifo(fifo_.c_str(), 0600), 0) << fifo_ << ": " << std::strerror(errno);
    }
    ~IioFeed() override {
        if (writer_ >= 0) ::close(writer_);
    }
    AccelSourceConfig config(bool) override {
        AccelSourceConfig c;
        c.kind = AccelSourceKind::iio;
        c.iio.device_dir = dev_;
        c.iio.buffer_path = fifo_;
        c.iio.enable_buffer = true;  // start() enables the channels and the buffer, stop() not
        c.iio.buffer_length = 64;
        return c;
    }
    void deliver(AccelSource&) override {
        // The source holds the read end: a non-blocking open for writing succeeds at once.
        writer_ = ::open(fifo_.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
        ASSERT_GE(writer_, 0) << fifo_ << ": " << std::strerror(errno);
        std::vector<std::uint8_t> bytes;
        for (int j : stream_indices()) {
            const RawSample r = raw_sample(j);
            std::uint8_t record[24];
            std::memset(record, 0xEE, sizeof record);  // padding 12..15
            put_le(record + 0, static_cast<std::uint32_t>(r.x), 4);
            put_le(record + 4, static_cast<std::uint32_t>(r.y), 4);
            put_le(record + 8, static_cast<std::uint32_t>(r.z), 4);
            put_le(record + 16, static_cast<std::uint64_t>(r.t_ns), 8);
            bytes.insert(bytes.end(), record, record + sizeof record);
        }
        std::size_t written = 0;  // 2880 bytes: well within the pipe's buffer
        while (written < bytes.size()) {
            const ssize_t n = ::write(writer_, bytes.data() + written, bytes.size() - written);
            ASSERT_GT(n, 0) << fifo_ << ": " << std::strerror(errno);
            written += static_cast<std::size_t>(n);
        }
    }
    void end_input() override {
        ASSERT_GE(writer_, 0);
        ::close(writer_);
        writer_ = -1;
    }
    // stop() disables the buffer start() enabled.
    std::string still_held() const override {
        const std::string enable = read_line(dev_ / "buffer/enable");
        return enable == "0" ? "" : "buffer/enable is '" + enable + "'";
    }

  private:
    static void put_le(std::uint8_t* out, std::uint64_t v, int bytes) {
        for (int i = 0; i < bytes; ++i) out[i] = static_cast<std::uint8_t>(v >> (8 * i));
    }
    fs::path dev_, fifo_;
    int writer_ = -1;
};

// A recording with the stream on face "top" (and other values on "side1", which must not
// play). Live: paced in real time, with one more sample an hour after the stream, so that the
// replay is running, waiting for it, when the test looks; it never lands. Otherwise as fast as
// possible, to its end. Times are the recording's own, so the hole is a time_jump.
class RecordingFeed final : public Feed {
  public:
    explicit RecordingFeed(const fs::path& dir) : dir_(dir) {}
    AccelSourceConfig config(bool live) override {
        hotgauge::core::Recording rec;
        rec.part_id = "P-1";
        rec.recipe = "hub-a";
        rec.captured_at = "2024-06-11T08:00:00Z";
        for (const char* name : {"top", "side1"}) {
            hotgauge::core::FaceScan f;
            f.name = name;
            const float sign = f.name == "top" ? 1.0f : -1.0f;
            for (const auto& s : stream()) {
                f.accel_times_ns.push_back(s.t_ns);
                f.accel_mps2.insert(f.accel_mps2.end(),
                                    {sign * s.x_mps2, sign * s.y_mps2, sign * s.z_mps2});
            }
            if (live) {
                f.accel_times_ns.push_back(kLastNs + 3600'000'000'000);
                f.accel_mps2.insert(f.accel_mps2.end(), {0.0f, 0.0f, 9.5f});
            }
            rec.faces.push_back(std::move(f));
        }
        const fs::path path = dir_ / (live ? "live" : "finite");
        auto written = hotgauge::io::write_recording(rec, path);
        EXPECT_TRUE(written.ok()) << written.error().message;
        AccelSourceConfig c;
        c.kind = AccelSourceKind::recording;
        c.recording = {path, "top", live};
        return c;
    }
    void deliver(AccelSource&) override {}

  private:
    fs::path dir_;
};

struct SourceKind {
    const char* name;
    std::function<std::unique_ptr<Feed>(const fs::path&)> feed;
    AccelGapCause hole_cause;   // how the ring records the hole
    std::uint64_t loss_events;  // losses the source itself detects in the stream
    bool finite;                // an input that ends (docs: state finished)
};

// gtest prints a failing case's parameter by its name.
void PrintTo(const SourceKind& kind, std::ostream* os) { *os << kind.name; }

template <typename F>
std::function<std::unique_ptr<Feed>(const fs::path&)> make_feed() {
    return [](const fs::path& dir) { return std::make_unique<F>(dir); };
}

const SourceKind kKinds[] = {
    {"udp", make_feed<UdpFeed>(), AccelGapCause::sequence_loss, 1, false},
    {"iio", make_feed<IioFeed>(), AccelGapCause::time_jump, 0, true},
    {"recording", make_feed<RecordingFeed>(), AccelGapCause::time_jump, 0, true},
};

class AccelSourceContract : public ::testing::TestWithParam<SourceKind> {
  protected:
    // A source from the factory, as the daemon makes it, fed by this kind's input.
    std::unique_ptr<AccelSource> make_source(bool live) {
        auto source = make_accel_source(feed->config(live), ring);
        EXPECT_TRUE(source.ok()) << source.error().message;
        return source ? std::move(*source) : nullptr;
    }
    // Starts the source, sends the stream, and waits (bounded) until all of it is in the ring
    // and counted in status().
    void start_and_deliver(AccelSource& source) {
        auto started = source.start();
        ASSERT_TRUE(started.ok()) << started.error().message;
        feed->deliver(source);
        ASSERT_TRUE(ring.wait_for(kLastNs, 5s)) << "the stream's last sample never landed";
        ASSERT_TRUE(eventually([&] { return source.status().samples == kStreamSamples; }))
            << source.status().samples << " samples counted";
    }
    // stop() with the time it took.
    static std::chrono::steady_clock::duration timed_stop(AccelSource& source) {
        const auto t = std::chrono::steady_clock::now();
        source.stop();
        return std::chrono::steady_clock::now() - t;
    }

    TempDir tmp;
    AccelRing ring{ring_config()};  // outlives every source of the test
    std::unique_ptr<Feed> feed = GetParam().feed(tmp.path);
};

}  // namespace

TEST_P(AccelSourceContract, StoppedUntilStartedRunningWhileOpenStopBoundedAndIdempotent) {
    auto source = make_source(true);
    ASSERT_NE(source, nullptr);
    EXPECT_EQ(source->status().state, AccelSourceState::stopped);
    EXPECT_EQ(source->status().samples, 0u);
    EXPECT_LT(timed_stop(*source), kStopBound);  // nothing to stop yet
    EXPECT_EQ(source->status().state, AccelSourceState::stopped);

    auto started = source->start();
    ASSERT_TRUE(started.ok()) << started.error().message;
    EXPECT_EQ(source->status().state, AccelSourceState::running);
    feed->deliver(*source);
    ASSERT_TRUE(ring.wait_for(kLastNs, 5s));
    ASSERT_TRUE(eventually([&] { return source->status().samples == kStreamSamples; }));
    // The input is still open (socket, FIFO writer, next paced sample an hour away): waiting for
    // more is running, neither finished nor failed.
    EXPECT_EQ(source->status().state, AccelSourceState::running);
    EXPECT_EQ(source->status().error, "");

    // Stopped while blocked on its input: bounded, the input given back.
    EXPECT_LT(timed_stop(*source), kStopBound);
    EXPECT_EQ(source->status().state, AccelSourceState::stopped);
    EXPECT_EQ(feed->still_held(), "");
    // Again: the same, at once.
    EXPECT_LT(timed_stop(*source), kStopBound);
    EXPECT_EQ(source->status().state, AccelSourceState::stopped);
    EXPECT_EQ(source->status().samples, kStreamSamples);
    EXPECT_EQ(ring.stats().stored, kStreamSamples);  // nothing more (the paced hour) landed
}

TEST_P(AccelSourceContract, RingHoldsTheStreamToTheBitAndItsHoleAsOneGap) {
    auto source = make_source(true);
    ASSERT_NE(source, nullptr);
    start_and_deliver(*source);

    const auto w = ring.copy_range(kT0, kLastNs + 1);
    expect_samples_eq(w.samples, stream());
    ASSERT_EQ(w.gaps.size(), 1u);
    EXPECT_EQ(w.gaps[0].last_before_ns, kLastBeforeHoleNs);
    EXPECT_EQ(w.gaps[0].first_after_ns, kFirstAfterHoleNs);
    EXPECT_EQ(w.gaps[0].cause, GetParam().hole_cause);
    EXPECT_EQ(w.gaps[0].missing_samples, kLost);
    EXPECT_EQ(w.missing_samples, kLost);
    EXPECT_TRUE(w.start_covered);
    EXPECT_FALSE(w.end_reached);  // nothing after the last sample yet
    // Before the hole and after it the record is whole; a window with the hole is not.
    EXPECT_TRUE(ring.copy_range(kT0, kLastBeforeHoleNs).complete());
    EXPECT_TRUE(ring.copy_range(kFirstAfterHoleNs + 1, kLastNs).complete());
    EXPECT_FALSE(ring.copy_range(kT0, kLastNs).complete());

    const auto stats = ring.stats();
    EXPECT_EQ(stats.stored, kStreamSamples);
    EXPECT_EQ(stats.non_monotonic_dropped, 0u);
    EXPECT_EQ(stats.gaps, 1u);
    const auto status = source->status();
    EXPECT_EQ(status.samples, kStreamSamples);
    EXPECT_EQ(status.loss_events, GetParam().loss_events);
    EXPECT_EQ(status.rejected, 0u);
    EXPECT_LT(timed_stop(*source), kStopBound);
}

TEST_P(AccelSourceContract, AFiniteInputFinishesAndStopKeepsIt) {
    auto source = make_source(false);
    ASSERT_NE(source, nullptr);
    start_and_deliver(*source);
    feed->end_input();
    if (!GetParam().finite) {
        // Datagrams have no end: the receiver keeps listening.
        EXPECT_EQ(source->status().state, AccelSourceState::running);
        EXPECT_LT(timed_stop(*source), kStopBound);
        EXPECT_EQ(source->status().state, AccelSourceState::stopped);
        return;
    }
    ASSERT_TRUE(eventually([&] { return source->status().state != AccelSourceState::running; }));
    EXPECT_EQ(source->status().state, AccelSourceState::finished);
    EXPECT_EQ(source->status().error, "");
    EXPECT_EQ(source->status().rejected, 0u);
    // stop() after the end: bounded, idempotent, and it does not rewrite how the source ended.
    EXPECT_LT(timed_stop(*source), kStopBound);
    EXPECT_EQ(source->status().state, AccelSourceState::finished);
    EXPECT_EQ(feed->still_held(), "");
    EXPECT_LT(timed_stop(*source), kStopBound);
    EXPECT_EQ(source->status().state, AccelSourceState::finished);
    expect_samples_eq(ring.copy_range(kT0, kLastNs + 1).samples, stream());
}

TEST_P(AccelSourceContract, TheDestructorStopsInBoundedTime) {
    auto source = make_source(true);
    ASSERT_NE(source, nullptr);
    start_and_deliver(*source);
    const auto t = std::chrono::steady_clock::now();
    source.reset();
    EXPECT_LT(std::chrono::steady_clock::now() - t, kStopBound);
    EXPECT_EQ(feed->still_held(), "");
    EXPECT_EQ(ring.stats().stored, kStreamSamples);
}

INSTANTIATE_TEST_SUITE_P(EverySource, AccelSourceContract, ::testing::ValuesIn(kKinds),
                         [](const ::testing::TestParamInfo<SourceKind>& p) {
                             return std::string(p.param.name);
                         });
