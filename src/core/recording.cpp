#include "hotgauge/core/recording.hpp"

#include <cstdio>

namespace hotgauge::core {

std::string describe(const std::string& face, const UntrustedProfiles& u) {
    char b[160];
    std::snprintf(b, sizeof b, "%s profiles %lld–%lld (%.3f–%.3f s): ", face.c_str(),
                  static_cast<long long>(u.first), static_cast<long long>(u.last), u.t0_s, u.t1_s);
    return b + u.cause;
}

}  // namespace hotgauge::core
