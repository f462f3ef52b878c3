// The virtual cell's parts against independent checks: rendered stripes against the extraction
// with known centres, peak rows against their decoder, and the GigE Vision device against
// Aravis (through acquire::Camera and acquire::CameraSession) on 127.0.0.4, in this process.
// The conveyor's pyrometer runs over a socat virtual serial pair.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <modbus.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <random>
#include <thread>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/accel/udp.hpp"
#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/session.hpp"
#include "hotgauge/io/recipe.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/sim/scene.hpp"
#include "hotgauge/vcell/gv_device.hpp"
#include "hotgauge/vcell/render.hpp"
#include "hotgauge/vcell/replay.hpp"
#include "hotgauge/vcell/virtual_cell.hpp"
#include "serial_pair.hpp"
#include "temp_dir.hpp"

namespace hotgauge {
namespace {

constexpr const char* kAddress = "127.0.0.4";  // this test's own GigE Vision address

sim::SensorConfig sensor() { return sim::SensorConfig{}; }

// A profile whose ray i images at row rows[i] (column i), facing the sensor.
std::vector<sim::RayReturn> profile_at_rows(const acquire::Triangulation& tri,
                                            const std::vector<double>& rows) {
    std::vector<sim::RayReturn> out(rows.size());
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const auto p = tri.to_camera(static_cast<double>(i), rows[i]);
        out[i] = {static_cast<float>(p.x_mm), static_cast<float>(p.z_mm), 1.0f, false};
    }
    return out;
}

struct StripeError {
    double rms_px = 0;
    int n = 0;
};

StripeError render_and_extract(int bytes_per_pixel, double temperature_c) {
    const auto tri = vcell::sensor_triangulation(sensor());
    EXPECT_TRUE(tri.ok());
    const int width = 2048, height = 1088;
    std::mt19937_64 gen(11);
    std::uniform_real_distribution<double> row(100.0, 990.0);
    std::vector<double> rows(width);
    for (auto& r : rows) r = row(gen);
    const auto returns = profile_at_rows(*tri, rows);
    // Rows come back through the float32 (x, z) of a RayReturn: the reference is that row.
    std::vector<double> truth(width);
    for (int i = 0; i < width; ++i) truth[i] = tri->to_image(returns[i].x_mm, returns[i].z_mm).v_px;

    vcell::StripeLook look;
    look.reflection_fraction = 0;  // here: accuracy only
    look.full_scale = bytes_per_pixel == 1 ? 255 : 4095;
    sim::RandomStream rng(5);
    std::vector<std::uint8_t> image(static_cast<std::size_t>(width * height * bytes_per_pixel));
    vcell::render_stripe(returns, *tri, look, 100.0, look.glow * vcell::glow_scale(temperature_c),
                         width, height, 0, 0, bytes_per_pixel, rng, image);
    acquire::StripeConfig config;
    config.max_value = look.full_scale;
    config.min_peak = bytes_per_pixel == 1 ? 20 : 40;
    std::vector<acquire::StripePoint> points;
    if (bytes_per_pixel == 1) {
        points = acquire::extract_stripe(image.data(), width, height, width, config);
    } else {
        std::vector<std::uint16_t> words(image.size() / 2);
        std::memcpy(words.data(), image.data(), image.size());
        points = acquire::extract_stripe(words.data(), width, height, width, config);
    }
    StripeError e;
    double sum2 = 0;
    for (int i = 0; i < width; ++i) {
        if (points[i].status != acquire::StripeStatus::kOk) continue;
        const double d = points[i].row - truth[i];
        sum2 += d * d;
        ++e.n;
    }
    e.rms_px = std::sqrt(sum2 / std::max(1, e.n));
    return e;
}

TEST(RenderStripe, ExtractionWithKnownCentresMono16) {
    // Good contrast: stripe peak 0.6 of full scale over the glow of a part at 1 000 °C, speckle,
    // shot and read noise. Issue 6: RMS ≤ 0.05 px.
    const auto e = render_and_extract(2, 1000.0);
    std::printf("Mono16, 1 000 °C: %d columns, RMS %.4f px\n", e.n, e.rms_px);
    EXPECT_GT(e.n, 2000);
    EXPECT_LE(e.rms_px, 0.05);
}

TEST(RenderStripe, ExtractionWithKnownCentresMono8) {
    const auto e = render_and_extract(1, 1000.0);
    std::printf("Mono8, 1 000 °C: %d columns, RMS %.4f px\n", e.n, e.rms_px);
    EXPECT_GT(e.n, 2000);
    EXPECT_LE(e.rms_px, 0.08);  // 8-bit quantisation of a 1.2 px stripe
}

TEST(RenderStripe, GlowGrowsWithTemperature) {
    EXPECT_EQ(vcell::glow_scale(20.0), 0.0);
    EXPECT_NEAR(vcell::glow_scale(1000.0), 1.0, 1e-12);
    EXPECT_GT(vcell::glow_scale(1100.0), 3.0);  // Planck at 405 nm: steep
    EXPECT_LT(vcell::glow_scale(900.0), 0.3);
}

TEST(RenderPeaks, DecodeToTheRenderedRows) {
    const auto tri = vcell::sensor_triangulation(sensor());
    ASSERT_TRUE(tri.ok());
    std::vector<double> rows(2048);
    for (std::size_t i = 0; i < rows.size(); ++i) rows[i] = 40.0 + 0.37 * static_cast<double>(i);
    auto returns = profile_at_rows(*tri, rows);
    returns[7].x_mm = returns[7].z_mm = std::numeric_limits<float>::quiet_NaN();  // no return
    acquire::PeakFormat format;
    format.intensity = true;
    std::vector<std::uint16_t> frame(2048 * 2);
    vcell::render_peaks(returns, *tri, format, 2048, 0, 32, frame.data());
    const auto points = acquire::decode_peaks(frame.data(), 2048, format);
    int ok = 0;
    for (int i = 0; i < 2048; ++i) {
        const double v = tri->to_image(returns[i].x_mm, returns[i].z_mm).v_px;
        if (i == 7) {
            EXPECT_EQ(points[i].status, acquire::StripeStatus::kNoReturn);
            continue;
        }
        if (v - 32 >= 1024.0) {  // past 6 fractional bits' reach: outside the window
            EXPECT_EQ(points[i].status, acquire::StripeStatus::kNoReturn) << i;
            continue;
        }
        ASSERT_EQ(points[i].status, acquire::StripeStatus::kOk) << i;
        EXPECT_NEAR(points[i].row + 32, v, 0.5 / 64 + 1e-9) << i;
        EXPECT_NEAR(points[i].quality, 1.0f, 1e-3);
        ++ok;
    }
    EXPECT_GT(ok, 1500);
}

// Replay (docs/virtual-cell.md "Replay"): peak rows → the receiver's profile → encode_profile
// gives the same rows back; its decoding (decode_peaks, triangulate with the region's offsets, as
// acquire::ScanBuilder does) is the recorded profile bit for bit.
TEST(ReplayEncoding, PeakRowsComeBackBitForBit) {
    const auto tri = vcell::sensor_triangulation(sensor());
    ASSERT_TRUE(tri.ok());
    vcell::PeakEncoding e;
    e.format.intensity = true;
    e.offset_x_px = 16;
    e.offset_y_px = 40;
    const int w = 2000;
    std::mt19937_64 rng(7);
    std::uniform_int_distribution<int> word(1, (1047 - 40) * 64);
    std::vector<std::uint16_t> rows(2 * w);
    for (int i = 0; i < w; ++i) rows[i] = i % 50 == 3 ? 0 : static_cast<std::uint16_t>(word(rng));
    const auto points = acquire::decode_peaks(rows.data(), w, e.format);
    std::vector<float> profile;
    acquire::triangulate(*tri, points, profile, e.offset_x_px, e.offset_y_px);
    std::vector<std::uint16_t> again(2 * w, 0xffff);
    vcell::EncodeStats st;
    vcell::encode_profile(profile, *tri, e, again.data(), st);
    EXPECT_EQ(st.exact, w - w / 50);
    EXPECT_EQ(st.no_return, w / 50);
    EXPECT_EQ(st.inexact, 0);
    for (int i = 0; i < w; ++i) {
        ASSERT_EQ(again[i], rows[i]) << i;
        EXPECT_EQ(again[w + i], rows[i] ? 4095 : 0) << i;  // intensity: full where there is a peak
    }

    // Off the format's grid (a recording taken in image mode): the nearest row, within half a
    // step of 1/64 px (< 5 µm in z over the range), counted as inexact.
    for (std::size_t i = 1; i < profile.size(); i += 2) profile[i] += 0.0011f;
    vcell::EncodeStats off;
    vcell::encode_profile(profile, *tri, e, again.data(), off);
    EXPECT_EQ(off.exact + off.inexact, w - w / 50);
    EXPECT_GT(off.inexact, w / 2);
    EXPECT_GT(off.max_error_mm, 0.0);
    EXPECT_LT(off.max_error_mm, 0.005);
}

TEST(ReplayFrames, FramesOfTheReceiversFormatOrTheFileAndProblem) {
    core::FaceScan face;
    face.name = "top";
    for (int k = 0; k < 30; ++k)  // frames 10 ms apart, profiles 1 ms apart within
        face.profile_times_ns.push_back(5'000'000'000LL + (k / 10) * 10'000'000 +
                                        (k % 10) * 1'000'000);
    auto frames = vcell::replay_frames(face, 10, 1'000'000, 1234, "REC/top");
    ASSERT_TRUE(frames.ok()) << frames.error().message;
    ASSERT_EQ(frames->size(), 3u);
    EXPECT_EQ((*frames)[2].camera_ns, 5'020'000'000LL - 1234);
    EXPECT_EQ((*frames)[2].first_profile, 20u);

    auto not_whole = vcell::replay_frames(face, 7, 1'000'000, 0, "REC/top");
    ASSERT_FALSE(not_whole.ok());
    EXPECT_EQ(not_whole.error().message,
              "REC/top: 30 profiles are not whole frames of 7 profiles (the receiver's profiles "
              "per frame)");
    face.profile_times_ns[13] += 1;
    auto uneven = vcell::replay_frames(face, 10, 1'000'000, 0, "REC/top");
    ASSERT_FALSE(uneven.ok());
    EXPECT_EQ(uneven.error().message,
              "REC/top/profile_times.npy: profile 13 is 1000001 ns after the one before, in a "
              "frame whose profiles are 1000000 ns apart (the line period)");
}

TEST(ReplayAccel, DatagramsGiveTheRecordedTimesAndKeepGaps) {
    core::FaceScan face;
    for (int q = 0; q < 95; ++q)  // 2 kHz, with 10 samples lost after the 40th
        if (q < 40 || q >= 50) face.accel_times_ns.push_back(1'000'000'000LL + q * 500'000LL);
    const auto batches = vcell::accel_batches(face, 20);
    std::vector<std::int64_t> times;
    for (const auto& b : batches) {
        EXPECT_LE(b.count, 20u);
        EXPECT_EQ(b.first, times.size());
        for (std::size_t q = 0; q < b.count; ++q)
            times.push_back(b.t_ns + static_cast<std::int64_t>(q) * b.period_ns);
    }
    EXPECT_EQ(times, face.accel_times_ns);
    EXPECT_EQ(batches.size(), 5u);  // 20 + 20 | 20 + 20 + 5
}

// The device with a renderer that stamps each frame with its id and remembers what it was asked.
struct Stamped {
    std::mutex mutex;
    std::vector<vcell::FrameRequest> requests;
    void operator()(const vcell::FrameRequest& r, std::span<std::uint8_t> data) {
        for (std::size_t i = 0; i < data.size(); ++i)
            data[i] = static_cast<std::uint8_t>((r.frame_id + i) & 0xff);
        std::lock_guard lock(mutex);
        requests.push_back(r);
    }
};

core::Result<std::unique_ptr<vcell::GvDevice>> start_device(Stamped& stamped, double loss = 0) {
    vcell::GvDeviceConfig c;
    c.address = kAddress;
    c.serial = "HG-TEST";
    c.packet_loss = loss;
    return vcell::GvDevice::start(
        c, [&stamped](const vcell::FrameRequest& r, std::span<std::uint8_t> d) { stamped(r, d); });
}

acquire::CameraConfig camera_config() {
    acquire::CameraConfig c;
    c.id = kAddress;
    c.width = 256;
    c.height = 64;
    c.pixel_format = "Mono8";
    c.frame_rate_hz = 100;
    c.exposure_us = 250;
    c.timeout_ms = 300;
    return c;
}

TEST(GvDevice, AravisReceivesWhatWasRenderedWithItsTimestamps) {
    Stamped stamped;
    auto device = start_device(stamped, 0.02);  // 2 % of the packets dropped: resend recovers
    ASSERT_TRUE(device.ok()) << device.error().message;
    auto cam = acquire::Camera::open(camera_config());
    ASSERT_TRUE(cam.ok()) << cam.error().message;
    EXPECT_NE((*cam)->description().find("HG-TEST"), std::string::npos);
    ASSERT_TRUE((*cam)->start().ok());
    std::vector<acquire::Frame> frames;
    while (frames.size() < 30) {
        auto f = (*cam)->next();
        ASSERT_TRUE(f.ok()) << f.error().message;
        frames.push_back(std::move(*f));
    }
    (*cam)->stop();
    std::lock_guard lock(stamped.mutex);
    for (const auto& f : frames) {
        ASSERT_EQ(f.width, 256);
        ASSERT_EQ(f.height, 64);
        // Find the request this frame answers: same timestamp; the pixels carry its id.
        const auto it = std::find_if(stamped.requests.begin(), stamped.requests.end(),
                                     [&](const auto& r) { return r.timestamp_ns == f.camera_ns; });
        ASSERT_NE(it, stamped.requests.end()) << "a frame with a timestamp never rendered";
        EXPECT_EQ(f.data[0], it->frame_id & 0xff);
        EXPECT_EQ(f.data[1000], (it->frame_id + 1000) & 0xff);
        EXPECT_NEAR(it->exposure_us, 250.0, 1.0);
    }
    for (std::size_t i = 1; i < frames.size(); ++i)  // 100 frames/s, none missing
        EXPECT_EQ(frames[i].camera_ns - frames[i - 1].camera_ns, 10'000'000);
    const auto st = (*device)->stats();
    EXPECT_GT(st.dropped, 0u);
    EXPECT_GE(st.resent, 1u);
    EXPECT_EQ((*cam)->stats().incomplete, 0);
}

TEST(GvDevice, MultiPartBuffersArriveAsPartsThroughAravis) {
    // Range and intensity as two parts of one buffer (GigE Vision 2.1 multi-part, as AT C6
    // sensors send them): rows [0, 8) go out as part 0, rows [8, 16) as part 1.
    vcell::GvDeviceConfig c;
    c.address = kAddress;
    c.multipart_parts = 2;
    // No loss here: Aravis 0.8.26 sizes a multi-part frame whose leader was lost from its
    // first data packet (255 parts at most) and then waits for packets that never come, so a
    // lost leader costs that frame even after resend (docs/virtual-cell.md).
    auto device =
        vcell::GvDevice::start(c, [](const vcell::FrameRequest& r, std::span<std::uint8_t> data) {
            const std::size_t half = data.size() / 2;
            for (std::size_t i = 0; i < data.size(); ++i)
                data[i] = static_cast<std::uint8_t>(i < half ? (r.frame_id + i) & 0x7f
                                                             : 0x80 | (i & 0x7f));
        });
    ASSERT_TRUE(device.ok()) << device.error().message;
    auto cc = camera_config();
    cc.height = 16;
    cc.pixel_format = "Mono16";
    auto cam = acquire::Camera::open(cc);
    ASSERT_TRUE(cam.ok()) << cam.error().message;
    ASSERT_TRUE((*cam)->start().ok());
    for (int n = 0; n < 20; ++n) {
        auto f = (*cam)->next();
        ASSERT_TRUE(f.ok()) << f.error().message;
        ASSERT_EQ(f->parts.size(), 2u);
        const std::size_t part_bytes = 256 * 8 * 2;
        for (int j = 0; j < 2; ++j) {
            EXPECT_EQ(f->parts[j].component, j);
            EXPECT_EQ(f->parts[j].width, 256);
            EXPECT_EQ(f->parts[j].height, 8);
            EXPECT_EQ(f->parts[j].bytes_per_pixel, 2);
            EXPECT_EQ(f->parts[j].size, part_bytes);
        }
        ASSERT_EQ(f->data.size(), 2 * part_bytes);
        EXPECT_EQ(f->data[part_bytes + 5], 0x80 | ((part_bytes + 5) & 0x7f));  // part 1's bytes
        EXPECT_EQ(f->data[5] & 0x80, 0);                                       // part 0's
    }
    (*cam)->stop();
    EXPECT_EQ((*cam)->stats().incomplete, 0);
}

TEST(GvDevice, SecondDeviceOnTheSameAddressIsRefusedByName) {
    Stamped stamped;
    auto first = start_device(stamped);
    ASSERT_TRUE(first.ok());
    auto second = start_device(stamped);
    ASSERT_FALSE(second.ok());
    EXPECT_NE(second.error().message.find("127.0.0.4:3956"), std::string::npos)
        << second.error().message;
}

TEST(CameraSession, LostCameraFailsTheScanAndIsReopenedWithBackoff) {
    const auto tri = vcell::sensor_triangulation(sensor());
    ASSERT_TRUE(tri.ok());
    acquire::ScanConfig scan;
    scan.stripe.max_value = 255;
    auto table = acquire::ExposureTable::create({{20, 400}, {1000, 100}, {1200, 50}});
    ASSERT_TRUE(table.ok());
    acquire::ReconnectPolicy policy;
    policy.first_backoff = std::chrono::milliseconds(200);
    policy.max_backoff = std::chrono::milliseconds(800);
    auto cc = camera_config();
    cc.width = 2048;
    cc.exposure_us = 0;
    auto session = std::make_unique<acquire::CameraSession>(cc, scan, *tri, *table, policy);

    Stamped stamped;
    auto device = start_device(stamped);
    ASSERT_TRUE(device.ok());
    auto ok = session->scan(0.3, 1100.0);
    ASSERT_TRUE(ok.ok()) << ok.error().message;
    EXPECT_GT(ok->face.n_profiles(), 10);
    ASSERT_TRUE(ok->exposure_us);
    EXPECT_DOUBLE_EQ(*ok->exposure_us, 75.0);  // halfway between 100 µs at 1000 °C and 50 at 1200
    {
        std::lock_guard lock(stamped.mutex);
        EXPECT_NEAR(stamped.requests.back().exposure_us, 75.0, 1.0);
    }

    // The camera vanishes mid-scan: the scan fails with the reason, nothing partial comes back.
    std::thread killer([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        device->reset();
    });
    auto lost = session->scan(3.0, 1100.0);
    killer.join();
    ASSERT_FALSE(lost.ok());
    EXPECT_NE(lost.error().message.find("camera lost"), std::string::npos) << lost.error().message;
    EXPECT_FALSE(session->connected());

    // While it is away: attempts fail, and back off.
    auto away = session->connect();
    ASSERT_FALSE(away.ok());
    EXPECT_NE(away.error().message.find("next attempt in"), std::string::npos)
        << away.error().message;
    std::this_thread::sleep_for(session->backoff_remaining());
    EXPECT_FALSE(session->connect().ok());  // nobody at the address
    EXPECT_GE(session->failures_in_a_row(), 2);
    EXPECT_GT(session->backoff_remaining().count(), 200);  // grew

    // It is back: the next attempt after the backoff reconnects and scans.
    Stamped again;
    auto back = start_device(again);
    ASSERT_TRUE(back.ok());
    std::this_thread::sleep_for(session->backoff_remaining());
    auto after = session->scan(0.3, 20.0);
    ASSERT_TRUE(after.ok()) << after.error().message;
    EXPECT_GT(after->face.n_profiles(), 10);
    EXPECT_DOUBLE_EQ(*after->exposure_us, 400.0);
    EXPECT_EQ(session->failures_in_a_row(), 0);
    session.reset();  // closed while the device still answers (a dead one costs seconds)
}

// Finding 8 of issue 18: positions count from a scan's first frame, so a scan whose first frames
// were lost is shifted; the session must say so. Frames lost whole show as the first frame's
// lateness after AcquisitionStart.
TEST(CameraSession, AScanThatLostItsFirstFramesSaysSo) {
    const auto tri = vcell::sensor_triangulation(sensor());
    ASSERT_TRUE(tri.ok());
    acquire::ScanConfig scan;
    scan.stripe.max_value = 255;
    auto cc = camera_config();
    cc.width = 2048;
    Stamped stamped;
    vcell::GvDeviceConfig c;
    c.address = kAddress;
    c.serial = "HG-TEST";
    c.lose_scan_start = 5;  // 50 ms at 100 frames/s
    c.lose_scan_start_count = 2;
    auto device = vcell::GvDevice::start(
        c, [&stamped](const vcell::FrameRequest& r, std::span<std::uint8_t> d) { stamped(r, d); });
    ASSERT_TRUE(device.ok()) << device.error().message;
    // After the device: closed while the device still answers (a dead one costs seconds).
    acquire::CameraSession session(cc, scan, *tri);
    for (int k = 0; k < 3; ++k) {
        auto out = session.scan(0.3, std::nullopt);
        ASSERT_TRUE(out.ok()) << out.error().message;
        EXPECT_GT(out->face.n_profiles(), 10);
        std::printf("scan %d: %lld profiles, first frame %.1f ms after start, %lld lost: %s\n", k,
                    static_cast<long long>(out->face.n_profiles()),
                    static_cast<double>(out->start.lag_ns) * 1e-6,
                    static_cast<long long>(out->start.lost), out->start_lost.c_str());
        if (k < 2) {
            EXPECT_FALSE(out->start_lost.empty()) << "scan " << k;
            EXPECT_TRUE(out->start.lost > 0 || out->start.lag_ns > 50'000'000) << out->start_lost;
        } else {
            EXPECT_EQ(out->start_lost, "") << "scan " << k;
            EXPECT_EQ(out->start.lost, 0);
            EXPECT_LT(out->start.lag_ns, 40'000'000);
        }
    }
    EXPECT_EQ((*device)->stats().start_frames_lost, 10u);
}

TEST(CameraSession, TheStartRuleNamesWhatWasLost) {
    const std::int64_t ms = 1'000'000;
    EXPECT_EQ(acquire::scan_start_lost({8 * ms, 0}, 10 * ms, 30 * ms), "");
    EXPECT_EQ(acquire::scan_start_lost({40 * ms, 0}, 10 * ms, 30 * ms), "");
    const std::string late = acquire::scan_start_lost({41 * ms, 0}, 10 * ms, 30 * ms);
    EXPECT_NE(late.find("first frame 41 ms after AcquisitionStart"), std::string::npos) << late;
    const std::string lost = acquire::scan_start_lost({5 * ms, 2}, 10 * ms, 30 * ms);
    EXPECT_NE(lost.find("2 incomplete frames before the first complete one"), std::string::npos)
        << lost;
    EXPECT_EQ(acquire::scan_start_lost({900 * ms, 0}, 0, 30 * ms), "");  // one frame: no period
}

TEST(ExposureTable, InterpolatesClampsAndNamesBadPoints) {
    auto t = acquire::ExposureTable::create({{700, 200}, {1000, 100}});
    ASSERT_TRUE(t.ok());
    EXPECT_DOUBLE_EQ(t->exposure_us(20), 200);
    EXPECT_DOUBLE_EQ(t->exposure_us(850), 150);
    EXPECT_DOUBLE_EQ(t->exposure_us(1300), 100);
    auto bad = acquire::ExposureTable::create({{700, 200}, {600, 100}});
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.error().message.find("point 2"), std::string::npos);
    EXPECT_FALSE(acquire::ExposureTable::create({{700, 0}}).ok());
}

// The virtual cell on this test's address, its accelerometer stream received into `ring`.
struct CellWithReceiver {
    sim::CellConfig cell;
    accel::AccelRing ring{{.capacity_s = 30, .sample_rate_hz = 2000, .gap_periods = 3}};
    std::unique_ptr<accel::UdpAccelReceiver> receiver;
    std::unique_ptr<vcell::VirtualCell> vcell;

