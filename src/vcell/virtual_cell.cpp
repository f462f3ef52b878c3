#include "hotgauge/vcell/virtual_cell.hpp"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "hotgauge/accel/udp.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/sim/scene.hpp"
#include "hotgauge/sim/vibration.hpp"
#include "log.hpp"

namespace hotgauge::vcell {
namespace {

constexpr double kServeHorizonS = 7 * 24 * 3600.0;  // press blows are drawn for a week

// One part on the support; immutable once built, shared with the renderer's snapshot.
struct LoadedPart {
    int number = 0;
    sim::SimOptions options;
    sim::Scene scene;
};

// Builds part n with `rng` seeded from its seed (start goes on drawing from it).
core::Result<std::shared_ptr<const LoadedPart>> build_part(const VirtualCellConfig& c, int n,
                                                           std::mt19937_64& rng) {
    sim::SimOptions options = conveyor_options(c, n);
    rng.seed(options.seed);
    auto scene = sim::Scene::create(c.recipe, c.cell, options, rng);
    if (!scene) return scene.error();
    return std::shared_ptr<const LoadedPart>(
        new LoadedPart{n, std::move(options), std::move(*scene)});
}

// Below the pyrometer's span: it reads nothing, as for a recording without a temperature.
constexpr double kNoReadingC = 20.0;

// Replay (docs/virtual-cell.md "Replay"): peaks through the receiver's calibration.
// The recording moves into the player.
core::Result<std::unique_ptr<RecordingPlayer>> make_player(VirtualCellConfig& c) {
    ReplayConfig& r = *c.replay;
    if (c.mode != "peaks" || c.device.multipart_parts >= 2)
        return core::make_error(
            "virtual cell: a replay sends single-part peak frames (--mode peaks)");
    auto tri = calib::triangulation(r.calibration.sensor);
    if (!tri) return tri.error();
    PlayerConfig pc;
    pc.dir = r.dir;
    pc.recording = std::move(r.recording);
    pc.clock_offset_ns = r.calibration.clock_offset_ns;
    pc.scan_s = r.scan_s;
    pc.line_period_s = c.line_period_s;
    pc.encoding.format = c.peaks;
    pc.encoding.offset_y_px = c.peak_row_offset;
    pc.datagram_samples = static_cast<std::size_t>(
        std::clamp(std::llround(c.cell.accel.rate_hz * c.accel_datagram_s), 1LL,
                   static_cast<long long>(accel::kDatagramMaxSamples)));
    return std::make_unique<RecordingPlayer>(std::move(pc), std::move(*tri));
}

core::Result<void> write_part_truth(const VirtualCellConfig& c, const LoadedPart& part) {
    if (c.truth_dir.empty()) return {};
    char name[32];
    std::snprintf(name, sizeof name, "part-%04d", part.number);
    return sim::write_truth(part.scene.truth(), c.truth_dir / name);
}

// The face the sensor starts at: its number on the axis (1-based; the last of that name), 0 if
// the cell has none of that name.
int face_number(const VirtualCellConfig& c) {
    int number = 0;
    for (std::size_t i = 0; i < c.cell.faces.size(); ++i)
        if (c.cell.faces[i].name == c.face) number = static_cast<int>(i) + 1;
    return number;
}

// The settings the virtual cell cannot run with, the first one found.
core::Result<void> check_config(const VirtualCellConfig& c) {
    if (c.mode != "image" && c.mode != "peaks")
        return core::make_error("virtual cell: mode '" + c.mode + "' is not image or peaks");
    if (face_number(c) == 0)
        return core::make_error("virtual cell: no face '" + c.face + "' in the cell");
    if (c.mode == "peaks")
        if (auto ok = acquire::check_peak_format(c.peaks); !ok) return ok.error();
    if (c.device.multipart_parts >= 2 &&
        (c.mode != "peaks" || c.device.multipart_parts != c.peaks.rows_per_profile()))
        return core::make_error(
            "virtual cell: multi-part frames need peaks mode with one part per row kind (" +
            std::to_string(c.peaks.rows_per_profile()) + ")");
    if (!(c.speed_mm_s > 0)) return core::make_error("virtual cell: speed_mm_s must be > 0");
    if (!(c.cell.accel.rate_hz > 0))
        return core::make_error("virtual cell: accelerometer rate must be > 0");
    return {};
}

// A bad part that cannot be built (an unknown feature, a die shift on a sharp part) is an error
// now, not a load that times out later.
core::Result<void> check_bad_parts(const VirtualCellConfig& c) {
    for (const auto& [n, bad] : c.bad_parts) {
        if (c.replay) break;  // no part is simulated
        if (n < 1) return core::make_error("virtual cell: bad part " + std::to_string(n) + " < 1");
        if (c.master_parts.contains(n))
            return core::make_error("virtual cell: part " + std::to_string(n) +
                                    " is the master, which is never bad");
        std::mt19937_64 check_rng;
        if (auto part = build_part(c, n, check_rng); !part)
            return core::make_error("virtual cell: bad part " + std::to_string(n) + ": " +
                                    part.error().message);
    }
    return {};
}

}  // namespace

sim::SimOptions part_options(const sim::SimOptions& base, int n) {
    sim::SimOptions o = base;
    const long long k = n - 1LL;
    o.seed = base.seed + static_cast<std::uint64_t>(k);
    o.temperature_c = base.temperature_c + static_cast<double>((k * 37 + 100) % 201 - 100);
    return o;
}

sim::SimOptions conveyor_options(const VirtualCellConfig& c, int n) {
    if (c.master_parts.contains(n)) return c.master;
    sim::SimOptions o = part_options(c.part, n);
    if (const auto it = c.bad_parts.find(n); it != c.bad_parts.end())
        for (const auto& [name, delta] : it->second) o.bad_mm[name] += delta;
    return o;
}

struct VirtualCell::Impl {
    VirtualCellConfig config;
    // The face the sensor is at: set at start, then by the axis (another thread).
    std::atomic<const sim::FaceConfig*> face{nullptr};
    std::unique_ptr<AxisServer> axis;
    std::unique_ptr<plc::PyrometerSimulator> pyrometer;
    std::optional<sim::Vibration> vibration;
    std::optional<acquire::Triangulation> triangulation;
    std::int64_t t0_ns = 0;  // the vibration's time origin
    std::unique_ptr<GvDevice> device;
    std::unique_ptr<RecordingPlayer> player;  // replay: what the camera and accelerometer send

