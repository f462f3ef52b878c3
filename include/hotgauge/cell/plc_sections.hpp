#pragma once
// Readers of the PLC server and pyrometer sections, shared by config/plc.yaml (`hotgauge plc`)
// and config/hotgauged.yaml (the daemon): same keys, same checks, same messages.
#include <string>

#include "hotgauge/io/yaml_reader.hpp"
#include "hotgauge/plc/pyrometer.hpp"
#include "hotgauge/plc/server.hpp"

namespace hotgauge::cell {

// Fill `out` from the mapping `node` (keys as in docs/plc-modbus.md); `what` names the section
// in messages. Throw io::YamlError (inside YamlReader::guarded) naming file:line:key.
void read_plc_server(const io::YamlReader& y, const YAML::Node& node, const std::string& what,
                     plc::ServerConfig& out);
void read_pyrometer(const io::YamlReader& y, const YAML::Node& node, const std::string& what,
                    plc::PyrometerConfig& out);

// An integer key in [lo, hi], or `fallback` when absent.
int integer_in(const io::YamlReader& y, const YAML::Node& map, const std::string& what,
               const char* key, int lo, int hi, int fallback);

}  // namespace hotgauge::cell
