// Mesh and scan files as oriented surface samples (surface_io.hpp). Formats: PLY
// (paulbourke.net/dataformats/ply), STL (ascii and binary: 80-byte header, u32 count, 50 bytes per
// triangle), PCD v0.7 (pointclouds.org/documentation/tutorials/pcd_file_format.html).
#include "hotgauge/io/surface_io.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <string_view>

#include "file_bytes.hpp"
#include "hotgauge/match/normals.hpp"

namespace hotgauge::io {
namespace {

namespace fs = std::filesystem;
using core::make_error;
using core::Result;

constexpr std::uint64_t kSamplingSeed = 20240517;  // any fixed value: reproducible models
constexpr double kMaxSamples = 5e7;                // beyond this the spacing is a mistake

std::string lower(std::string_view s) {
    std::string out(s);
    for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return out;
}

bool parse_number(std::string_view s, double& out) {
    if (!s.empty() && s.front() == '+') s.remove_prefix(1);
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size();
}

// For messages: "8", "-1", "2.5", "1e+20".
std::string number(double v) {
    std::ostringstream s;
    s << v;
    return s.str();
}

bool parse_count(std::string_view s, std::uint64_t& out) {
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size();
}

// Whitespace-separated tokens of a text section, with line numbers for messages.
class Tokens {
  public:
    Tokens(const std::vector<unsigned char>& b, std::size_t pos, int line)
        : b_(b), pos_(pos), line_(line) {}

    // The next token, or nullopt at the end of the data.
    std::optional<std::string_view> next() {
        while (pos_ < b_.size() && std::isspace(b_[pos_])) {
            if (b_[pos_] == '\n') ++line_;
            ++pos_;
        }
        if (pos_ == b_.size()) return std::nullopt;
        const std::size_t start = pos_;
        while (pos_ < b_.size() && !std::isspace(b_[pos_])) ++pos_;
        return std::string_view(reinterpret_cast<const char*>(b_.data()) + start, pos_ - start);
    }
    // The rest of the current line (after a keyword such as "solid name with spaces").
    void skip_line() {
        while (pos_ < b_.size() && b_[pos_] != '\n') ++pos_;
    }
    int line() const { return line_; }

  private:
    const std::vector<unsigned char>& b_;
    std::size_t pos_;
    int line_;
};

// Header lines (PLY, PCD): split into words, '\r' dropped; `end` is the offset after the '\n'.
struct HeaderLine {
    std::vector<std::string_view> words;
    std::size_t end = 0;
};

std::optional<HeaderLine> header_line(const std::vector<unsigned char>& b, std::size_t pos) {
    const auto nl = std::find(b.begin() + static_cast<std::ptrdiff_t>(pos), b.end(), '\n');
    if (nl == b.end()) return std::nullopt;
    HeaderLine line;
    line.end = static_cast<std::size_t>(nl - b.begin()) + 1;
    std::size_t i = pos;
    while (i < line.end - 1) {
        while (i < line.end - 1 && std::isspace(b[i])) ++i;
        const std::size_t start = i;
        while (i < line.end - 1 && !std::isspace(b[i])) ++i;
        if (i > start)
            line.words.emplace_back(reinterpret_cast<const char*>(b.data()) + start, i - start);
    }
    return line;
}

// ---- binary numbers ----

enum class Scalar { kI8, kU8, kI16, kU16, kI32, kU32, kI64, kU64, kF32, kF64 };

std::size_t scalar_bytes(Scalar t) {
    switch (t) {
        case Scalar::kI8:
        case Scalar::kU8:
            return 1;
        case Scalar::kI16:
        case Scalar::kU16:
            return 2;
        case Scalar::kI32:
        case Scalar::kU32:
        case Scalar::kF32:
            return 4;
        default:
            return 8;
    }
}

// A little-endian value at p (scalar_bytes(t) bytes available).
double load_scalar(const unsigned char* p, Scalar t) {
    std::uint64_t u = 0;
    const std::size_t n = scalar_bytes(t);
    for (std::size_t i = 0; i < n; ++i) u |= std::uint64_t{p[i]} << (8 * i);
    switch (t) {
        case Scalar::kI8:
            return static_cast<std::int8_t>(u);
        case Scalar::kU8:
            return static_cast<double>(u);
        case Scalar::kI16:
            return static_cast<std::int16_t>(u);
        case Scalar::kU16:
            return static_cast<double>(u);
        case Scalar::kI32:
            return static_cast<std::int32_t>(u);
        case Scalar::kU32:
            return static_cast<double>(u);
        case Scalar::kI64:
            return static_cast<double>(static_cast<std::int64_t>(u));
        case Scalar::kU64:
            return static_cast<double>(u);
        case Scalar::kF32:
            return std::bit_cast<float>(static_cast<std::uint32_t>(u));
        case Scalar::kF64:
            return std::bit_cast<double>(u);
    }
    return 0;
}

// Values of a PLY or PCD data section, ascii or binary; the first failure is kept in `error`.
class Values {
  public:
    Values(const std::vector<unsigned char>& b, std::size_t pos, bool binary, int line)
        : b_(b), pos_(pos), binary_(binary), tokens_(b, pos, line) {}

