// The quality statistics (issue 19) against answers computed with NumPy and statsmodels
// (data/oracle/quality-statistics.json, written by tests/oracle/make_quality_reference.py), and
// the study input they refuse.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "hotgauge/quality/drift.hpp"
#include "hotgauge/quality/statistics.hpp"

using namespace hotgauge;
using nlohmann::json;

namespace {

const json& reference() {
    static const json j = [] {
        std::ifstream in(HOTGAUGE_SOURCE_DIR "/data/oracle/quality-statistics.json");
        if (!in) throw std::runtime_error("data/oracle/quality-statistics.json missing");
        return json::parse(in);
    }();
    return j;
}

// Relative agreement to 1e-9 (absolute below 1e-9).
void near(double ours, double theirs, const std::string& what) {
    EXPECT_NEAR(ours, theirs, 1e-9 * std::max(1.0, std::abs(theirs))) << what;
}

}  // namespace

TEST(QualityOracle, CapabilityAndControlLimits) {
    ASSERT_GE(reference()["capability"].size(), 3u);
    for (const auto& c : reference()["capability"]) {
        const auto x = c["values"].get<std::vector<double>>();
        const std::string name = c["name"];
        const auto cap = quality::capability(x, c["lsl"], c["usl"]);
        ASSERT_TRUE(cap.ok()) << name << ": " << cap.error().message;
        near(cap->mean, c["mean"], name + " mean");
        near(cap->s_overall, c["s_overall"], name + " s");
        near(cap->s_within, c["s_within"], name + " s within");
        near(cap->cp, c["cp"], name + " Cp");
        near(cap->cpk, c["cpk"], name + " Cpk");
        near(cap->pp, c["pp"], name + " Pp");
        near(cap->ppk, c["ppk"], name + " Ppk");
        const auto chart = quality::individuals_chart(x);
        ASSERT_TRUE(chart.ok()) << name;
        near(chart->centre, c["centre"], name + " centre");
        near(chart->lcl, c["lcl"], name + " LCL");
        near(chart->ucl, c["ucl"], name + " UCL");
        near(chart->mr_bar, c["mr_bar"], name + " MR");
        near(chart->mr_ucl, c["mr_ucl"], name + " MR UCL");
    }
}

TEST(QualityOracle, Type1Study) {
    ASSERT_GE(reference()["type1"].size(), 3u);
    for (const auto& c : reference()["type1"]) {
        const auto x = c["values"].get<std::vector<double>>();
        const std::string name = c["name"];
        const auto t = quality::type1_study(x, c["reference"], c["tolerance"], c["resolution"]);
        ASSERT_TRUE(t.ok()) << name << ": " << t.error().message;
        near(t->mean, c["mean"], name + " mean");
        near(t->s, c["s"], name + " s");
        near(t->bias, c["bias"], name + " bias");
        near(t->cg, c["cg"], name + " Cg");
        near(t->cgk, c["cgk"], name + " Cgk");
        near(t->t, c["t"], name + " t");
        near(t->p_value, c["p_value"], name + " p");
        near(t->resolution_share, c["resolution_share"], name + " resolution");
    }
}

TEST(QualityOracle, Type3Study) {
    ASSERT_GE(reference()["type3"].size(), 3u);
    for (const auto& c : reference()["type3"]) {
        const auto parts = c["by_part"].get<std::vector<std::vector<double>>>();
        const std::string name = c["name"];
        const auto s = quality::type3_study(parts, c["tolerance"]);
        ASSERT_TRUE(s.ok()) << name << ": " << s.error().message;
        near(s->ms_parts, c["ms_parts"], name + " MS parts");
        near(s->ms_within, c["ms_within"], name + " MS within");
        near(s->grr, c["grr"], name + " GRR");
        near(s->pv, c["pv"], name + " PV");
        near(s->tv, c["tv"], name + " TV");
        near(s->grr_percent_tv, c["grr_percent_tv"], name + " %GRR of TV");
        near(s->grr_percent_tolerance, c["grr_percent_tolerance"], name + " %GRR of T");
        EXPECT_EQ(s->ndc, c["ndc"].get<int>()) << name;
    }
}

