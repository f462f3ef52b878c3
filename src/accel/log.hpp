#pragma once
// Private to the accel module: its named logger (core/log.hpp).
#include "hotgauge/core/log.hpp"

namespace hotgauge::accel::detail {

inline spdlog::logger& log() {
    static const std::shared_ptr<spdlog::logger> logger = core::module_logger("accel");
    return *logger;
}

}  // namespace hotgauge::accel::detail