    std::string error;

    bool read(Scalar t, double& v) {
        if (!error.empty()) return false;
        if (binary_) {
            const std::size_t n = scalar_bytes(t);
            if (b_.size() - pos_ < n) {
                error = "truncated: data ends at byte " + std::to_string(b_.size());
                return false;
            }
            v = load_scalar(b_.data() + pos_, t);
            pos_ += n;
            return true;
        }
        const auto tok = tokens_.next();
        if (!tok) {
            error = "truncated: data ends early";
            return false;
        }
        if (!parse_number(*tok, v)) {
            error = "line " + std::to_string(tokens_.line()) + ": not a number: '" +
                    std::string(tok->substr(0, 40)) + "'";
            return false;
        }
        return true;
    }

  private:
    const std::vector<unsigned char>& b_;
    std::size_t pos_;
    bool binary_;
    Tokens tokens_;
};

// ---- PLY ----

std::optional<Scalar> ply_scalar(std::string_view name) {
    static const std::pair<std::string_view, Scalar> kTypes[] = {
        {"char", Scalar::kI8},    {"int8", Scalar::kI8},     {"uchar", Scalar::kU8},
        {"uint8", Scalar::kU8},   {"short", Scalar::kI16},   {"int16", Scalar::kI16},
        {"ushort", Scalar::kU16}, {"uint16", Scalar::kU16},  {"int", Scalar::kI32},
        {"int32", Scalar::kI32},  {"uint", Scalar::kU32},    {"uint32", Scalar::kU32},
        {"float", Scalar::kF32},  {"float32", Scalar::kF32}, {"double", Scalar::kF64},
        {"float64", Scalar::kF64}};
    for (const auto& [n, t] : kTypes)
        if (n == name) return t;
    return std::nullopt;
}

struct PlyProperty {
    std::string name;
    bool list = false;
    Scalar count_type = Scalar::kU8, type = Scalar::kF32;
};

struct PlyElement {
    std::string name;
    std::uint64_t count = 0;
    std::vector<PlyProperty> properties;
};

struct PlyHeader {
    bool binary = false;
    std::vector<PlyElement> elements;
    std::size_t data_start = 0;
    int data_line = 0;  // line number of the first data line (ascii)
};

Result<PlyHeader> read_ply_header(const std::vector<unsigned char>& b, const std::string& where) {
    PlyHeader h;
    std::size_t pos = 0;
    bool have_format = false;
    for (int line_no = 1;; ++line_no) {
        const auto line = header_line(b, pos);
        if (!line) return make_error(where + "bad PLY header: no end_header");
        pos = line->end;
        const auto& w = line->words;
        const std::string at = where + std::to_string(line_no) + ": ";
        if (line_no == 1) {
            if (w.size() != 1 || w[0] != "ply") return make_error(where + "not a PLY file");
            continue;
        }
        if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
        if (w[0] == "end_header") {
            if (!have_format) return make_error(at + "bad PLY header: no format line");
            h.data_start = pos;
            h.data_line = line_no + 1;
            return h;
        }
        if (w[0] == "format") {
            if (w.size() != 3 || w[2] != "1.0") return make_error(at + "bad PLY format line");
            if (w[1] == "ascii") {
                h.binary = false;
            } else if (w[1] == "binary_little_endian") {
                h.binary = true;
            } else {
                return make_error(at + "PLY format '" + std::string(w[1]) +
                                  "' is not supported (ascii or binary_little_endian)");
            }
            have_format = true;
        } else if (w[0] == "element") {
            std::uint64_t count = 0;
            if (w.size() != 3 || !parse_count(w[2], count))
                return make_error(at + "bad PLY element line");
            h.elements.push_back({std::string(w[1]), count, {}});
        } else if (w[0] == "property") {
            if (h.elements.empty()) return make_error(at + "PLY property before any element");
            PlyProperty p;
            std::optional<Scalar> t, c;
            if (w.size() == 3 && (t = ply_scalar(w[1]))) {
                p.type = *t;
            } else if (w.size() == 5 && w[1] == "list" && (c = ply_scalar(w[2])) &&
                       (t = ply_scalar(w[3]))) {
                p.list = true;
                p.count_type = *c;
                p.type = *t;
            } else {
                return make_error(at + "bad PLY property line");
            }
            p.name = std::string(w.back());
            h.elements.back().properties.push_back(std::move(p));
        } else {
            return make_error(at + "bad PLY header: unknown keyword '" + std::string(w[0]) + "'");
        }
    }
}

struct PlyData {
    std::vector<Eigen::Vector3d> vertices, normals;  // normals empty when the file has none
    std::vector<std::array<std::uint32_t, 3>> triangles;
    std::uint64_t faces = 0;
};

// Index of the scalar property `name` in `e`, -1 if absent.
int find_property(const PlyElement& e, std::string_view name) {
    for (std::size_t i = 0; i < e.properties.size(); ++i)
        if (e.properties[i].name == name && !e.properties[i].list) return static_cast<int>(i);
    return -1;
}

Result<PlyData> read_ply(const std::vector<unsigned char>& b, const std::string& where) {
    auto header = read_ply_header(b, where);
    if (!header) return header.error();
    const PlyHeader& h = *header;
    const PlyElement* vertex_el = nullptr;
    for (const PlyElement& e : h.elements)
        if (e.name == "vertex") vertex_el = &e;
    if (!vertex_el) return make_error(where + "PLY has no vertex element");
    const std::uint64_t n_vertices = vertex_el->count;

    PlyData out;
    Values values(b, h.data_start, h.binary, h.data_line);
    std::vector<double> record, list;
    for (const PlyElement& e : h.elements) {
        const bool is_vertex = &e == vertex_el;
        const bool is_face = e.name == "face";
        std::array<int, 6> xyz{};  // x y z nx ny nz
        if (is_vertex) {
            const char* names[] = {"x", "y", "z", "nx", "ny", "nz"};
            for (int k = 0; k < 6; ++k) xyz[k] = find_property(e, names[k]);
            if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0)
                return make_error(where + "PLY vertex element has no x, y, z properties");
            const int n_normal = (xyz[3] >= 0) + (xyz[4] >= 0) + (xyz[5] >= 0);
            if (n_normal != 0 && n_normal != 3)
                return make_error(where + "PLY vertex element has some of nx, ny, nz, not all");
        }
        int index_list = -1;
        if (is_face)
            for (std::size_t i = 0; i < e.properties.size(); ++i)
                if (e.properties[i].list && (e.properties[i].name == "vertex_indices" ||
                                             e.properties[i].name == "vertex_index"))
                    index_list = static_cast<int>(i);
        if (e.properties.empty()) continue;  // records without data
        record.resize(e.properties.size());
        for (std::uint64_t r = 0; r < e.count; ++r) {
            for (std::size_t i = 0; i < e.properties.size(); ++i) {
                const PlyProperty& p = e.properties[i];
                if (!p.list) {
                    values.read(p.type, record[i]);
                    continue;
                }
                double count = 0;
                if (!values.read(p.count_type, count)) break;
                if (!(count >= 0 && count == std::floor(count)))
                    return make_error(where + e.name + " " + std::to_string(r) + ": list count " +
                                      number(count));
                // Values are read one by one: a corrupt count runs into the end of the data
                // instead of allocating.
                list.clear();
                for (double j = 0, v = 0; j < count && values.read(p.type, v); ++j)
                    if (static_cast<int>(i) == index_list) list.push_back(v);
                if (static_cast<int>(i) != index_list || !values.error.empty()) continue;
                for (double v : list)
                    if (!(v >= 0 && v == std::floor(v) && v < static_cast<double>(n_vertices)))
                        return make_error(where + "face " + std::to_string(r) + ": vertex index " +
                                          number(v) + " out of range (" +
                                          std::to_string(n_vertices) + " vertices)");
                for (std::size_t k = 2; k < list.size(); ++k)  // fan
                    out.triangles.push_back({static_cast<std::uint32_t>(list[0]),
                                             static_cast<std::uint32_t>(list[k - 1]),
                                             static_cast<std::uint32_t>(list[k])});
            }
            if (!values.error.empty())
                return make_error(where + values.error + " (" + e.name + " " + std::to_string(r) +
                                  " of " + std::to_string(e.count) + ")");
            if (is_vertex) {
                out.vertices.emplace_back(record[xyz[0]], record[xyz[1]], record[xyz[2]]);
                if (xyz[3] >= 0)
                    out.normals.emplace_back(record[xyz[3]], record[xyz[4]], record[xyz[5]]);
            }
        }
        if (is_face) out.faces += e.count;
    }
    return out;
}

// ---- STL ----

struct Mesh {
    std::vector<Eigen::Vector3d> vertices;
    std::vector<std::array<std::uint32_t, 3>> triangles;
    std::uint64_t faces = 0;
};

Result<Mesh> read_stl_binary(const std::vector<unsigned char>& b, const std::string& where) {
    const std::uint64_t n = std::uint64_t{b[80]} | std::uint64_t{b[81]} << 8 |
                            std::uint64_t{b[82]} << 16 | std::uint64_t{b[83]} << 24;
    if (b.size() < 84 + 50 * n)
        return make_error(where + "truncated: binary STL of " + std::to_string(n) +
                          " triangles needs " + std::to_string(84 + 50 * n) + " bytes, file has " +
                          std::to_string(b.size()));
    Mesh m;
    m.faces = n;
    m.vertices.reserve(3 * n);
    for (std::uint64_t t = 0; t < n; ++t) {
        const unsigned char* p = b.data() + 84 + 50 * t + 12;  // after the stored normal
        for (std::uint32_t k = 0; k < 3; ++k, p += 12)
            m.vertices.emplace_back(load_scalar(p, Scalar::kF32), load_scalar(p + 4, Scalar::kF32),
                                    load_scalar(p + 8, Scalar::kF32));
        const auto i = static_cast<std::uint32_t>(3 * t);
        m.triangles.push_back({i, i + 1, i + 2});
    }
    return m;
}

Result<Mesh> read_stl_ascii(const std::vector<unsigned char>& b, const std::string& where) {
    Tokens t(b, 0, 1);
    t.next();  // "solid"
    t.skip_line();
    Mesh m;
    auto fail = [&](const std::string& what) {
        return make_error(where + std::to_string(t.line()) + ": " + what);
    };
    auto expect = [&](std::string_view word) {
        const auto tok = t.next();
        return tok && lower(*tok) == word;
    };
    auto vec = [&](Eigen::Vector3d& v) {
        for (int k = 0; k < 3; ++k) {
            const auto tok = t.next();
            if (!tok || !parse_number(*tok, v[k])) return false;
        }
        return true;
    };
    std::vector<Eigen::Vector3d> loop;
    for (;;) {
        const auto tok = t.next();
        if (!tok) return fail("truncated: no endsolid");
        const std::string word = lower(*tok);
        if (word == "endsolid") break;
        if (word != "facet")
            return fail("expected 'facet' or 'endsolid', found '" +
                        std::string(tok->substr(0, 40)) + "'");
        Eigen::Vector3d normal;
        if (!expect("normal") || !vec(normal)) return fail("bad facet normal");
        if (!expect("outer") || !expect("loop")) return fail("expected 'outer loop'");
        loop.clear();
        for (;;) {
            const auto v = t.next();
            if (!v) return fail("truncated inside a facet");
            const std::string vw = lower(*v);
            if (vw == "endloop") break;
            if (vw != "vertex" || !vec(loop.emplace_back()))
                return fail("expected 'vertex x y z' or 'endloop'");
        }
        if (!expect("endfacet")) return fail("expected 'endfacet'");
        ++m.faces;
        const auto base = static_cast<std::uint32_t>(m.vertices.size());
        m.vertices.insert(m.vertices.end(), loop.begin(), loop.end());
        for (std::uint32_t k = 2; k < loop.size(); ++k)
            m.triangles.push_back({base, base + k - 1, base + k});
    }
    return m;
}

Result<Mesh> read_stl(const std::vector<unsigned char>& b, const std::string& where) {
    if (b.size() >= 84) {
        const std::uint64_t n = std::uint64_t{b[80]} | std::uint64_t{b[81]} << 8 |
                                std::uint64_t{b[82]} << 16 | std::uint64_t{b[83]} << 24;
        if (b.size() == 84 + 50 * n) return read_stl_binary(b, where);
    }
    // "solid" starts an ascii STL, though some binary writers put it in their header too: the
    // binary size check above comes first.
    const std::size_t n_head = std::min<std::size_t>(b.size(), 6);
    const std::string head(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n_head));
    if (lower(head).starts_with("solid") && (head.size() == 5 || std::isspace(head[5]) != 0))
        return read_stl_ascii(b, where);
    if (b.size() < 84) return make_error(where + "not an STL file (too short, no 'solid')");
    return read_stl_binary(b, where);
}

