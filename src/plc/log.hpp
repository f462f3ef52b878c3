#pragma once
// Private to the plc module: its named logger (core/log.hpp).
#include "hotgauge/core/log.hpp"

namespace hotgauge::plc::detail {

inline spdlog::logger& log() {
    static const std::shared_ptr<spdlog::logger> logger = core::module_logger("plc");
    return *logger;
}

}  // namespace hotgauge::plc::detail
