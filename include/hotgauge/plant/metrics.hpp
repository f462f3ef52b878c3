#pragma once
// Metrics for plant IT in Prometheus's text exposition format, version 0.0.4 (docs/plant-data.md
// "Metrics"): counters, gauges and histograms with labels, declared once and updated from any
// thread; text() is what GET /metrics answers.
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace hotgauge::plant {

using Labels = std::map<std::string, std::string>;  // name -> value, sorted by name

enum class MetricType { kCounter, kGauge, kHistogram };

class Metrics {
  public:
    // Declares a metric family: its name ([a-zA-Z_:][a-zA-Z0-9_:]*), help and type; a
    // histogram's bucket upper bounds, increasing (+Inf is added). Declaring twice, or updating
    // an undeclared name or with the wrong kind of update, throws std::logic_error: a programming
    // error, not an input.
    void declare(const std::string& name, MetricType type, const std::string& help,
                 std::vector<double> buckets = {});
    void add(const std::string& name, const Labels& labels, double by = 1.0);  // counter
    // A gauge; or a counter kept elsewhere (a device's own count), copied at a scrape.
    void set(const std::string& name, const Labels& labels, double value);
    void observe(const std::string& name, const Labels& labels, double value);  // histogram
    // The exposition: families in declaration order, series in label order.
    std::string text() const;

  private:
    struct Series {
        double value = 0;               // counter, gauge
        std::vector<std::uint64_t> le;  // histogram: counts per bucket (cumulative at output)
        std::uint64_t count = 0;
        double sum = 0;
    };
    struct Family {
        std::string name, help;
        MetricType type;
        std::vector<double> buckets;
        std::map<Labels, Series> series;
    };
    Family& family(const std::string& name, MetricType type);
    mutable std::mutex mutex_;
    std::vector<Family> families_;
};

}  // namespace hotgauge::plant
