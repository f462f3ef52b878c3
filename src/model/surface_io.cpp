// Mesh and scan files as oriented surface samples (surface_io.hpp). The files are read by PCL's io
// (PLY: pcl::PLYReader, every PLY encoding; PCD: pcl::PCDReader, ascii, binary and
// binary_compressed) and by VTK's vtkSTLReader (STL, ascii and binary: what PCL's
// loadPolygonFileSTL wraps, called directly for its error text and to keep every triangle).
// What stays here is what they do not do: an error naming the file instead of PCL's -1 and its
// message on stderr, the checks they skip (face indices, finite vertices, a binary STL shorter
// than its triangle count), the sampling of a mesh by area and the cleanup of a scan.
#include "hotgauge/model/surface_io.hpp"

#include <pcl/PCLPointCloud2.h>
#include <pcl/PolygonMesh.h>
#include <pcl/console/print.h>
#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <vtkCallbackCommand.h>
#include <vtkCellArray.h>
#include <vtkCommand.h>
#include <vtkExecutive.h>
#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkSTLReader.h>
#include <vtkUnsignedCharArray.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <string_view>

#include "hotgauge/match/normals.hpp"

namespace hotgauge::model {
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

// PCL's readers return -1 for a missing file as for a bad one: the file is checked first, so
// that their failure means "PCL cannot read what is in it".
std::optional<std::string> file_problem(const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(path, ec)) return "no such file";
    if (!fs::is_regular_file(path, ec)) return "not a regular file";
    if (!std::ifstream(path, std::ios::binary))
        return std::string("cannot open: ") + std::strerror(errno);
    return std::nullopt;
}

// PCL prints its failures and the properties it skips on stderr; ours name the file instead.
void quiet_pcl() { pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS); }

// ---- clouds as PCL returns them ----

// Points (mesh vertices) and, when the file has them, normals (same length), unfiltered.
struct RawScan {
    std::vector<Eigen::Vector3d> points, normals;
};

template <class T>
double load(const std::uint8_t* p) {
    T v;
    std::memcpy(&v, p, sizeof v);
    return static_cast<double>(v);
}

// PCL's numeric field types: INT8 (1) to FLOAT64 (8), INT64 (9), UINT64 (10); not BOOL (11).
bool is_number(std::uint8_t datatype) {
    return datatype >= pcl::PCLPointField::INT8 && datatype <= pcl::PCLPointField::UINT64;
}

// The first value of field `f` of a point (host byte order: PCL swapped what the file had); the
// type is one is_number accepts.
double field_value(const pcl::PCLPointField& f, const std::uint8_t* point) {
    const std::uint8_t* p = point + f.offset;
    switch (f.datatype) {
        case pcl::PCLPointField::INT8:
            return load<std::int8_t>(p);
        case pcl::PCLPointField::UINT8:
            return load<std::uint8_t>(p);
        case pcl::PCLPointField::INT16:
            return load<std::int16_t>(p);
        case pcl::PCLPointField::UINT16:
            return load<std::uint16_t>(p);
        case pcl::PCLPointField::INT32:
            return load<std::int32_t>(p);
        case pcl::PCLPointField::UINT32:
            return load<std::uint32_t>(p);
        case pcl::PCLPointField::INT64:
            return load<std::int64_t>(p);
        case pcl::PCLPointField::UINT64:
            return load<std::uint64_t>(p);
        case pcl::PCLPointField::FLOAT32:
            return load<float>(p);
        case pcl::PCLPointField::FLOAT64:
            return load<double>(p);
        default:
            return 0;  // not reached: find_fields refuses the other types
    }
}

// x y z and, if present, the normal fields (PCL names PLY's nx ny nz normal_x ...).
struct Fields {
    std::array<const pcl::PCLPointField*, 3> xyz{}, normal{};
    bool has_normals = false;
};

Result<Fields> find_fields(const pcl::PCLPointCloud2& c, const std::string& where,
                           const std::string& format) {
    auto field = [&](std::string_view name) -> const pcl::PCLPointField* {
        for (const pcl::PCLPointField& f : c.fields)
            if (f.name == name) return &f;
        return nullptr;
    };
    Fields out;
    out.xyz = {field("x"), field("y"), field("z")};
    out.normal = {field("normal_x"), field("normal_y"), field("normal_z")};
    if (!out.xyz[0] || !out.xyz[1] || !out.xyz[2])
        return make_error(where + format + " has no x, y, z fields");
    const int n_normal =
        (out.normal[0] != nullptr) + (out.normal[1] != nullptr) + (out.normal[2] != nullptr);
    if (n_normal != 0 && n_normal != 3)
        return make_error(where + format + " has some of normal_x, normal_y, normal_z, not all");
    out.has_normals = n_normal == 3;
    for (const pcl::PCLPointField* f :
         {out.xyz[0], out.xyz[1], out.xyz[2], out.normal[0], out.normal[1], out.normal[2]}) {
        if (!f) continue;
        const std::size_t size = pcl::getFieldSize(f->datatype);
        if (!is_number(f->datatype) || f->count == 0 || f->offset + size > c.point_step)
            return make_error(where + format + " field '" + f->name +
                              "' has a type or size PCL does not read");
    }
    return out;
}

