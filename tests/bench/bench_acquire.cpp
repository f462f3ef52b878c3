// Acquisition benchmarks (docs/benchmarks.md "Acquisition"): run `make bench`.
//  - Stripe extraction throughput, GB/s of pixels on one core, ours against the same job done
//    the plain OpenCV way (transpose, then minMaxLoc and a centre of gravity per column), on the
//    same rendered 2048 × 1088 frames.
//  - Ingestion over loopback: a GigE Vision device (vcell::GvDevice on 127.0.0.5) streams peaks
//    frames of 2048-point profiles at a set line rate; acquire::Camera + ScanBuilder take them in.
//    Counters: profiles/s received, profiles lost (sent but not received), CPU of the receiving
//    thread per profile.
#include <benchmark/benchmark.h>
#include <time.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <random>

#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/stripe.hpp"
#include "hotgauge/sim/scene.hpp"
#include "hotgauge/vcell/gv_device.hpp"
#include "hotgauge/vcell/render.hpp"

using namespace hotgauge;

namespace {

constexpr int kWidth = 2048, kHeight = 1088;

// A realistic frame: a stripe wandering over the rows, glow of a part at 1 000 °C, speckle,
// shot and read noise (vcell::render_stripe), in 16 or 8 bits.
std::vector<std::uint8_t> frame(int bytes_per_pixel) {
    const auto tri = vcell::sensor_triangulation(sim::SensorConfig{});
    if (!tri) std::abort();
    std::vector<sim::RayReturn> returns(kWidth);
    for (int i = 0; i < kWidth; ++i) {
        const double v = 544.0 + 300.0 * std::sin(i / 200.0);
        const auto p = tri->to_camera(i, v);
        returns[i] = {static_cast<float>(p.x_mm), static_cast<float>(p.z_mm), 0.9f, false};
    }
    vcell::StripeLook look;
    look.full_scale = bytes_per_pixel == 1 ? 255 : 4095;
    sim::RandomStream rng(3);
    std::vector<std::uint8_t> out(static_cast<std::size_t>(kWidth * kHeight * bytes_per_pixel));
    vcell::render_stripe(returns, *tri, look, 100.0, look.glow, kWidth, kHeight, 0, 0,
                         bytes_per_pixel, rng, out);
    return out;
}

void BM_ExtractStripeMono16(benchmark::State& state) {
    const auto bytes = frame(2);
    std::vector<std::uint16_t> px(bytes.size() / 2);
    std::memcpy(px.data(), bytes.data(), bytes.size());
    acquire::StripeConfig config;
    for (auto _ : state) {
        auto points = acquire::extract_stripe(px.data(), kWidth, kHeight, kWidth, config);
        benchmark::DoNotOptimize(points.data());
    }
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(bytes.size()));
    state.SetLabel("ours, 2048x1088 Mono16");
}
BENCHMARK(BM_ExtractStripeMono16)->Unit(benchmark::kMillisecond)->MinTime(1.0);

void BM_ExtractStripeMono8(benchmark::State& state) {
    const auto bytes = frame(1);
    acquire::StripeConfig config;
    config.max_value = 255;
    config.min_peak = 20;
    for (auto _ : state) {
        auto points = acquire::extract_stripe(bytes.data(), kWidth, kHeight, kWidth, config);
        benchmark::DoNotOptimize(points.data());
    }
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(bytes.size()));
    state.SetLabel("ours, 2048x1088 Mono8");
}
BENCHMARK(BM_ExtractStripeMono8)->Unit(benchmark::kMillisecond)->MinTime(1.0);

// The plain OpenCV way: columns become rows (cv::transpose), then per column the maximum
// (cv::minMaxLoc) and the centre of gravity of ±4 rows around it above the row's median-free
// background (the mean of the band just outside). No quality flags, no double peaks.
void BM_ExtractStripeOpenCvMono16(benchmark::State& state) {
    const auto bytes = frame(2);
    cv::Mat image(kHeight, kWidth, CV_16UC1, const_cast<std::uint8_t*>(bytes.data()));
    cv::Mat columns;
    std::vector<float> rows(kWidth);
    for (auto _ : state) {
        cv::transpose(image, columns);
        for (int c = 0; c < kWidth; ++c) {
            const cv::Mat col = columns.row(c);
            double max_value = 0;
            cv::Point at;
            cv::minMaxLoc(col, nullptr, &max_value, nullptr, &at);
            const int r0 = std::max(0, at.x - 4), r1 = std::min(kHeight - 1, at.x + 4);
            const auto* p = col.ptr<std::uint16_t>();
            double bg = 0;
            int nb = 0;
            for (int r = r0 - 3; r < r0; ++r)
                if (r >= 0) bg += p[r], ++nb;
            for (int r = r1 + 1; r <= r1 + 3; ++r)
                if (r < kHeight) bg += p[r], ++nb;
            bg = nb ? bg / nb : 0;
            double s = 0, sr = 0;
            for (int r = r0; r <= r1; ++r) {
                const double w = std::max(0.0, p[r] - bg);
                s += w;
                sr += w * r;
            }
            rows[c] = s > 0 ? static_cast<float>(sr / s) : NAN;
        }
        benchmark::DoNotOptimize(rows.data());
    }
    state.SetBytesProcessed(state.iterations() * static_cast<std::int64_t>(bytes.size()));
    state.SetLabel("OpenCV transpose + minMaxLoc + COG, Mono16");
}
BENCHMARK(BM_ExtractStripeOpenCvMono16)->Unit(benchmark::kMillisecond)->MinTime(1.0);