    // Stream thread (the device's renderer) only.
    sim::RandomStream render_rng{0};
    std::vector<sim::RayReturn> returns;
    std::vector<std::uint16_t> words, profile_rows;
    std::uint64_t acquisition = 0;
    std::int64_t t_scan_start_ns = 0;
    bool warned_format = false;

    // The part on the support: the renderer takes a snapshot per frame, the loader swaps it.
    mutable std::mutex part_mutex;
    // part, requested and stop_loader are guarded by part_mutex; `axis` and `pyrometer` are set
    // before the loader starts, and reset after it stops.
    std::shared_ptr<const LoadedPart> part;
    int requested = 0;  // a part request the loader has not taken yet
    bool stop_loader = false;
    std::condition_variable loader_wake;
    std::atomic<int> loaded{0};  // register 7's value, changed under part_mutex
    std::thread loader_thread;

    // Accelerometer thread.
    std::optional<accel::UdpAccelSender> sender;
    std::thread accel_thread;
    std::atomic<bool> stop{false};

    mutable std::mutex stats_mutex;
    VirtualCellStats stats;

    ~Impl() {
        stop = true;
        {
            std::lock_guard lock(part_mutex);
            stop_loader = true;
        }
        loader_wake.notify_one();
        if (loader_thread.joinable()) loader_thread.join();  // it reports to the axis
        axis.reset();
        if (accel_thread.joinable()) accel_thread.join();
        device.reset();  // stops the renderer's thread before what it renders from goes
    }

    // Where the sensor is when the camera stamps `camera_ns`: the camera's clock runs
    // cell.clock_offset_ns behind the accelerometer's (the true time), the axis travels
    // travel_scale × the commanded speed (sim::with_geometry).
    Eigen::Vector3d sensor_origin(std::int64_t camera_ns) const {
        const sim::FaceConfig* f = face.load();
        const double travel_mm = config.speed_mm_s * f->travel_scale *
                                 static_cast<double>(camera_ns - t_scan_start_ns) * 1e-9;
        const std::int64_t t_ns = camera_ns + config.cell.clock_offset_ns;
        const Eigen::Vector3d u =
            vibration->displacement_mm(static_cast<double>(t_ns - t0_ns) * 1e-9);
        return f->T_world_camera.translation() + travel_mm * f->scan_direction.normalized() + u;
    }

    std::shared_ptr<const LoadedPart> current_part() const {
        std::lock_guard lock(part_mutex);
        return part;
    }