Result<RawScan> cloud_points(const pcl::PCLPointCloud2& c, const std::string& where,
                             const std::string& format) {
    auto fields = find_fields(c, where, format);
    if (!fields) return fields.error();
    const std::size_t n = std::size_t{c.width} * c.height;
    if (c.data.size() < n * c.point_step)
        return make_error(where + format + ": PCL returned " + std::to_string(c.data.size()) +
                          " bytes for " + std::to_string(n) + " points");
    RawScan out;
    out.points.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint8_t* p = c.data.data() + i * c.point_step;
        const auto& [x, y, z] = fields->xyz;
        out.points.emplace_back(field_value(*x, p), field_value(*y, p), field_value(*z, p));
        if (!fields->has_normals) continue;
        const auto& [nx, ny, nz] = fields->normal;
        out.normals.emplace_back(field_value(*nx, p), field_value(*ny, p), field_value(*nz, p));
    }
    return out;
}

// PCL throws now and then (pcl::IOException, std::bad_alloc on a huge count) where it mostly
// returns -1: both become "cannot read", with the exception's text when there is one.
template <class Read>
std::optional<std::string> pcl_failure(Read read) {
    try {
        if (read() != 0) return std::string();
    } catch (const std::exception& e) {
        return std::string(": ") + e.what();
    }
    return std::nullopt;
}

// ---- meshes ----

struct Mesh {
    std::vector<Eigen::Vector3d> vertices;
    std::vector<std::array<std::uint32_t, 3>> triangles;
};

// PCL checks neither the indices nor the numbers: an index past the vertices is an error, and
// so is a vertex a face uses that is not finite (PCL reads a word that is no number as NaN).
Result<Mesh> read_ply_mesh(const fs::path& path, const std::string& where) {
    pcl::PolygonMesh pm;
    pcl::PLYReader reader;
    if (auto failed = pcl_failure([&] { return reader.read(path.string(), pm); }))
        return make_error(where + "PCL cannot read it as PLY (not a PLY file, a bad header, or " +
                          "data truncated or malformed)" + *failed);
    auto vertices = cloud_points(pm.cloud, where, "PLY");
    if (!vertices) return vertices.error();
    if (pm.polygons.empty()) return make_error(where + "no triangles: the PLY has no faces");
    Mesh mesh{std::move(vertices->points), {}};
    const std::size_t n = mesh.vertices.size();
    for (std::size_t r = 0; r < pm.polygons.size(); ++r) {
        const auto& v = pm.polygons[r].vertices;
        for (const auto i : v) {  // pcl::index_t: signed
            if (i < 0 || static_cast<std::size_t>(i) >= n)
                return make_error(where + "face " + std::to_string(r) + ": vertex index " +
                                  std::to_string(i) + " out of range (" + std::to_string(n) +
                                  " vertices)");
            if (!mesh.vertices[i].allFinite())
                return make_error(where + "face " + std::to_string(r) + ": vertex " +
                                  std::to_string(i) + " is not finite");
        }
        for (std::size_t k = 2; k < v.size(); ++k)  // fan
            mesh.triangles.push_back({static_cast<std::uint32_t>(v[0]),
                                      static_cast<std::uint32_t>(v[k - 1]),
                                      static_cast<std::uint32_t>(v[k])});
    }
    if (mesh.triangles.empty())
        return make_error(where + "no triangles: no face has a vertex_indices list PCL reads " +
                          "(a list of uchar or uint count)");
    return mesh;
}

// VTK reports through vtkErrorMacro, "ERROR: In <source>, line <n>\nvtkSTLReader (0x…):
// STLReader: error while reading file <path> at line 3: Parse error. Expecting …". An observer
// on the reader receives it instead of stderr; what follows the path is kept.
struct VtkError {
    std::string path, text;
};

void keep_first_error(vtkObject*, unsigned long, void* client, void* call) {
    auto* kept = static_cast<VtkError*>(client);
    if (!kept->text.empty() || !call) return;
    std::string text = static_cast<const char*>(call);
    if (const auto at = text.find("): "); at != std::string::npos) text.erase(0, at + 3);
    if (const auto at = text.find(kept->path + " "); at != std::string::npos)
        text.erase(0, at + kept->path.size() + 1);
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
    kept->text = text.empty() ? "failed" : text;
}

// vtkSTLReader reads a binary STL to the end of the file whatever its count says (many writers
// write a bogus one), so a file cut short would lose triangles silently: refused here.
std::optional<std::string> stl_truncated(const fs::path& path) {
    std::array<unsigned char, 84> head{};
    std::ifstream f(path, std::ios::binary);
    if (!f.read(reinterpret_cast<char*>(head.data()), head.size())) return std::nullopt;
    const std::uint64_t n = std::uint64_t{head[80]} | std::uint64_t{head[81]} << 8 |
                            std::uint64_t{head[82]} << 16 | std::uint64_t{head[83]} << 24;
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(path, ec);
    if (ec || size >= 84 + 50 * n) return std::nullopt;
    return "truncated: binary STL of " + std::to_string(n) + " triangles needs " +
           std::to_string(84 + 50 * n) + " bytes, file has " + std::to_string(size);
}

