#pragma once
// The daemon's configuration (config/hotgauged.yaml, docs/operations.md "Configuration"): one
// YAML file for the whole cell, read and validated at start (and again at SIGHUP) with every
// error naming file:line:key, and `hotgauged --check-config` to check it before a restart.
// Paths in it are relative to the file's folder.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hotgauge/accel/source.hpp"
#include "hotgauge/acquire/camera.hpp"
#include "hotgauge/acquire/scan.hpp"
#include "hotgauge/acquire/session.hpp"
#include "hotgauge/cell/quality_feed.hpp"
#include "hotgauge/compensate/compensate.hpp"
#include "hotgauge/core/part.hpp"
#include "hotgauge/core/result.hpp"
#include "hotgauge/io/bytes.hpp"
#include "hotgauge/plant/mqtt.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/server.hpp"
#include "hotgauge/results/archive.hpp"
#include "hotgauge/results/results_log.hpp"

namespace hotgauge::cell {

// A read-only HTTP endpoint: the status page (docs/operations.md "Status page") or the metrics
// (docs/plant-data.md "Metrics"). Without its section there is none: no port opens that the
// config does not name.
struct HttpEndpointConfig {
    bool enabled = false;
    std::string bind_address = "127.0.0.1";  // loopback: this computer only
    int port = 8080;                         // 0: an ephemeral port (tests; the log names it)
};

// The robot or axis that takes the sensor from face to face (vcell/axis_server.hpp's map).
struct AxisConfig {
    std::string kind = "none";  // none: the sensor does not move (one face, or moved by others)
    std::string address;        // modbus: HOST:PORT
    int unit_id = 1;
    std::map<std::string, int> faces;  // face name -> the controller's position number
    int timeout_ms = 10'000;           // a move that takes longer is a fault
};

struct AcquisitionConfig {
    acquire::CameraConfig camera;
    acquire::ScanConfig scan;  // frame mode, stripe/peaks settings, speed, line period, offsets
    std::vector<std::pair<double, double>> exposure_table;  // (°C, µs), increasing °C
    double scan_s = 2.5;                                    // each face's scan
};

// The pipeline's settings that `hotgauge measure` takes as options, so that the daemon measures
// as the tool does with the same ones (docs/operations.md "Configuration", `pipeline:`). The
// part's own (matching.min_score, sampling) are in its recipe.
struct PipelineSettings {
    bool compensate = true;  // false: as --no-compensation (with an accelerometer configured)
    double highpass_hz = compensate::CompensationConfig{}.highpass_hz;  // --highpass-hz
    int threads = 0;  // --threads: matching and measuring; 0: one per core
};

struct DaemonConfig {
    std::filesystem::path file;              // where it was read from
    std::filesystem::path calibration_file;  // the cell's measured geometry (calib)
    // Older than this, the calibration is due (PLC input 119, the status page); the quality
    // department's interval.
    int calibration_interval_days = 180;
    std::map<int, std::filesystem::path> recipes;  // PLC recipe slot -> recipe file
    std::map<int, std::filesystem::path> models;   // optional saved .hgm models per slot
    // Master slots (docs/verification.md): slot -> the master's certificate; the slot's recipe
    // measures it and the result is a verification.
    std::map<int, std::filesystem::path> masters;
    std::vector<std::string> faces;  // scan order for "all faces"
    AcquisitionConfig acquisition;
    PipelineSettings pipeline;
    std::optional<accel::AccelSourceConfig> accelerometer;  // absent: no compensation
    double accel_margin_s = 0.75;
    // The sensor's sample rate: sizes the ring and sets its gap threshold (a datagram whose
    // period differs by more than 1 % is logged once).
    double accel_rate_hz = 4000.0;
    AxisConfig axis;
    plc::ServerConfig plc;
    std::optional<plc::PyrometerConfig> pyrometer;  // absent: the temperature comes from nowhere
    results::ResultsConfig results;
    results::ArchiveConfig archive;
    QualityConfig quality;           // results.drift_baseline, .lot_report, .lot_report_every_s
    int results_min_free_mb = 1024;  // less free space on the results disk: a device fault
    HttpEndpointConfig status_page;
    HttpEndpointConfig metrics{false, "127.0.0.1", 9464};
    // The plant's MQTT broker (docs/plant-data.md); absent: results leave only through the PLC
    // and the files.
    std::optional<plant::MqttConfig> mqtt;
    std::string hash;  // of the file's bytes: goes with every result
};

// FNV-1a over each file's name and bytes and then `extra`, as 16 hex digits: a hash of
// everything that decided a result (daemon.hpp's Setup::result_hash).
std::string files_hash(const std::vector<std::filesystem::path>& files, const std::string& extra);

// The recipe file's 16-bit revision for the PLC (input 118, `hotgauge plc map --recipe`): its
// bytes' FNV-1a, folded; any edit changes it (with odds 1 in 65 536 of a repeat).
std::uint16_t recipe_revision(const std::filesystem::path& recipe_file);

// A recipe as this cell can run it (issue 40): at most plc::kMaxFeatures features, each on its
// own slot within the register map's kMaxFeatures blocks, and, with `faces` (hotgauged.yaml's
// `faces:`), every face a feature needs among those the cell scans (a forging's diameter needs
// only its first face). The error names the recipe file, the feature and its slot or face.
core::Result<void> check_recipe_for_cell(const core::Recipe& recipe,
                                         const std::filesystem::path& file,
                                         const std::vector<std::string>* faces);

// Reads and validates; errors name file:line and the key. Referenced files (recipes, models,
// the calibration) must exist; their content is checked by their own readers at start.
core::Result<DaemonConfig> read_daemon_config(const std::filesystem::path& file);
// The same on the file's text: `file` names it in errors and is the folder referenced files are
// found in; `exists` is asked whether they exist.
core::Result<DaemonConfig> parse_daemon_config(std::string_view text,
                                               const std::filesystem::path& file,
                                               const io::PathExists& exists = io::exists_on_disk);

}  // namespace hotgauge::cell
