#include "plant_feed.hpp"

#include <spdlog/spdlog.h>

#include <nlohmann/json.hpp>

#include "hotgauge/core/clock.hpp"
#include "hotgauge/results/results_log.hpp"

namespace hotgauge::cell {
namespace {

using plant::MetricType;

const std::vector<double> kCycleBuckets = {0.5, 1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 30, 60};
const std::vector<double> kStageBuckets = {0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10};

// "idle: waiting for a trigger" -> "idle"
std::string state_word(const std::string& text) { return text.substr(0, text.find(':')); }

nlohmann::json stamped(const std::string& site, const std::string& cell) {
    const std::int64_t now = core::realtime_ns();
    return {{"site", site}, {"cell", cell}, {"time", core::iso8601_utc(now)}, {"time_ns", now}};
}

// configured and ok of every device: a change of either is news for the retained health.
std::uint16_t health_key(const DeviceHealth& h) {
    std::uint16_t key = 0;
    for (int d = 0; d < kDeviceCount; ++d)
        key |= static_cast<std::uint16_t>((h.devices[d].configured ? 1u : 0u) << d |
                                          (h.devices[d].ok ? 1u : 0u) << (d + 8));
    return key;
}

}  // namespace

PlantFeed::PlantFeed(const DaemonConfig& config, const accel::AccelRing* ring) : ring_(ring) {
    declare();
    metrics_.set("hotgauge_build_info", {{"version", HOTGAUGE_VERSION}}, 1);
    if (config.mqtt) {
        site_ = config.mqtt->site;
        cell_ = config.mqtt->cell;
        broker_ = config.mqtt->host + ":" + std::to_string(config.mqtt->port);
        if (auto p = plant::Publisher::start(*config.mqtt))
            mqtt_ = std::move(*p);
        else
            mqtt_problem_ = p.error().message;
        if (!mqtt_)
            spdlog::error("MQTT: {}: results go only to the PLC and the files", mqtt_problem_);
        else
            spdlog::info("MQTT: publishing to {} under {}", broker_, mqtt_->topic("#"));
        if (mqtt_) catch_up(config.results.dir);
    }
    if (config.metrics.enabled) {
        web::ServerConfig wc;
        wc.bind_address = config.metrics.bind_address;
        wc.port = config.metrics.port;
        auto s = web::Server::start_metrics(wc, [this] { return metrics_text(); });
        if (s) {
            metrics_web_ = std::move(*s);
            spdlog::info("metrics on {}metrics", metrics_web_->url());
        } else {
            spdlog::error("{}: the cell runs without it", s.error().message);
        }
    }
}

PlantFeed::~PlantFeed() {
    metrics_web_.reset();  // no scrape reads the publisher while it goes
    mqtt_.reset();         // says "offline" (retained) before it disconnects
}

void PlantFeed::declare() {
    auto& m = metrics_;
    m.declare("hotgauge_build_info", MetricType::kGauge, "The daemon's version (value 1).");
    m.declare("hotgauge_cycles_total", MetricType::kCounter,
              "Parts stored in the results files, by the files' verdict.");
    m.declare("hotgauge_faults_total", MetricType::kCounter,
              "Cycles that ended in a PLC fault, by fault code (docs/plc-modbus.md).");
    m.declare("hotgauge_cycle_seconds", MetricType::kHistogram, "Trigger to DONE or fault.",
              kCycleBuckets);
    m.declare("hotgauge_scan_seconds", MetricType::kHistogram,
              "Trigger to scans done (the part may move).", kCycleBuckets);
    m.declare("hotgauge_stage_seconds", MetricType::kHistogram,
              "The pipeline's stages, wall time per part.", kStageBuckets);
    m.declare("hotgauge_camera_scans_total", MetricType::kCounter, "Face scans made.");
    m.declare("hotgauge_camera_frames_total", MetricType::kCounter,
              "Camera frames received in scans.");
    m.declare("hotgauge_camera_frames_refused_total", MetricType::kCounter,
              "Frames refused (wrong size, timestamp not after the previous).");
    m.declare("hotgauge_camera_profile_points_total", MetricType::kCounter,
              "Profile points by what the peak finder saw.");
    m.declare("hotgauge_accel_samples_total", MetricType::kCounter,
              "Accelerometer samples stored since start.");
    m.declare("hotgauge_accel_gaps_total", MetricType::kCounter,
              "Gaps in the accelerometer stream since start.");
    m.declare("hotgauge_accel_missing_samples_total", MetricType::kCounter,
              "Samples estimated lost in those gaps.");
    m.declare("hotgauge_accel_last_sample_age_seconds", MetricType::kGauge,
              "Age of the newest accelerometer sample.");
    m.declare("hotgauge_device_up", MetricType::kGauge,
              "1 when a configured device works (PLC input 113), 0 when not.");
    m.declare("hotgauge_mqtt_connected", MetricType::kGauge, "1 when connected to the broker.");
    m.declare("hotgauge_mqtt_published_total", MetricType::kCounter,
              "Results the broker acknowledged since start.");
    m.declare("hotgauge_mqtt_spool_depth", MetricType::kGauge,
              "Results in the spool waiting for the broker.");
    m.declare("hotgauge_mqtt_spool_bytes", MetricType::kGauge, "Their size in bytes.");
    m.declare("hotgauge_mqtt_spool_refused_total", MetricType::kCounter,
              "Results the spool refused (full or not writable) since start.");
    m.declare("hotgauge_mqtt_connect_failures", MetricType::kGauge,
              "Failed connection attempts since the last success.");
}

bool PlantFeed::result(const std::string& jsonl_line, std::uint64_t sequence) {
    if (!mqtt_) return true;
    if (auto ok = mqtt_->result(jsonl_line); !ok) {
        spdlog::error("seq {}: not spooled for the broker (it is in the results files): {}",
                      sequence, ok.error().message);
        return false;
    }
    return true;
}

// After a crash between a part's commit and its spooling: the committed results after the
// spool's newest, spooled now and in order (docs/plant-data.md "Nothing lost"). A spool never
// written to starts after the results files' last line (none: with the first part).
void PlantFeed::catch_up(const std::filesystem::path& results_dir) {
    const auto sequence = [](const std::string& line) -> std::optional<std::uint64_t> {
        const auto j = nlohmann::json::parse(line, nullptr, false);
        if (!j.is_object() || !j.contains("sequence") || !j["sequence"].is_number_unsigned())
            return std::nullopt;
        return j["sequence"].get<std::uint64_t>();
    };
    const auto newest = mqtt_->last_result();
    if (!newest) {
        const auto lines = results::last_result_lines(results_dir, 1);
        if (auto ok = mqtt_->start_after(lines.empty() ? R"({"sequence":0})" : lines.back()); !ok)
            spdlog::warn("MQTT: {}", ok.error().message);
        return;
    }
    const auto after = sequence(*newest);
    if (!after) return;
    std::vector<std::uint64_t> spooled;
    for (const auto& line :
         results::last_result_lines(results_dir, results::ResultsLog::kRecoverLines)) {
        const auto n = sequence(line);
        if (!n || *n <= *after) continue;
        if (!result(line, *n)) break;  // refused: said, and the order kept
        spooled.push_back(*n);
    }
    if (!spooled.empty())
        spdlog::warn(
            "MQTT: spooled sequences {}..{} ({} results) from the results files: the "
            "daemon had stopped after committing them, before spooling",
            spooled.front(), spooled.back(), spooled.size());
}

void PlantFeed::part(const PartMetrics& p) {
    if (!p.verdict.empty()) metrics_.add("hotgauge_cycles_total", {{"verdict", p.verdict}});
    if (p.fault) metrics_.add("hotgauge_faults_total", {{"code", std::to_string(p.fault)}});
    if (p.scan_s) metrics_.observe("hotgauge_scan_seconds", {}, *p.scan_s);
    if (p.cycle_s) metrics_.observe("hotgauge_cycle_seconds", {}, *p.cycle_s);
    for (const auto& [stage, ms] : p.stage_ms)
        metrics_.observe("hotgauge_stage_seconds", {{"stage", stage}}, ms * 1e-3);
}

void PlantFeed::refused(std::uint16_t fault) {
    metrics_.add("hotgauge_faults_total", {{"code", std::to_string(fault)}});
}

void PlantFeed::scanned(const acquire::ScanOutcome& scan) {
    const auto& s = scan.scan;
    metrics_.add("hotgauge_camera_scans_total", {});
    metrics_.add("hotgauge_camera_frames_total", {}, static_cast<double>(s.frames));
    metrics_.add("hotgauge_camera_frames_refused_total", {}, static_cast<double>(s.refused_frames));
    const std::pair<const char*, std::int64_t> points[] = {{"ok", s.ok},
                                                           {"no_return", s.no_return},
                                                           {"dark", s.dark},
                                                           {"saturated", s.saturated},
                                                           {"double_peak", s.double_peak}};
    for (const auto& [what, n] : points)
        metrics_.add("hotgauge_camera_profile_points_total", {{"quality", what}},
                     static_cast<double>(n));
}

void PlantFeed::state(const std::string& state_text) {
    if (!mqtt_) return;
    auto j = stamped(site_, cell_);
    j["state"] = state_word(state_text);
    j["detail"] = state_text;
    j["software_version"] = HOTGAUGE_VERSION;
    mqtt_->state(j.dump());
}

void PlantFeed::health(const DeviceHealth& h) {
    {
        std::lock_guard lock(mutex_);
        last_health_ = h;
        if (!mqtt_ || health_key(h) == published_health_bits_) return;
        published_health_bits_ = health_key(h);
    }
    auto j = stamped(site_, cell_);
    j["faults"] = h.fault_bits();  // as at the PLC's input 113
    for (int d = 0; d < kDeviceCount; ++d) {
        const DeviceStatus& s = h.devices[d];
        j["devices"][to_string(Device(d))] = {
            {"configured", s.configured}, {"ok", s.ok}, {"detail", s.detail}};
    }
    mqtt_->health(j.dump());
}

DeviceStatus PlantFeed::link_status() const {
    if (!mqtt_ && mqtt_problem_.empty()) return {false, false, "not configured"};
    if (!mqtt_) return {true, false, mqtt_problem_};
    const plant::PublisherStatus s = mqtt_->status();
    const std::string spooled = std::to_string(s.spool.depth) + " result(s) in the spool";
    if (s.spool.full || !s.spool.error.empty())
        return {true, false,
                "the spool refuses results (" +
                    (s.spool.error.empty() ? std::string("full") : s.spool.error) + "); " +
                    spooled};
    if (!s.connected) return {true, false, "broker " + broker_ + ": " + s.problem + "; " + spooled};
    return {true, true, "connected to " + broker_ + "; " + spooled};
}

void PlantFeed::refresh_gauges() {
    DeviceHealth h;
    {
        std::lock_guard lock(mutex_);
        h = last_health_;
    }
    for (int d = 0; d < kDeviceCount; ++d)
        if (h.devices[d].configured)
            metrics_.set("hotgauge_device_up", {{"device", to_string(Device(d))}},
                         h.devices[d].ok ? 1 : 0);
    if (ring_) {
        const accel::AccelRingStats a = ring_->stats();
        metrics_.set("hotgauge_accel_samples_total", {}, static_cast<double>(a.stored));
        metrics_.set("hotgauge_accel_gaps_total", {}, static_cast<double>(a.gaps));
        metrics_.set("hotgauge_accel_missing_samples_total", {},
                     static_cast<double>(a.missing_samples));
        if (a.newest_ns)
            metrics_.set("hotgauge_accel_last_sample_age_seconds", {},
                         static_cast<double>(core::realtime_ns() - *a.newest_ns) * 1e-9);
    }
    if (!mqtt_) return;
    const plant::PublisherStatus s = mqtt_->status();
    metrics_.set("hotgauge_mqtt_connected", {}, s.connected ? 1 : 0);
    metrics_.set("hotgauge_mqtt_published_total", {}, static_cast<double>(s.published));
    metrics_.set("hotgauge_mqtt_spool_depth", {}, static_cast<double>(s.spool.depth));
    metrics_.set("hotgauge_mqtt_spool_bytes", {}, static_cast<double>(s.spool.bytes));
    metrics_.set("hotgauge_mqtt_spool_refused_total", {}, static_cast<double>(s.spool.refused));
    metrics_.set("hotgauge_mqtt_connect_failures", {}, static_cast<double>(s.attempts));
}

std::string PlantFeed::metrics_text() {
    refresh_gauges();
    return metrics_.text();
}

}  // namespace hotgauge::cell
