// The comparison of `hotgauge remeasure` (docs/results.md): compare_parts, its terminal table and
// its JSON.
#include "hotgauge/results/compare.hpp"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <string_view>
#include <utility>

#include "hotgauge/core/text.hpp"

namespace hotgauge::results {
namespace {

using json = nlohmann::ordered_json;  // keys in the documented order

struct Pair {
    const PartRecord* before;
    const PartRecord* after;
};

// The production parts in both, by sequence (read_parts gives one line per sequence).
std::vector<Pair> pair_parts(const std::vector<PartRecord>& before,
                             const std::vector<PartRecord>& after) {
    std::map<std::uint64_t, const PartRecord*> by_sequence;
    for (const PartRecord& p : before)
        if (!p.master_check) by_sequence[p.sequence] = &p;
    std::vector<Pair> pairs;
    for (const PartRecord& p : after) {
        if (p.master_check) continue;
        if (const auto it = by_sequence.find(p.sequence); it != by_sequence.end())
            pairs.push_back({it->second, &p});
    }
    std::stable_sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
        return a.after->sequence < b.after->sequence;
    });
    return pairs;
}

const FeatureRecord* find_feature(const PartRecord& p, const std::string& name) {
    for (const FeatureRecord& f : p.features)
        if (f.name == name) return &f;
    return nullptr;
}

// "Unchanged" is to the bit: a value measured again from the same recording with the same
// recipe and calibration must come out identical, and any difference is worth a look.
bool same_value(const std::optional<double>& a, const std::optional<double>& b) {
    if (!a || !b) return !a && !b;
    return std::bit_cast<std::uint64_t>(*a) == std::bit_cast<std::uint64_t>(*b);
}

// The shifts being summed, in the order their features were first seen.
class ShiftSums {
  public:
    void add_feature(const std::string& name) {
        if (index_.emplace(name, shifts_.size()).second) {
            shifts_.push_back({});
            shifts_.back().feature = name;
            sums_.push_back(0.0);
        }
    }
    void add_value(const std::string& name, double shift_mm, const PartRecord& part) {
        add_feature(name);
        const std::size_t i = index_.at(name);
        FeatureShift& s = shifts_[i];
        sums_[i] += shift_mm;
        // The first of equal shifts stays the worst: the earliest part is the one to look at.
        if (s.n == 0 || std::abs(shift_mm) > std::abs(s.worst_mm)) {
            s.worst_mm = shift_mm;
            s.worst_sequence = part.sequence;
            s.worst_part_id = part.part_id;
        }
        ++s.n;
    }
    std::vector<FeatureShift> take() {
        for (std::size_t i = 0; i < shifts_.size(); ++i)
            if (shifts_[i].n) shifts_[i].mean_mm = sums_[i] / double(shifts_[i].n);
        return std::move(shifts_);
    }

  private:
    std::map<std::string, std::size_t> index_;
    std::vector<FeatureShift> shifts_;
    std::vector<double> sums_;
};

VerdictFlip flip_of(const PartRecord& part, const std::string& feature, const FeatureRecord* b,
                    const FeatureRecord* a) {
    return {part.sequence,
            part.part_id,
            feature,
            b ? b->verdict : kAbsent,
            a ? a->verdict : kAbsent,
            b ? b->cold_mm : std::nullopt,
            a ? a->cold_mm : std::nullopt};
}

// One feature of one pair: its flip when the verdict changed, its shift when both have a value.
// Returns whether it is unchanged (verdict and value to the bit).
bool compare_feature(const Pair& p, const std::string& name, Comparison& c, ShiftSums& sums) {
    const FeatureRecord* b = find_feature(*p.before, name);
    const FeatureRecord* a = find_feature(*p.after, name);
    sums.add_feature(name);
    if (!a || !b || a->verdict != b->verdict) c.flips.push_back(flip_of(*p.after, name, b, a));
    if (a && b && a->cold_mm && b->cold_mm)
        sums.add_value(name, *a->cold_mm - *b->cold_mm, *p.after);
    return a && b && a->verdict == b->verdict && same_value(a->cold_mm, b->cold_mm);
}

// Every feature of one pair, in the new recipe's order, then the ones it no longer has.
bool compare_part(const Pair& p, Comparison& c, ShiftSums& sums) {
    bool same = p.before->verdict == p.after->verdict;
    if (!same)
        c.part_flips.push_back({p.after->sequence, p.after->part_id, "", p.before->verdict,
                                p.after->verdict, std::nullopt, std::nullopt});
    for (const FeatureRecord& f : p.after->features) same &= compare_feature(p, f.name, c, sums);
    for (const FeatureRecord& f : p.before->features)
        if (!find_feature(*p.after, f.name)) same &= compare_feature(p, f.name, c, sums);
    return same;
}

json optional_json(const std::optional<double>& v) { return v ? json(*v) : json(nullptr); }