    void start(const std::function<void(vcell::VirtualCellConfig&)>& adjust = {}) {
        auto recipe = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
        ASSERT_TRUE(recipe.ok());
        auto c = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
        ASSERT_TRUE(c.ok());
        cell = *c;
        accel::UdpReceiverConfig rc;
        rc.bind = "127.0.0.1:0";
        receiver = std::make_unique<accel::UdpAccelReceiver>(rc, ring);
        ASSERT_TRUE(receiver->start().ok());
        vcell::VirtualCellConfig vc;
        vc.recipe = *recipe;
        vc.cell = cell;
        vc.device.address = kAddress;
        vc.accel_to = "127.0.0.1:" + std::to_string(receiver->port());
        if (adjust) adjust(vc);
        auto started = vcell::VirtualCell::start(vc);
        ASSERT_TRUE(started.ok()) << started.error().message;
        vcell = std::move(*started);
    }
    ~CellWithReceiver() {
        vcell.reset();
        if (receiver) receiver->stop();
    }
};

TEST(VirtualCell, AccelerometerStreamIsContinuousAndFeelsGravity) {
    CellWithReceiver c;
    ASSERT_NO_FATAL_FAILURE(c.start());
    auto& ring = c.ring;
    const auto t0 = std::chrono::system_clock::now();
    const auto ns = [](auto tp) {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(tp.time_since_epoch()).count();
    };
    const std::int64_t from = ns(t0) + 100'000'000, to = from + 500'000'000;
    ASSERT_TRUE(ring.wait_for(to, std::chrono::milliseconds(5000)));
    const auto w = ring.copy_range(from, to);
    EXPECT_TRUE(w.complete());
    EXPECT_NEAR(static_cast<double>(w.samples.size()), 1000.0, 2.0);  // 2 kHz
    double gz = 0;  // top face: the accelerometer's z is along world −z... its norm is g
    for (const auto& s : w.samples)
        gz += std::sqrt(s.x_mps2 * s.x_mps2 + s.y_mps2 * s.y_mps2 + s.z_mps2 * s.z_mps2);
    EXPECT_NEAR(gz / static_cast<double>(w.samples.size()), 9.81, 0.5);
}

TEST(VirtualCell, TheAxisMovesTheHeadToAnotherFaceOverModbus) {
    CellWithReceiver c;
    ASSERT_NO_FATAL_FAILURE(c.start([](vcell::VirtualCellConfig& vc) {
        vc.axis_port = 0;
        vc.axis_move_s = 0.1;
    }));
    auto& ring = c.ring;
    const auto& cell = c.cell;
    ASSERT_GE(cell.faces.size(), 2u);
    auto& vcell = c.vcell;
    ASSERT_GT(vcell->axis_port(), 0);

    // Gravity as the head's accelerometer should read it at face f (1-based).
    auto gravity = [&](int f) {
        const auto& face = cell.faces[static_cast<std::size_t>(f - 1)];
        const Eigen::Matrix3d R = face.T_world_camera.linear() * face.R_camera_accel;
        return Eigen::Vector3d(R.transpose() * Eigen::Vector3d(0, 0, 9.81));
    };
    auto mean_reading = [&] {
        const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::system_clock::now().time_since_epoch())
                             .count();
        EXPECT_TRUE(ring.wait_for(now + 300'000'000, std::chrono::milliseconds(3000)));
        const auto w = ring.copy_range(now + 50'000'000, now + 300'000'000);
        Eigen::Vector3d m = Eigen::Vector3d::Zero();
        for (const auto& smp : w.samples) m += Eigen::Vector3d(smp.x_mps2, smp.y_mps2, smp.z_mps2);
        return Eigen::Vector3d(m / std::max<double>(1.0, static_cast<double>(w.samples.size())));
    };
    EXPECT_LT((mean_reading() - gravity(1)).norm(), 0.5);  // at the first face (top)

