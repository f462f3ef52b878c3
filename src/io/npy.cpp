// NumPy .npy format version 1.0, as specified in numpy/lib/format.py ("Format Version 1.0"):
// magic "\x93NUMPY", major 1, minor 0, uint16 LE header length, an ASCII Python dict literal
// {'descr': ..., 'fortran_order': ..., 'shape': (...), } padded with spaces and a final '\n',
// then the raw array bytes.
#include "hotgauge/io/npy.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <string_view>
#include <system_error>

#include "hotgauge/io/bytes.hpp"

namespace hotgauge::io {
namespace {

using core::Error;
using core::make_error;

constexpr std::array<unsigned char, 6> kMagic = {0x93, 'N', 'U', 'M', 'P', 'Y'};
constexpr std::size_t kPreludeV1 = 10;  // magic (6) + version (2) + header length (2)
// NumPy aligns the data start to 64 bytes (format.py ARRAY_ALIGN) and leaves room in the header
// for the first axis to grow to 21 digits (GROWTH_AXIS_MAX_DIGITS); we write identical headers.
constexpr std::size_t kArrayAlign = 64;
constexpr std::size_t kGrowthAxisMaxDigits = 21;

std::string where(const std::filesystem::path& path) { return path.string() + ": "; }

// Item size in bytes of a simple (non-structured) NumPy dtype string such as "<f4", "|u1",
// "<U8"; nullopt when the string is not one.
std::optional<std::size_t> item_size(const std::string& descr) {
    std::string_view d = descr;
    if (!d.empty() && (d[0] == '<' || d[0] == '>' || d[0] == '|' || d[0] == '='))
        d.remove_prefix(1);
    if (d.size() < 2) return std::nullopt;
    const char kind = d[0];
    if (std::string_view("biufcSVUmM").find(kind) == std::string_view::npos) return std::nullopt;
    d.remove_prefix(1);
    if (kind == 'm' || kind == 'M') {  // datetime64/timedelta64: "<M8[ns]"
        const auto bracket = d.find('[');
        if (bracket == std::string_view::npos || d.back() != ']') return std::nullopt;
        d = d.substr(0, bracket);
    }
    std::size_t n = 0;
    if (d.empty() || d.size() > 9) return std::nullopt;
    for (char c : d) {
        if (!std::isdigit(static_cast<unsigned char>(c))) return std::nullopt;
        n = n * 10 + static_cast<std::size_t>(c - '0');
    }
    return kind == 'U' ? n * 4 : n;
}

// A recursive-descent parser for the header's Python dict literal. Accepts what NumPy writes and
// what other writers plausibly produce: keys in any order, single or double quotes, arbitrary
// whitespace, trailing commas, Python 2 "L" integer suffixes.
class HeaderParser {
  public:
    explicit HeaderParser(std::string_view text) : s_(text) {}

    // Fills `out` (descr, fortran_order, shape) or returns what is wrong.
    std::optional<std::string> parse(NpyArray& out) {
        bool have_descr = false, have_fortran = false, have_shape = false;
        skip_ws();
        if (!eat('{')) return "header is not a Python dict literal";
        while (true) {
            skip_ws();
            if (eat('}')) break;
            std::string key;
            if (!parse_string(key)) return "expected a quoted key in the header dict";
            skip_ws();
            if (!eat(':')) return "expected ':' after key '" + key + "'";
            skip_ws();
            if (key == "descr") {
                if (peek() == '[') return "structured dtypes are not supported";
                if (!parse_string(out.descr)) return "'descr' is not a dtype string";
                have_descr = true;
            } else if (key == "fortran_order") {
                if (eat_word("True")) {
                    out.fortran_order = true;
                } else if (eat_word("False")) {
                    out.fortran_order = false;
                } else {
                    return "'fortran_order' is not True or False";
                }
                have_fortran = true;
            } else if (key == "shape") {
                if (!parse_shape(out.shape)) return "'shape' is not a tuple of non-negative ints";
                have_shape = true;
            } else {
                return "unexpected key '" + key + "' in header";
            }
            skip_ws();
            if (eat(',')) continue;
            skip_ws();
            if (eat('}')) break;
            return "expected ',' or '}' in header dict";
        }
        skip_ws();
        if (pos_ != s_.size()) return "unexpected text after the header dict";
        if (!have_descr) return "header has no 'descr'";
        if (!have_fortran) return "header has no 'fortran_order'";
        if (!have_shape) return "header has no 'shape'";
        return std::nullopt;
    }

