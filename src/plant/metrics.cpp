#include "hotgauge/plant/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>

namespace hotgauge::plant {
namespace {

bool valid_name(const std::string& n) {
    if (n.empty() || std::isdigit(static_cast<unsigned char>(n[0]))) return false;
    return std::all_of(n.begin(), n.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == ':';
    });
}

// A sample value as Prometheus reads it: integers without a fraction, +Inf/-Inf/NaN spelled out.
std::string number(double v) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
    char buf[32];
    if (v == std::floor(v) && std::fabs(v) < 1e15)
        std::snprintf(buf, sizeof buf, "%.0f", v);
    else if (std::snprintf(buf, sizeof buf, "%.15g", v); std::strtod(buf, nullptr) != v)
        std::snprintf(buf, sizeof buf, "%.17g", v);  // the shortest that reads back the same
    return buf;
}

// Label values escape backslash, double quote and newline; HELP text backslash and newline.
std::string escaped(const std::string& s, bool quote) {
    std::string out;
    for (char c : s) {
        if (c == '\\')
            out += "\\\\";
        else if (c == '\n')
            out += "\\n";
        else if (c == '"' && quote)
            out += "\\\"";
        else
            out += c;
    }
    return out;
}

std::string label_set(const Labels& labels, const std::string& le = {}) {
    std::string out;
    for (const auto& [k, v] : labels)
        out += (out.empty() ? "" : ",") + k + "=\"" + escaped(v, true) + '"';
    if (!le.empty()) out += (out.empty() ? "" : ",") + std::string("le=\"") + le + '"';
    return out.empty() ? out : '{' + out + '}';
}

const char* type_name(MetricType t) {
    switch (t) {
        case MetricType::kCounter:
            return "counter";
        case MetricType::kGauge:
            return "gauge";
        case MetricType::kHistogram:
            return "histogram";
    }
    return "untyped";
}

}  // namespace

void Metrics::declare(const std::string& name, MetricType type, const std::string& help,
                      std::vector<double> buckets) {
    if (!valid_name(name)) throw std::logic_error("metrics: invalid name '" + name + "'");
    if (type == MetricType::kHistogram &&
        (buckets.empty() || !std::is_sorted(buckets.begin(), buckets.end()) ||
         std::adjacent_find(buckets.begin(), buckets.end()) != buckets.end()))
        throw std::logic_error("metrics: " + name + ": buckets must increase");
    std::lock_guard lock(mutex_);
    for (const auto& f : families_)
        if (f.name == name) throw std::logic_error("metrics: " + name + " declared twice");
    families_.push_back(Family{name, help, type, std::move(buckets), {}});
}

Metrics::Family& Metrics::family(const std::string& name, MetricType type) {
    for (auto& f : families_)
        if (f.name == name) {
            if (f.type != type)
                throw std::logic_error("metrics: " + name + " is a " + type_name(f.type));
            return f;
        }
    throw std::logic_error("metrics: " + name + " not declared");
}

void Metrics::add(const std::string& name, const Labels& labels, double by) {
    if (!(by >= 0)) throw std::logic_error("metrics: counter " + name + " may only grow");
    std::lock_guard lock(mutex_);
    family(name, MetricType::kCounter).series[labels].value += by;
}

void Metrics::set(const std::string& name, const Labels& labels, double value) {
    std::lock_guard lock(mutex_);
    for (auto& f : families_)
        if (f.name == name && f.type == MetricType::kCounter) {
            f.series[labels].value = value;
            return;
        }
    family(name, MetricType::kGauge).series[labels].value = value;
}

void Metrics::observe(const std::string& name, const Labels& labels, double value) {
    std::lock_guard lock(mutex_);
    Family& f = family(name, MetricType::kHistogram);
    Series& s = f.series[labels];
    if (s.le.empty()) s.le.assign(f.buckets.size(), 0);
    // The first bucket whose upper bound holds the value; the +Inf bucket is the count.
    const auto at = std::lower_bound(f.buckets.begin(), f.buckets.end(), value) - f.buckets.begin();
    if (static_cast<std::size_t>(at) < s.le.size()) ++s.le[at];
    ++s.count;
    s.sum += value;
}

std::string Metrics::text() const {
    std::lock_guard lock(mutex_);
    std::string out;
    for (const auto& f : families_) {
        out += "# HELP " + f.name + ' ' + escaped(f.help, false) + '\n';
        out += "# TYPE " + f.name + ' ' + type_name(f.type) + '\n';
        for (const auto& [labels, s] : f.series) {
            if (f.type != MetricType::kHistogram) {
                out += f.name + label_set(labels) + ' ' + number(s.value) + '\n';
                continue;
            }
            std::uint64_t cumulative = 0;
            for (std::size_t b = 0; b < f.buckets.size(); ++b) {
                cumulative += s.le[b];
                out += f.name + "_bucket" + label_set(labels, number(f.buckets[b])) + ' ' +
                       number(static_cast<double>(cumulative)) + '\n';
            }
            out += f.name + "_bucket" + label_set(labels, "+Inf") + ' ' +
                   number(static_cast<double>(s.count)) + '\n';
            out += f.name + "_sum" + label_set(labels) + ' ' + number(s.sum) + '\n';
            out += f.name + "_count" + label_set(labels) + ' ' +
                   number(static_cast<double>(s.count)) + '\n';
        }
    }
    return out;
}

}  // namespace hotgauge::plant
