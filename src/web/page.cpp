#include <nlohmann/json.hpp>

#include "hotgauge/core/text.hpp"
#include "hotgauge/web/cell_view.hpp"

namespace hotgauge::web {
namespace {

using core::html_escape;

constexpr const char* kStyle = R"(<style>
body{font-family:sans-serif;margin:1em;background:#fafafa;color:#222}
h1{font-size:1.3em;margin:0 0 .5em}h2{font-size:1.1em;margin:1.2em 0 .4em}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}
th{background:#eee}.OK{background:#c8f0c8}.NOK,.fault,.bad{background:#f6c0c0}
.DEGRADED,.warning{background:#f8e8b0}.NOT_MEASURED,.unconfigured{background:#ddd}
.feature{display:inline-block;margin:1px;padding:0 4px;border:1px solid #bbb;font-size:.85em}
figure{display:inline-block;margin:0 1em 0 0}
img{border:1px solid #888;max-width:16em;height:auto;image-rendering:pixelated}
#results td:nth-child(2){white-space:nowrap}
</style>)";

std::string verdict_cell(const std::string& verdict) {
    return "<td class=\"" + html_escape(verdict) + "\">" + html_escape(verdict) + "</td>";
}

std::string devices_html(const CellView& v) {
    std::string h = "<h2>Devices</h2>";
    if (v.health_updated.empty()) return h + "<p id=\"health\">not reported yet</p>";
    h += "<p id=\"health\">as of " + html_escape(v.health_updated) +
         "</p><table id=\"devices\"><tr><th>device</th><th>state</th><th>detail</th></tr>";
    for (const auto& d : v.devices) {
        const char* state = !d.configured ? "not configured" : d.ok ? "ok" : "FAULT";
        const char* cls = !d.configured ? "unconfigured" : d.ok ? "OK" : "bad";
        h += "<tr class=\"device\" data-ok=\"" + std::string(d.ok ? "1" : "0") + "\"><td>" +
             html_escape(d.name) + "</td><td class=\"" + cls + "\">" + state + "</td><td>" +
             html_escape(d.detail) + "</td></tr>";
    }
    return h + "</table>";
}

// One box per feature, coloured by its verdict: name, value, and the verdict and reason
// unless OK.
std::string features_html(const ResultView& r) {
    std::string h;
    for (const auto& f : r.features)
        h += "<span class=\"feature " + html_escape(f.verdict) + "\" data-name=\"" +
             html_escape(f.name) + "\" data-verdict=\"" + html_escape(f.verdict) + "\">" +
             html_escape(f.name) + " " +
             (f.value_mm ? core::fixed(*f.value_mm, 3) : std::string("—")) +
             (f.verdict == "OK" ? "" : " " + html_escape(f.verdict)) +
             (f.reason.empty() ? "" : ": " + html_escape(f.reason)) + "</span> ";
    return h;
}

std::string results_html(const CellView& v) {
    std::string h = "<h2>Last results</h2>";
    if (v.results.empty()) return h + "<p>no part since the start</p>";
    h += "<table id=\"results\"><tr><th>seq</th><th>time</th><th>part</th><th>recipe</th>"
         "<th>verdict</th><th>PLC got</th><th>features</th></tr>";
    for (const auto& r : v.results)
        h += "<tr class=\"result\" data-sequence=\"" + std::to_string(r.sequence) +
             "\" data-part=\"" + html_escape(r.part_id) + "\" data-verdict=\"" +
             html_escape(r.verdict) + "\"><td>" + std::to_string(r.sequence) + "</td><td>" +
             html_escape(r.time) + "</td><td>" + html_escape(r.part_id) + "</td><td>" +
             html_escape(r.recipe) + "</td>" + verdict_cell(r.verdict) + "<td>" +
             html_escape(r.outcome) + "</td><td>" + features_html(r) + "</td></tr>";
    return h + "</table>";
}

std::string pictures_html(const CellView& v) {
    std::string h = "<h2>Last part's range images</h2>";
    if (!v.pictures_sequence) return h + "<p>no part scanned since the start</p>";
    h += "<p id=\"pictures\" data-sequence=\"" + std::to_string(*v.pictures_sequence) + "\">part " +
         html_escape(v.pictures_part_id) + ", seq " + std::to_string(*v.pictures_sequence) +
         " (drawn in " + core::fixed(v.pictures_ms, 0) + " ms)</p>";
    for (const auto& p : v.pictures)
        h += "<figure><img class=\"range\" alt=\"" + html_escape(p.face) + "\" src=\"" +
             html_escape(picture_href(*v.pictures_sequence, p.face)) + "\" width=\"" +
             std::to_string(p.width) + "\" height=\"" + std::to_string(p.height) +
             "\"><figcaption>" + html_escape(p.face) + "</figcaption></figure>";
    return h;
}

std::string events_html(const CellView& v) {
    std::string h = "<h2>Recent faults and warnings</h2>";
    if (v.events.empty()) return h + "<p>none since the start</p>";
    h += "<table id=\"events\">";
    for (const auto& e : v.events)
        h += "<tr class=\"" + std::string(e.fault ? "fault" : "warning") + "\"><td>" +
             html_escape(e.time) + "</td><td>" + html_escape(e.text) + "</td></tr>";
    return h + "</table>";
}

std::string files_html(const CellView& v) {
    std::string h = "<h2>Results files</h2><ul id=\"files\">";
    for (const auto& l : v.files)
        h += "<li><a href=\"" + html_escape(l.href) + "\">" + html_escape(l.label) + "</a></li>";
    return h + "</ul>";
}

}  // namespace

std::string picture_href(std::uint64_t sequence, const std::string& face) {
    return "/pictures/" + std::to_string(sequence) + "/" + face + ".png";
}

std::string render_status_page(const CellView& v) {
    return "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\">"
           "<meta http-equiv=\"refresh\" content=\"" +
           std::to_string(v.refresh_s) + "\"><title>hotgauged: " + html_escape(v.state) +
           "</title>" + kStyle + "</head><body><h1>hotgauged</h1><table><tr><th>daemon</th>" +
           "<td id=\"state\">" + html_escape(v.state) +
           "</td></tr><tr><th>PLC</th><td id=\"plc\">" + html_escape(v.plc_state) +
           "</td></tr></table>" + pictures_html(v) + results_html(v) + devices_html(v) +
           events_html(v) + files_html(v) +
           "<p><a href=\"/status.json\">status.json</a> · read-only; reloads every " +
           std::to_string(v.refresh_s) + " s</p></body></html>\n";
}

std::string render_status_json(const CellView& v) {
    using nlohmann::json;
    json j{{"state", v.state}, {"plc_state", v.plc_state}};
    j["health_updated"] = v.health_updated.empty() ? json() : json(v.health_updated);
    j["devices"] = json::array();
    for (const auto& d : v.devices)
        j["devices"].push_back(
            {{"name", d.name}, {"configured", d.configured}, {"ok", d.ok}, {"detail", d.detail}});
    j["results"] = json::array();
    for (const auto& r : v.results) {
        json features = json::array();
        for (const auto& f : r.features)
            features.push_back({{"name", f.name},
                                {"value_mm", f.value_mm ? json(*f.value_mm) : json()},
                                {"verdict", f.verdict},
                                {"reason", f.reason}});
        j["results"].push_back({{"sequence", r.sequence},
                                {"time", r.time},
                                {"part_id", r.part_id},
                                {"recipe", r.recipe},
                                {"verdict", r.verdict},
                                {"outcome", r.outcome},
                                {"features", std::move(features)}});
    }
    j["events"] = json::array();
    for (const auto& e : v.events)
        j["events"].push_back({{"time", e.time}, {"text", e.text}, {"fault", e.fault}});
    j["files"] = json::array();
    for (const auto& l : v.files) j["files"].push_back({{"label", l.label}, {"href", l.href}});
    json pictures = json::array();
    for (const auto& p : v.pictures)
        pictures.push_back({{"face", p.face},
                            {"width", p.width},
                            {"height", p.height},
                            {"href", picture_href(*v.pictures_sequence, p.face)}});
    j["pictures"] = {{"sequence", v.pictures_sequence ? json(*v.pictures_sequence) : json()},
                     {"part_id", v.pictures_part_id},
                     {"ms", v.pictures_ms},
                     {"faces", std::move(pictures)}};
    // Replace, not throw, should a text ever carry bytes that are not UTF-8.
    return j.dump(1, ' ', false, json::error_handler_t::replace) + "\n";
}

}  // namespace hotgauge::web
