// The lot report's statistics and page, the AQDEF export and reading the results back
// (issue 19; docs/results.md). The statistics themselves are checked against NumPy and
// statsmodels in test_quality; here: that the report feeds them the right values.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "hotgauge/quality/statistics.hpp"
#include "hotgauge/report/aqdef.hpp"
#include "hotgauge/report/lot_report.hpp"
#include "hotgauge/results/read_back.hpp"
#include "temp_dir.hpp"

using namespace hotgauge;

namespace {

results::FeatureRecord feature(const std::string& name, std::optional<double> v,
                               const std::string& verdict, const std::string& reason = "") {
    return {name, 1, 69.5, -0.3, 0.3, v, 0.002, verdict, reason};
}

// 60 parts: Diameter 3 ~ N(69.5, 0.01) with an outlier at part 40, a degraded value at 45, not
// measured at 50; a master check after part 30; Height 1 always measured.
std::vector<results::PartRecord> lot_parts() {
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 0.01);
    std::vector<results::PartRecord> parts;
    for (int i = 1; i <= 60; ++i) {
        results::PartRecord p;
        p.sequence = std::uint64_t(i);
        p.time =
            "2026-12-04T08:" + std::string(i < 10 ? "0" : "") + std::to_string(i) + ":00.000+01:00";
        p.part_id = std::to_string(240000 + i);
        p.recipe = "hub-a";
        p.verdict = "OK";
        const double d = 69.5 + noise(rng) + (i == 40 ? 0.08 : 0.0);
        if (i == 45)
            p.features.push_back(feature("Diameter 3", d, "DEGRADED",
                                         "degraded: measured with untrusted profiles; top "
                                         "profiles 0–1299 (0.000–1.299 s): accelerometer gap"));
        else if (i == 50)
            p.features.push_back(feature("Diameter 3", std::nullopt, "NOT_MEASURED",
                                         "not measured: edge not found"));
        else
            p.features.push_back(feature("Diameter 3", d, "OK"));
        p.features.push_back(feature("Height 1", 39.3 + noise(rng), "OK"));
        parts.push_back(p);
        if (i == 30) {
            p.master_check = true;
            p.sequence = 1000;
            p.features[0].cold_mm = 80.0;  // would wreck the statistics if it were used
            parts.push_back(p);
        }
    }
    return parts;
}

std::size_t count(const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
}

}  // namespace

TEST(LotReport, StatisticsUseTheOkAndNokValuesOfProductionParts) {
    const auto parts = lot_parts();
    const report::Lot lot = report::summarize_lot(parts, {});
    EXPECT_EQ(lot.parts, 60u);
    EXPECT_EQ(lot.master_checks, 1u);
    ASSERT_EQ(lot.features.size(), 2u);
    const report::FeatureLot& d = lot.features[0];
    ASSERT_EQ(d.values.size(), 58u);  // not the degraded, the not measured, the master's
    EXPECT_EQ(d.verdicts.at("DEGRADED"), 1u);
    EXPECT_EQ(d.verdicts.at("NOT_MEASURED"), 1u);
    std::vector<double> expected;
    for (const auto& p : parts)
        if (!p.master_check && p.features[0].verdict == "OK")
            expected.push_back(*p.features[0].cold_mm);
    const auto cap = quality::capability(expected, 69.2, 69.8);
    const auto chart = quality::individuals_chart(std::span(expected).first(25));
    ASSERT_TRUE(cap && chart && d.capability && d.chart);
    EXPECT_DOUBLE_EQ(d.capability->cpk, cap->cpk);
    EXPECT_DOUBLE_EQ(d.capability->ppk, cap->ppk);
    EXPECT_DOUBLE_EQ(d.chart->ucl, chart->ucl);
    EXPECT_EQ(d.baseline, 25u);
    // The outlier (part 40, 8σ) is marked by rule 1, on its own sequence number.
    bool outlier = false;
    for (const auto& v : d.violations) outlier |= v.rule == 1 && d.sequences[v.index] == 40;
    EXPECT_TRUE(outlier);
    EXPECT_EQ(d.reasons.count("degraded: measured with untrusted profiles (accelerometer gap)"),
              1u);
    EXPECT_FALSE(lot.features[1].drift_at);  // no drift in Height 1
}

