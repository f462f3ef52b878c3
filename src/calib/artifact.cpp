#include "hotgauge/calib/artifact.hpp"

#include <set>

#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::calib {
namespace {

using io::YamlReader;

Eigen::Vector3d vec3(const YamlReader& y, const YAML::Node& map, const std::string& what,
                     const char* key) {
    const auto v = y.numbers(y.require(map, what, key), what + "." + key, 3);
    return {v[0], v[1], v[2]};
}

ArtifactSphere read_sphere(const YamlReader& y, const YAML::Node& n, const std::string& w) {
    y.expect_map(n, w, {"name", "center_mm", "diameter_mm"});
    ArtifactSphere s;
    s.name = y.string(y.require(n, w, "name"), w + ".name");
    s.center_mm = vec3(y, n, w, "center_mm");
    s.diameter_mm = y.number(y.require(n, w, "diameter_mm"), w + ".diameter_mm");
    if (!(s.diameter_mm > 0.0)) y.fail(n["diameter_mm"], w + ".diameter_mm: must be positive");
    return s;
}

ArtifactPlane read_plane(const YamlReader& y, const YAML::Node& n, const std::string& w) {
    y.expect_map(n, w, {"name", "point_mm", "normal"});
    ArtifactPlane p;
    p.name = y.string(y.require(n, w, "name"), w + ".name");
    p.point_mm = vec3(y, n, w, "point_mm");
    const Eigen::Vector3d normal = vec3(y, n, w, "normal");
    if (!(normal.norm() > 1e-9)) y.fail(n["normal"], w + ".normal: must not be zero");
    p.normal = normal.normalized();
    return p;
}

}  // namespace

std::size_t surface_count(const Artifact& a) { return a.spheres.size() + a.planes.size(); }

const std::string& surface_name(const Artifact& a, std::size_t j) {
    return j < a.spheres.size() ? a.spheres[j].name : a.planes[j - a.spheres.size()].name;
}

double surface_distance(const Artifact& a, std::size_t j, const Eigen::Vector3d& p,
                        Eigen::Vector3d& n) {
    if (j < a.spheres.size()) {
        const Eigen::Vector3d d = p - a.spheres[j].center_mm;
        const double r = d.norm();
        n = d / r;
        return r - 0.5 * a.spheres[j].diameter_mm;
    }
    const ArtifactPlane& pl = a.planes[j - a.spheres.size()];
    n = pl.normal;
    return pl.normal.dot(p - pl.point_mm);
}

core::Result<Artifact> parse_artifact(std::string_view text, const std::filesystem::path& file) {
    const YamlReader y(file.string(), text);
    return y.guarded<Artifact>([&] {
        const YAML::Node root = y.load();
        y.expect_map(root, "artifact file", {"artifact", "spheres", "planes"});
        Artifact a;
        a.name = y.string(y.require(root, "artifact file", "artifact"), "artifact");
        const YAML::Node spheres = y.require(root, "artifact file", "spheres");
        if (!spheres.IsSequence() || spheres.size() < 3)
            y.fail(spheres, "spheres: expected a list of at least 3 spheres");
        std::set<std::string> names;
        for (std::size_t i = 0; i < spheres.size(); ++i) {
            const std::string w = "spheres[" + std::to_string(i) + "]";
            ArtifactSphere s = read_sphere(y, spheres[i], w);
            if (!names.insert(s.name).second)
                y.fail(spheres[i], w + ".name: duplicate name '" + s.name + "'");
            for (const auto& o : a.spheres)
                if ((o.center_mm - s.center_mm).norm() < 0.5 * (o.diameter_mm + s.diameter_mm))
                    y.fail(spheres[i], w + ": sphere " + s.name + " overlaps " + o.name);
            a.spheres.push_back(std::move(s));
        }
        if (const YAML::Node planes = root["planes"]) {
            if (!planes.IsSequence()) y.fail(planes, "planes: expected a list");
            for (std::size_t i = 0; i < planes.size(); ++i) {
                const std::string w = "planes[" + std::to_string(i) + "]";
                ArtifactPlane p = read_plane(y, planes[i], w);
                if (!names.insert(p.name).second)
                    y.fail(planes[i], w + ".name: duplicate name '" + p.name + "'");
                a.planes.push_back(std::move(p));
            }
        }
        return a;
    });
}

core::Result<Artifact> read_artifact(const std::filesystem::path& file) {
    return io::parse_file(file, parse_artifact);
}

}  // namespace hotgauge::calib
