#include "hotgauge/io/yaml_reader.hpp"

#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "hotgauge/core/geometry.hpp"

namespace hotgauge::io {

namespace {

// The line (0-based) of the last '[' or '{' opened on or before `error_line` that the whole text
// never closes, comments and quoted scalars skipped; -1 when there is none (the collection is
// closed and the mistake is inside it, where yaml-cpp says). yaml-cpp reports an unclosed flow
// collection where it gave up looking for its end, a line or more after the mistake.
int unclosed_flow_line(std::string_view text, int error_line) {
    std::vector<int> open;  // the lines of the brackets still open
    int line = 0;
    char quote = 0;
    char prev = '\n';  // the character just before
    char last = '\n';  // the last one that is not a space ('\n': none yet on this line)
    bool comment = false, escaped = false;
    for (const char c : text) {
        if (c == '\n') {
            ++line, comment = false, prev = last = '\n';
            if (quote == '\'') quote = 0;  // not valid YAML either way; do not run on
            continue;
        }
        if (comment) continue;
        if (quote) {
            if (escaped)
                escaped = false;
            else if (quote == '"' && c == '\\')
                escaped = true;
            else if (c == quote)
                quote = 0, last = c;
            prev = c;
            continue;
        }
        if (c == '#' && (prev == '\n' || prev == ' ' || prev == '\t')) {
            comment = true;
            continue;
        }
        // Where a scalar or a collection begins (in a flow collection after , [ { : too);
        // elsewhere quotes and brackets are characters of a plain scalar ("it's [1").
        const bool begins = std::strchr(open.empty() ? "\n:-?" : "\n:-?,[{", last) != nullptr;
        if ((c == '"' || c == '\'') && begins)
            quote = c;
        else if ((c == '[' || c == '{') && begins)
            open.push_back(line);
        else if ((c == ']' || c == '}') && !open.empty())
            open.pop_back();
        if (!std::isspace(static_cast<unsigned char>(c))) last = c;
        prev = c;
    }
    for (auto it = open.rbegin(); it != open.rend(); ++it)
        if (*it <= error_line) return *it;
    return -1;
}

}  // namespace

YamlSyntaxError yaml_syntax_error(std::string_view text, const YAML::Exception& e) {
    if (e.mark.is_null()) return {0, 0, e.msg};
    YamlSyntaxError out{e.mark.line + 1, e.mark.column + 1, e.msg};
    if (e.msg.find("flow not found") != std::string::npos) {  // an unclosed [ or {
        if (const int at = unclosed_flow_line(text, e.mark.line); at >= 0) {
            out.message += " (the bracket opened on this line is not closed)";
            out.line = at + 1;
            out.column = 0;
        }
    }
    return out;
}

YAML::Node YamlReader::load() const {
    if (!given_) {
        auto bytes = read_bytes(file_);
        if (!bytes) throw YamlError(bytes.error().message);
        read_ = std::string(bytes->text());
        text_ = read_;
    }
    try {
        return YAML::Load(std::string(text_));
    } catch (const YAML::Exception& e) {
        const YamlSyntaxError where = yaml_syntax_error(text_, e);
        throw YamlError(file_ + ":" + std::to_string(where.line) +
                        ": YAML syntax error: " + where.message);
    }
}

std::filesystem::path YamlReader::existing(const YAML::Node& node, const std::string& what,
                                           const std::filesystem::path& path) const {
    std::error_code ec;
    const bool there = exists_(path, ec);
    if (ec) fail(node, what + ": " + path.string() + ": " + ec.message());
    if (!there) fail(node, what + ": " + path.string() + " does not exist");
    return path;
}

std::string YamlReader::where(const YAML::Node& node) const {
    const auto mark = node.Mark();
    if (mark.line < 0) return file_ + ": ";
    return file_ + ":" + std::to_string(mark.line + 1) + ": ";
}

void YamlReader::fail(const YAML::Node& node, const std::string& message) const {
    throw YamlError(where(node) + message);
}

void YamlReader::expect_map(const YAML::Node& node, const std::string& what,
                            std::initializer_list<const char*> allowed) const {
    if (!node.IsMap()) fail(node, what + ": expected a mapping");
    for (const auto& kv : node) {
        const auto key = kv.first.as<std::string>();
        bool known = false;
        for (const char* a : allowed) known = known || key == a;
        if (!known) {
            std::string list;
            for (const char* a : allowed) list += std::string(list.empty() ? "" : ", ") + a;
            fail(kv.first, what + ": unknown key '" + key + "' (allowed: " + list + ")");
        }
    }
}

YAML::Node YamlReader::require(const YAML::Node& map, const std::string& what,
                               const char* key) const {
    YAML::Node child = map[key];
    if (!child.IsDefined() || child.IsNull()) fail(map, what + ": missing key '" + key + "'");
    return child;
}

double YamlReader::number(const YAML::Node& node, const std::string& what) const {
    double v = 0.0;
    if (!node.IsScalar() || !YAML::convert<double>::decode(node, v) || !std::isfinite(v))
        fail(node, what + ": expected a finite number, found '" +
                       (node.IsScalar() ? node.Scalar() : std::string("non-scalar")) + "'");
    return v;
}

std::int64_t YamlReader::integer(const YAML::Node& node, const std::string& what) const {
    long long v = 0;
    if (!node.IsScalar() || !YAML::convert<long long>::decode(node, v))
        fail(node, what + ": expected an integer, found '" +
                       (node.IsScalar() ? node.Scalar() : std::string("non-scalar")) + "'");
    return v;
}

bool YamlReader::boolean(const YAML::Node& node, const std::string& what) const {
    bool v = false;
    if (!node.IsScalar() || !YAML::convert<bool>::decode(node, v))
        fail(node, what + ": expected true or false");
    return v;
}

std::string YamlReader::string(const YAML::Node& node, const std::string& what) const {
    if (!node.IsScalar() || node.Scalar().empty())
        fail(node, what + ": expected a non-empty string");
    return node.Scalar();
}

std::vector<std::string> YamlReader::strings(const YAML::Node& node,
                                             const std::string& what) const {
    if (!node.IsSequence() || node.size() == 0) fail(node, what + ": expected a non-empty list");
    std::vector<std::string> out;
    for (const auto& n : node) out.push_back(string(n, what));
    return out;
}

std::vector<double> YamlReader::numbers(const YAML::Node& node, const std::string& what,
                                        std::size_t expected_size) const {
    if (!node.IsSequence()) fail(node, what + ": expected a list of numbers");
    if (expected_size && node.size() != expected_size)
        fail(node, what + ": expected " + std::to_string(expected_size) + " numbers, found " +
                       std::to_string(node.size()));
    std::vector<double> out;
    for (const auto& n : node) out.push_back(number(n, what));
    return out;
}

Eigen::Isometry3d YamlReader::isometry(const YAML::Node& n, const std::string& what) const {
    if (!n.IsSequence() || n.size() != 4) fail(n, what + ": expected a 4x4 matrix (4 rows)");
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
        const auto row = numbers(n[r], what, 4);
        for (int c = 0; c < 4; ++c) M(r, c) = row[c];
    }
    if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-12)
        fail(n, what + ": last row must be [0, 0, 0, 1]");
    if (!core::is_rotation(M.topLeftCorner<3, 3>()))
        fail(n, what + ": not a proper rotation (orthonormal, det +1)");
    Eigen::Isometry3d T;
    T.matrix() = M;
    return T;
}

Eigen::Matrix3d YamlReader::rotation(const YAML::Node& n, const std::string& what) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, what + ": expected a 3x3 matrix (3 rows)");
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
        const auto row = numbers(n[r], what, 3);
        for (int c = 0; c < 3; ++c) R(r, c) = row[c];
    }
    if (!core::is_rotation(R)) fail(n, what + ": not a proper rotation (orthonormal, det +1)");
    return R;
}

double YamlReader::number_or(const YAML::Node& map, const std::string& what, const char* key,
                             double fallback) const {
    const YAML::Node n = map[key];
    return n.IsDefined() && !n.IsNull() ? number(n, what + "." + key) : fallback;
}

}  // namespace hotgauge::io
