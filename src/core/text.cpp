#include "hotgauge/core/text.hpp"

#include <cstdio>

namespace hotgauge::core {

std::string html_escape(std::string_view text) {
    std::string out;
    out.reserve(text.size());
    for (const char c : text) {
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
            case '\'':
                out += "&#39;";
                break;
            default:
                out += c;
        }
    }
    return out;
}

std::string fixed(double value, int decimals, bool sign) {
    char b[64];
    std::snprintf(b, sizeof b, sign ? "%+.*f" : "%.*f", decimals, value);
    return b;
}

}  // namespace hotgauge::core