    // A PLC or the daemon moves the axis: target face 2, command 1, wait until in position.
    modbus_t* mb = modbus_new_tcp("127.0.0.1", vcell->axis_port());
    ASSERT_NE(mb, nullptr);
    ASSERT_EQ(modbus_connect(mb), 0);
    const std::uint16_t move[2] = {2, 1};
    ASSERT_EQ(modbus_write_registers(mb, 0, 2, move), 2);
    std::uint16_t regs[6] = {};
    bool arrived = false;
    for (int i = 0; i < 100 && !arrived; ++i) {
        ASSERT_EQ(modbus_read_registers(mb, 0, 6, regs), 6);
        arrived = regs[3] == 0 && regs[2] == 2;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    EXPECT_TRUE(arrived) << "state " << regs[3] << " face " << regs[2];
    EXPECT_EQ(regs[4], cell.faces.size());
    EXPECT_EQ(regs[5], 1);                                 // one move completed
    EXPECT_LT((mean_reading() - gravity(2)).norm(), 0.5);  // the head now reads face 2's gravity
    EXPECT_GT((gravity(1) - gravity(2)).norm(), 1.0);      // ...which differs from face 1's

    const std::uint16_t bad[2] = {99, 1};  // no such face: fault, the head stays
    ASSERT_EQ(modbus_write_registers(mb, 0, 2, bad), 2);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    ASSERT_EQ(modbus_read_registers(mb, 0, 6, regs), 6);
    EXPECT_EQ(regs[3], 2);
    EXPECT_EQ(regs[2], 2);
    modbus_close(mb);
    modbus_free(mb);
}

// Polls `done` until it holds or `timeout` passes.
bool eventually(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
}

// A virtual serial pair: socat linking two ptys, DIR/a <-> DIR/b (as in test_plc.cpp).
std::string read_text(const std::filesystem::path& p) {
    std::ifstream f(p);
    return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

TEST(VirtualCell, PartOffsetsFollowTheDocumentedFormula) {
    sim::SimOptions base;
    base.seed = 40;
    base.temperature_c = 1000;
    // d(n) = ((n − 1)·37 + 100) mod 201 − 100, written out for parts 1..12.
    const double d[] = {0, 37, 74, -90, -53, -16, 21, 58, 95, -69, -32, 5};
    for (int n = 1; n <= 12; ++n) {
        const auto o = vcell::part_options(base, n);
        EXPECT_EQ(o.seed, 40u + static_cast<std::uint64_t>(n - 1)) << "part " << n;
        EXPECT_DOUBLE_EQ(o.temperature_c, 1000 + d[n - 1]) << "part " << n;
    }
    for (int n = 1; n <= 402; ++n)  // within ±100 °C for any n
        EXPECT_LE(std::abs(vcell::part_options(base, n).temperature_c - 1000), 100.0);
}

// The master on the conveyor is the same physical part each time it comes, cold; the parts
// around it keep their own seeds and temperatures (docs/virtual-cell.md "The master").
TEST(VirtualCell, TheMasterIsTheSamePartEachTime) {
    vcell::VirtualCellConfig c;
    c.part.seed = 40;
    c.part.temperature_c = 1000;
    c.master = c.part;
    c.master.seed = 1000;
    c.master.temperature_c = 20;
    c.master_parts = {4, 9};
    for (int n = 1; n <= 12; ++n) {
        const auto o = vcell::conveyor_options(c, n);
        const bool master = n == 4 || n == 9;
        EXPECT_EQ(o.seed, master ? 1000u : vcell::part_options(c.part, n).seed) << "part " << n;
        EXPECT_DOUBLE_EQ(o.temperature_c,
                         master ? 20.0 : vcell::part_options(c.part, n).temperature_c)
            << "part " << n;
    }
}

// Bad parts (--bad-part): part N alone has its features moved, on top of every part's; a master
// part is never bad; a bad part that cannot be built stops the cell at start, naming it.
TEST(VirtualCell, BadPartsAreBadAloneAndCheckedAtStart) {
    vcell::VirtualCellConfig c;
    c.part.seed = 40;
    c.part.bad_mm = {{"Height 2", -0.5}};
    c.master = c.part;
    c.master.bad_mm.clear();
    c.master_parts = {9};
    c.bad_parts = {{4, {{"Diameter 3", 0.7}, {"Height 2", 0.125}}}};
    for (int n = 1; n <= 12; ++n) {
        const auto o = vcell::conveyor_options(c, n);
        if (n == 9) {
            EXPECT_TRUE(o.bad_mm.empty());
        } else if (n == 4) {
            ASSERT_EQ(o.bad_mm.size(), 2u);
            EXPECT_DOUBLE_EQ(o.bad_mm.at("Diameter 3"), 0.7);
            EXPECT_DOUBLE_EQ(o.bad_mm.at("Height 2"), -0.375);
        } else {
            EXPECT_EQ(o.bad_mm, c.part.bad_mm) << "part " << n;
        }
    }

    auto recipe = io::read_recipe(HOTGAUGE_SOURCE_DIR "/config/parts/hub-a.yaml");
    ASSERT_TRUE(recipe.ok());
    auto cell = sim::read_cell_config(HOTGAUGE_SOURCE_DIR "/config/cell.yaml");
    ASSERT_TRUE(cell.ok());
    vcell::VirtualCellConfig v;
    v.recipe = *recipe;
    v.cell = *cell;
    v.bad_parts = {{5, {{"Diameter 9", 0.5}}}};
    auto started = vcell::VirtualCell::start(v);
    ASSERT_FALSE(started.ok());
    EXPECT_NE(started.error().message.find("bad part 5"), std::string::npos)
        << started.error().message;
    EXPECT_NE(started.error().message.find("Diameter 9"), std::string::npos)
        << started.error().message;
    v.bad_parts = {{2, {{"Die shift", 0.6}}}};  // a die shift needs an as-forged part
    started = vcell::VirtualCell::start(v);
    ASSERT_FALSE(started.ok());
    EXPECT_NE(started.error().message.find("--forged"), std::string::npos)
        << started.error().message;
}

// A scripted PLC loads part 3 through the axis controller's registers 6 and 7: its truth is on
// disk when register 7 says so, the camera's part and the pyrometer follow.
TEST(VirtualCell, APlcLoadsAnotherPartOverModbus) {
    test::TempDir dir;
    test::SerialPair serial;
    ASSERT_TRUE(serial.ok()) << "socat did not come up";
    const std::filesystem::path truth_dir = dir.path / "truth";
    CellWithReceiver c;
    ASSERT_NO_FATAL_FAILURE(c.start([&](vcell::VirtualCellConfig& vc) {
        vc.axis_port = 0;
        vc.part.seed = 7;
        vc.part.temperature_c = 1000;
        vc.truth_dir = truth_dir;
        plc::SerialConfig sc;
        sc.device = serial.a();
        vc.pyrometer = sc;
    }));
    auto& vcell = *c.vcell;
    EXPECT_EQ(vcell.part_loaded(), 1);  // part 1 is the configured part itself
    EXPECT_DOUBLE_EQ(vcell.part_temperature_c(), 1000.0);
    const sim::SimTruth first = vcell.truth();
    EXPECT_DOUBLE_EQ(first.temperature_c, 1000.0);
    EXPECT_TRUE(std::filesystem::exists(truth_dir / "part-0001" / "truth.yaml"));

    plc::PyrometerConfig pc;
    pc.serial.device = serial.b();
    pc.poll_period_ms = 20;
    pc.response_timeout_ms = 100;
    auto pyro = plc::Pyrometer::start(pc);
    ASSERT_TRUE(pyro) << pyro.error().message;
    auto pyrometer_reads = [&](double t) {
        return eventually(
            [&] {
                const auto r = (*pyro)->latest();
                return r.temperature_c && std::abs(*r.temperature_c - t) < 0.051;
            },
            std::chrono::milliseconds(5000));
    };
    EXPECT_TRUE(pyrometer_reads(1000.0)) << (*pyro)->latest().last_error;

    modbus_t* mb = modbus_new_tcp("127.0.0.1", vcell.axis_port());
    ASSERT_NE(mb, nullptr);
    ASSERT_EQ(modbus_connect(mb), 0);
    std::uint16_t regs[2] = {};
    ASSERT_EQ(modbus_read_registers(mb, 6, 2, regs), 2);
    EXPECT_EQ(regs[0], 0);
    EXPECT_EQ(regs[1], 1);
    ASSERT_EQ(modbus_write_register(mb, 6, 3), 1);
    ASSERT_EQ(modbus_read_registers(mb, 6, 2, regs), 2);
    EXPECT_EQ(regs[0], 0);                                 // the request was taken
    EXPECT_TRUE(regs[1] == 0 || regs[1] == 3) << regs[1];  // 0 while loading
    const bool loaded =
        eventually([&] { return modbus_read_registers(mb, 6, 2, regs) == 2 && regs[1] == 3; },
                   std::chrono::milliseconds(20'000));
    modbus_close(mb);
    modbus_free(mb);
    ASSERT_TRUE(loaded) << "register 7 reads " << regs[1];
    // Read the moment register 7 says 3: the truth is complete.
    const std::string yaml = read_text(truth_dir / "part-0003" / "truth.yaml");
    EXPECT_NE(yaml.find("temperature_c: 1074\n"), std::string::npos) << yaml;
    EXPECT_NE(yaml.find("features:"), std::string::npos);

    // Part 3: seed 7 + 2, 1 000 °C + d(3) = (2·37 + 100) mod 201 − 100 = 74 °C.
    EXPECT_EQ(vcell.part_loaded(), 3);
    EXPECT_DOUBLE_EQ(vcell.part_temperature_c(), 1074.0);
    const sim::SimTruth third = vcell.truth();
    EXPECT_DOUBLE_EQ(third.temperature_c, 1074.0);
    EXPECT_GT(third.growth, first.growth);
    EXPECT_NE(third.levels_mm, first.levels_mm);  // another seed: another forging
    EXPECT_FALSE(std::filesystem::exists(truth_dir / "part-0002"));
    EXPECT_TRUE(pyrometer_reads(1074.0)) << (*pyro)->latest().last_error;
}

}  // namespace
}  // namespace hotgauge