TEST(QualityBadInput, StudiesRefuseWhatTheyCannotJudge) {
    const std::vector<double> one{1.0}, two{1.0, 1.1}, same{2.0, 2.0, 2.0};
    const std::vector<double> inf{1.0, std::numeric_limits<double>::infinity()};
    auto says = [](const auto& r, const std::string& part) {
        ASSERT_FALSE(r.ok());
        EXPECT_NE(r.error().message.find(part), std::string::npos) << r.error().message;
    };
    says(quality::capability(one, 0, 1), "at least 2 values");
    says(quality::capability(two, 1, 1), "not above the lower limit");
    says(quality::capability(same, 0, 3), "do not vary");
    says(quality::capability(inf, 0, 3), "value 2 is not finite");
    says(quality::individuals_chart(one), "at least 2 values");
    says(quality::individuals_chart(same), "do not change from one to the next");
    says(quality::type1_study(two, 1.0, 0.0, 0.001), "tolerance must be positive");
    says(quality::type1_study(two, 1.0, -0.6, 0.001), "tolerance must be positive");
    says(quality::type1_study(same, 2.0, 0.6, 0.001), "all 3 values are equal");
    says(quality::type1_study(one, 1.0, 0.6, 0.001), "at least 2 values");
    says(quality::type3_study({two}, 0.6), "at least 2 parts");
    says(quality::type3_study({two, {1.0, 1.1, 1.2}}, 0.6), "part 2 has 3 measurements");
    says(quality::type3_study({two, two}, 0.0), "tolerance must be positive");
    says(quality::type3_study({same, same}, 0.6), "do not vary");
    says(quality::type3_study({two, inf}, 0.6), "(part 2)");
}

namespace {

// A feature's values over n parts: nominal, a die wearing `drift_per_part` from part `from` on,
// and the process's N(0, σ); seeded.
std::vector<double> die_series(std::size_t n, double nominal, double drift_per_part,
                               std::size_t from, double sigma, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, sigma);
    std::vector<double> x(n);
    for (std::size_t i = 0; i < n; ++i)
        x[i] = nominal + drift_per_part * static_cast<double>(i > from ? i - from : 0) + noise(rng);
    return x;
}

constexpr std::size_t kBaseline = 100;

}  // namespace

// Diameter 3 (69.5 ± 0.3 mm) with the die wearing 5 µm per 100 parts after a 100-part baseline:
// the warning comes while the process mean is at least 20 % of the tolerance (0.12 mm) short of
// where it is at the first NOK (issue 19). Capable processes (σ 0.01-0.03 mm, Cp 3.3-10); the
// margin for σ 0.05 mm is printed, not asserted (docs/quality.md "Drift warning").
TEST(DriftWarning, FiresOnDieWearWellBeforeTheFirstNok) {
    const double nominal = 69.5, lower = 69.2, upper = 69.8, drift = 0.005 / 100;
    for (double sigma : {0.01, 0.02, 0.03, 0.05}) {
        const auto x = die_series(20000, nominal, drift, kBaseline, sigma, 7);
        auto m = quality::DriftMonitor::from_baseline(std::span(x).first(kBaseline));
        ASSERT_TRUE(m.ok()) << m.error().message;
        std::size_t warned = 0, nok = 0;
        for (std::size_t i = kBaseline; i < x.size() && !nok; ++i) {
            if (m->add(x[i]) == quality::Drift::kUp && !warned) warned = i;
            if (x[i] > upper || x[i] < lower) nok = i;
        }
        ASSERT_GT(nok, 0u) << "the series never left the tolerance";
        const auto shift = [&](std::size_t i) {
            return drift * static_cast<double>(i - kBaseline);
        };
        std::printf(
            "sigma %.2f mm: warning at part %zu (mean +%.3f mm), first NOK at part %zu "
            "(mean +%.3f mm): %.0f %% of the tolerance before it\n",
            sigma, warned, warned ? shift(warned) : 0.0, nok, shift(nok),
            warned ? 100 * (shift(nok) - shift(warned)) / 0.6 : 0.0);
        if (sigma > 0.031) continue;
        ASSERT_GT(warned, 0u) << "no warning before the first NOK, sigma " << sigma;
        EXPECT_GE(shift(nok) - shift(warned), 0.2 * 0.6) << "sigma " << sigma;
    }
}

