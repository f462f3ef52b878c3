// Metrics for plant IT (plant::Metrics) and their endpoint (web::Server::start_metrics): the text
// is read back by prometheus_client's own parser (tests/prometheus_parse.py), the oracle, over
// real HTTP on a loopback ephemeral port.
#include <gtest/gtest.h>
#include <httplib.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "hotgauge/plant/metrics.hpp"
#include "hotgauge/web/server.hpp"
#include "temp_dir.hpp"

namespace {

using namespace hotgauge;
using plant::MetricType;

// name{k="v",...} -> value, as prometheus_client parsed the text.
std::map<std::string, double> parsed(const std::string& text) {
    test::TempDir dir;
    const auto in = dir.path / "metrics.txt";
    std::ofstream(in) << text;
    const std::string cmd = std::string(HOTGAUGE_PYTHON) + " " + HOTGAUGE_SOURCE_DIR +
                            "/tests/prometheus_parse.py < " + in.string();
    FILE* p = ::popen(cmd.c_str(), "r");
    if (!p) throw std::runtime_error("cannot run " + cmd);
    std::string out;
    char buf[4096];
    for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;) out.append(buf, n);
    if (::pclose(p) != 0) throw std::runtime_error("the parser refused:\n" + text);
    std::map<std::string, double> samples;
    std::size_t from = 0;
    for (std::size_t to; (to = out.find('\n', from)) != std::string::npos; from = to + 1) {
        const auto j = nlohmann::json::parse(out.substr(from, to - from));
        std::string key = j["name"];
        std::string labels;
        for (const auto& [k, v] : j["labels"].items())
            labels += (labels.empty() ? "" : ",") + k + "=" + v.get<std::string>();
        samples[labels.empty() ? key : key + "{" + labels + "}"] = j["value"];
    }
    return samples;
}

void fill(plant::Metrics& m) {
    m.declare("hg_cycles_total", MetricType::kCounter, "Cycles by verdict.");
    m.declare("hg_spool_depth", MetricType::kGauge, "Results waiting.\nSecond line \\ too.");
    m.declare("hg_cycle_seconds", MetricType::kHistogram, "Trigger to DONE.", {0.5, 1, 2.5});
    m.add("hg_cycles_total", {{"verdict", "OK"}});
    m.add("hg_cycles_total", {{"verdict", "OK"}}, 2);
    m.add("hg_cycles_total", {{"verdict", "N\"O\\K\n"}});
    m.set("hg_spool_depth", {}, 17);
    m.set("hg_spool_depth", {}, 4);
    for (double v : {0.2, 0.5, 0.9, 2.4, 7.0}) m.observe("hg_cycle_seconds", {{"stage", "a"}}, v);
    m.observe("hg_cycle_seconds", {{"stage", "b"}}, 0.1);
}

TEST(Metrics, TheOracleReadsBackEveryValue) {
    plant::Metrics m;
    fill(m);
    const auto s = parsed(m.text());
    EXPECT_EQ(s.at("hg_cycles_total{verdict=OK}"), 3);
    EXPECT_EQ(s.at("hg_cycles_total{verdict=N\"O\\K\n}"), 1);  // escaped, and unescaped by it
    EXPECT_EQ(s.at("hg_spool_depth"), 4);
    // Buckets cumulative: a value on a bound belongs to it (le = less or equal).
    EXPECT_EQ(s.at("hg_cycle_seconds_bucket{le=0.5,stage=a}"), 2);
    EXPECT_EQ(s.at("hg_cycle_seconds_bucket{le=1,stage=a}"), 3);
    EXPECT_EQ(s.at("hg_cycle_seconds_bucket{le=2.5,stage=a}"), 4);
    EXPECT_EQ(s.at("hg_cycle_seconds_bucket{le=+Inf,stage=a}"), 5);
    EXPECT_EQ(s.at("hg_cycle_seconds_count{stage=a}"), 5);
    EXPECT_DOUBLE_EQ(s.at("hg_cycle_seconds_sum{stage=a}"), 11.0);
    EXPECT_EQ(s.at("hg_cycle_seconds_bucket{le=0.5,stage=b}"), 1);
    EXPECT_EQ(s.size(), 3u + 2 * 6);
}

TEST(Metrics, NumbersReadBackExactly) {
    plant::Metrics m;
    m.declare("g", MetricType::kGauge, "g");
    const double values[] = {0.1, 1e-9, 123456789.125, -2.5, 1e20, 3};
    for (std::size_t i = 0; i < std::size(values); ++i)
        m.set("g", {{"i", std::to_string(i)}}, values[i]);
    const auto s = parsed(m.text());
    for (std::size_t i = 0; i < std::size(values); ++i)
        EXPECT_EQ(s.at("g{i=" + std::to_string(i) + "}"), values[i]) << i;
}

TEST(Metrics, ProgrammingErrorsThrow) {
    plant::Metrics m;
    m.declare("c_total", MetricType::kCounter, "c");
    EXPECT_THROW(m.declare("c_total", MetricType::kGauge, "again"), std::logic_error);
    EXPECT_THROW(m.declare("1bad", MetricType::kGauge, "x"), std::logic_error);
    EXPECT_THROW(m.declare("h2", MetricType::kHistogram, "x", {1, 1}), std::logic_error);
    m.declare("h", MetricType::kHistogram, "x", {1});
    EXPECT_THROW(m.set("h", {}, 1), std::logic_error);  // a histogram is observed
    EXPECT_THROW(m.add("h", {}), std::logic_error);
    EXPECT_THROW(m.observe("c_total", {}, 1), std::logic_error);
    EXPECT_THROW(m.add("c_total", {}, -1), std::logic_error);  // a counter is not lowered
    EXPECT_THROW(m.add("nope", {}), std::logic_error);
}

TEST(MetricsEndpoint, ServesTheTextOverHttpAndNothingElse) {
    plant::Metrics m;
    fill(m);
    web::ServerConfig wc;
    wc.port = 0;
    auto server = web::Server::start_metrics(wc, [&m] { return m.text(); });
    ASSERT_TRUE(server) << server.error().message;
    httplib::Client client("127.0.0.1", (*server)->port());
    auto r = client.Get("/metrics");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200);
    EXPECT_EQ(r->get_header_value("Content-Type"), "text/plain; version=0.0.4; charset=utf-8");
    EXPECT_EQ(parsed(r->body).at("hg_spool_depth"), 4);
    m.set("hg_spool_depth", {}, 9);  // a scrape reads the values of now
    EXPECT_EQ(parsed(client.Get("/metrics")->body).at("hg_spool_depth"), 9);
    EXPECT_EQ(client.Get("/")->status, 404);
    EXPECT_EQ(client.Get("/results/x.csv")->status, 404);
    EXPECT_EQ(client.Post("/metrics", "x", "text/plain")->status, 405);
    // The same port twice: the second is refused, naming the address.
    wc.port = (*server)->port();
    auto second = web::Server::start_metrics(wc, [] { return std::string(); });
    ASSERT_FALSE(second);
    EXPECT_NE(second.error().message.find("metrics endpoint: cannot listen on 127.0.0.1:"),
              std::string::npos);
}

}  // namespace