// ---- sampling ----

// Uniform in [0, 1) from the engine's bits: the same on every standard library, unlike
// std::uniform_real_distribution.
double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

Result<SurfaceSamples> sample_mesh(const Mesh& mesh, double spacing_mm, const std::string& where) {
    struct Tri {
        Eigen::Vector3d a, e1, e2;
        Eigen::Vector3f normal;
    };
    std::vector<Tri> tris;
    std::vector<double> cumulative_area;
    double total = 0;
    for (const auto& t : mesh.triangles) {
        const Eigen::Vector3d& a = mesh.vertices[t[0]];
        const Eigen::Vector3d e1 = mesh.vertices[t[1]] - a, e2 = mesh.vertices[t[2]] - a;
        const Eigen::Vector3d c = e1.cross(e2);
        const double longest2 =
            std::max({e1.squaredNorm(), e2.squaredNorm(), (e2 - e1).squaredNorm()});
        // Zero, collinear (sin of the angle below 1e-12) or non-finite: no surface to sample.
        if (!(c.norm() > 1e-12 * longest2) || !std::isfinite(longest2)) continue;
        tris.push_back({a, e1, e2, c.normalized().cast<float>()});
        total += 0.5 * c.norm();
        cumulative_area.push_back(total);
    }
    if (tris.empty())
        return make_error(
            where + "no triangles" +
            (mesh.triangles.empty()
                 ? std::string()
                 : " with an area (" + std::to_string(mesh.triangles.size()) + " degenerate)"));
    const double cell = spacing_mm * spacing_mm;
    if (total / cell > kMaxSamples)
        return make_error(where + std::to_string(total) + " mm² at " + std::to_string(spacing_mm) +
                          " mm spacing would be more than " + std::to_string(kMaxSamples) +
                          " samples");
    // Systematic sampling of the cumulative area (one random offset, then one sample per
    // spacing² of area): every triangle gets its share of samples up to one, at random places.
    std::mt19937_64 rng(kSamplingSeed);
    SurfaceSamples out;
    std::size_t tri = 0;
    for (double target = uniform01(rng) * cell; target < total; target += cell) {
        while (tri + 1 < tris.size() && cumulative_area[tri] <= target) ++tri;
        const Tri& t = tris[tri];
        const double s = std::sqrt(uniform01(rng)), r2 = uniform01(rng);
        const Eigen::Vector3d p = t.a + s * (1 - r2) * t.e1 + s * r2 * t.e2;
        out.points.push_back(p.cast<float>());
        out.normals.push_back(t.normal);
    }
    if (out.points.empty())
        return make_error(where + "surface of " + std::to_string(total) +
                          " mm² is smaller than one sample at " + std::to_string(spacing_mm) +
                          " mm spacing");
    return out;
}

