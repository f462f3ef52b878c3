#include "hotgauge/io/yaml_reader.hpp"

#include <cmath>
#include <filesystem>

namespace hotgauge::io {

YAML::Node YamlReader::load() const {
    if (!std::filesystem::exists(file_)) throw YamlError(file_ + ": file not found");
    try {
        return YAML::LoadFile(file_);
    } catch (const YAML::Exception& e) {
        throw YamlError(file_ + ":" + std::to_string(e.mark.line + 1) +
                        ": YAML syntax error: " + e.msg);
    }
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

double YamlReader::number_or(const YAML::Node& map, const std::string& what, const char* key,
                             double fallback) const {
    const YAML::Node n = map[key];
    return n.IsDefined() && !n.IsNull() ? number(n, what + "." + key) : fallback;
}

}  // namespace hotgauge::io
