// The daemon's setup (daemon_state.hpp): the configuration, calibration, recipes, models and
// masters loaded and checked together, so that a reload either takes all of them or none.
#include <algorithm>
#include <sstream>

#include "daemon_state.hpp"
#include "hotgauge/io/certificate.hpp"
#include "hotgauge/io/recipe.hpp"

namespace hotgauge::cell {
namespace {

// Setup::result_hash: per slot, the files that decide its results and the software version.
std::map<int, std::string> result_hashes(const Setup& s) {
    std::map<int, std::string> out;
    for (const auto& [slot, recipe_file] : s.config.recipes) {
        std::vector<std::filesystem::path> files{s.config.file, s.config.calibration_file,
                                                 recipe_file};
        for (const auto* more : {&s.config.models, &s.config.masters})
            if (auto it = more->find(slot); it != more->end()) files.push_back(it->second);
        if (const auto& mesh = s.recipes.at(slot).mesh_file; !mesh.empty()) files.push_back(mesh);
        out[slot] = files_hash(files, HOTGAUGE_VERSION);
    }
    return out;
}

}  // namespace

core::Result<std::shared_ptr<const Setup>> load_setup(const fs::path& config_file) {
    auto config = read_daemon_config(config_file);
    if (!config) return config.error();
    auto s = std::make_shared<Setup>();
    s->config = std::move(*config);
    auto calibration = calib::read_calibration(s->config.calibration_file);
    if (!calibration) return calibration.error();
    s->calibration = std::move(*calibration);
    for (const auto& name : s->config.faces)
        if (!s->calibration.face(name))
            return core::make_error(s->config.file.string() + ": faces: '" + name +
                                    "' is not a face of " + s->config.calibration_file.string());
    for (const auto& [slot, path] : s->config.recipes) {
        auto recipe = io::read_recipe(path);
        if (!recipe) return recipe.error();
        if (auto ok = check_recipe_for_cell(*recipe, path, &s->config.faces); !ok)
            return core::make_error("recipe slot " + std::to_string(slot) + ": " +
                                    ok.error().message);
        const auto file = s->config.models.find(slot);
        auto model = pipeline::part_model(
            *recipe, {.model_file = file == s->config.models.end() ? fs::path() : file->second});
        if (!model)
            return core::make_error("recipe slot " + std::to_string(slot) + ": " +
                                    model.error().message);
        s->models.emplace(slot, std::make_shared<const match::Model>(std::move(*model)));
        s->recipes.emplace(slot, std::move(*recipe));
    }
    for (const auto& [slot, path] : s->config.masters) {
        auto cert = io::read_certificate(path);
        if (!cert) return cert.error();
        if (cert->recipe != s->recipes.at(slot).name)
            return core::make_error(path.string() + ": master of recipe '" + cert->recipe +
                                    "', recipe slot " + std::to_string(slot) + " is '" +
                                    s->recipes.at(slot).name + "'");
        const core::Recipe& recipe = s->recipes.at(slot);
        for (const auto& cf : cert->features)
            if (std::none_of(recipe.features.begin(), recipe.features.end(),
                             [&](const auto& f) { return f.name == cf.name; }))
                return core::make_error(path.string() + ": certified feature '" + cf.name +
                                        "' is not in recipe " + recipe.name + " (slot " +
                                        std::to_string(slot) + ")");
        s->masters.emplace(slot, std::move(*cert));
    }
    s->result_hash = result_hashes(*s);
    for (const auto& [slot, file] : s->config.recipes)
        s->recipe_revision[slot] = recipe_revision(file);
    auto tri = calib::triangulation(s->calibration.sensor);
    if (!tri)
        return core::make_error(s->config.calibration_file.string() + ": " + tri.error().message);
    s->triangulation.emplace(std::move(*tri));
    auto table = acquire::ExposureTable::create(s->config.acquisition.exposure_table);
    if (!table)
        return core::make_error(s->config.file.string() +
                                ": camera.exposure_table: " + table.error().message);
    s->exposure = std::move(*table);
    return std::shared_ptr<const Setup>(std::move(s));
}

std::string describe(const Setup& s) {
    std::ostringstream o;
    const auto& c = s.config;
    o << "config " << c.file.string() << " (hash " << c.hash << ")\n";
    const calib::Calibration& cal = s.calibration;
    o << "  calibration " << c.calibration_file.string() << ": " << cal.method << ", "
      << cal.calibrated_at << " from " << cal.source
      << (cal.measured() ? "" : " (design values, NOT MEASURED: commission the cell)") << "\n";
    o << "  faces";
    for (const auto& f : c.faces) o << " " << f;
    o << "\n";
    for (const auto& [slot, r] : s.recipes) {
        o << "  recipe slot " << slot << ": " << r.name << " (" << r.features.size()
          << " features), model " << s.models.at(slot)->refs.size() << " references";
        if (auto m = s.masters.find(slot); m != s.masters.end())
            o << "; master " << m->second.master << " (certified " << m->second.certified_at << ", "
              << m->second.features.size() << " features)";
        o << "\n";
    }
    o << "  camera " << c.acquisition.camera.id << " (" << c.acquisition.scan.frame_mode
      << " mode), " << c.acquisition.scan_s << " s per face\n";
    o << "  accelerometer "
      << (c.accelerometer ? (c.accelerometer->kind == accel::AccelSourceKind::udp
                                 ? "udp " + c.accelerometer->udp.bind
                                 : "iio " + c.accelerometer->iio.device_dir.string())
                          : std::string("none (no compensation)"))
      << "\n";
    o << "  axis " << c.axis.kind << (c.axis.kind == "modbus" ? " " + c.axis.address : "") << "\n";
    o << "  PLC Modbus TCP " << c.plc.bind_address << ":" << c.plc.port << "\n";
    o << "  pyrometer " << (c.pyrometer ? c.pyrometer->serial.device : "none") << "\n";
    o << "  results " << c.results.dir.string() << ", archive " << c.archive.dir.string() << "\n";
    return o.str();
}

}  // namespace hotgauge::cell
