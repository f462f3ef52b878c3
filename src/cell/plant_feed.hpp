#pragma once
// What leaves the cell for the plant (docs/plant-data.md): results, state and health to the MQTT
// broker (plant::Publisher, through its disk spool) and the metrics plant IT scrapes
// (plant::Metrics behind web::Server::start_metrics). Neither is part of measuring: what cannot
// start is logged and shown in the health, and the cell measures on without it.
// Thread safety: every member may be called from any of the daemon's threads.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/accel/ring.hpp"
#include "hotgauge/acquire/session.hpp"
#include "hotgauge/cell/config.hpp"
#include "hotgauge/cell/health.hpp"
#include "hotgauge/plant/metrics.hpp"
#include "hotgauge/plant/mqtt.hpp"
#include "hotgauge/web/server.hpp"

namespace hotgauge::cell {

// One part's outcome as the metrics count it.
struct PartMetrics {
    std::string verdict;            // the results file's part.verdict; "" when not stored
    std::uint16_t fault = 0;        // the PLC's fault code, 0 for none
    std::optional<double> scan_s;   // trigger -> scans done
    std::optional<double> cycle_s;  // trigger -> DONE (or the fault)
    std::vector<std::pair<std::string, double>> stage_ms;  // the pipeline's stages
};

class PlantFeed {
  public:
    // Starts what the config names; `ring` (may be null) is read at every scrape.
    PlantFeed(const DaemonConfig& config, const accel::AccelRing* ring);
    ~PlantFeed();
    PlantFeed(const PlantFeed&) = delete;
    PlantFeed& operator=(const PlantFeed&) = delete;

    // The results file's JSON line of a part, to the spool; false (and logged) when refused.
    bool result(const std::string& jsonl_line, std::uint64_t sequence);
    void part(const PartMetrics& m);
    void refused(std::uint16_t fault);  // a trigger refused before it became a part
    void scanned(const acquire::ScanOutcome& scan);
    void state(const std::string& state_text);
    void health(const DeviceHealth& h);
    DeviceStatus link_status() const;  // the plant link's health: Device::kPlantLink
    std::string metrics_text();
    const web::Server* metrics_server() const { return metrics_web_.get(); }

  private:
    void declare();
    void refresh_gauges();
    void catch_up(const std::filesystem::path& results_dir);

    plant::Metrics metrics_;
    std::unique_ptr<plant::Publisher> mqtt_;
    std::string mqtt_problem_;  // why there is no publisher although one is configured
    std::string broker_;        // "host:port", for the health's detail
    std::unique_ptr<web::Server> metrics_web_;
    const accel::AccelRing* ring_;
    std::string site_, cell_;
    mutable std::mutex mutex_;
    std::uint16_t published_health_bits_ = 0xFFFF;  // what the retained health last said
    DeviceHealth last_health_;
};

}  // namespace hotgauge::cell
