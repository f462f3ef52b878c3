#pragma once
// Small helpers for writing HTML and inline SVG by hand (the reports have no script and fetch
// nothing, so there is no template engine or charting library to lean on).
#include <cstdio>
#include <string>

namespace hotgauge::report::svg {

// Text for HTML content and attribute values.
inline std::string escape(const std::string& s) {
    std::string out;
    out.reserve(s.size());
    for (char c : s) {
        switch (c) {
            case '&':
                out += "&amp;";
                break;
            case '<':
                out += "&lt;";
                break;
            case '>':
                out += "&gt;";
                break;
            case '"':
                out += "&quot;";
                break;
            default:
                out += c;
        }
    }
    return out;
}

// A number with `decimals` decimals ("−" for a non-finite one: nothing is invented).
inline std::string num(double v, int decimals) {
    if (!(v == v) || v > 1e300 || v < -1e300) return "\u2212";
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
    return buf;
}

// Linear map from [d0, d1] (data) to [p0, p1] (pixels).
struct Scale {
    double d0, d1, p0, p1;
    double operator()(double v) const { return p0 + (v - d0) * (p1 - p0) / (d1 - d0); }
};

}  // namespace hotgauge::report::svg
