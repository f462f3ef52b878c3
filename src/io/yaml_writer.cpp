#include "hotgauge/io/yaml_writer.hpp"

#include <charconv>
#include <cstdio>
#include <fstream>

namespace hotgauge::io {

std::string fmt_double(double v) {
    char buf[64];
    const auto res = std::to_chars(buf, buf + sizeof buf, v);
    std::string s(buf, res.ptr);
    if (s.find_first_of(".ne") == std::string::npos) {  // n: nan/inf never reach here
        s += ".0";
    } else if (const auto e = s.find('e');
               e != std::string::npos && s.find('.') == std::string::npos) {
        s.insert(e, ".0");
    }
    return s;
}

std::string quote(const std::string& s) {
    std::string out = "\"";
    for (unsigned char c : s) {
        if (c == '"' || c == '\\') {
            out += '\\';
            out += static_cast<char>(c);
        } else if (c < 0x20 || c == 0x7f) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\x%02x", c);
            out += buf;
        } else {
            out += static_cast<char>(c);
        }
    }
    return out + "\"";
}

std::string fmt_row(const double* v, int n) {
    std::string s = "[";
    for (int i = 0; i < n; ++i) s += (i ? ", " : "") + fmt_double(v[i]);
    return s + "]";
}

core::Result<void> write_text(const std::filesystem::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return core::make_error(path.string() + ": cannot open for writing");
    out << text;
    out.close();
    if (!out) return core::make_error(path.string() + ": write failed");
    return {};
}

}  // namespace hotgauge::io
