// Parts measured again against the daemon's results (`hotgauge remeasure`, docs/results.md):
// results::compare_parts and its table, JSON and page. The oracle is the parts built here: each
// test changes known values and verdicts and checks that exactly those come out.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "hotgauge/report/remeasure_report.hpp"
#include "hotgauge/results/compare.hpp"

namespace hotgauge {
namespace {

using results::PartRecord;

constexpr double kTolMm = 0.3;  // every feature here: nominal ± 0.3 mm

results::FeatureRecord feature(const std::string& name, double nominal_mm,
                               std::optional<double> cold_mm, const std::string& verdict) {
    results::FeatureRecord f;
    f.name = name;
    f.nominal_mm = nominal_mm;
    f.lower_mm = -kTolMm;
    f.upper_mm = kTolMm;
    f.cold_mm = cold_mm;
    f.verdict = verdict;
    return f;
}

// Four parts of three features, all OK, values a few µm apart; a master check after part 2.
std::vector<PartRecord> daemon_parts() {
    std::vector<PartRecord> parts;
    for (int i = 1; i <= 4; ++i) {
        PartRecord p;
        p.sequence = std::uint64_t(i);
        p.part_id = "F-" + std::to_string(1000 + i);
        p.recipe = "hub-a";
        p.verdict = "OK";
        p.features = {feature("Diameter 1", 69.5, 69.5 + 0.003 * i, "OK"),
                      feature("Height 2", 39.3, 39.3 - 0.002 * i, "OK"),
                      feature("Width 3", 12.0, 12.0 + 0.001 * i, "OK")};
        parts.push_back(p);
        if (i == 2) {
            PartRecord m = p;
            m.master_check = true;
            m.sequence = 100;
            m.part_id = "MASTER-7";
            parts.push_back(m);
        }
    }
    return parts;
}

PartRecord& part(std::vector<PartRecord>& parts, std::uint64_t sequence) {
    for (PartRecord& p : parts)
        if (p.sequence == sequence) return p;
    throw std::logic_error("no part " + std::to_string(sequence));
}

results::FeatureRecord& feature_of(PartRecord& p, const std::string& name) {
    for (results::FeatureRecord& f : p.features)
        if (f.name == name) return f;
    throw std::logic_error("no feature " + name);
}

// Part 3's Diameter 1 measured again 0.35 mm over nominal: beyond the upper limit, NOK.
std::vector<PartRecord> one_flip(const std::vector<PartRecord>& before) {
    std::vector<PartRecord> after = before;
    PartRecord& p = part(after, 3);
    feature_of(p, "Diameter 1").cold_mm = 69.5 + 0.35;
    feature_of(p, "Diameter 1").verdict = "NOK";
    p.verdict = "NOK";
    return after;
}

TEST(RemeasureCompare, IdenticalPartsAreUnchangedWithZeroShifts) {
    const auto parts = daemon_parts();
    const auto c = results::compare_parts(parts, parts);
    EXPECT_EQ(c.parts, 4u);
    EXPECT_EQ(c.unchanged, 4u);
    EXPECT_TRUE(c.flips.empty());
    EXPECT_TRUE(c.part_flips.empty());
    ASSERT_EQ(c.shifts.size(), 3u);
    const std::vector<std::string> order = {"Diameter 1", "Height 2", "Width 3"};
    for (std::size_t i = 0; i < order.size(); ++i) {
        EXPECT_EQ(c.shifts[i].feature, order[i]);
        EXPECT_EQ(c.shifts[i].n, 4u);
        EXPECT_EQ(c.shifts[i].mean_mm, 0.0);
        EXPECT_EQ(c.shifts[i].worst_mm, 0.0);
    }
}

TEST(RemeasureCompare, AValueMovedOverALimitIsExactlyThatFlip) {
    const auto before = daemon_parts();
    const auto c = results::compare_parts(before, one_flip(before));
    ASSERT_EQ(c.flips.size(), 1u);
    const auto& f = c.flips[0];
    EXPECT_EQ(f.sequence, 3u);
    EXPECT_EQ(f.part_id, "F-1003");
    EXPECT_EQ(f.feature, "Diameter 1");
    EXPECT_EQ(f.before, "OK");
    EXPECT_EQ(f.after, "NOK");
    EXPECT_EQ(f.before_mm, std::optional<double>(69.5 + 0.003 * 3));
    EXPECT_EQ(f.after_mm, std::optional<double>(69.5 + 0.35));
    EXPECT_EQ(c.count("OK", "NOK"), 1u);
    EXPECT_EQ(c.count("NOK", "OK"), 0u);
    ASSERT_EQ(c.part_flips.size(), 1u);
    EXPECT_EQ(c.part_flips[0].sequence, 3u);
    EXPECT_EQ(c.part_flips[0].feature, "");
    EXPECT_EQ(c.part_flips[0].after, "NOK");
    EXPECT_EQ(c.unchanged, 3u);
}

TEST(RemeasureCompare, AValueOneBitOffIsNotUnchanged) {
    const auto before = daemon_parts();
    auto after = before;
    auto& v = feature_of(part(after, 2), "Width 3").cold_mm;
    v = std::nextafter(*v, 100.0);  // same verdict, a value changed in its last bit
    const auto c = results::compare_parts(before, after);
    EXPECT_TRUE(c.flips.empty());
    EXPECT_EQ(c.unchanged, 3u);
}

TEST(RemeasureCompare, ShiftMeanAndWorstAreSignedAndNameTheirPart) {
    auto before = daemon_parts();
    auto after = before;
    // Height 2 moves +2, −10, +4 and 0 µm; Width 3 of part 4 is not measured again.
    const double moved_mm[] = {0.002, -0.010, 0.004, 0.0};
    for (std::uint64_t s = 1; s <= 4; ++s)
        *feature_of(part(after, s), "Height 2").cold_mm += moved_mm[s - 1];
    auto& width = feature_of(part(after, 4), "Width 3");
    width.cold_mm.reset();
    width.verdict = "NOT_MEASURED";
    const auto c = results::compare_parts(before, after);

    ASSERT_EQ(c.shifts.size(), 3u);
    const auto& h = c.shifts[1];
    EXPECT_EQ(h.feature, "Height 2");
    EXPECT_EQ(h.n, 4u);
    double sum = 0;  // the differences as doubles give them, not as written above
    for (std::uint64_t s = 1; s <= 4; ++s)
        sum += *feature_of(part(after, s), "Height 2").cold_mm -
               *feature_of(part(before, s), "Height 2").cold_mm;
    EXPECT_NEAR(h.mean_mm, sum / 4, 1e-15);
    EXPECT_NEAR(h.mean_mm, -0.001, 1e-12);
    EXPECT_NEAR(h.worst_mm, -0.010, 1e-12);  // signed: the largest |shift| is a negative one
    EXPECT_EQ(h.worst_sequence, 2u);
    EXPECT_EQ(h.worst_part_id, "F-1002");

    EXPECT_EQ(c.shifts[2].n, 3u);  // the part not measured again has no shift
    ASSERT_EQ(c.flips.size(), 1u);
    EXPECT_EQ(c.flips[0].after, "NOT_MEASURED");
    EXPECT_EQ(c.flips[0].after_mm, std::nullopt);
    EXPECT_EQ(c.unchanged, 0u);
}

TEST(RemeasureCompare, AFeatureOnlyOnOneSideIsAFlipFromOrToAbsent) {
    const auto before = daemon_parts();
    auto after = before;
    PartRecord& p = part(after, 1);
    p.features.push_back(feature("Depth 4", 8.0, 8.01, "OK"));  // a new feature of the recipe
    p.features.erase(p.features.begin());                       // and Diameter 1 dropped
    const auto c = results::compare_parts(before, after);

    ASSERT_EQ(c.flips.size(), 2u);
    EXPECT_EQ(c.flips[0].feature, "Depth 4");  // the new recipe's order, then what it dropped
    EXPECT_EQ(c.flips[0].before, results::kAbsent);
    EXPECT_EQ(c.flips[0].after, "OK");
    EXPECT_EQ(c.flips[0].before_mm, std::nullopt);
    EXPECT_EQ(c.flips[0].after_mm, std::optional<double>(8.01));
    EXPECT_EQ(c.flips[1].feature, "Diameter 1");
    EXPECT_EQ(c.flips[1].after, results::kAbsent);
    EXPECT_EQ(c.count(results::kAbsent, "OK"), 1u);
    EXPECT_EQ(c.unchanged, 3u);
}

TEST(RemeasureCompare, MasterChecksAreSkipped) {
    const auto before = daemon_parts();
    auto after = before;
    PartRecord& m = part(after, 100);
    ASSERT_TRUE(m.master_check);
    m.verdict = "NOK";
    feature_of(m, "Diameter 1").verdict = "NOK";
    feature_of(m, "Diameter 1").cold_mm = 80.0;
    const auto c = results::compare_parts(before, after);
    EXPECT_EQ(c.parts, 4u);
    EXPECT_EQ(c.unchanged, 4u);
    EXPECT_TRUE(c.flips.empty());
    EXPECT_TRUE(c.part_flips.empty());
    EXPECT_EQ(c.shifts[0].worst_mm, 0.0);
}

TEST(RemeasureCompare, OnlyPartsInBothArePairedAndNotRemeasuredIsKept) {
    const auto before = daemon_parts();
    auto after = before;
    after.erase(after.begin() + 1);  // part 2 not measured again
    const std::vector<results::NotRemeasured> gone = {{2, "F-1002", "recording deleted (quota)"},
                                                      {9, "F-1009", "not archived"}};
    const auto c = results::compare_parts(before, after, gone);
    EXPECT_EQ(c.parts, 3u);
    ASSERT_EQ(c.not_remeasured.size(), 2u);
    EXPECT_EQ(c.not_remeasured[0].sequence, 2u);
    EXPECT_EQ(c.not_remeasured[0].why, "recording deleted (quota)");
    EXPECT_EQ(c.not_remeasured[1].part_id, "F-1009");
}

TEST(RemeasureCompare, JsonParsesBackWithTheSameNumbers) {
    const auto before = daemon_parts();
    auto after = one_flip(before);
    part(after, 1).features.push_back(feature("Depth 4", 8.0, 8.01, "OK"));
    const auto c = results::compare_parts(before, after, {{2, "F-1002", "not archived"}});
    const auto j = nlohmann::json::parse(results::comparison_json(c));

    EXPECT_EQ(j.at("parts").get<std::size_t>(), c.parts);
    EXPECT_EQ(j.at("unchanged").get<std::size_t>(), c.unchanged);
    ASSERT_EQ(j.at("flips").size(), 2u);
    const auto& absent = j.at("flips")[0];  // sequence 1 first
    EXPECT_EQ(absent.at("before").get<std::string>(), "ABSENT");
    EXPECT_TRUE(absent.at("before_mm").is_null());
    const auto& f = j.at("flips")[1];
    EXPECT_EQ(f.at("sequence").get<std::uint64_t>(), 3u);
    EXPECT_EQ(f.at("feature").get<std::string>(), "Diameter 1");
    EXPECT_EQ(f.at("before_mm").get<double>(), *c.flips[1].before_mm);  // to the bit
    EXPECT_EQ(f.at("after_mm").get<double>(), *c.flips[1].after_mm);
    ASSERT_EQ(j.at("part_flips").size(), 1u);
    EXPECT_EQ(j.at("part_flips")[0].at("after").get<std::string>(), "NOK");
    ASSERT_EQ(j.at("shifts").size(), c.shifts.size());
    for (std::size_t i = 0; i < c.shifts.size(); ++i) {
        EXPECT_EQ(j.at("shifts")[i].at("n").get<std::size_t>(), c.shifts[i].n);
        if (c.shifts[i].n == 0) {  // Depth 4: in one part, and only after
            EXPECT_TRUE(j.at("shifts")[i].at("mean_mm").is_null());
            continue;
        }
        EXPECT_EQ(j.at("shifts")[i].at("mean_mm").get<double>(), c.shifts[i].mean_mm);
        EXPECT_EQ(j.at("shifts")[i].at("worst_mm").get<double>(), c.shifts[i].worst_mm);
    }
    EXPECT_EQ(j.at("shifts")[0].at("worst_part_id").get<std::string>(), "F-1003");
    ASSERT_EQ(j.at("not_remeasured").size(), 1u);
    EXPECT_EQ(j.at("not_remeasured")[0].at("why").get<std::string>(), "not archived");
}

std::size_t columns(const std::string& line) {  // code points: µ, → and … are one column each
    std::size_t n = 0;
    for (char ch : line) n += (static_cast<unsigned char>(ch) & 0xC0) != 0x80;
    return n;
}

TEST(RemeasureCompare, TableNamesTheFlipAndKeepsLinesShort) {
    const auto before = daemon_parts();
    const std::string table =
        results::comparison_table(results::compare_parts(before, one_flip(before)));
    EXPECT_NE(table.find("F-1003"), std::string::npos);
    EXPECT_NE(table.find("Diameter 1"), std::string::npos);
    EXPECT_NE(table.find("OK \u2192 NOK"), std::string::npos);

    // 30 parts all flipping, with long ids and reasons: 20 lines, then the rest counted.
    std::vector<PartRecord> many_before, many_after;
    for (int i = 1; i <= 30; ++i) {
        PartRecord p;
        p.sequence = std::uint64_t(i);
        p.part_id = std::string(60, 'P') + std::to_string(i);
        p.verdict = "OK";
        p.features = {feature(std::string(50, 'D'), 1.0, 1.0, "OK")};
        many_before.push_back(p);
        p.features[0].verdict = "NOK";
        p.features[0].cold_mm = 1.5;
        many_after.push_back(p);
    }
    const auto long_table = results::comparison_table(results::compare_parts(
        many_before, many_after, {{31, std::string(40, 'X'), std::string(200, 'w')}}));
    EXPECT_NE(long_table.find("\u2026 and 10 more"), std::string::npos);
    std::istringstream in(long_table);
    for (std::string line; std::getline(in, line);) EXPECT_LE(columns(line), 100u) << line;
}

TEST(RemeasureHtml, EscapesSaysStoppedAndFetchesNothing) {
    auto before = daemon_parts();
    for (PartRecord& p : before)
        if (p.sequence == 3) p.part_id = "<b>&";
    auto c = results::compare_parts(before, one_flip(before), {{2, "<i>", "gone <now>"}});
    report::RemeasureInfo info;
    info.results_dir = "/srv/results";
    info.out_dir = "/tmp/again";
    info.parts_in_range = 4;
    info.parts_measured = 3;

    const std::string page = report::remeasure_html(c, info);
    EXPECT_NE(page.find("&lt;b&gt;&amp;"), std::string::npos);
    EXPECT_EQ(page.find("<b>&"), std::string::npos);
    EXPECT_EQ(page.find("<i>"), std::string::npos);
    EXPECT_NE(page.find("gone &lt;now&gt;"), std::string::npos);
    EXPECT_EQ(page.find("<script"), std::string::npos);
    EXPECT_EQ(page.find("src=\"http"), std::string::npos);
    EXPECT_EQ(page.find("http"), std::string::npos);  // no link, no fetch of any kind
    EXPECT_EQ(page.find("class='stopped'"), std::string::npos);

    info.stopped = true;
    const std::string stopped = report::remeasure_html(c, info);
    EXPECT_NE(stopped.find("class='stopped'"), std::string::npos);
    EXPECT_NE(stopped.find("Stopped before the end"), std::string::npos);
}

}  // namespace
}  // namespace hotgauge