// Merging off: every triangle keeps its own three points and none is dropped, as in the file.
Result<Mesh> read_stl_mesh(const fs::path& path, const std::string& where) {
    VtkError error{path.string(), {}};
    vtkNew<vtkCallbackCommand> on_error, mute;
    on_error->SetCallback(keep_first_error);
    on_error->SetClientData(&error);
    vtkNew<vtkSTLReader> reader;
    reader->AddObserver(vtkCommand::ErrorEvent, on_error);
    reader->AddObserver(vtkCommand::WarningEvent, mute);  // "File type not recognized; ..."
    // The pipeline's own "Algorithm vtkSTLReader returned failure for request": said above.
    reader->GetExecutive()->AddObserver(vtkCommand::ErrorEvent, mute);
    reader->MergingOff();
    reader->SetFileName(path.c_str());
    const bool ok = reader->GetExecutive()->Update() != 0;  // vtkAlgorithm::Update says nothing
    if (!ok || !error.text.empty())
        return make_error(
            where + "VTK cannot read it as STL: " + (error.text.empty() ? "failed" : error.text));
    if (reader->GetBinaryHeader())
        if (auto cut = stl_truncated(path)) return make_error(where + *cut);
    vtkPolyData* data = reader->GetOutput();
    Mesh mesh;
    vtkPoints* points = data->GetPoints();
    for (vtkIdType i = 0; points && i < points->GetNumberOfPoints(); ++i) {
        std::array<double, 3> p{};
        points->GetPoint(i, p.data());
        mesh.vertices.emplace_back(p[0], p[1], p[2]);
    }
    vtkCellArray* polys = data->GetPolys();
    for (vtkIdType c = 0; polys && c < polys->GetNumberOfCells(); ++c) {
        vtkIdType npts = 0;
        const vtkIdType* ids = nullptr;
        polys->GetCellAtId(c, npts, ids);
        if (npts == 3)
            mesh.triangles.push_back({static_cast<std::uint32_t>(ids[0]),
                                      static_cast<std::uint32_t>(ids[1]),
                                      static_cast<std::uint32_t>(ids[2])});
    }
    return mesh;
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

// The header first: a file without x, y, z is refused for that, and a failure of the body then
// says which data it was.
Result<RawScan> read_pcd_scan(const fs::path& path, const std::string& where) {
    pcl::PCDReader reader;
    pcl::PCLPointCloud2 header;
    Eigen::Vector4f origin;
    Eigen::Quaternionf orientation;
    int version = 0, data_type = 0;
    unsigned int data_idx = 0;
    if (auto failed = pcl_failure([&] {
            return reader.readHeader(path.string(), header, origin, orientation, version, data_type,
                                     data_idx);
        }))
        return make_error(where + "PCL cannot read it as PCD (not a PCD file, or a bad header)" +
                          *failed);
    if (auto fields = find_fields(header, where, "PCD"); !fields) return fields.error();
    pcl::PCLPointCloud2 cloud;
    if (auto failed = pcl_failure([&] { return reader.read(path.string(), cloud); })) {
        const char* kinds[] = {"ascii", "binary", "binary_compressed"};
        const std::string kind = data_type >= 0 && data_type <= 2 ? kinds[data_type] : "?";
        return make_error(where + "PCD " + kind + " data of " +
                          std::to_string(std::size_t{header.width} * header.height) +
                          " points: truncated or corrupt, PCL cannot read it" + *failed);
    }
    return cloud_points(cloud, where, "PCD");
}

Result<RawScan> read_ply_scan(const fs::path& path, const std::string& where) {
    pcl::PCLPointCloud2 cloud;
    pcl::PLYReader reader;
    if (auto failed = pcl_failure([&] { return reader.read(path.string(), cloud); }))
        return make_error(where + "PCL cannot read it as PLY (not a PLY file, a bad header, or " +
                          "data truncated or malformed)" + *failed);
    return cloud_points(cloud, where, "PLY");
}

// Points with a non-finite coordinate or normal (or a zero normal) are dropped; normals the
// file has are normalised, others estimated (match::estimate_normals).
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
    if (auto problem = file_problem(path)) return make_error(where + *problem);
    quiet_pcl();
    auto mesh = ext == ".stl" ? read_stl_mesh(path, where) : read_ply_mesh(path, where);
    if (!mesh) return mesh.error();
    return sample_mesh(*mesh, spacing_mm, where);
}

Result<SurfaceSamples> read_scan_samples(const fs::path& path) {
    const std::string where = path.string() + ": ";
    const std::string ext = lower(path.extension().string());
    if (ext != ".ply" && ext != ".pcd")
        return make_error(where + "expected a scan file .ply or .pcd");
    if (auto problem = file_problem(path)) return make_error(where + *problem);
    quiet_pcl();
    auto raw = ext == ".pcd" ? read_pcd_scan(path, where) : read_ply_scan(path, where);
    if (!raw) return raw.error();
    return finish_scan(*raw, where);
}

}  // namespace hotgauge::model
