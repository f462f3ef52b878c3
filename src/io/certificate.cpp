#include "hotgauge/io/certificate.hpp"

#include <set>

#include "hotgauge/io/yaml_reader.hpp"

namespace hotgauge::io {
namespace {

constexpr const char* kFormat = "hotgauge-master-1";

core::CertifiedFeature read_feature(const YamlReader& y, const YAML::Node& n,
                                    const std::string& w) {
    y.expect_map(n, w, {"name", "value_mm", "u_mm", "tolerance_mm"});
    core::CertifiedFeature f;
    f.name = y.string(y.require(n, w, "name"), w + ".name");
    f.value_mm = y.number(y.require(n, w, "value_mm"), w + ".value_mm");
    f.u_mm = y.number(y.require(n, w, "u_mm"), w + ".u_mm");
    if (!(f.u_mm >= 0.0)) y.fail(n["u_mm"], w + ".u_mm: must not be negative");
    if (const YAML::Node t = n["tolerance_mm"]) {
        f.tolerance_mm = y.number(t, w + ".tolerance_mm");
        if (!(*f.tolerance_mm > 0.0)) y.fail(t, w + ".tolerance_mm: must be positive");
    }
    return f;
}

}  // namespace

core::Result<core::MasterCertificate> parse_certificate(std::string_view text,
                                                        const std::filesystem::path& file) {
    const YamlReader y(file.string(), text);
    return y.guarded<core::MasterCertificate>([&] {
        const YAML::Node root = y.load();
        const std::string w = "certificate";
        y.expect_map(root, w,
                     {"format", "master", "recipe", "certified_at", "certified_by", "temperature_c",
                      "tolerance_mm", "features"});
        const std::string format = y.string(y.require(root, w, "format"), "format");
        if (format != kFormat)
            y.fail(root["format"], "format: '" + format + "', expected " + kFormat);
        core::MasterCertificate c;
        c.master = y.string(y.require(root, w, "master"), "master");
        c.recipe = y.string(y.require(root, w, "recipe"), "recipe");
        c.certified_at = y.string(y.require(root, w, "certified_at"), "certified_at");
        c.certified_by = y.string(y.require(root, w, "certified_by"), "certified_by");
        c.temperature_c = y.number(y.require(root, w, "temperature_c"), "temperature_c");
        c.tolerance_mm = y.number(y.require(root, w, "tolerance_mm"), "tolerance_mm");
        if (!(c.tolerance_mm > 0.0)) y.fail(root["tolerance_mm"], "tolerance_mm: must be positive");
        const YAML::Node fs = y.require(root, w, "features");
        if (!fs.IsSequence() || fs.size() == 0) y.fail(fs, "features: expected a non-empty list");
        std::set<std::string> names;
        for (std::size_t i = 0; i < fs.size(); ++i) {
            const std::string wf = "features[" + std::to_string(i) + "]";
            core::CertifiedFeature f = read_feature(y, fs[i], wf);
            if (!names.insert(f.name).second)
                y.fail(fs[i], wf + ".name: duplicate feature '" + f.name + "'");
            c.features.push_back(std::move(f));
        }
        return c;
    });
}

core::Result<core::MasterCertificate> read_certificate(const std::filesystem::path& file) {
    return parse_file(file, parse_certificate);
}

}  // namespace hotgauge::io
