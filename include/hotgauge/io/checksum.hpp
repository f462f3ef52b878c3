#pragma once
// FNV-1a (64 bit): the checksum of model files (docs/model-file.md) and the hash that ties every
// result to the daemon configuration that produced it (docs/operations.md).
#include <cstddef>
#include <cstdint>

namespace hotgauge::io {

inline std::uint64_t fnv1a64(const unsigned char* data, std::size_t n) {
    std::uint64_t h = 0xcbf29ce484222325ull;
    for (std::size_t i = 0; i < n; ++i) {
        h ^= data[i];
        h *= 0x100000001b3ull;
    }
    return h;
}

}  // namespace hotgauge::io
