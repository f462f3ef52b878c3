#pragma once
// Private to the io module: a whole file as bytes, for the binary readers (model, mesh, scan).
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io::detail {

inline core::Result<std::vector<unsigned char>> read_file_bytes(const std::filesystem::path& path) {
    const std::string where = path.string() + ": ";
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) return core::make_error(where + "no such file");
    if (!std::filesystem::is_regular_file(path, ec))
        return core::make_error(where + "not a regular file");
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) return core::make_error(where + "cannot open: " + std::strerror(errno));
    std::vector<unsigned char> bytes;
    std::array<unsigned char, 1 << 16> buf;
    for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), f)) > 0;)
        bytes.insert(bytes.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(n));
    const bool failed = std::ferror(f) != 0;
    std::fclose(f);
    if (failed) return core::make_error(where + "read error");
    return bytes;
}

}  // namespace hotgauge::io::detail
