// The quality statistics (issue 19) against answers computed with NumPy and statsmodels
// (data/oracle/quality-statistics.json, written by tests/oracle/make_quality_reference.py), and
// the study input they refuse.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

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