// ---- scans ----

struct PcdField {
    std::string name;
    Scalar type = Scalar::kF32;
    std::size_t count = 1;
    std::size_t offset = 0;  // bytes (binary) or values (ascii) from the start of the point
};

std::optional<Scalar> pcd_scalar(char type, std::uint64_t size) {
    if (type == 'F' && size == 4) return Scalar::kF32;
    if (type == 'F' && size == 8) return Scalar::kF64;
    if (type == 'I' || type == 'U') {
        const bool u = type == 'U';
        switch (size) {
            case 1:
                return u ? Scalar::kU8 : Scalar::kI8;
            case 2:
                return u ? Scalar::kU16 : Scalar::kI16;
            case 4:
                return u ? Scalar::kU32 : Scalar::kI32;
            case 8:
                return u ? Scalar::kU64 : Scalar::kI64;
            default:
                break;
        }
    }
    return std::nullopt;
}

// Points and, when the file has them, normals (same length), unfiltered.
struct RawScan {
    std::vector<Eigen::Vector3d> points, normals;
};

Result<RawScan> read_pcd(const std::vector<unsigned char>& b, const std::string& where) {
    std::vector<std::string_view> names, sizes, types, counts;
    std::uint64_t width = 0, height = 1, points = 0;
    bool have_points = false, have_width = false;
    std::string data;
    std::size_t pos = 0;
    int line_no = 0;
    while (data.empty()) {
        const auto line = header_line(b, pos);
        ++line_no;
        if (!line) return make_error(where + "bad PCD header: no DATA line");
        pos = line->end;
        const auto& w = line->words;
        if (w.empty() || w[0].starts_with("#")) continue;
        const std::string at = where + std::to_string(line_no) + ": ";
        const std::string key(w[0]);
        const std::vector<std::string_view> rest(w.begin() + 1, w.end());
        if (key == "VERSION" || key == "VIEWPOINT") continue;
        if (key == "FIELDS") {
            names = rest;
        } else if (key == "SIZE") {
            sizes = rest;
        } else if (key == "TYPE") {
            types = rest;
        } else if (key == "COUNT") {
            counts = rest;
        } else if (key == "WIDTH" || key == "HEIGHT" || key == "POINTS") {
            std::uint64_t v = 0;
            if (rest.size() != 1 || !parse_count(rest[0], v))
                return make_error(at + key + ": expected a count");
            (key == "WIDTH" ? width : key == "HEIGHT" ? height : points) = v;
            have_points = have_points || key == "POINTS";
            have_width = have_width || key == "WIDTH";
        } else if (key == "DATA") {
            if (rest.size() != 1) return make_error(at + "bad DATA line");
            data = std::string(rest[0]);
            if (data != "ascii" && data != "binary")
                return make_error(at + "PCD DATA " + data +
                                  " is not supported (ascii or binary; re-save it uncompressed)");
        } else {
            return make_error(at + (line_no == 1
                                        ? "not a PCD file"
                                        : "bad PCD header: unknown keyword '" + key + "'"));
        }
    }
    if (names.empty() || sizes.size() != names.size() || types.size() != names.size() ||
        (!counts.empty() && counts.size() != names.size()))
        return make_error(where + "bad PCD header: FIELDS, SIZE, TYPE and COUNT disagree");
    if (!have_points) {
        if (!have_width) return make_error(where + "bad PCD header: no POINTS or WIDTH");
        if (height != 0 && width > std::numeric_limits<std::uint64_t>::max() / height)
            return make_error(where + "bad PCD header: WIDTH × HEIGHT overflows");
        points = width * height;
    }
    std::vector<PcdField> fields;
    std::size_t stride = 0, values_per_point = 0;
    for (std::size_t i = 0; i < names.size(); ++i) {
        std::uint64_t size = 0, count = 1;
        std::optional<Scalar> t;
        if (!parse_count(sizes[i], size) || types[i].size() != 1 ||
            !(t = pcd_scalar(types[i][0], size)) ||
            (!counts.empty() && (!parse_count(counts[i], count) || count == 0 || count > 4096)))
            return make_error(where + "bad PCD header: field '" + std::string(names[i]) +
                              "' has an unsupported SIZE/TYPE/COUNT");
        fields.push_back(
            {std::string(names[i]), *t, count, data == "binary" ? stride : values_per_point});
        stride += size * count;
        values_per_point += count;
    }
    auto field = [&](std::string_view name) -> const PcdField* {
        for (const PcdField& f : fields)
            if (f.name == name) return &f;
        return nullptr;
    };
    const PcdField* xyz[6] = {field("x"),        field("y"),        field("z"),
                              field("normal_x"), field("normal_y"), field("normal_z")};
    if (!xyz[0] || !xyz[1] || !xyz[2]) return make_error(where + "PCD has no x, y, z fields");
    const int n_normal = (xyz[3] != nullptr) + (xyz[4] != nullptr) + (xyz[5] != nullptr);
    if (n_normal != 0 && n_normal != 3)
        return make_error(where + "PCD has some of normal_x, normal_y, normal_z, not all");

    RawScan out;
    std::array<double, 6> v{};
    if (data == "binary") {
        const std::size_t left = b.size() - pos;
        if (points > left / stride)
            return make_error(where + "truncated: " + std::to_string(points) + " points of " +
                              std::to_string(stride) + " bytes need " +
                              std::to_string(points * stride) + " bytes, " + std::to_string(left) +
                              " follow the header");
        for (std::uint64_t i = 0; i < points; ++i) {
            const unsigned char* p = b.data() + pos + i * stride;
            for (int k = 0; k < 3 + n_normal; ++k)
                v[k] = load_scalar(p + xyz[k]->offset, xyz[k]->type);
            out.points.emplace_back(v[0], v[1], v[2]);
            if (n_normal) out.normals.emplace_back(v[3], v[4], v[5]);
        }
        return out;
    }
    Values values(b, pos, false, line_no + 1);
    std::vector<double> row(values_per_point);
    for (std::uint64_t i = 0; i < points; ++i) {
        for (std::size_t f = 0; f < fields.size(); ++f)
            for (std::size_t c = 0; c < fields[f].count; ++c)
                values.read(Scalar::kF64, row[fields[f].offset + c]);
        if (!values.error.empty())
            return make_error(where + values.error + " (point " + std::to_string(i) + " of " +
                              std::to_string(points) + ")");
        for (int k = 0; k < 3 + n_normal; ++k) v[k] = row[xyz[k]->offset];
        out.points.emplace_back(v[0], v[1], v[2]);
        if (n_normal) out.normals.emplace_back(v[3], v[4], v[5]);
    }
    return out;
}

