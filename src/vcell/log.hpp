#pragma once
// Private to the vcell module: its named logger (core/log.hpp).
#include "hotgauge/core/log.hpp"

namespace hotgauge::vcell::detail {

inline spdlog::logger& log() {
    static const std::shared_ptr<spdlog::logger> logger = core::module_logger("vcell");
    return *logger;
}

}  // namespace hotgauge::vcell::detail