// Without drift: not one warning in 1 000 parts after the baseline; over 200 such series the
// share with any warning is printed (the chart's false-alarm rate with a 100-part baseline).
TEST(DriftWarning, SilentOnAThousandPartsWithoutDrift) {
    int series_with_alarm = 0;
    for (std::uint64_t seed = 1; seed <= 200; ++seed) {
        const auto x = die_series(kBaseline + 1000, 69.5, 0.0, 0, 0.03, seed);
        auto m = quality::DriftMonitor::from_baseline(std::span(x).first(kBaseline));
        ASSERT_TRUE(m.ok());
        int alarms = 0;
        for (std::size_t i = kBaseline; i < x.size(); ++i)
            alarms += m->add(x[i]) != quality::Drift::kNone;
        if (seed == 1) {
            EXPECT_EQ(alarms, 0) << "a warning without drift";
        }
        series_with_alarm += alarms > 0;
    }
    std::printf("series of 1000 parts without drift with a warning: %d of 200\n",
                series_with_alarm);
    EXPECT_LE(series_with_alarm, 2);  // 1 %: the baseline's σ is an estimate
}

TEST(DriftWarning, RefusesABaselineItCannotUse) {
    const std::vector<double> short_one(10, 1.0), flat(50, 1.0);
    EXPECT_FALSE(quality::DriftMonitor::from_baseline(short_one).ok());
    EXPECT_FALSE(quality::DriftMonitor::from_baseline(flat).ok());
    auto m = quality::DriftMonitor::from_baseline(die_series(50, 1.0, 0, 0, 0.01, 3));
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->add(std::nan("")), quality::Drift::kNone);  // not measured: skipped
    EXPECT_EQ(m->count(), 0u);
    quality::DriftConfig bad;
    bad.lambda = 0;
    EXPECT_FALSE(
        quality::DriftMonitor::from_baseline(die_series(50, 1.0, 0, 0, 0.01, 3), bad).ok());
}

// Western Electric rules on series written in σ from the centre (centre 2, σ 0.5: the rules
// must read the zones in σ, not in mm), each built to complete one rule at a known point.
TEST(WesternElectric, MarksThePointThatCompletesEachRule) {
    auto marks = [](std::vector<double> z) {
        for (double& v : z) v = 2.0 + 0.5 * v;
        std::vector<std::pair<std::size_t, int>> out;
        for (const auto& v : quality::western_electric(z, 2.0, 0.5))
            out.emplace_back(v.index, v.rule);
        return out;
    };
    using Marks = std::vector<std::pair<std::size_t, int>>;
    EXPECT_EQ(marks({0, 0.5, -3.2, 0}), (Marks{{2, 1}}));
    EXPECT_EQ(marks({0, 2.5, 0, 2.4}), (Marks{{3, 2}}));
    EXPECT_EQ(marks({0, -2.5, -2.1, 0}), (Marks{{2, 2}}));
    EXPECT_EQ(marks({0, 2.5, -2.5, 0}), Marks{});    // opposite sides
    EXPECT_EQ(marks({0, 2.5, 0, 0, 2.5}), Marks{});  // 2 of 4, not of 3
    EXPECT_EQ(marks({1.5, 1.2, 0, 1.9, 1.1, 0}), (Marks{{4, 3}}));
    EXPECT_EQ(marks({1.5, -1.2, 0, 1.9, 1.1}), Marks{});   // 3 of 5 on the side
    EXPECT_EQ(marks({1.5, 1.5, 1.5, 1.5, 0.2}), Marks{});  // completing point not beyond 1σ
    EXPECT_EQ(marks({0.1, 0.3, 0.2, 0.9, 0.4, 0.1, 0.5, 0.2, 0.3}), (Marks{{7, 4}, {8, 4}}));
    EXPECT_EQ(marks({-0.1, -0.3, -0.2, -0.9, -0.4, -0.1, -0.5, 0.2}), Marks{});  // 7 below
    // 3.5σ in the middle of a run above: rule 1, and rule 4 at its 8th point.
    EXPECT_EQ(marks({0.2, 0.2, 0.2, 3.5, 0.2, 0.2, 0.2, 0.2}), (Marks{{3, 1}, {7, 4}}));
}