  private:
    char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
    bool eat(char c) {
        if (peek() != c) return false;
        ++pos_;
        return true;
    }
    bool eat_word(std::string_view w) {
        if (s_.substr(pos_, w.size()) != w) return false;
        const std::size_t end = pos_ + w.size();
        if (end < s_.size() &&
            (std::isalnum(static_cast<unsigned char>(s_[end])) || s_[end] == '_'))
            return false;
        pos_ = end;
        return true;
    }
    void skip_ws() {
        while (pos_ < s_.size() &&
               (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r'))
            ++pos_;
    }
    bool parse_string(std::string& out) {
        const char q = peek();
        if (q != '\'' && q != '"') return false;
        ++pos_;
        out.clear();
        while (pos_ < s_.size() && s_[pos_] != q) {
            if (s_[pos_] == '\\') return false;  // dtype strings and keys never need escapes
            out.push_back(s_[pos_++]);
        }
        return eat(q);
    }
    bool parse_int(std::int64_t& v) {
        if (!std::isdigit(static_cast<unsigned char>(peek()))) return false;
        v = 0;
        while (std::isdigit(static_cast<unsigned char>(peek()))) {
            const int digit = peek() - '0';
            if (v > (std::numeric_limits<std::int64_t>::max() - digit) / 10) return false;
            v = v * 10 + digit;
            ++pos_;
        }
        eat('L');
        return true;
    }
    bool parse_shape(std::vector<std::int64_t>& shape) {
        shape.clear();
        if (!eat('(')) return false;
        while (true) {
            skip_ws();
            if (eat(')')) return true;
            std::int64_t v = 0;
            if (!parse_int(v)) return false;
            shape.push_back(v);
            skip_ws();
            if (eat(',')) continue;
            skip_ws();
            // "(5)" is an int in Python, not a tuple; NumPy never writes it.
            if (eat(')')) return shape.size() != 1;
            return false;
        }
    }

    std::string_view s_;
    std::size_t pos_ = 0;
};

std::string shape_repr(const std::vector<std::int64_t>& shape) {
    std::string s = "(";
    for (std::size_t i = 0; i < shape.size(); ++i) {
        if (i) s += ", ";
        s += std::to_string(shape[i]);
    }
    if (shape.size() == 1) s += ",";
    return s + ")";
}

// Bytes of an array of `shape` with items of `itemsize`, or nullopt on overflow.
std::optional<std::uint64_t> data_bytes(const std::vector<std::int64_t>& shape,
                                        std::size_t itemsize) {
    std::uint64_t n = itemsize;
    for (std::int64_t d : shape) {
        if (d < 0) return std::nullopt;
        const auto ud = static_cast<std::uint64_t>(d);
        if (ud != 0 && n > std::numeric_limits<std::uint64_t>::max() / ud) return std::nullopt;
        n *= ud;
    }
    return n;
}

}  // namespace

core::Result<NpyArray> parse_npy_header(std::span<const unsigned char> file,
                                        const std::filesystem::path& path,
                                        std::uint64_t file_size) {
    if (file_size < 8 || !std::equal(kMagic.begin(), kMagic.end(), file.begin()))
        return make_error(where(path) + "not a .npy file (no \\x93NUMPY magic)");
    const int major = file[6], minor = file[7];
    if (major != 1 || minor != 0)
        return make_error(where(path) + ".npy format version " + std::to_string(major) + "." +
                          std::to_string(minor) + ", recording format v1 requires 1.0");
    if (file_size < kPreludeV1)
        return make_error(where(path) + "truncated .npy header: file has " +
                          std::to_string(file_size) + " bytes");
    const std::size_t header_len =
        static_cast<std::size_t>(file[8]) | (static_cast<std::size_t>(file[9]) << 8);
    const std::uint64_t data_offset = kPreludeV1 + header_len;
    if (file_size < data_offset)
        return make_error(where(path) + "truncated .npy header: header length " +
                          std::to_string(header_len) + " needs " + std::to_string(data_offset) +
                          " bytes, file has " + std::to_string(file_size));
    if (file.size() < data_offset)
        return make_error(where(path) + "the header's first " + std::to_string(file.size()) +
                          " bytes given for a header of " + std::to_string(data_offset));
    const std::string_view header(reinterpret_cast<const char*>(file.data()) + kPreludeV1,
                                  header_len);
    for (char c : header)
        if (static_cast<unsigned char>(c) >= 0x80 || c == '\0')
            return make_error(where(path) + "malformed .npy header: not ASCII");

    NpyArray arr;
    if (auto problem = HeaderParser(header).parse(arr))
        return make_error(where(path) + "malformed .npy header: " + *problem);
    const auto itemsize = item_size(arr.descr);
    if (!itemsize) return make_error(where(path) + "unsupported dtype '" + arr.descr + "'");
    const auto expected = data_bytes(arr.shape, *itemsize);
    if (!expected)
        return make_error(where(path) + "shape " + shape_repr(arr.shape) + " is too large");
    const std::uint64_t actual = file_size - data_offset;
    if (actual < *expected)
        return make_error(where(path) + "truncated data: shape " + shape_repr(arr.shape) + " of '" +
                          arr.descr + "' needs " + std::to_string(*expected) + " bytes, file has " +
                          std::to_string(actual));
    if (actual > *expected)
        return make_error(where(path) + "unexpected trailing data: shape " + shape_repr(arr.shape) +
                          " of '" + arr.descr + "' needs " + std::to_string(*expected) +
                          " bytes, file has " + std::to_string(actual));
    arr.data_offset = data_offset;
    arr.data_bytes = *expected;
    return arr;
}

core::Result<NpyArray> parse_npy(std::span<const unsigned char> file,
                                 const std::filesystem::path& path) {
    auto arr = parse_npy_header(file, path, file.size());
    if (!arr) return arr.error();
    const auto data = file.subspan(arr->data_offset, arr->data_bytes);
    arr->data.assign(data.begin(), data.end());
    return arr;
}

core::Result<NpyArray> read_npy(const std::filesystem::path& path) {
    auto bytes = read_bytes(path);
    if (!bytes) return bytes.error();
    return parse_npy(bytes->data, path);
}

core::Result<std::string> npy_bytes(const std::filesystem::path& path, const std::string& descr,
                                    const std::vector<std::int64_t>& shape, const void* data,
                                    std::size_t bytes) {
    const auto itemsize = item_size(descr);
    if (!itemsize) return make_error(where(path) + "unsupported dtype '" + descr + "'");
    const auto expected = data_bytes(shape, *itemsize);
    if (!expected) return make_error(where(path) + "invalid shape " + shape_repr(shape));
    if (*expected != bytes)
        return make_error(where(path) + "shape " + shape_repr(shape) + " of '" + descr +
                          "' needs " + std::to_string(*expected) + " bytes, got " +
                          std::to_string(bytes));
    if (bytes != 0 && data == nullptr) return make_error(where(path) + "no data");

    // Byte-for-byte what numpy.save writes (format.py _write_array_header / _wrap_header).
    std::string header =
        "{'descr': '" + descr + "', 'fortran_order': False, 'shape': " + shape_repr(shape) + ", }";
    if (!shape.empty()) {
        const std::size_t digits = std::to_string(shape[0]).size();
        if (digits < kGrowthAxisMaxDigits) header.append(kGrowthAxisMaxDigits - digits, ' ');
    }
    const std::size_t hlen = header.size() + 1;  // + '\n'
    const std::size_t padlen = kArrayAlign - (kPreludeV1 + hlen) % kArrayAlign;
    header.append(padlen, ' ');
    header.push_back('\n');
    if (header.size() > 0xFFFF)
        return make_error(where(path) + "header too long for .npy format version 1.0");

    std::string out;
    out.reserve(kPreludeV1 + header.size() + bytes);
    out.append(reinterpret_cast<const char*>(kMagic.data()), kMagic.size());
    out.push_back(1);
    out.push_back(0);
    out.push_back(static_cast<char>(header.size() & 0xFF));
    out.push_back(static_cast<char>(header.size() >> 8));
    out += header;
    if (bytes) out.append(static_cast<const char*>(data), bytes);
    return out;
}

core::Result<void> write_npy(const std::filesystem::path& path, const std::string& descr,
                             const std::vector<std::int64_t>& shape, const void* data,
                             std::size_t bytes) {
    auto file = npy_bytes(path, descr, shape, data, bytes);
    if (!file) return file.error();
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return make_error(where(path) + "cannot open for writing");
    out.write(file->data(), static_cast<std::streamsize>(file->size()));
    out.close();
    if (!out) return make_error(where(path) + "write failed");
    return {};
}

}  // namespace hotgauge::io
