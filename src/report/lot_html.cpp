// The lot report's page: lot_report_html() and its charts (docs/results.md "Lot report").
#include <algorithm>
#include <cmath>
#include <string>

#include "hotgauge/report/html.hpp"
#include "hotgauge/report/lot_report.hpp"

namespace hotgauge::report {
namespace {

// A number with `decimals` decimals; "−" for a non-finite one (nothing is invented).
std::string num(double v, int decimals) { return std::isfinite(v) ? fixed(v, decimals) : "\u2212"; }

// Linear map from [d0, d1] (data) to [p0, p1] (pixels); an empty data range maps to the middle.
struct Scale {
    double d0, d1, p0, p1;
    double operator()(double v) const {
        return d1 == d0 ? (p0 + p1) / 2 : p0 + (v - d0) * (p1 - p0) / (d1 - d0);
    }
};

constexpr double kChartW = 960, kLeft = 76, kRight = 16;

// "y" axis ticks and labels of one panel, 5 of them.
std::string y_axis(const Scale& y, int decimals) {
    std::string s;
    for (int k = 0; k <= 4; ++k) {
        const double v = y.d0 + (y.d1 - y.d0) * k / 4.0, py = y(v);
        s += "<line x1='" + num(kLeft - 4, 1) + "' x2='" + num(kChartW - kRight, 1) + "' y1='" +
             num(py, 1) + "' y2='" + num(py, 1) + "' class='grid'/><text x='" + num(kLeft - 6, 1) +
             "' y='" + num(py + 4, 1) + "' text-anchor='end'>" + num(v, decimals) + "</text>";
    }
    return s;
}

std::string hline(const Scale& y, double v, const char* cls, const std::string& label) {
    const std::string py = num(y(v), 1);
    return "<line x1='" + num(kLeft, 1) + "' x2='" + num(kChartW - kRight, 1) + "' y1='" + py +
           "' y2='" + py + "' class='" + cls + "'/><text x='" + num(kChartW - kRight - 2, 1) +
           "' y='" + num(y(v) - 3, 1) + "' text-anchor='end' class='" + cls + "'>" + escape(label) +
           "</text>";
}

std::string polyline(const Scale& x, const Scale& y, const std::vector<double>& v,
                     std::size_t first) {
    std::string pts;
    pts.reserve(16 * v.size());
    for (std::size_t i = first; i < v.size(); ++i)
        pts += num(x(double(i)), 1) + "," + num(y(v[i]), 1) + " ";
    return "<polyline class='data' points='" + pts + "'/>";
}

// The individuals chart's panel: values, baseline, centre and control limits, the tolerance
// when it is near, rule violations and the drift warning.
std::string individuals_panel(const FeatureLot& f, const Scale& x, double top, double h) {
    auto [mn, mx] = std::minmax_element(f.values.begin(), f.values.end());
    double lo = *mn, hi = *mx;
    if (f.chart) lo = std::min(lo, f.chart->lcl), hi = std::max(hi, f.chart->ucl);
    const double lsl = f.nominal_mm + f.lower_mm, usl = f.nominal_mm + f.upper_mm;
    const double near = std::max(hi - lo, 1e-6);
    if (lsl > lo - near) lo = std::min(lo, lsl);
    if (usl < hi + near) hi = std::max(hi, usl);
    const double pad = 0.06 * std::max(hi - lo, 1e-4);
    const Scale y{lo - pad, hi + pad, top + h, top};
    std::string s = y_axis(y, 4);
    if (f.chart) {
        s += "<rect class='baseline' x='" + num(x(0) - 2, 1) + "' y='" + num(top, 1) + "' width='" +
             num(x(double(f.baseline - 1)) - x(0) + 4, 1) + "' height='" + num(h, 1) + "'/>";
        s += hline(y, f.chart->centre, "centre", "x\u0304 " + num(f.chart->centre, 4));
        s += hline(y, f.chart->ucl, "limit", "UCL " + num(f.chart->ucl, 4));
        s += hline(y, f.chart->lcl, "limit", "LCL " + num(f.chart->lcl, 4));
    }
    if (lsl >= y.d0 && lsl <= y.d1) s += hline(y, lsl, "spec", "LSL " + num(lsl, 3));
    if (usl >= y.d0 && usl <= y.d1) s += hline(y, usl, "spec", "USL " + num(usl, 3));
    s += polyline(x, y, f.values, 0);
    for (const auto& v : f.violations)
        s += "<circle class='rule' r='3.5' cx='" + num(x(double(v.index)), 1) + "' cy='" +
             num(y(f.values[v.index]), 1) + "'><title>rule " + std::to_string(v.rule) + ", part " +
             std::to_string(f.sequences[v.index]) + "</title></circle>";
    if (f.drift_at)
        s += "<line class='drift' x1='" + num(x(double(*f.drift_at)), 1) + "' x2='" +
             num(x(double(*f.drift_at)), 1) + "' y1='" + num(top, 1) + "' y2='" + num(top + h, 1) +
             "'/><text class='drift' x='" + num(x(double(*f.drift_at)) + 4, 1) + "' y='" +
             num(top + 12, 1) + "'>drift warning, part " +
             std::to_string(f.sequences[*f.drift_at]) + "</text>";
    return s;
}

std::string moving_range_panel(const FeatureLot& f, const Scale& x, double top, double h) {
    std::vector<double> mr(f.values.size(), 0.0);
    for (std::size_t i = 1; i < mr.size(); ++i) mr[i] = std::abs(f.values[i] - f.values[i - 1]);
    double hi = *std::max_element(mr.begin(), mr.end());
    if (f.chart) hi = std::max(hi, f.chart->mr_ucl);
    const Scale y{0, std::max(hi * 1.08, 1e-4), top + h, top};
    std::string s = y_axis(y, 4);
    if (f.chart) {
        s += hline(y, f.chart->mr_bar, "centre", "MR\u0304 " + num(f.chart->mr_bar, 4));
        s += hline(y, f.chart->mr_ucl, "limit", "UCL " + num(f.chart->mr_ucl, 4));
    }
    return s + polyline(x, y, mr, 1);
}

// The parts' sequence numbers under the chart, at 6 places.
std::string x_axis(const FeatureLot& f, const Scale& x, double y) {
    std::string s = "<text x='4' y='" + num(y, 1) + "'>part</text>";
    for (int k = 0; k <= 5; ++k) {
        const auto i = std::size_t(std::lround(double(f.values.size() - 1) * k / 5.0));
        s += "<text x='" + num(x(double(i)), 1) + "' y='" + num(y, 1) + "' text-anchor='middle'>" +
             std::to_string(f.sequences[i]) + "</text>";
    }
    return s;
}

std::string chart_svg(const FeatureLot& f) {
    const double n = double(std::max<std::size_t>(f.values.size(), 2));
    const Scale x{0, n - 1, kLeft + 6, kChartW - kRight - 6};
    return "<svg class='chart' xmlns='http://www.w3.org/2000/svg' width='960' height='346' "
           "viewBox='0 0 960 346'><text x='4' y='14'>individuals (mm)</text>" +
           individuals_panel(f, x, 22, 200) + "<text x='4' y='244'>moving range (mm)</text>" +
           moving_range_panel(f, x, 252, 64) + x_axis(f, x, 338) + "</svg>";
}

// Histogram of the values against the tolerance: bins over the values, axis over both.
std::string histogram_svg(const FeatureLot& f) {
    const double lsl = f.nominal_mm + f.lower_mm, usl = f.nominal_mm + f.upper_mm;
    auto [mn, mx] = std::minmax_element(f.values.begin(), f.values.end());
    const std::size_t bins =
        std::clamp<std::size_t>(std::size_t(std::sqrt(f.values.size())), 5, 40);
    const double width = std::max(*mx - *mn, 1e-6) / double(bins);
    std::vector<std::size_t> count(bins, 0);
    for (double v : f.values) ++count[std::min(bins - 1, std::size_t((v - *mn) / width))];
    const double lo = std::min(lsl, *mn), hi = std::max(usl, *mx), pad = 0.05 * (hi - lo);
    const Scale x{lo - pad, hi + pad, 20, 460};
    const Scale y{0, double(*std::max_element(count.begin(), count.end())), 190, 24};
    std::string s =
        "<svg class='histogram' xmlns='http://www.w3.org/2000/svg' width='480' "
        "height='220' viewBox='0 0 480 220'><text x='4' y='14'>values against the "
        "tolerance (mm)</text>";
    // Values far inside a wide tolerance (a die shift of a few µm in [0, 0.5]) make bins narrower
    // than a pixel: each is drawn 2 px wide on whole pixels, not as an antialiased sliver.
    for (std::size_t b = 0; b < bins; ++b) {
        const double x0 = x(*mn + width * double(b)), x1 = x(*mn + width * double(b + 1));
        const bool thin = x1 - x0 < 2.0;
        s += "<rect class='bar' shape-rendering='crispEdges' x='" +
             num(thin ? std::floor(x0) : x0, 2) + "' y='" + num(y(double(count[b])), 1) +
             "' width='" + num(thin ? 2.0 : x1 - x0, 2) + "' height='" +
             num(190 - y(double(count[b])), 1) + "'/>";
    }
    auto vline = [&](double v, const char* cls, const std::string& label) {
        return "<line class='" + std::string(cls) + "' x1='" + num(x(v), 1) + "' x2='" +
               num(x(v), 1) + "' y1='24' y2='190'/><text class='" + cls + "' x='" + num(x(v), 1) +
               "' y='206' text-anchor='middle'>" + label + "</text>";
    };
    s += vline(lsl, "spec", "LSL " + num(lsl, 3)) + vline(usl, "spec", "USL " + num(usl, 3)) +
         vline(f.nominal_mm, "nominal", "");
    return s + "<line class='axis' x1='20' x2='460' y1='190' y2='190'/></svg>";
}

std::string count_of(const std::map<std::string, std::size_t>& m, const char* key) {
    const auto it = m.find(key);
    return std::to_string(it == m.end() ? 0 : it->second);
}

const char* kStyle = R"(
body{font-family:DejaVu Sans,Arial,sans-serif;margin:16px;color:#222}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #bbb;padding:2px 6px;
text-align:right}th{background:#eee}td.l,th.l{text-align:left}
svg{background:#fff;border:1px solid #ccc;margin:4px}svg text{font-size:11px;fill:#333}
.grid{stroke:#e4e4e4}.data{fill:none;stroke:#1f5fa8;stroke-width:1}.centre{stroke:#2a8a2a}
.limit{stroke:#c62828;stroke-dasharray:5 3}.spec{stroke:#7b1fa2;stroke-width:1.5}
text.centre,text.limit,text.spec,text.drift{stroke:none}text.centre{fill:#2a8a2a}
text.limit{fill:#c62828}text.spec{fill:#7b1fa2}.baseline{fill:#f2f2e6}.rule{fill:#c62828}.drift{stroke:#ef6c00;
stroke-width:2}text.drift{fill:#ef6c00}.bar{fill:#6f9fd8}.nominal{stroke:#555;
stroke-dasharray:2 2}.axis{stroke:#333}.nok{color:#c62828;font-weight:bold}
)";

std::string cell(const std::string& v, const char* cls = nullptr) {
    return cls ? "<td class='" + std::string(cls) + "'>" + v + "</td>" : "<td>" + v + "</td>";
}

std::string index_cells(const FeatureLot& f) {
    if (!f.capability) return "<td colspan='6' class='l'>" + escape(f.no_statistics) + "</td>";
    const auto& c = *f.capability;
    return cell(num(c.mean, 4)) + cell(num(c.s_overall, 4)) + cell(num(c.cp, 2)) +
           cell(num(c.cpk, 2)) + cell(num(c.pp, 2)) + cell(num(c.ppk, 2));
}

std::string summary_table(const Lot& lot) {
    std::string s =
        "<table class='summary'><tr><th class='l'>feature</th><th>nominal</th><th>LSL</th>"
        "<th>USL</th><th>OK</th><th>NOK</th><th>not measured</th><th>degraded</th><th>mean</th>"
        "<th>s</th><th>Cp</th><th>Cpk</th><th>Pp</th><th>Ppk</th><th>rule violations</th>"
        "<th>drift</th></tr>";
    for (std::size_t i = 0; i < lot.features.size(); ++i) {
        const FeatureLot& f = lot.features[i];
        s += "<tr><td class='l'><a href='#f" + std::to_string(i) + "'>" + escape(f.title) +
             "</a></td>" + cell(num(f.nominal_mm, 3)) + cell(num(f.nominal_mm + f.lower_mm, 3)) +
             cell(num(f.nominal_mm + f.upper_mm, 3)) + cell(count_of(f.verdicts, "OK")) +
             cell(count_of(f.verdicts, "NOK"), f.verdicts.count("NOK") ? "nok" : nullptr) +
             cell(count_of(f.verdicts, "NOT_MEASURED")) + cell(count_of(f.verdicts, "DEGRADED")) +
             index_cells(f) + cell(std::to_string(f.violations.size())) +
             cell(f.drift_at ? std::string(quality::to_string(f.first_drift)) + " from part " +
                                   std::to_string(f.sequences[*f.drift_at]) +
                                   (f.drift == quality::Drift::kNone ? ", ended" : "")
                             : "none",
                  f.drift_at ? "nok" : nullptr) +
             "</tr>";
    }
    return s + "</table>";
}

std::string feature_section(const FeatureLot& f, std::size_t i) {
    std::string s = "<section id='f" + std::to_string(i) + "'><h2>" + escape(f.title) + "</h2>";
    if (f.values.empty()) return s + "<p>No value measured OK or NOK: no chart.</p></section>";
    s += chart_svg(f) + histogram_svg(f);
    if (f.chart)
        s += "<p>Control limits from the first " + std::to_string(f.baseline) + " values: centre " +
             num(f.chart->centre, 4) + " mm, LCL " + num(f.chart->lcl, 4) + ", UCL " +
             num(f.chart->ucl, 4) + " (σ within " + num(f.chart->sigma, 5) +
             " mm = MR̄/d2). Red points: Western Electric rules 1–4 (hover for the rule and "
             "part).</p>";
    else
        s += "<p>No control limits: " + escape(f.no_statistics) + ".</p>";
    if (!f.reasons.empty()) {
        s +=
            "<table><tr><th class='l'>reason (not measured, NOK, degraded)</th><th>parts</th></tr>";
        for (const auto& [why, n] : f.reasons)
            s += "<tr><td class='l'>" + escape(why) + "</td>" + cell(std::to_string(n)) + "</tr>";
        s += "</table>";
    }
    return s + "</section>";
}

std::string master_table(const Lot& lot) {
    if (lot.masters.empty()) return "";
    std::string s =
        "<h2>Master checks: type-1 gauge study</h2><p>Each certified feature of each master, "
        "over its checks in this lot (docs/quality.md): reference = the certificate's value, T = "
        "the recipe's tolerance; Cg = 0.2·T/6s, Cgk = (0.1·T − |bias|)/3s (1.33 or more to "
        "pass).</p><table class='masters'><tr><th class='l'>master</th><th class='l'>feature"
        "</th><th>checks</th><th>reference</th><th>mean</th><th>bias</th><th>p (bias)</th>"
        "<th>s</th><th>Cg</th><th>Cgk</th></tr>";
    for (const MasterStudy& m : lot.masters) {
        s += "<tr><td class='l'>" + escape(m.master) + "</td><td class='l'>" + escape(m.feature) +
             "</td>" + cell(std::to_string(m.values.size())) + cell(num(m.reference_mm, 4));
        if (!m.study) {
            s += "<td colspan='6' class='l'>" + escape(m.no_study) + "</td></tr>";
            continue;
        }
        const auto& t = *m.study;
        s += cell(num(t.mean, 4)) + cell(num(t.bias, 4)) + cell(num(t.p_value, 3)) +
             cell(num(t.s, 5)) + cell(num(t.cg, 2), t.cg < 1.33 ? "nok" : nullptr) +
             cell(num(t.cgk, 2), t.cgk < 1.33 ? "nok" : nullptr) + "</tr>";
    }
    return s + "</table>";
}

std::string repeat_table(const Lot& lot) {
    if (lot.repeats.empty()) return "";
    std::string s =
        "<h2>Repeat scans: type-3 gauge study</h2><p>Parts measured more than once in this lot "
        "(docs/quality.md): one-way ANOVA with the part as factor; GRR = repeatability (an "
        "automatic gauge has no operator), PV = part variation; %GRR of the tolerance ≤ 10 % "
        "good, ≤ 30 % conditional; ndc ≥ 5.</p><table class='repeats'><tr><th class='l'>feature"
        "</th><th>parts</th><th>repeats</th><th>GRR</th><th>PV</th><th>%GRR of TV</th>"
        "<th>%GRR of T</th><th>ndc</th></tr>";
    for (const RepeatStudy& r : lot.repeats) {
        s += "<tr><td class='l'>" + escape(r.feature) + "</td>" + cell(std::to_string(r.parts)) +
             cell(std::to_string(r.repeats));
        if (!r.study) {
            s += "<td colspan='5' class='l'>" + escape(r.no_study) + "</td></tr>";
            continue;
        }
        const auto& t = *r.study;
        s += cell(num(t.grr, 5)) + cell(num(t.pv, 5)) + cell(num(t.grr_percent_tv, 1)) +
             cell(num(t.grr_percent_tolerance, 1), t.grr_percent_tolerance > 30 ? "nok" : nullptr) +
             cell(std::to_string(t.ndc), t.ndc < 5 ? "nok" : nullptr) + "</tr>";
    }
    return s + "</table>";
}

}  // namespace

std::string lot_report_html(const Lot& lot, const LotOptions& options) {
    std::string s = "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>" +
                    escape(options.title) + "</title><style>" + kStyle + "</style></head><body>";
    s += "<h1>" + escape(options.title) + "</h1><p>" + std::to_string(lot.parts) + " parts";
    if (lot.parts)
        s += ", sequence " + std::to_string(lot.first_sequence) + "–" +
             std::to_string(lot.last_sequence) + ", " + escape(lot.first_time) + " to " +
             escape(lot.last_time);
    s += ": ";
    for (const char* v : {"OK", "NOK", "NOT_MEASURED", "DEGRADED"})
        s += std::string(v) + " " + count_of(lot.verdicts, v) + (v[0] == 'D' ? "" : ", ");
    s += ". Master checks: " + std::to_string(lot.master_checks) +
         " (not in the statistics). Values are cold (20 °C), mm; statistics use values measured "
         "OK or NOK (degraded values are counted, not used).</p>";
    s += summary_table(lot) + master_table(lot) + repeat_table(lot);
    for (std::size_t i = 0; i < lot.features.size(); ++i) s += feature_section(lot.features[i], i);
    return s + "</body></html>\n";
}

}  // namespace hotgauge::report
