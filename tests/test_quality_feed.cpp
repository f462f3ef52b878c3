// The daemon's drift watch and day's lot report (cell::QualityFeed, docs/quality.md "In the
// daemon"): the states that go with each result, the page rewritten after every part, and the
// watch taken up again from the results files after a restart.
#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

#include "hotgauge/cell/quality_feed.hpp"
#include "hotgauge/core/clock.hpp"
#include "hotgauge/results/results_log.hpp"
#include "temp_dir.hpp"

using namespace hotgauge;

namespace {

pipeline::PartResult part(double diameter_mm, bool degraded = false) {
    pipeline::PartResult r;
    r.part_id = "P";
    r.recipe = "hub-a";
    r.measurement.verdict = measure::Verdict::kOk;
    measure::FeatureResult f;
    f.name = "Diameter 3";
    f.slot = 3;
    f.nominal_mm = 69.5;
    f.tol_lower_mm = -0.3;
    f.tol_upper_mm = 0.3;
    f.cold_mm = diameter_mm;
    f.deviation_mm = diameter_mm - 69.5;
    f.verdict = degraded ? measure::Verdict::kDegraded : measure::Verdict::kOk;
    r.measurement.features.push_back(f);
    return r;
}

std::string state_of(const std::vector<std::pair<std::string, std::string>>& drift) {
    return drift.empty() ? "" : drift[0].second;
}

std::string read(const std::filesystem::path& p) {
    std::ifstream in(p);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

}  // namespace

TEST(QualityFeed, DriftPerDieAndTheDaysReportGoOnAfterARestart) {
    test::TempDir tmp;
    const auto dir = tmp.path / "results";
    auto log = results::ResultsLog::open({dir, false});
    ASSERT_TRUE(log.ok()) << log.error().message;
    const std::int64_t t0 = 1'795'000'000'000'000'000;  // 2026-11-18, away from midnight
    std::mt19937 rng(21);
    std::normal_distribution<double> noise(0.0, 0.01);
    cell::QualityFeed feed(dir,
                           {.drift_baseline = 20, .lot_report = true, .lot_report_every_s = 0});
    feed.load(t0);  // no results yet
    // Die 1: 100 parts steady, then wearing 5 µm per 10 parts (fast, to keep the test short).
    std::vector<std::string> states;
    for (int i = 0; i < 300; ++i) {
        const auto r = part(69.5 + noise(rng) + (i >= 100 ? 5e-4 * (i - 100) : 0.0), i == 5);
        results::ResultEntry e{t0 + i * 1'000'000, std::uint64_t(i + 1), &r, "v", "h",
                               std::nullopt};
        e.die_id = 1;
        e.drift = feed.observe(e.die_id, r);
        states.push_back(state_of(e.drift));
        ASSERT_TRUE(log->append(e).ok());
        feed.stored(results::jsonl_line(e), e.time_ns);
    }
    EXPECT_EQ(states[19], "BASELINE");  // part 6 was degraded: not in the baseline
    EXPECT_EQ(states[20], "WATCHING");
    EXPECT_EQ(states[99], "WATCHING");
    const auto first_up = std::find(states.begin(), states.end(), "DRIFT_UP") - states.begin();
    EXPECT_GT(first_up, 100);
    EXPECT_LT(first_up, 200);  // within 50 µm of drift, the tolerance is ±300 µm
    EXPECT_EQ(states.back(), "DRIFT_UP");

    // The day's page: every part, the drift marked, nothing left half written.
    const auto page = dir / (results::local_date(t0) + ".report.html");
    const std::string html = read(page);
    EXPECT_NE(html.find("300 parts"), std::string::npos);
    EXPECT_NE(html.find("drift warning, part"), std::string::npos);
    EXPECT_FALSE(std::filesystem::exists(page.string() + ".tmp"));

    // A restart: the watch as saved after the last part, so die 1 is still drifting; die 2 is
    // new. Without the saved watch (or with a broken one), it is rebuilt from the results files,
    // where a torn line in an older day's file is skipped, not the end of the watch.
    ASSERT_TRUE(std::filesystem::exists(dir / "drift-watch.json"));
    const auto r = part(69.5 + 0.1);
    std::ofstream(dir / "2026-11-17.jsonl") << "{\"sequence\": 1, \"time\": \"2026-11-17T23:5";
    for (const char* saved : {"keep", "remove", "break"}) {
        if (saved == std::string("remove")) std::filesystem::remove(dir / "drift-watch.json");
        if (saved == std::string("break")) std::ofstream(dir / "drift-watch.json") << "{\"seri";
        cell::QualityFeed restarted(dir, {.drift_baseline = 20, .lot_report = false});
        restarted.load(t0 + 300'000'000);
        EXPECT_EQ(state_of(restarted.observe(1, r)), "DRIFT_UP") << saved;
        EXPECT_EQ(state_of(restarted.observe(2, r)), "BASELINE") << saved;
    }
    cell::QualityFeed again(dir,
                            {.drift_baseline = 20, .lot_report = true, .lot_report_every_s = 0});
    again.load(t0 + 300'000'000);
    results::ResultEntry e{t0 + 301'000'000, 301, &r, "v", "h", std::nullopt};
    ASSERT_TRUE(log->append(e).ok());
    again.stored(results::jsonl_line(e), e.time_ns);
    EXPECT_NE(read(page).find("301 parts"), std::string::npos);

    // Written at most every lot_report_every_s: the parts in between come with the last write,
    // at the latest when the feed ends (the daemon stops).
    {
        cell::QualityFeed slow(
            dir, {.drift_baseline = 20, .lot_report = true, .lot_report_every_s = 3600});
        slow.load(t0 + 302'000'000);
        for (std::uint64_t seq : {302u, 303u}) {
            results::ResultEntry s{
                t0 + std::int64_t(seq) * 1'000'000, seq, &r, "v", "h", std::nullopt};
            ASSERT_TRUE(log->append(s).ok());
            slow.stored(results::jsonl_line(s), s.time_ns);
        }
        EXPECT_NE(read(page).find("302 parts"), std::string::npos);  // the first write
    }
    EXPECT_NE(read(page).find("303 parts"), std::string::npos);  // the one at the end

    // No watch configured: no states.
    cell::QualityFeed off(dir, {.drift_baseline = 0, .lot_report = false, .lot_report_every_s = 0});
    EXPECT_TRUE(off.observe(1, r).empty());
}