// The daemon's drift watch: per die, a baseline, then the EWMA; dies apart; values skipped.
TEST(DriftWatch, BaselineThenWatchPerDie) {
    quality::DriftWatch watch({.baseline = 30});
    std::mt19937 rng(11);
    std::normal_distribution<double> noise(0.0, 0.01);
    using quality::Watch;
    for (int i = 0; i < 29; ++i)
        EXPECT_EQ(watch.add(1, "hub-a", "Diameter 3", 69.5 + noise(rng)), Watch::kBaseline);
    EXPECT_EQ(watch.add(1, "hub-a", "Diameter 3", std::nullopt), Watch::kBaseline);  // skipped
    EXPECT_EQ(watch.add(1, "hub-a", "Diameter 3", 69.5 + noise(rng)), Watch::kWatching);
    // Die 1 wears 5 µm per 100 parts; die 2 (the same feature) does not.
    int warned_at = -1;
    for (int i = 0; i < 1000 && warned_at < 0; ++i) {
        if (watch.add(1, "hub-a", "Diameter 3", 69.5 + 5e-5 * i + noise(rng)) == Watch::kUp)
            warned_at = i;
        watch.add(2, "hub-a", "Diameter 3", 69.5 + noise(rng));
    }
    EXPECT_GT(warned_at, 50);
    EXPECT_LT(warned_at, 600);  // at most 30 µm into a drift that takes ~6 000 parts to a NOK
    EXPECT_EQ(watch.state(1, "hub-a", "Diameter 3"), Watch::kUp);
    EXPECT_EQ(watch.state(2, "hub-a", "Diameter 3"), Watch::kWatching);
    EXPECT_EQ(watch.state(3, "hub-a", "Diameter 3"), Watch::kBaseline);
    // A baseline that does not vary sets no limits: a new one is collected.
    for (int i = 0; i < 30; ++i) watch.add(4, "hub-a", "Height 1", 39.3);
    EXPECT_EQ(watch.state(4, "hub-a", "Height 1"), Watch::kBaseline);
}

// What the watch saves is what it goes on from: a watch restored from saved() gives the same
// states as the one that never stopped, part after part.
TEST(DriftWatch, RestoredFromWhatItSavedGoesOnTheSame) {
    quality::DriftWatch a({.baseline = 25});
    std::mt19937 rng(4);
    std::normal_distribution<double> noise(0.0, 0.01);
    for (int i = 0; i < 60; ++i) {
        a.add(1, "hub-a", "Diameter 3", 69.5 + noise(rng) + 4e-4 * std::max(0, i - 40));
        if (i < 40) a.add(2, "hub-a", "Height 1", 39.3 + noise(rng));  // 15 of 25 values
    }
    quality::DriftWatch b({.baseline = 25});
    for (const auto& s : a.saved()) b.restore(s);
    for (int i = 60; i < 200; ++i) {
        const double d = 69.5 + noise(rng) + 4e-4 * (i - 40), h = 39.3 + noise(rng);
        ASSERT_EQ(a.add(1, "hub-a", "Diameter 3", d), b.add(1, "hub-a", "Diameter 3", d)) << i;
        ASSERT_EQ(a.add(2, "hub-a", "Height 1", h), b.add(2, "hub-a", "Height 1", h)) << i;
    }
    EXPECT_EQ(b.state(1, "hub-a", "Diameter 3"), quality::Watch::kUp);
    EXPECT_EQ(b.state(2, "hub-a", "Height 1"), quality::Watch::kWatching);
    quality::DriftWatch::Saved bad{1, "hub-a", "Diameter 3", {}, true, 69.5, 0.0, 69.5, 3};
    quality::DriftWatch c;
    c.restore(bad);  // σ 0: ignored
    EXPECT_EQ(c.state(1, "hub-a", "Diameter 3"), quality::Watch::kBaseline);
}