json flip_json(const VerdictFlip& f) {
    return {{"sequence", f.sequence},
            {"part_id", f.part_id},
            {"feature", f.feature},
            {"before", f.before},
            {"after", f.after},
            {"before_mm", optional_json(f.before_mm)},
            {"after_mm", optional_json(f.after_mm)}};
}

json shift_json(const FeatureShift& s) {
    const auto or_null = [&](json v) { return s.n ? v : json(nullptr); };
    return {{"feature", s.feature},
            {"n", s.n},
            {"mean_mm", or_null(s.mean_mm)},
            {"worst_mm", or_null(s.worst_mm)},
            {"worst_sequence", or_null(s.worst_sequence)},
            {"worst_part_id", or_null(s.worst_part_id)}};
}

// --- The terminal table ---

// A terminal line's width: style.md's 100 columns, so that the table reads in an 80-100 wide
// terminal and pastes into a mail or a ticket unwrapped.
[[maybe_unused]] constexpr std::size_t kLineColumns = 100;
// Flips listed per group: a recipe change can flip every part; the JSON and the page have all.
constexpr std::size_t kMaxLinesPerGroup = 20;
constexpr double kUmPerMm = 1000;

// Columns a UTF-8 text takes: one per code point (the texts here have no wide characters).
std::size_t columns(std::string_view s) {
    return std::size_t(std::count_if(s.begin(), s.end(), [](char ch) {
        return (static_cast<unsigned char>(ch) & 0xC0) != 0x80;
    }));
}

// `s` in at most `width` columns, its last one "…" when it was cut.
std::string fit(std::string_view s, std::size_t width) {
    if (columns(s) <= width) return std::string(s);
    std::string out;
    std::size_t used = 0;
    for (std::size_t i = 0; i < s.size(); ++i) {
        const bool starts = (static_cast<unsigned char>(s[i]) & 0xC0) != 0x80;
        if (starts && ++used == width) break;
        out += s[i];
    }
    return out + "\u2026";
}

struct Column {
    std::string head;
    std::size_t max_width;  // longer cells are cut
    bool right = false;     // numbers align right
};
using Rows = std::vector<std::vector<std::string>>;

std::string padded(const std::string& s, std::size_t width, bool right) {
    const std::string pad(width - columns(s), ' ');
    return right ? pad + s : s + pad;
}

// The rows under their heads, two spaces in and between columns, no trailing space.
std::string render(const std::vector<Column>& cols, const Rows& rows) {
    [[maybe_unused]] std::size_t widest = 0;  // the line with every column at its most
    for (const Column& col : cols) widest += 2 + col.max_width;
    assert(widest <= kLineColumns);
    std::vector<std::size_t> width(cols.size());
    for (std::size_t k = 0; k < cols.size(); ++k) {
        width[k] = std::min(columns(cols[k].head), cols[k].max_width);
        for (const auto& r : rows)
            width[k] = std::max(width[k], std::min(columns(r[k]), cols[k].max_width));
    }
    std::string out;
    const auto line = [&](const std::vector<std::string>& cells) {
        std::string l;
        for (std::size_t k = 0; k < cols.size(); ++k)
            l += "  " + padded(fit(cells[k], width[k]), width[k], cols[k].right);
        l.erase(l.find_last_not_of(' ') + 1);
        out += l + "\n";
    };
    std::vector<std::string> heads;
    for (const Column& col : cols) heads.push_back(col.head);
    line(heads);
    for (const auto& r : rows) line(r);
    return out;
}

std::string mm_text(const std::optional<double>& v) { return v ? core::fixed(*v, 4) : "-"; }
std::string um_text(double mm) { return core::fixed(mm * kUmPerMm, 1, true); }
std::string change_text(const VerdictFlip& f) { return f.before + " \u2192 " + f.after; }

// Widths 10 + 14 + 18 + 23 + 9 + 9, and 2 spaces before each: 95 columns (render asserts it).
std::string flips_text(const std::string& title, const std::vector<const VerdictFlip*>& flips) {
    std::string s = title + ": " + std::to_string(flips.size()) + "\n";
    if (flips.empty()) return s;
    Rows rows;
    for (std::size_t i = 0; i < flips.size() && i < kMaxLinesPerGroup; ++i) {
        const VerdictFlip& f = *flips[i];
        rows.push_back({std::to_string(f.sequence), f.part_id, f.feature, change_text(f),
                        mm_text(f.before_mm), mm_text(f.after_mm)});
    }
    s += render({{"sequence", 10, true},
                 {"part id", 14},
                 {"feature", 18},
                 {"verdicts", 23},
                 {"before mm", 9, true},
                 {"after mm", 9, true}},
                rows);
    if (flips.size() > kMaxLinesPerGroup)
        s += "  \u2026 and " + std::to_string(flips.size() - kMaxLinesPerGroup) + " more\n";
    return s;
}

