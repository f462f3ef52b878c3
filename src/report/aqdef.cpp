#include "hotgauge/report/aqdef.hpp"

#include <cstdio>
#include <map>

namespace hotgauge::report {
namespace {

constexpr const char* kEol = "\r\n";
constexpr int kValid = 0, kNotUsed = 255;  // K0002 attributes

// One line "Kxxxx/i value": AQDEF text fields are single-line ASCII.
std::string field(const char* key, std::size_t index, const std::string& value) {
    std::string v;
    for (char c : value)
        v += (c == '\r' || c == '\n' || static_cast<unsigned char>(c) > 126) ? '?' : c;
    return std::string(key) + "/" + std::to_string(index) + " " + v + kEol;
}

std::string number(double v, int decimals) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
    return buf;
}

// A part type: the recipe's features as characteristics, numbered from `first`.
struct PartType {
    std::size_t index = 0, first = 0;
    std::vector<results::FeatureRecord> features;
};

std::string characteristics(const std::string& recipe, const PartType& t) {
    std::string s = field("K1001", t.index, recipe) + field("K1002", t.index, recipe + " forging");
    for (std::size_t k = 0; k < t.features.size(); ++k) {
        const auto& f = t.features[k];
        const std::size_t c = t.first + k;
        s += field("K2001", c, f.name) + field("K2002", c, f.name + ", cold (20 C)") +
             field("K2101", c, number(f.nominal_mm, 4)) +
             field("K2110", c, number(f.nominal_mm + f.lower_mm, 4)) +
             field("K2111", c, number(f.nominal_mm + f.upper_mm, 4)) + field("K2142", c, "mm") +
             field("K2022", c, "4");
    }
    return s;
}

std::string value_block(const results::PartRecord& p, const results::FeatureRecord& f,
                        std::size_t c) {
    const bool used = f.usable_mm().has_value();
    std::string s = field("K0001", c, f.cold_mm ? number(*f.cold_mm, 6) : "") +
                    field("K0002", c, std::to_string(used ? kValid : kNotUsed)) +
                    field("K0004", c, aqdef_time(p.time)) + field("K0006", c, p.part_id) +
                    field("K0014", c, p.part_id);
    // The text of the value (at most 255 characters): the results files' sequence, the reason.
    std::string text = "seq " + std::to_string(p.sequence);
    if (!f.reason.empty()) text += "; " + f.verdict + ": " + f.reason;
    return s + field("K0009", c, text.substr(0, 255));
}

}  // namespace

std::string aqdef_time(const std::string& t) {
    if (t.size() < 19 || t[4] != '-' || t[7] != '-' || t[10] != 'T') return "";
    return t.substr(8, 2) + "." + t.substr(5, 2) + "." + t.substr(0, 4) + "/" + t.substr(11, 8);
}

std::string aqdef_dfq(const std::vector<results::PartRecord>& parts) {
    std::map<std::string, PartType> types;  // recipe → its part type
    std::vector<const std::string*> order;
    std::size_t characteristic_count = 0;
    for (const auto& p : parts) {
        if (p.master_check || types.count(p.recipe)) continue;
        PartType t{types.size() + 1, characteristic_count + 1, p.features};
        characteristic_count += t.features.size();
        order.push_back(&types.emplace(p.recipe, std::move(t)).first->first);
    }
    std::string s = "K0100 " + std::to_string(characteristic_count) + kEol;
    for (const std::string* recipe : order) s += characteristics(*recipe, types.at(*recipe));
    for (const auto& p : parts) {
        if (p.master_check) continue;
        const PartType& t = types.at(p.recipe);
        for (std::size_t k = 0; k < t.features.size(); ++k) {
            const auto& name = t.features[k].name;
            for (const auto& f : p.features)
                if (f.name == name) s += value_block(p, f, t.first + k);
        }
    }
    return s;
}

}  // namespace hotgauge::report