TEST(LotReport, PageHasTwoChartsPerFeatureWithValuesAndNoOutsideReference) {
    auto parts = lot_parts();
    parts[0].features[1].name = "Height <1>";  // escaped, not markup
    for (auto& p : parts) p.features[1].name = "Height <1>";
    const std::string html = report::lot_report_html(report::summarize_lot(parts, {}), {});
    EXPECT_EQ(count(html, "<svg class='chart'"), 2u);
    EXPECT_EQ(count(html, "<svg class='histogram'"), 2u);
    EXPECT_EQ(count(html, "Height &lt;1&gt;"), 2u);  // summary row and section heading
    EXPECT_EQ(count(html, "<script"), 0u);
    for (const std::string attr : {"src='", "href='", "src=\"", "href=\""})  // only #fragments
        for (auto at = html.find(attr); at != std::string::npos; at = html.find(attr, at + 1))
            EXPECT_EQ(html[at + attr.size()], '#') << html.substr(at, 40);
    // Too few values: no limits and a reason, still a chart of what there is.
    parts.resize(10);
    const std::string few = report::lot_report_html(report::summarize_lot(parts, {}), {});
    EXPECT_EQ(count(few, "<svg class='chart'"), 2u);
    EXPECT_NE(few.find("10 values measured OK or NOK, 20 needed"), std::string::npos);
    EXPECT_EQ(count(few, "UCL"), 0u);
}

// A die shift of a few µm in a [0, 0.5] mm tolerance: its bins are narrower than a pixel, and
// each bar is still drawn 2 px wide on whole pixels (an antialiased sliver of 1 px at a
// fractional x showed no bar colour at all in Chromium).
TEST(LotReport, BarsFarInsideAWideToleranceAreWholePixels) {
    std::vector<results::PartRecord> parts;
    for (int i = 1; i <= 5; ++i) {
        results::PartRecord p;
        p.sequence = std::uint64_t(i);
        p.time = "2026-12-04T08:0" + std::to_string(i) + ":00.000+01:00";
        p.part_id = std::to_string(240000 + i);
        p.recipe = "hub-a";
        p.verdict = "OK";
        p.features.push_back({"Die shift", 14, 0.0, 0.0, 0.5, 0.001 * i, 0.01, "OK", ""});
        parts.push_back(p);
    }
    const std::string html = report::lot_report_html(report::summarize_lot(parts, {}), {});
    std::size_t bars = 0;
    for (auto at = html.find("<rect class='bar'"); at != std::string::npos;
         at = html.find("<rect class='bar'", at + 1), ++bars) {
        const auto attr = [&](const std::string& name) {
            return std::stod(html.substr(html.find(name + "='", at) + name.size() + 2));
        };
        EXPECT_GE(attr("width"), 2.0);
        EXPECT_EQ(attr("x"), std::floor(attr("x")));
    }
    EXPECT_EQ(bars, 5u);
}

TEST(LotReport, DriftIsMarkedWhereTheEwmaLeavesItsLimits) {
    auto parts = lot_parts();
    for (std::size_t i = 0; i < parts.size(); ++i)  // 1.5 µm a part from part 30 on
        if (!parts[i].master_check && parts[i].sequence > 30 && parts[i].features[1].cold_mm)
            *parts[i].features[1].cold_mm += 0.0015 * double(parts[i].sequence - 30);
    const report::Lot lot = report::summarize_lot(parts, {});
    const report::FeatureLot& h = lot.features[1];
    ASSERT_TRUE(h.drift_at);
    EXPECT_EQ(h.drift, quality::Drift::kUp);
    EXPECT_GT(h.sequences[*h.drift_at], 30u);
    EXPECT_NE(report::lot_report_html(lot, {}).find("drift warning, part"), std::string::npos);
}

TEST(LotReport, ReasonGroupDropsTheNumbersAndKeepsTheCauses) {
    EXPECT_EQ(report::reason_group("degraded: measured with untrusted profiles; bottom profiles "
                                   "0–1131 (0.000–1.131 s): accelerometer gap; bottom profiles "
                                   "1221–1309 (1.221–1.309 s): no accelerometer samples"),
              "degraded: measured with untrusted profiles (accelerometer gap, no accelerometer "
              "samples)");
    EXPECT_EQ(report::reason_group("not measured: edge not found"), "not measured: edge not found");
}