    double temperature_c() const {
        if (player) return player->recording().temperature_c.value_or(kNoReadingC);
        return current_part()->options.temperature_c;
    }

    // Register 7, the pyrometer and the renderer all change to `p` at once, under the lock, so
    // that a newer request (which sets register 7 to 0 under it too) is never overtaken.
    void publish(std::shared_ptr<const LoadedPart> p) {
        if (pyrometer) pyrometer->set_temperature(p->options.temperature_c);
        loaded = p->number;
        if (axis) axis->set_part_loaded(p->number);
        part = std::move(p);
    }

    core::Result<void> load_first_part(std::mt19937_64& rng);
    core::Result<void> start_axis(int initial_face);
    void request_part(int n);  // the axis thread: returns at once
    void run_loader();
    void render(FrameRequest& req, std::span<std::uint8_t> data);
    void run_accel();
    void run_replay_accel();
};

// Part 1 on the support before the renderer runs (`rng` goes on to seed the scan), or, for a
// replay, the recording's player.
core::Result<void> VirtualCell::Impl::load_first_part(std::mt19937_64& rng) {
    VirtualCellConfig& c = config;
    if (c.replay) {
        auto made = make_player(c);
        if (!made) return made.error();
        player = std::move(*made);
        c.device.renderer_paces = true;
    } else {
        auto first = build_part(c, 1, rng);
        if (!first) return first.error();
        if (auto ok = write_part_truth(c, **first); !ok) return ok.error();
        part = std::move(*first);  // before the renderer runs
    }
    return {};
}

// The robot/axis controller's Modbus server, at face `initial_face` (1-based).
core::Result<void> VirtualCell::Impl::start_axis(int initial_face) {
    AxisServerConfig ac;
    ac.bind = config.axis_bind;
    ac.port = config.axis_port;
    ac.n_faces = static_cast<int>(config.cell.faces.size());
    ac.initial_face = initial_face;
    ac.move_time_s = config.axis_move_s;
    Impl* raw = this;
    auto started = AxisServer::start(
        ac,
        [raw](int f) {
            const auto& faces = raw->config.cell.faces;
            raw->face = &faces[static_cast<std::size_t>(f - 1)];
            detail::log().info("axis: at face {} ({})", f,
                               faces[static_cast<std::size_t>(f - 1)].name);
        },
        [raw](int n) { raw->request_part(n); });
    if (!started) return started.error();
    std::lock_guard lock(part_mutex);  // its thread may already be asking for a part
    axis = std::move(*started);
    axis->set_part_loaded(loaded);
    return {};
}

void VirtualCell::Impl::request_part(int n) {
    if (player) {  // a replay has one part, the recording's: it is there at once
        std::lock_guard lock(part_mutex);
        loaded = n;
        if (axis) axis->set_part_loaded(n);
        return;
    }
    {
        std::lock_guard lock(part_mutex);
        requested = n;  // a newer request supersedes one not yet loaded
        loaded = 0;
        if (axis) axis->set_part_loaded(0);
    }
    loader_wake.notify_one();
    detail::log().info("part {} requested", n);
}

// Builds parts off the render, stream and axis threads: Scene::create takes a while.
void VirtualCell::Impl::run_loader() {
    std::unique_lock lock(part_mutex);
    while (true) {
        loader_wake.wait(lock, [this] { return stop_loader || requested != 0; });
        if (stop_loader) return;
        const int n = std::exchange(requested, 0);
        lock.unlock();
        std::mt19937_64 rng;
        auto built = build_part(config, n, rng);
        core::Result<void> written = built ? write_part_truth(config, **built) : built.error();
        lock.lock();
        if (!written) {  // register 7 stays 0: the PLC's load times out, as with a jammed feeder
            detail::log().error("part {} not loaded: {}", n, written.error().message);
            continue;
        }
        if (requested != 0 || stop_loader) continue;  // superseded meanwhile
        const sim::SimOptions& o = (*built)->options;
        detail::log().info("part {} loaded: seed {}, {} °C", n, o.seed, o.temperature_c);
        publish(std::move(*built));
    }
}

void VirtualCell::Impl::render(FrameRequest& req, std::span<std::uint8_t> data) {
    if (player) {
        player->render(req, data, face.load()->name, stop);
        return;
    }
    const std::shared_ptr<const LoadedPart> p = current_part();  // one part for the whole frame
    const sim::Scene& scene = p->scene;
    if (req.acquisition != acquisition) {
        acquisition = req.acquisition;
        t_scan_start_ns = req.timestamp_ns;
        std::lock_guard lock(stats_mutex);
        ++stats.acquisitions;
    }
    if (config.mode == "image") {
        sim::ProfileEffects effects;  // the image's own noise replaces the range noise;
        effects.range_noise = false;  // reflections are drawn as second stripes
        effects.spikes = false;
        scene.cast_profile(*face.load(), sensor_origin(req.timestamp_ns), render_rng, returns,
                           effects);
        StripeLook look = config.look;
        look.full_scale = req.bytes_per_pixel == 1 ? 255 : config.look.full_scale;
        render_stripe(returns, *triangulation, look, req.exposure_us,
                      look.glow * glow_scale(p->options.temperature_c), req.width, req.height,
                      req.offset_x, req.offset_y, req.bytes_per_pixel, render_rng, data);
        return;
    }
    const int rpp = config.peaks.rows_per_profile();
    if (req.bytes_per_pixel != 2 || req.height < rpp) {
        if (!warned_format)
            detail::log().warn(
                "peaks mode needs Mono16 frames of at least {} rows (got {} bytes "
                "per pixel, {} rows): sending empty frames",
                rpp, req.bytes_per_pixel, req.height);
        warned_format = true;
        return;
    }
    const int profiles = req.height / rpp;
    const auto w = static_cast<std::size_t>(req.width);
    words.assign(w * static_cast<std::size_t>(req.height), 0);
    const auto period_ns = static_cast<std::int64_t>(std::llround(config.line_period_s * 1e9));
    const bool multipart = config.device.multipart_parts >= 2;
    profile_rows.resize(w * static_cast<std::size_t>(rpp));
    for (int k = 0; k < profiles; ++k) {
        const std::int64_t t = req.timestamp_ns + k * period_ns;
        scene.cast_profile(*face.load(), sensor_origin(t), render_rng, returns);
        render_peaks(returns, *triangulation, config.peaks, req.width, req.offset_x,
                     config.peak_row_offset, profile_rows.data());
        // One frame: the profile's rows together; multi-part: row kind j of every profile in
        // part j (range, then intensity, ...).
        for (int j = 0; j < rpp; ++j) {
            const std::size_t row = multipart ? static_cast<std::size_t>(j * profiles + k)
                                              : static_cast<std::size_t>(k * rpp + j);
            std::memcpy(words.data() + row * w,
                        profile_rows.data() + static_cast<std::size_t>(j) * w, w * 2);
        }
    }
    std::memcpy(data.data(), words.data(), std::min(data.size(), words.size() * 2));
}

// Replay: the record of the face being scanned as its samples' time comes, silent otherwise.
void VirtualCell::Impl::run_replay_accel() {
    while (!stop) {
        std::this_thread::sleep_for(std::chrono::duration<double>(config.accel_datagram_s));
        for (const auto& d : player->due(core::realtime_ns())) {
            const bool ok = sender->send(d.t_ns, d.period_ns, d.samples).ok();
            std::lock_guard lock(stats_mutex);
            if (ok) {
                ++stats.accel_datagrams;
                stats.accel_samples += d.samples.size() / 3;
            } else {
                ++stats.accel_send_errors;
            }
        }
    }
}

void VirtualCell::Impl::run_accel() {
    if (player) return run_replay_accel();
    const auto& a = config.cell.accel;
    const auto period_ns = static_cast<std::int64_t>(std::llround(1e9 / a.rate_hz));
    const auto per_datagram =
        static_cast<std::size_t>(std::clamp(std::llround(a.rate_hz * config.accel_datagram_s), 1LL,
                                            static_cast<long long>(accel::kDatagramMaxSamples)));
    sim::RandomStream rng(config.part.seed ^ 0xacce1);
    const sim::FaceConfig* at = face.load();
    sim::AccelHead head(a, at->T_world_camera.linear() * at->R_camera_accel, rng);
    std::int64_t next_ns =
        (core::realtime_ns() / period_ns + 1) * period_ns;  // samples on a fixed grid
    std::vector<float> batch;
    while (!stop) {
        std::this_thread::sleep_for(std::chrono::duration<double>(config.accel_datagram_s));
        const std::int64_t now = core::realtime_ns();
        if (const sim::FaceConfig* f = face.load(); f != at) {  // the axis moved the head
            at = f;
            head.set_R_world_accel(at->T_world_camera.linear() * at->R_camera_accel);
        }
        while (next_ns + static_cast<std::int64_t>(per_datagram - 1) * period_ns <= now) {
            batch.clear();
            for (std::size_t q = 0; q < per_datagram; ++q) {
                const std::int64_t t = next_ns + static_cast<std::int64_t>(q) * period_ns;
                const Eigen::Vector3f s =
                    head.sample(*vibration, static_cast<double>(t - t0_ns) * 1e-9, rng);
                batch.insert(batch.end(), s.data(), s.data() + 3);
            }
            const bool ok =
                sender->send(next_ns, static_cast<std::uint32_t>(period_ns), batch).ok();
            next_ns += static_cast<std::int64_t>(per_datagram) * period_ns;
            std::lock_guard lock(stats_mutex);
            if (ok) {
                ++stats.accel_datagrams;
                stats.accel_samples += per_datagram;
            } else {
                ++stats.accel_send_errors;
            }
        }
    }
}

VirtualCell::VirtualCell(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
VirtualCell::~VirtualCell() = default;

sim::SimTruth VirtualCell::truth() const {
    const auto p = impl_->current_part();
    return p ? p->scene.truth() : sim::SimTruth{};
}
double VirtualCell::part_temperature_c() const { return impl_->temperature_c(); }
EncodeStats VirtualCell::replay_stats() const {
    return impl_->player ? impl_->player->stats() : EncodeStats{};
}
int VirtualCell::part_loaded() const { return impl_->loaded; }

int VirtualCell::axis_port() const { return impl_->axis ? impl_->axis->port() : -1; }

VirtualCellStats VirtualCell::stats() const {
    std::lock_guard lock(impl_->stats_mutex);
    VirtualCellStats s = impl_->stats;
    s.camera = impl_->device->stats();
    return s;
}

core::Result<std::unique_ptr<VirtualCell>> VirtualCell::start(VirtualCellConfig config) {
    auto impl = std::make_unique<Impl>();
    impl->config = std::move(config);
    VirtualCellConfig& c = impl->config;
    if (auto ok = check_config(c); !ok) return ok.error();
    const int initial = face_number(c);
    impl->face = &c.cell.faces[static_cast<std::size_t>(initial - 1)];
    if (auto ok = check_bad_parts(c); !ok) return ok.error();
    std::mt19937_64 rng;
    if (auto ok = impl->load_first_part(rng); !ok) return ok.error();
    impl->loaded = 1;
    std::mt19937_64 scan_rng(c.part.scan_seed ? *c.part.scan_seed : rng());
    impl->vibration.emplace(c.cell.vibration, 0.0, kServeHorizonS, scan_rng);
    impl->render_rng = sim::RandomStream(scan_rng());
    auto tri = sensor_triangulation(c.cell.sensor);
    if (!tri) return tri.error();
    impl->triangulation.emplace(std::move(*tri));
    impl->t0_ns = core::realtime_ns();

    if (!c.accel_to.empty()) {
        auto sender = accel::UdpAccelSender::open(c.accel_to, c.accel_sensor_id);
        if (!sender) return sender.error();
        impl->sender.emplace(std::move(*sender));
    }
    if (c.pyrometer) {
        auto pyro = plc::PyrometerSimulator::start(*c.pyrometer, 0, 0.1);
        if (!pyro) return core::make_error("virtual cell: pyrometer: " + pyro.error().message);
        impl->pyrometer = std::move(*pyro);
        impl->pyrometer->set_temperature(impl->temperature_c());
    }
    Impl* raw = impl.get();
    auto device = GvDevice::start(c.device, [raw](FrameRequest& req, std::span<std::uint8_t> data) {
        raw->render(req, data);
    });
    if (!device) return device.error();
    impl->device = std::move(*device);
    if (c.axis_port >= 0)
        if (auto ok = impl->start_axis(initial); !ok) return ok.error();
    impl->loader_thread = std::thread([raw] { raw->run_loader(); });
    if (impl->sender) impl->accel_thread = std::thread([raw] { raw->run_accel(); });
    detail::log().info("virtual cell: face {}, {} mode, {} mm/s, accelerometer {}, pyrometer {}",
                       c.face, c.mode, c.speed_mm_s,
                       c.accel_to.empty() ? "off" : "-> " + c.accel_to,
                       c.pyrometer ? "on " + c.pyrometer->device : "off");
    return std::unique_ptr<VirtualCell>(new VirtualCell(std::move(impl)));
}

}  // namespace hotgauge::vcell
