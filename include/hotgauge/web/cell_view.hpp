#pragma once
// What the status page shows (docs/operations.md "Status page"): a plain snapshot of the cell,
// filled by the daemon (cell::StatusBoard) and rendered here, so that web knows nothing of cell.
// Times are text as the results files write them (local time with its UTC offset).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace hotgauge::web {

struct DeviceView {
    std::string name;  // "camera"
    bool configured = false, ok = false;
    std::string detail;
};

struct FeatureView {
    std::string name;
    std::optional<double> value_mm;  // cold value as in the results files; empty: not measured
    std::string verdict;             // OK, NOK, NOT_MEASURED, DEGRADED
    std::string reason;
};

struct ResultView {
    std::uint64_t sequence = 0;
    std::string time, part_id, recipe;
    std::string verdict;  // the part's overall verdict, as in the results files
    std::string outcome;  // what the PLC got: the verdict, or the fault and its reason
    std::vector<FeatureView> features;
};

struct EventView {
    std::string time, text;
    bool fault = false;  // else a warning
};

struct LinkView {
    std::string label, href;  // href: a path of this server ("/results/2026-12-04.csv")
};

struct PictureView {
    std::string face;
    int width = 0, height = 0;
    std::shared_ptr<const std::vector<std::uint8_t>> png;  // shared: a snapshot copies no bytes
};

struct CellView {
    std::string state;      // the daemon's, as in systemd's STATUS=
    std::string plc_state;  // the handshake's: idle, busy, done, fault
    // Empty: no device health reported yet.
    std::string health_updated;
    std::vector<DeviceView> devices;
    std::vector<ResultView> results;  // newest first
    std::vector<EventView> events;    // faults and warnings, newest first
    std::vector<LinkView> files;
    // The last part with scans: its range image per face.
    std::optional<std::uint64_t> pictures_sequence;
    std::string pictures_part_id;
    std::vector<PictureView> pictures;
    double pictures_ms = 0;  // what drawing and encoding them took
    int refresh_s = 2;       // the page reloads itself this often
};

// The page: server-side HTML, no script, no external resource; the pictures by URL
// (picture_href).
std::string render_status_page(const CellView& view);
// The same data for machines (docs/operations.md "Status page").
std::string render_status_json(const CellView& view);
// "/pictures/<sequence>/<face>.png": a picture's URL, tied to its part so that a page never
// shows another part's picture under its own.
std::string picture_href(std::uint64_t sequence, const std::string& face);

}  // namespace hotgauge::web