double thread_cpu_s() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Ingestion at state.range(0) profiles/s: 100 profiles per frame, 2048 Mono16 peaks each,
// 4 s of streaming per iteration; peaks pre-rendered (the device must not be the bottleneck).
void BM_IngestPeaksOverLoopback(benchmark::State& state) {
    const int line_rate = static_cast<int>(state.range(0));
    constexpr int kProfilesPerFrame = 100;
    const double frame_rate = static_cast<double>(line_rate) / kProfilesPerFrame;
    std::vector<std::uint16_t> peaks(static_cast<std::size_t>(kWidth * kProfilesPerFrame));
    std::mt19937 gen(1);
    for (auto& v : peaks) v = static_cast<std::uint16_t>(64 * (300 + gen() % 400) + gen() % 64);
    std::atomic<std::uint64_t> rendered{0};
    vcell::GvDeviceConfig dc;
    dc.address = "127.0.0.5";
    dc.serial = "HG-BENCH";
    auto device =
        vcell::GvDevice::start(dc, [&](const vcell::FrameRequest&, std::span<std::uint8_t> data) {
            std::memcpy(data.data(), peaks.data(), std::min(data.size(), peaks.size() * 2));
            ++rendered;
        });
    if (!device) {
        state.SkipWithError(device.error().message.c_str());
        return;
    }
    acquire::CameraConfig cc;
    cc.id = dc.address;
    cc.width = kWidth;
    cc.height = kProfilesPerFrame;
    cc.pixel_format = "Mono16";
    cc.frame_rate_hz = frame_rate;
    cc.packet_size = 8000;  // jumbo frames, as a GigE Vision profile camera link is set up
    cc.n_buffers = 64;
    auto cam = acquire::Camera::open(cc);
    if (!cam) {
        state.SkipWithError(cam.error().message.c_str());
        return;
    }
    const auto tri = vcell::sensor_triangulation(sim::SensorConfig{});
    acquire::ScanConfig sc;
    sc.frame_mode = "peaks";
    sc.peaks.profiles_per_frame = kProfilesPerFrame;
    sc.line_period_s = 1.0 / line_rate;
    double received = 0, expected = 0, cpu = 0, wall = 0;
    for (auto _ : state) {
        acquire::ScanBuilder builder(sc, *tri);
        std::int64_t taken = 0;
        const auto sent_before = (*device)->stats().frames;
        if (!(*cam)->start()) {
            state.SkipWithError("start failed");
            return;
        }
        const double cpu0 = thread_cpu_s();
        const auto t0 = std::chrono::steady_clock::now();
        while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(4)) {
            auto f = (*cam)->next();
            if (!f) continue;
            builder.add(*f);
            // A face is about 1 200 profiles: hand one on every 2 000, as the daemon does.
            if (builder.stats().profiles - taken >= 2000) {
                auto face = builder.take();
                benchmark::DoNotOptimize(face.profiles_mm.data());
                taken = builder.stats().profiles;
            }
        }
        (*cam)->stop();
        // Frames in flight at the stop: drained by the next start; count what was sent.
        cpu += thread_cpu_s() - cpu0;
        wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        received += static_cast<double>(builder.stats().profiles);
        expected +=
            static_cast<double>((*device)->stats().frames - sent_before) * kProfilesPerFrame;
    }
    const auto& cs = (*cam)->stats();
    state.counters["profiles_per_s"] = received / wall;
    state.counters["lost_profiles"] = std::max(0.0, expected - received - kProfilesPerFrame);
    state.counters["missing_packets"] = static_cast<double>(cs.missing_packets);
    state.counters["underruns"] = static_cast<double>(cs.underruns);
    state.counters["cpu_us_per_profile"] = 1e6 * cpu / std::max(1.0, received);
    state.SetLabel("2048-point Mono16 peaks, 100 profiles/frame, 8000-byte packets");
}
BENCHMARK(BM_IngestPeaksOverLoopback)
    ->Arg(10'000)
    ->Arg(20'000)
    ->Arg(40'000)
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

// Triangulation alone: one 2048-point profile, direct-beam model.
void BM_TriangulateProfile(benchmark::State& state) {
    const auto tri = vcell::sensor_triangulation(sim::SensorConfig{});
    std::vector<acquire::StripePoint> profile(2048);
    for (int i = 0; i < 2048; ++i)
        profile[i] = {static_cast<float>(300 + (i * 37) % 400) + 0.25f, 1.0f,
                      acquire::StripeStatus::kOk};
    std::vector<float> out;
    for (auto _ : state) {
        if (out.size() > 4096 * 1000) out.clear();
        acquire::triangulate(*tri, profile, out);
        benchmark::DoNotOptimize(out.data());
    }
    state.SetItemsProcessed(state.iterations() * 2048);
}
BENCHMARK(BM_TriangulateProfile);
}  // namespace

BENCHMARK_MAIN();