TEST(Aqdef, NotMeasuredIsAnEmptyValueNeverAZero) {
    const std::string dfq = report::aqdef_dfq(lot_parts());
    EXPECT_EQ(dfq.rfind("K0100 2\r\n", 0), 0u);
    EXPECT_NE(dfq.find("K2110/1 69.2000\r\nK2111/1 69.8000\r\nK2142/1 mm\r\n"), std::string::npos);
    // Part 50's Diameter 3: empty value, attribute 255, its reason.
    const auto at = dfq.find("K0009/1 seq 50; NOT_MEASURED: not measured: edge not found\r\n");
    ASSERT_NE(at, std::string::npos);
    const auto block = dfq.rfind("K0001/1", at);
    EXPECT_EQ(dfq.substr(block, 24), "K0001/1 \r\nK0002/1 255\r\nK");
    EXPECT_EQ(count(dfq, "K0001/1 \r\n"), 1u);
    EXPECT_EQ(count(dfq, "K0001/1 80."), 0u);  // the master check is left out
    EXPECT_EQ(count(dfq, "K0001/1 "), 60u);
    EXPECT_EQ(count(dfq, "K0002/1 255"), 2u);  // not measured and degraded
    EXPECT_EQ(report::aqdef_time("2026-12-04T08:05:00.123+01:00"), "04.12.2026/08:05:00");
}

TEST(ReadParts, TimeRangeAndRetriedLines) {
    test::TempDir dir;
    auto line = [](int seq, const std::string& time, double v) {
        return "{\"sequence\":" + std::to_string(seq) + ",\"time\":\"" + time +
               "\",\"part\":{\"part_id\":\"P" + std::to_string(seq) +
               "\",\"recipe\":\"hub-a\",\"verdict\":\"OK\",\"temperature_c\":1050,\"faces\":[1],"
               "\"features\":[{\"name\":\"Height 1\",\"nominal_mm\":39.3,\"tolerance_mm\":[-0.3,"
               "0.3],\"cold_mm\":" +
               std::to_string(v) +
               ",\"verdict\":\"OK\",\"reason\":null,"
               "\"u_budget_mm\":{\"fit\":1}}]}}\n";
    };
    std::ofstream(dir.path / "2026-12-03.jsonl") << line(1, "2026-12-03T22:00:00.000+01:00", 39.1);
    std::ofstream(dir.path / "2026-12-04.jsonl") << line(2, "2026-12-04T05:59:59.000+01:00", 39.2)
                                                 << line(3, "2026-12-04T06:00:00.000+01:00", 39.3)
                                                 << line(3, "2026-12-04T06:00:00.000+01:00", 39.35)
                                                 << line(4, "2026-12-04T14:00:00.000+01:00", 39.4);
    const auto all = results::read_parts(dir.path);
    ASSERT_TRUE(all) << all.error().message;
    ASSERT_EQ(all->parts.size(), 4u);
    EXPECT_DOUBLE_EQ(*all->parts[2].features[0].cold_mm, 39.35);  // the retried line, once
    const auto shift = results::read_parts(dir.path, {"2026-12-04T06", "2026-12-04T13"});
    ASSERT_TRUE(shift);
    ASSERT_EQ(shift->parts.size(), 1u);
    EXPECT_EQ(shift->parts[0].sequence, 3u);
    EXPECT_EQ(shift->files, 1u);  // the day before is not opened
    std::ofstream(dir.path / "2026-12-04.jsonl", std::ios::app) << "{\"sequence\":5}\n";
    const auto bad = results::read_parts(dir.path);
    ASSERT_FALSE(bad);
    EXPECT_NE(bad.error().message.find("2026-12-04.jsonl:5: not a result line"), std::string::npos)
        << bad.error().message;
}

