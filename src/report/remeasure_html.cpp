// The page of `hotgauge remeasure`: remeasure_html() (docs/results.md).
#include <optional>
#include <string>

#include "hotgauge/report/html.hpp"
#include "hotgauge/report/remeasure_report.hpp"

namespace hotgauge::report {
namespace {

constexpr double kUmPerMm = 1000;

// The lot report's look (lot_html.cpp), for the tables this page has.
const char* kStyle = R"(
body{font-family:DejaVu Sans,Arial,sans-serif;margin:16px;color:#222}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #bbb;padding:2px 6px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}
tr.worse td{background:#ffebee}tr.better td{background:#e8f5e9}
.stopped{border:2px solid #ef6c00;background:#fff3e0;padding:6px 10px;font-weight:bold}
)";

std::string cell(const std::string& v) { return "<td>" + v + "</td>"; }
std::string text_cell(const std::string& v) { return "<td class='l'>" + escape(v) + "</td>"; }
std::string mm_cell(const std::optional<double>& v) {
    return cell(v ? fixed(*v, 4) : "\u2212");  // never a number for a value not measured
}
std::string um_cell(double mm) { return cell(fixed(mm * kUmPerMm, 1, true)); }
std::string verdicts_cell(const results::VerdictFlip& f) {
    return text_cell(f.before + " \u2192 " + f.after);
}

// "as archived" when the parts were measured with what the archive holds.
std::string as_given(const std::string& what) {
    return what.empty() ? "as archived" : "<code>" + escape(what) + "</code>";
}

std::string header(const results::Comparison& c, const RemeasureInfo& info) {
    std::string s = "<h1>" + escape(info.title) + "</h1><p>Results read from <code>" +
                    escape(info.results_dir) + "</code>; measured again into <code>" +
                    escape(info.out_dir) + "</code> with the recipe " + as_given(info.recipe) +
                    " and the calibration " + as_given(info.calibration) + ".</p>";
    s += "<p>" + std::to_string(info.parts_in_range) + " parts in the range, " +
         std::to_string(info.parts_measured) + " measured again, " + std::to_string(c.parts) +
         " compared, in " + fixed(info.wall_s, 1) + " s.";
    if (!info.generated_at.empty()) s += " Generated " + escape(info.generated_at) + ".";
    s += "</p>";
    if (info.stopped)
        s += "<p class='stopped'>Stopped before the end (Ctrl-C): this page covers only the " +
             std::to_string(info.parts_measured) + " parts measured before the stop.</p>";
    return s;
}

std::string summary(const results::Comparison& c) {
    const std::size_t worse = c.count("OK", "NOK"), better = c.count("NOK", "OK");
    return "<p class='summary'><strong>" + std::to_string(c.unchanged) + " of " +
           std::to_string(c.parts) +
           " parts unchanged</strong> (every verdict and value the same). " +
           "Part verdicts changed: " + std::to_string(c.part_flips.size()) +
           ". Feature verdicts changed: " + std::to_string(c.flips.size()) + " (OK \u2192 NOK " +
           std::to_string(worse) + ", NOK \u2192 OK " + std::to_string(better) + ", other " +
           std::to_string(c.flips.size() - worse - better) + ").</p>";
}

// OK → NOK red, NOK → OK green: the two a quality engineer acts on.
const char* row_class(const results::VerdictFlip& f) {
    if (f.before == "OK" && f.after == "NOK") return " class='worse'";
    if (f.before == "NOK" && f.after == "OK") return " class='better'";
    return "";
}

std::string part_flips_table(const results::Comparison& c) {
    if (c.part_flips.empty()) return "<h2>Part verdicts changed</h2><p>None.</p>";
    std::string s =
        "<h2>Part verdicts changed</h2><table class='part-flips'><tr><th>sequence</th>"
        "<th class='l'>part</th><th class='l'>before \u2192 after</th></tr>";
    for (const results::VerdictFlip& f : c.part_flips)
        s += "<tr" + std::string(row_class(f)) + ">" + cell(std::to_string(f.sequence)) +
             text_cell(f.part_id) + verdicts_cell(f) + "</tr>";
    return s + "</table>";
}

std::string flips_table(const results::Comparison& c) {
    if (c.flips.empty()) return "<h2>Feature verdicts changed</h2><p>None.</p>";
    std::string s =
        "<h2>Feature verdicts changed</h2><p>Cold values (20 \u00b0C), mm. ABSENT: the "
        "feature is not in that measurement's recipe.</p><table class='flips'><tr>"
        "<th>sequence</th><th class='l'>part</th><th class='l'>feature</th>"
        "<th class='l'>before \u2192 after</th><th>before</th><th>after</th></tr>";
    for (const results::VerdictFlip& f : c.flips)
        s += "<tr" + std::string(row_class(f)) + ">" + cell(std::to_string(f.sequence)) +
             text_cell(f.part_id) + text_cell(f.feature) + verdicts_cell(f) + mm_cell(f.before_mm) +
             mm_cell(f.after_mm) + "</tr>";
    return s + "</table>";
}

std::string shifts_table(const results::Comparison& c) {
    std::string s =
        "<h2>Shift per feature</h2><p>After \u2212 before, \u00b5m, over the parts with a value "
        "both times.</p><table class='shifts'><tr><th class='l'>feature</th><th>parts</th>"
        "<th>mean</th><th>worst</th><th class='l'>worst part</th></tr>";
    for (const results::FeatureShift& f : c.shifts) {
        s += "<tr>" + text_cell(f.feature) + cell(std::to_string(f.n));
        if (!f.n) {
            s += "<td colspan='3' class='l'>no value both times</td></tr>";
            continue;
        }
        s += um_cell(f.mean_mm) + um_cell(f.worst_mm) +
             text_cell(std::to_string(f.worst_sequence) + " " + f.worst_part_id) + "</tr>";
    }
    return s + "</table>";
}

std::string not_remeasured_table(const results::Comparison& c) {
    if (c.not_remeasured.empty()) return "<h2>Parts not measured again</h2><p>None.</p>";
    std::string s =
        "<h2>Parts not measured again</h2><table class='not-remeasured'><tr><th>sequence</th>"
        "<th class='l'>part</th><th class='l'>why</th></tr>";
    for (const results::NotRemeasured& n : c.not_remeasured)
        s += "<tr>" + cell(std::to_string(n.sequence)) + text_cell(n.part_id) + text_cell(n.why) +
             "</tr>";
    return s + "</table>";
}

}  // namespace

std::string remeasure_html(const results::Comparison& c, const RemeasureInfo& info) {
    return "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>" +
           escape(info.title) + "</title><style>" + kStyle + "</style></head><body>" +
           header(c, info) + summary(c) + part_flips_table(c) + flips_table(c) + shifts_table(c) +
           not_remeasured_table(c) + "</body></html>\n";
}

}  // namespace hotgauge::report
