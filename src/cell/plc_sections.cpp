#include "hotgauge/cell/plc_sections.hpp"

#include <map>

namespace hotgauge::cell {

int integer_in(const io::YamlReader& y, const YAML::Node& map, const std::string& what,
               const char* key, int lo, int hi, int fallback) {
    if (!map[key]) return fallback;
    const auto v = y.integer(map[key], what + "." + key);
    if (v < lo || v > hi)
        y.fail(map[key],
               what + "." + key + ": must be in " + std::to_string(lo) + ".." + std::to_string(hi));
    return static_cast<int>(v);
}

namespace {

// integer_in with the reader bound: int_in(map, what, key, lo, hi, fallback).
auto bound_integer_in(const io::YamlReader& y) {
    return [&y](const YAML::Node& map, const std::string& w, const char* key, int lo, int hi,
                int fallback) { return integer_in(y, map, w, key, lo, hi, fallback); };
}

}  // namespace

void read_plc_server(const io::YamlReader& y, const YAML::Node& s, const std::string& what,
                     plc::ServerConfig& out) {
    const auto int_in = bound_integer_in(y);
    const std::string w = what;
    y.expect_map(s, w,
                 {"bind_address", "port", "unit_ids", "allowed_clients", "max_connections",
                  "idle_timeout_ms", "heartbeat_period_ms", "word_order"});
    auto& o = out;
    if (s["bind_address"]) o.bind_address = y.string(s["bind_address"], w + ".bind_address");
    o.port = int_in(s, w, "port", 0, 65535, o.port);
    if (const YAML::Node u = s["unit_ids"]) {
        if (!u.IsSequence() || u.size() == 0) y.fail(u, w + ".unit_ids: expected a non-empty list");
        o.unit_ids.clear();
        for (std::size_t i = 0; i < u.size(); ++i) {
            const auto id = y.integer(u[i], w + ".unit_ids");
            if (id < 0 || id > 255) y.fail(u[i], w + ".unit_ids: must be in 0..255");
            o.unit_ids.push_back(static_cast<int>(id));
        }
    }
    if (const YAML::Node al = s["allowed_clients"]; al && !(al.IsSequence() && al.size() == 0))
        o.allowed_clients = y.strings(al, w + ".allowed_clients");  // [] is anyone
    o.max_connections = int_in(s, w, "max_connections", 1, 1000, o.max_connections);
    o.idle_timeout_ms = int_in(s, w, "idle_timeout_ms", 0, 86400000, o.idle_timeout_ms);
    o.heartbeat_period_ms = int_in(s, w, "heartbeat_period_ms", 10, 60000, o.heartbeat_period_ms);
    if (s["word_order"]) {
        const auto order = plc::parse_word_order(y.string(s["word_order"], w));
        if (!order) y.fail(s["word_order"], w + ".word_order: must be big or little");
        o.word_order = *order;
    }
    if (auto ok = plc::check_config(o); !ok) y.fail(s, w + ": " + ok.error().message);
}

void read_pyrometer(const io::YamlReader& y, const YAML::Node& p, const std::string& what,
                    plc::PyrometerConfig& out) {
    const auto int_in = bound_integer_in(y);
    const std::string w = what;
    y.expect_map(p, w,
                 {"device", "baud", "parity", "data_bits", "stop_bits", "slave_id", "register",
                  "function", "signed", "scale", "offset_c", "poll_period_ms",
                  "response_timeout_ms", "stale_after_ms", "min_valid_c", "max_valid_c"});
    auto& o = out;
    if (p["device"]) o.serial.device = y.string(p["device"], w + ".device");
    o.serial.baud = int_in(p, w, "baud", 300, 4000000, o.serial.baud);
    if (p["parity"]) {
        const std::string par = y.string(p["parity"], w + ".parity");
        const std::map<std::string, char> names = {{"none", 'N'}, {"even", 'E'}, {"odd", 'O'}};
        if (!names.count(par)) y.fail(p["parity"], w + ".parity: must be none, even or odd");
        o.serial.parity = names.at(par);
    }
    o.serial.data_bits = int_in(p, w, "data_bits", 7, 8, o.serial.data_bits);
    o.serial.stop_bits = int_in(p, w, "stop_bits", 1, 2, o.serial.stop_bits);
    o.serial.slave_id = int_in(p, w, "slave_id", 1, 247, o.serial.slave_id);
    o.register_address = int_in(p, w, "register", 0, 65535, o.register_address);
    if (p["function"]) {
        const std::string f = y.string(p["function"], w + ".function");
        if (f != "holding" && f != "input")
            y.fail(p["function"], w + ".function: must be holding (03) or input (04)");
        o.input_register = f == "input";
    }
    if (p["signed"]) o.signed_value = y.boolean(p["signed"], w + ".signed");
    o.scale = y.number_or(p, w, "scale", o.scale);
    if (o.scale == 0.0) y.fail(p["scale"], w + ".scale: must be non-zero");
    o.offset_c = y.number_or(p, w, "offset_c", o.offset_c);
    o.poll_period_ms = int_in(p, w, "poll_period_ms", 10, 60000, o.poll_period_ms);
    o.response_timeout_ms = int_in(p, w, "response_timeout_ms", 1, 10000, o.response_timeout_ms);
    o.stale_after_ms = int_in(p, w, "stale_after_ms", 10, 600000, o.stale_after_ms);
    o.min_valid_c = y.number_or(p, w, "min_valid_c", o.min_valid_c);
    o.max_valid_c = y.number_or(p, w, "max_valid_c", o.max_valid_c);
    if (auto ok = plc::check_config(o); !ok) y.fail(p, w + ": " + ok.error().message);
}

}  // namespace hotgauge::cell
