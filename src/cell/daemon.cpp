// The daemon's lifecycle (daemon_state.hpp): start (devices, results, threads), run, stop.
#include <spdlog/spdlog.h>

#include "daemon_state.hpp"

namespace hotgauge::cell {

Daemon::Daemon(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Daemon::~Daemon() {
    impl_->stop = true;
    impl_->shutdown();
}

core::Result<std::unique_ptr<Daemon>> Daemon::start(std::shared_ptr<const Setup> setup,
                                                    Supervisor supervisor) {
    auto impl = std::make_unique<Impl>();
    impl->setup = setup;
    impl->sup = std::move(supervisor);
    const DaemonConfig& c = setup->config;
    impl->board = std::make_unique<StatusBoard>(c.results.dir, c.archive.dir);
    // Numbering goes on after the highest number used (.sequence) or committed (the files); the
    // PLC's input 5 starts at the last committed one.
    const std::uint64_t committed = results::last_sequence(c.results.dir);
    impl->committed_seq = committed;
    impl->stats.next_sequence = committed + 1;
    impl->open_sequences(c.results.dir);
    impl->find_unfinished(c.results.dir);
    // What a crash left half done (a CSV row, an archive folder) is completed before the PLC is
    // served (docs/results.md "One commit per part"); the plant spool's share when it starts.
    impl->prepare_results(setup);
    if (!impl->log) spdlog::error("results: {}", impl->log_error);
    if (c.accelerometer) {
        // Room for a whole part: every face, the moves and the margins, twice over.
        const double part_s = static_cast<double>(c.faces.size()) *
                                  (c.acquisition.scan_s + c.axis.timeout_ms * 1e-3) +
                              4 * c.accel_margin_s;
        impl->ring = std::make_unique<accel::AccelRing>(
            accel::AccelRingConfig{.capacity_s = 2 * part_s + 10.0,
                                   .sample_rate_hz = c.accel_rate_hz,
                                   .gap_periods = 3.0});
        auto src = accel::make_accel_source(*c.accelerometer, *impl->ring);
        if (!src) return core::make_error("accelerometer: " + src.error().message);
        impl->accel = std::move(*src);
        if (auto ok = impl->accel->start(); !ok)
            return core::make_error("accelerometer: " + ok.error().message);
    }
    if (c.pyrometer) {
        auto p = plc::Pyrometer::start(*c.pyrometer);
        if (!p) return core::make_error("pyrometer: " + p.error().message);
        impl->pyrometer = std::move(*p);
    }
    plc::ServerConfig plc = c.plc;  // the PLC's count goes on from the results files
    plc.first_sequence = static_cast<std::uint16_t>(committed & 0xFFFF);
    auto server = plc::Server::start(plc);
    if (!server) return server.error();
    impl->server = std::move(*server);
    // The camera: opened now so that the first part does not wait; if it is not there, the
    // first trigger tries again (and fails that part with the reason if it still is not).
    impl->prepare_acquisition(setup);
    if (impl->axis)  // its health known from the start, as the camera's
        impl->ask(Device::kAxis, [raw = impl.get()] { return raw->axis->check(); });
    const auto opening = Clock::now();
    const auto opened = impl->session->connect();
    impl->devices.answered(Device::kCamera, static_cast<bool>(opened),
                           opened ? "opened" : opened.error().message);
    if (!opened)
        spdlog::warn("camera {}: {} (retried at the first trigger)", c.acquisition.camera.id,
                     opened.error().message);
    else if (const auto took = std::chrono::duration_cast<milliseconds>(Clock::now() - opening);
             took > milliseconds(500))  // after a crash: the old control channel had to expire
        spdlog::info("camera {}: opened in {} ms", c.acquisition.camera.id, took.count());
    impl->start_status_page();
    impl->plant = std::make_unique<PlantFeed>(c, impl->ring.get());
    impl->acq_beat = impl->proc_beat = Impl::steady_ns();
    Impl* raw = impl.get();
    impl->acquisition_thread = std::thread([raw] { raw->acquisition_loop(); });
    impl->processing_thread = std::thread([raw] { raw->processing_loop(); });
    spdlog::info("hotgauged {} up: PLC on port {}, next sequence {}\n{}", HOTGAUGE_VERSION,
                 impl->server->port(), impl->stats.next_sequence, describe(*setup));
    if (impl->sup.ready) impl->sup.ready();
    return std::unique_ptr<Daemon>(new Daemon(std::move(impl)));
}

void Daemon::run() {
    impl_->control_loop();
    impl_->shutdown();
}

void Daemon::request_stop() { impl_->stop = true; }
void Daemon::request_reload() { impl_->reload = true; }
int Daemon::plc_port() const { return impl_->server->port(); }

DaemonStats Daemon::stats() const {
    std::lock_guard lock(impl_->stats_mutex);
    return impl_->stats;
}

}  // namespace hotgauge::cell
