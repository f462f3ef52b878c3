// The daemon's control thread (daemon_state.hpp): PLC events, sequence numbers, the part a
// crash left unfinished, reload, health and shutdown.
#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>
#include <set>

#include "daemon_state.hpp"
#include "hotgauge/cell/journal.hpp"
#include "hotgauge/core/clock.hpp"
#include "plc_result.hpp"

namespace hotgauge::cell {
namespace {

// The PLC's face register → the cell's face name (docs/plc-modbus.md).
const char* face_name(plc::Face f) {
    switch (f) {
        case plc::Face::kTop:
            return "top";
        case plc::Face::kBottom:
            return "bottom";
        case plc::Face::kSide1:
            return "side1";
        case plc::Face::kSide2:
            return "side2";
        case plc::Face::kAll:
            break;
    }
    return "";
}

// The faces to scan: all faces the recipe's features need, in the configured order; or the one
// face the PLC asked for.
std::vector<std::string> faces_to_scan(const Setup& s, const core::Recipe& recipe, plc::Face f) {
    if (f != plc::Face::kAll) return {face_name(f)};
    std::set<std::string> needed;
    for (const auto& feature : recipe.features)
        needed.insert(feature.faces.begin(), feature.faces.end());
    std::vector<std::string> out;
    for (const auto& name : s.config.faces)
        if (needed.count(name)) out.push_back(name);
    return out;
}

// What PlantFeed was started with, to tell a reload that changes it (it needs a restart).
std::string plant_settings(const DaemonConfig& c) {
    std::string s = c.metrics.bind_address + ":" + std::to_string(c.metrics.port) +
                    (c.metrics.enabled ? "+" : "-");
    if (const auto& m = c.mqtt)
        s += "|" + m->host + ":" + std::to_string(m->port) + "/" + m->site + "/" + m->cell + "/" +
             m->client_id + "/" + m->username + "/" + m->password_file.string() + "/" +
             m->tls.ca_file.string() + "/" + m->tls.cert_file.string() + "/" +
             m->spool.dir.string() + "/" + std::to_string(m->spool.max_bytes) + "/" +
             std::to_string(m->keepalive_s);
    return s;
}

}  // namespace

void Daemon::Impl::control_loop() {
    set_state("idle: waiting for a trigger");
    while (!stop) {
        if (auto ev = server->wait_event(kLoopPeriod)) on_event(*ev);
        if (reload && in_flight == 0) apply_reload();
        if (healthy() && sup.watchdog) sup.watchdog();
        update_health();
        if (in_flight == 0) {
            const auto st = server->state();
            mark_taken(st);
            set_state(st == plc::State::kFault ? "fault: waiting for the PLC's reset"
                                               : "idle: waiting for a trigger");
        }
    }
}

// The devices' health into the PLC's registers and the stats, every control loop; a device that
// changes between working and not is logged once each way.
void Daemon::Impl::update_health() {
    constexpr std::int64_t kAccelSilentNs = 500'000'000;
    const Setup& s = *setup;
    const std::int64_t now = core::realtime_ns();
    DeviceHealth h;
    h.updated_ns = now;
    h[Device::kCamera] = devices.status(Device::kCamera, true, now);
    h[Device::kAxis] = devices.status(Device::kAxis, s.config.axis.kind == "modbus", now);
    h[Device::kAccelerometer] = ring ? accelerometer_status(*ring, now, kAccelSilentNs)
                                     : DeviceStatus{false, false, "not configured"};
    h[Device::kPyrometer] =
        pyrometer ? pyrometer_status(*pyrometer) : DeviceStatus{false, false, "not configured"};
    std::string last_store_error;
    {
        std::lock_guard lock(stats_mutex);
        last_store_error = store_error;
    }
    h[Device::kResultsDisk] =
        disk_status(s.config.results.dir, s.config.results_min_free_mb, last_store_error);
    h[Device::kPlantLink] = plant->link_status();
    plc::CellStatus cs = calibration_status(s.calibration.calibrated_at, s.calibration.measured(),
                                            s.config.calibration_interval_days, now);
    cs.device_faults = h.fault_bits();
    DeviceHealth before;
    {
        std::lock_guard lock(stats_mutex);
        cs.expected_scan_s = scan_times.median();
        cs.expected_cycle_s = cycle_times.median();
        before = std::exchange(stats.health, h);
    }
    server->set_cell_status(cs);
    board->set_health(h);
    plant->health(h);
    const bool first = before.updated_ns == 0;  // then only what is not working is news
    for (int d = 0; d < kDeviceCount; ++d) {
        const DeviceStatus &was = before.devices[d], &is = h.devices[d];
        if (!is.configured || (first ? is.ok : was.ok == is.ok)) continue;
        const std::string what = "device health: " + std::string(to_string(Device(d))) +
                                 (is.ok ? " working again: " : " NOT working: ") + is.detail;
        if (is.ok)
            spdlog::info("{}", what);
        else
            spdlog::warn("{}", what);
        board->event(what, !is.ok);  // the status page's recent events
    }
}

void Daemon::Impl::on_event(const plc::PlcEvent& ev) {
    if (ev.kind == plc::PlcEvent::Kind::kReset) {
        if (in_flight > 0) {
            std::lock_guard lock(stats_mutex);
            abandoned = stats.next_sequence - 1;
            spdlog::warn("PLC reset during part sequence {}: the cycle is abandoned",
                         abandoned.load());
        }
        return;
    }
    const plc::TriggerRequest& t = ev.trigger;
    const auto r = setup->recipes.find(t.recipe_slot);
    if (r == setup->recipes.end())
        return refuse(t, "slot " + std::to_string(t.recipe_slot),
                      "no recipe in slot " + std::to_string(t.recipe_slot),
                      plc::ErrorCode::kUnknownRecipe);
    std::optional<Unfinished> before;
    {
        std::lock_guard lock(stats_mutex);
        before.swap(unfinished);  // only the next trigger can be that part again
    }
    const bool same_part =
        before && t.part_id != 0 && before->part_id == t.part_id && before->slot == t.recipe_slot;
    if (same_part && !before->committed_line.empty() && show_again(t, *before)) return;
    const auto sequence = take_sequence(t.part_id, t.recipe_slot);
    if (!sequence) {  // a number not kept is not used; the part triggered again is still that one
        std::lock_guard lock(stats_mutex);
        if (!unfinished) unfinished = std::move(before);
    }
    if (!sequence)
        return refuse(t, r->second.name,
                      "no sequence number can be kept: " + sequence.error().message,
                      plc::ErrorCode::kNotStored);
    Job job;
    job.trigger = t;
    job.setup = setup;
    job.triggered = Clock::now();
    job.sequence = *sequence;
    open_cycle = job.sequence;
    if (same_part && before->committed_line.empty()) job.remeasure_of = before->sequence;
    {
        std::lock_guard lock(stats_mutex);
        ++stats.triggers;
    }
    job.recipe = &r->second;
    job.faces = faces_to_scan(*setup, r->second, t.face);
    ++in_flight;
    set_state("busy: part " + std::to_string(t.part_id) + " (seq " + std::to_string(job.sequence) +
              ")");
    if (!jobs.try_push(std::move(job))) {  // the handshake allows one cycle at a time
        --in_flight;
        spdlog::error("trigger while a part is queued: PLC fault 205");
        server->fault(code(plc::ErrorCode::kInternal));
    }
}

// A trigger refused before it becomes a part: no sequence number, no row; the PLC and the
// journal get the reason.
void Daemon::Impl::refuse(const plc::TriggerRequest& t, const std::string& recipe,
                          const std::string& reason, plc::ErrorCode error) {
    const std::string why = "part " + std::to_string(t.part_id) + ": " + reason + ": PLC fault " +
                            std::to_string(code(error));
    log_part({0, std::to_string(t.part_id), recipe, "FAULT", why, true});
    board->event(why, true);
    server->fault(code(error));
    plant->refused(code(error));
    std::lock_guard lock(stats_mutex);
    ++stats.triggers;
    ++stats.failed;
}

// The PLC took the committed result of the last part numbered (acknowledged DONE, or reset a
// FAULT or its cycle): its cycle is over, and a restart now has nothing to show again. A part
// whose result never committed stays in its cycle until measured again.
void Daemon::Impl::mark_taken(plc::State st) {
    if (st != plc::State::kIdle || !sequences || !sequences->last().unfinished()) return;
    const std::uint64_t n = sequences->reserved();
    // Only a cycle this run opened (or showed again): a number the last run left open stays so
    // until its part is triggered again.
    if (open_cycle != n || committed_seq != n || taken_failed == n) return;
    if (auto ok = sequences->taken(); !ok) {
        taken_failed = n;  // said once; the next part's number rewrites the line
        spdlog::warn("{}", ok.error().message);
    }
}

// The part the last run had numbered when it died (no clean stop after it), and whether its
// result committed (it is then the results files' last line).
void Daemon::Impl::find_unfinished(const fs::path& dir) {
    if (!sequences) return;
    const auto& last = sequences->last();
    if (!last.unfinished() || last.sequence == 0 || last.part_id == 0) return;  // 0: no id
    Unfinished u{last.sequence, last.part_id, last.slot, {}};
    const auto lines = results::last_result_lines(dir, 1);
    if (!lines.empty()) {
        const auto j = nlohmann::json::parse(lines.back(), nullptr, false);
        if (j.is_object() && j.value("sequence", std::uint64_t{0}) == last.sequence)
            u.committed_line = lines.back();
    }
    spdlog::warn(
        "the last run stopped during or after part {} (seq {}), whose result {}; if the "
        "PLC triggers it again, {}",
        u.part_id, u.sequence, u.committed_line.empty() ? "never committed" : "committed",
        u.committed_line.empty() ? "it is measured under a new number"
                                 : "that result is shown again");
    std::lock_guard lock(stats_mutex);
    unfinished = std::move(u);
}

// A part whose result committed before a crash, triggered again: the PLC is shown that result
// (its sequence, values and verdicts, as kept in the line), nothing is measured or written.
// False, and the part is measured, when that result was a fault (the PLC triggers again to have
// it measured) or the line does not say what the PLC was shown (written before this was kept).
bool Daemon::Impl::show_again(const plc::TriggerRequest& t, const Unfinished& u) {
    auto shown = plc_from_json(u.committed_line);
    if (!shown || shown->fault) {
        spdlog::warn("part {} seq {}: its committed result {}; measured again", t.part_id,
                     u.sequence,
                     shown ? "was FAULT " + std::to_string(shown->fault)
                           : "cannot be shown again (" + shown.error().message + ")");
        return false;
    }
    open_cycle = u.sequence;  // taken once the PLC acknowledges it
    std::string outcome;
    if (auto ok = server->finish(t.trigger_id, shown->result); !ok) {
        outcome = "not published: " + ok.error().message;
    } else {
        outcome = plc::to_string(shown->result.overall);
    }
    const auto j = nlohmann::json::parse(u.committed_line);
    const std::string recipe = j.at("part").value("recipe", std::string());
    log_part({u.sequence, std::to_string(t.part_id), recipe, plc::to_string(shown->result.overall),
              "part " + std::to_string(t.part_id) + " seq " + std::to_string(u.sequence) +
                  " triggered again after a restart: its result had committed before the "
                  "restart and is shown again, not measured again: " +
                  outcome,
              false});
    std::lock_guard lock(stats_mutex);
    ++stats.triggers;
    return true;
}

// The numbers used in `dir`: numbering goes on past them and past the files' last one.
void Daemon::Impl::open_sequences(const fs::path& dir) {
    auto r = results::SequenceReservation::open(dir);
    if (!r) {
        sequences.reset();
        sequences_error = r.error().message;
        spdlog::error("{}: parts fault 206 until it can be written", sequences_error);
        return;
    }
    const std::uint64_t there = std::max(results::last_sequence(dir), r->reserved());
    sequences.emplace(std::move(*r));
    sequences_error.clear();
    std::lock_guard lock(stats_mutex);
    stats.next_sequence = std::max(stats.next_sequence, there + 1);
}

// The next part's number, kept before it is used: a part whose result never reaches the files,
// or a crash during it, must not give it to the next part too. A number that could not be kept
// is not taken.
core::Result<std::uint64_t> Daemon::Impl::take_sequence(std::uint32_t part_id, std::uint16_t slot) {
    if (!sequences) open_sequences(setup->config.results.dir);  // the folder may be back
    if (!sequences) return core::make_error(sequences_error);
    std::uint64_t n = 0;
    {
        std::lock_guard lock(stats_mutex);
        n = stats.next_sequence;
    }
    if (auto kept = sequences->reserve(n, part_id, slot); !kept) return kept.error();
    std::lock_guard lock(stats_mutex);
    stats.next_sequence = n + 1;
    return n;
}

void Daemon::Impl::apply_reload() {
    reload = false;
    const fs::path file = setup->config.file;
    spdlog::info("reloading {}", file.string());
    auto next = load_setup(file);
    if (!next) {
        spdlog::error("reload REJECTED, the running configuration is kept: {}",
                      next.error().message);
        {
            std::lock_guard lock(stats_mutex);
            ++stats.rejected_reloads;
            reload_note = "reload rejected at " + core::iso8601_utc(core::realtime_ns()) + ": " +
                          next.error().message;
        }
        publish_status();
        return;
    }
    const auto& a = setup->config;
    const auto& b = (*next)->config;
    // These run for the whole life of the process; a change needs a restart.
    if (a.plc.port != b.plc.port || a.plc.bind_address != b.plc.bind_address)
        spdlog::warn("reload: the PLC server's address changes only at a restart");
    if (a.accelerometer.has_value() != b.accelerometer.has_value() ||
        (a.pyrometer.has_value() != b.pyrometer.has_value()))
        spdlog::warn("reload: accelerometer and pyrometer sources change only at a restart");
    if (a.status_page.enabled != b.status_page.enabled ||
        a.status_page.port != b.status_page.port ||
        a.status_page.bind_address != b.status_page.bind_address)
        spdlog::warn("reload: the status page's address changes only at a restart");
    if (plant_settings(a) != plant_settings(b))
        spdlog::warn("reload: the MQTT broker and the metrics endpoint change only at a restart");
    if (a.results.dir != b.results.dir) open_sequences(b.results.dir);  // numbering goes on
    setup = std::move(*next);
    spdlog::info("reloaded: config hash {}\n{}", setup->config.hash, describe(*setup));
    {
        std::lock_guard lock(stats_mutex);
        ++stats.reloads;
        reload_note.clear();
    }
    publish_status();
}

bool Daemon::Impl::healthy() const {
    // A worker that has not come round its loop for longer than its longest step (a face's scan
    // and an axis move, or the pipeline) is stuck: the watchdog then lets systemd restart us.
    const auto& c = setup->config;
    const double limit_s = c.acquisition.scan_s + c.axis.timeout_ms * 1e-3 +
                           c.acquisition.camera.timeout_ms * 1e-3 * 10 + 30.0;
    const auto limit_ns = static_cast<std::int64_t>(limit_s * 1e9);
    const std::int64_t now = steady_ns();
    return now - acq_beat < limit_ns && now - proc_beat < limit_ns;
}

void Daemon::Impl::shutdown() {
    if (shut_down) return;
    shut_down = true;
    if (sup.stopping) sup.stopping("stopping");
    // Workers finish (or fail, and report) the part in progress, then leave.
    const auto deadline = Clock::now() + std::chrono::seconds(60);
    while (in_flight > 0 && Clock::now() < deadline) {
        if (auto ev = server->wait_event(kLoopPeriod);
            ev && ev.value().kind == plc::PlcEvent::Kind::kTrigger)
            server->fault(code(plc::ErrorCode::kDeviceLost));  // no new part while stopping
    }
    workers_stop = true;
    if (acquisition_thread.joinable()) acquisition_thread.join();
    if (processing_thread.joinable()) processing_thread.join();
    if (accel) accel->stop();
    // A result the PLC has not taken yet (or a part to measure again) stays open for the next
    // start, clean stop or not.
    mark_taken(server->state());
    if (sequences && in_flight == 0 && sequences->last().state == 'D')
        if (auto ok = sequences->stopped(); !ok) spdlog::warn("{}", ok.error().message);
    web.reset();    // the page shows the state up to the last part
    plant.reset();  // the broker is told "offline"; what is spooled stays for the next start
}

// The page is a window on the cell, not part of measuring: if it cannot listen, the cell runs
// without it and says so (log and page of faults), rather than stopping the line.
void Daemon::Impl::start_status_page() {
    const HttpEndpointConfig& sp = setup->config.status_page;
    if (!sp.enabled) return;
    web::ServerConfig wc;
    wc.bind_address = sp.bind_address;
    wc.port = sp.port;
    wc.roots = board->roots();
    auto started = web::Server::start(wc, [this] {
        web::CellView v = board->view();
        v.plc_state = plc::to_string(server->state());
        return v;
    });
    if (!started) {
        spdlog::error("{}: the cell runs without it", started.error().message);
        board->event(started.error().message, true);
        return;
    }
    web = std::move(*started);
    spdlog::info("status page on {}", web->url());
}

}  // namespace hotgauge::cell