// Master checks in the lot: a type-1 study per master and certified feature, from the checks'
// values measured OK or NOK, against the certificate's value and the recipe's tolerance.
TEST(LotReport, MasterChecksGiveATypeOneStudy) {
    auto parts = lot_parts();
    std::mt19937 rng(8);
    std::normal_distribution<double> noise(0.002, 0.003);  // a 2 µm bias
    std::vector<double> values;
    for (int k = 0; k < 12; ++k) {
        results::PartRecord m = parts[0];
        m.sequence = 2000 + k;
        m.master_check = true;
        m.master = "M-1";
        m.certified = {{"Diameter 3", 69.51}};
        m.features[0].cold_mm = 69.51 + noise(rng);
        if (k == 4)
            m.features[0].verdict = "DEGRADED";  // not used
        else
            values.push_back(*m.features[0].cold_mm);
        parts.push_back(m);
    }
    const report::Lot lot = report::summarize_lot(parts, {});
    EXPECT_EQ(lot.master_checks, 13u);  // and lot_parts()'s own, which has no certificate
    ASSERT_EQ(lot.masters.size(), 1u);
    const report::MasterStudy& m = lot.masters[0];
    EXPECT_EQ(m.master, "M-1");
    ASSERT_TRUE(m.study) << m.no_study;
    const auto expected = quality::type1_study(values, 69.51, 0.6, 0.0001);
    ASSERT_TRUE(expected);
    EXPECT_EQ(m.study->n, 11u);
    EXPECT_DOUBLE_EQ(m.study->cg, expected->cg);
    EXPECT_DOUBLE_EQ(m.study->cgk, expected->cgk);
    EXPECT_DOUBLE_EQ(m.study->bias, expected->bias);
    const std::string html = report::lot_report_html(lot, {});
    EXPECT_NE(html.find("Master checks: type-1 gauge study"), std::string::npos);
    // Too few checks: no study, and why.
    parts.resize(parts.size() - 3);
    const report::Lot few = report::summarize_lot(parts, {});
    ASSERT_EQ(few.masters.size(), 1u);
    EXPECT_FALSE(few.masters[0].study);
    EXPECT_EQ(few.masters[0].no_study,
              "8 checks measured OK or NOK, 10 needed (VDA 5 asks for 25)");
}

// A master certified anew (or two certificates of one master, as the virtual line's wrong one):
// each certified value is its own reference, never mixed.
TEST(LotReport, EachCertifiedValueIsItsOwnStudy) {
    auto parts = lot_parts();
    for (int k = 0; k < 4; ++k) {
        results::PartRecord m = parts[0];
        m.master_check = true;
        m.master = "M-1";
        m.sequence = 3000 + k;
        m.certified = {{"Diameter 3", k % 2 ? 69.51 : 69.56}};
        parts.push_back(m);
    }
    const report::Lot lot = report::summarize_lot(parts, {});
    ASSERT_EQ(lot.masters.size(), 2u);
    EXPECT_EQ(lot.masters[0].reference_mm, 69.56);
    EXPECT_EQ(lot.masters[1].reference_mm, 69.51);
    EXPECT_EQ(lot.masters[0].values.size(), 2u);
}

// Repeat scans: production parts measured again give a type-3 study, with the most common number
// of repeats; the parts measured once are not in it.
TEST(LotReport, RepeatScansGiveATypeThreeStudy) {
    auto parts = lot_parts();  // 60 parts, each once
    std::mt19937 rng(9);
    std::normal_distribution<double> part_to_part(0.0, 0.02), repeat(0.0, 0.003);
    std::vector<std::vector<double>> expected;
    for (int id = 0; id < 6; ++id) {
        const double true_mm = 69.5 + part_to_part(rng);
        const int scans = id == 5 ? 2 : 3;  // one part scanned only twice: left out of r = 3
        std::vector<double> v;
        for (int k = 0; k < scans; ++k) {
            results::PartRecord p = parts[0];
            p.part_id = "R-" + std::to_string(id);
            p.sequence = 4000 + 10 * id + k;
            p.features[0].cold_mm = true_mm + repeat(rng);
            p.features[0].verdict = "OK";
            v.push_back(*p.features[0].cold_mm);
            parts.push_back(p);
        }
        if (scans == 3) expected.push_back(v);
    }
    const report::Lot lot = report::summarize_lot(parts, {});
    ASSERT_EQ(lot.repeats.size(), 2u);  // one per feature
    const report::RepeatStudy& r = lot.repeats[0];
    EXPECT_EQ(r.feature, "Diameter 3");
    EXPECT_EQ(r.repeats, 3u);
    ASSERT_EQ(r.parts, 5u);
    ASSERT_TRUE(r.study) << r.no_study;
    const auto want = quality::type3_study(expected, 0.6);
    ASSERT_TRUE(want);
    EXPECT_DOUBLE_EQ(r.study->grr, want->grr);
    EXPECT_DOUBLE_EQ(r.study->grr_percent_tolerance, want->grr_percent_tolerance);
    EXPECT_EQ(r.study->ndc, want->ndc);
    EXPECT_NE(report::lot_report_html(lot, {}).find("Repeat scans: type-3 gauge study"),
              std::string::npos);
    // Without repeats: no section.
    EXPECT_TRUE(report::summarize_lot(lot_parts(), {}).repeats.empty());
}