std::string part_flips_text(const Comparison& c) {
    std::string s = "Part verdicts changed: " + std::to_string(c.part_flips.size()) + "\n";
    if (c.part_flips.empty()) return s;
    Rows rows;
    for (const VerdictFlip& f : c.part_flips)
        rows.push_back({std::to_string(f.sequence), f.part_id, change_text(f)});
    return s + render({{"sequence", 20, true}, {"part id", 40}, {"verdicts", 32}}, rows);
}

std::string feature_flips_text(const Comparison& c) {
    std::vector<const VerdictFlip*> ok_nok, nok_ok, other;
    for (const VerdictFlip& f : c.flips) {
        if (f.before == "OK" && f.after == "NOK")
            ok_nok.push_back(&f);
        else if (f.before == "NOK" && f.after == "OK")
            nok_ok.push_back(&f);
        else
            other.push_back(&f);
    }
    return flips_text("Feature verdicts OK \u2192 NOK", ok_nok) +
           flips_text("Feature verdicts NOK \u2192 OK", nok_ok) +
           flips_text("Other feature verdict changes", other);
}

// Widths 30 + 6 + 10 + 10 + 34, and 2 spaces before each: 100 columns.
std::string shifts_text(const Comparison& c) {
    std::string s =
        "Shift per feature, after \u2212 before, over the parts with a value both times:\n";
    Rows rows;
    for (const FeatureShift& f : c.shifts) {
        if (!f.n) {
            rows.push_back({f.feature, "0", "-", "-", "-"});
            continue;
        }
        rows.push_back({f.feature, std::to_string(f.n), um_text(f.mean_mm), um_text(f.worst_mm),
                        std::to_string(f.worst_sequence) + " " + f.worst_part_id});
    }
    return s + render({{"feature", 30},
                       {"n", 6, true},
                       {"mean \u00b5m", 10, true},
                       {"worst \u00b5m", 10, true},
                       {"worst part", 34}},
                      rows);
}

// Widths 12 + 16 + 64, and 2 spaces before each: 98 columns.
std::string not_remeasured_text(const Comparison& c) {
    std::string s = "Parts not measured again: " + std::to_string(c.not_remeasured.size()) + "\n";
    if (c.not_remeasured.empty()) return s;
    Rows rows;
    for (const NotRemeasured& n : c.not_remeasured)
        rows.push_back({std::to_string(n.sequence), n.part_id, n.why});
    return s + render({{"sequence", 12, true}, {"part id", 16}, {"why", 64}}, rows);
}

}  // namespace

std::size_t Comparison::count(const std::string& from, const std::string& to) const {
    return std::size_t(std::count_if(flips.begin(), flips.end(), [&](const VerdictFlip& f) {
        return f.before == from && f.after == to;
    }));
}

Comparison compare_parts(const std::vector<PartRecord>& before,
                         const std::vector<PartRecord>& after,
                         std::vector<NotRemeasured> not_remeasured) {
    Comparison c;
    ShiftSums sums;
    for (const Pair& p : pair_parts(before, after)) {
        ++c.parts;
        if (compare_part(p, c, sums)) ++c.unchanged;
    }
    c.shifts = sums.take();
    c.not_remeasured = std::move(not_remeasured);
    return c;
}

std::string comparison_json(const Comparison& c) {
    json j = {
        {"parts", c.parts},       {"unchanged", c.unchanged}, {"part_flips", json::array()},
        {"flips", json::array()}, {"shifts", json::array()},  {"not_remeasured", json::array()}};
    for (const VerdictFlip& f : c.part_flips) j["part_flips"].push_back(flip_json(f));
    for (const VerdictFlip& f : c.flips) j["flips"].push_back(flip_json(f));
    for (const FeatureShift& s : c.shifts) j["shifts"].push_back(shift_json(s));
    for (const NotRemeasured& n : c.not_remeasured)
        j["not_remeasured"].push_back(
            {{"sequence", n.sequence}, {"part_id", n.part_id}, {"why", n.why}});
    // Replace, not throw, on bytes that are not UTF-8: a `why` may quote a file name.
    return j.dump(2, ' ', false, json::error_handler_t::replace);
}

std::string comparison_table(const Comparison& c) {
    const std::size_t other = c.flips.size() - c.count("OK", "NOK") - c.count("NOK", "OK");
    std::string s = std::to_string(c.parts) + " parts compared, " + std::to_string(c.unchanged) +
                    " unchanged, " + std::to_string(c.part_flips.size()) +
                    " with another part verdict\n";
    s += "Feature verdicts changed: " + std::to_string(c.flips.size()) + " (OK \u2192 NOK " +
         std::to_string(c.count("OK", "NOK")) + ", NOK \u2192 OK " +
         std::to_string(c.count("NOK", "OK")) + ", other " + std::to_string(other) + ")\n\n";
    return s + part_flips_text(c) + "\n" + feature_flips_text(c) + "\n" + shifts_text(c) + "\n" +
           not_remeasured_text(c);
}

}  // namespace hotgauge::results