Result<SurfaceSamples> finish_scan(const RawScan& raw, const std::string& where) {
    const bool has_normals = !raw.normals.empty();
    SurfaceSamples s;
    for (std::size_t i = 0; i < raw.points.size(); ++i) {
        if (!raw.points[i].allFinite()) continue;
        if (has_normals) {
            const double len = raw.normals[i].norm();
            if (!(len > 0) || !std::isfinite(len)) continue;
            s.normals.push_back((raw.normals[i] / len).cast<float>());
        }
        s.points.push_back(raw.points[i].cast<float>());
    }
    if (s.points.size() < 3)
        return make_error(where + std::to_string(s.points.size()) + " valid points of " +
                          std::to_string(raw.points.size()) + ": not a surface");
    if (has_normals) return s;
    auto estimated = match::estimate_normals(s.points);
    if (!estimated) return make_error(where + estimated.error().message);
    if (estimated->points.size() < 3)
        return make_error(where + "no surface: the points lie on a line");
    return SurfaceSamples{std::move(estimated->points), std::move(estimated->normals)};
}

}  // namespace

Result<SurfaceSamples> read_mesh_samples(const fs::path& path, double spacing_mm) {
    const std::string where = path.string() + ": ";
    if (!(spacing_mm > 0) || !std::isfinite(spacing_mm))
        return make_error(where + "sampling spacing must be a positive number of mm");
    const std::string ext = lower(path.extension().string());
    if (ext != ".ply" && ext != ".stl")
        return make_error(where + "expected a mesh file .ply or .stl");
    auto bytes = detail::read_file_bytes(path);
    if (!bytes) return bytes.error();
    if (ext == ".stl") {
        auto mesh = read_stl(*bytes, where);
        if (!mesh) return mesh.error();
        return sample_mesh(*mesh, spacing_mm, where);
    }
    auto ply = read_ply(*bytes, where);
    if (!ply) return ply.error();
    if (ply->faces == 0) return make_error(where + "no triangles: the PLY has no faces");
    Mesh mesh{std::move(ply->vertices), std::move(ply->triangles), ply->faces};
    return sample_mesh(mesh, spacing_mm, where);
}

Result<SurfaceSamples> read_scan_samples(const fs::path& path) {
    const std::string where = path.string() + ": ";
    const std::string ext = lower(path.extension().string());
    if (ext != ".ply" && ext != ".pcd")
        return make_error(where + "expected a scan file .ply or .pcd");
    auto bytes = detail::read_file_bytes(path);
    if (!bytes) return bytes.error();
    if (ext == ".pcd") {
        auto raw = read_pcd(*bytes, where);
        if (!raw) return raw.error();
        return finish_scan(*raw, where);
    }
    auto ply = read_ply(*bytes, where);
    if (!ply) return ply.error();
    return finish_scan(RawScan{std::move(ply->vertices), std::move(ply->normals)}, where);
}

}  // namespace hotgauge::io
