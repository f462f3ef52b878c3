#pragma once
// NumPy .npy files, format version 1.0 (the version recording format v1 prescribes).
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::io {

struct NpyArray {
    std::string descr;  // dtype string as in the header, e.g. "<f4"
    bool fortran_order = false;
    std::vector<std::int64_t> shape;
    std::vector<unsigned char> data;  // raw bytes, exactly product(shape) * itemsize
    std::uint64_t data_offset = 0;    // where the data starts in the file
    std::uint64_t data_bytes = 0;     // product(shape) * itemsize
};

// Reads a .npy file; an Error names the file and what is wrong (missing, not .npy, unsupported
// version, malformed header, truncated data).
core::Result<NpyArray> read_npy(const std::filesystem::path& path);
// The same on the file's bytes, `path` naming it in errors.
core::Result<NpyArray> parse_npy(std::span<const unsigned char> file,
                                 const std::filesystem::path& path);
// The header only (`data` stays empty) from the file's first bytes (`file`: at least
// min(file_size, kNpyHeaderMax) of them), checked against the file's size: a reader checks
// shapes before it allocates anything, then reads the data (data_bytes at data_offset) straight
// into its own buffer.
inline constexpr std::size_t kNpyHeaderMax = 10 + 0xFFFF;  // prelude + the longest header
core::Result<NpyArray> parse_npy_header(std::span<const unsigned char> file,
                                        const std::filesystem::path& path, std::uint64_t file_size);

// Writes a .npy v1.0 file in C order. `descr` is a NumPy dtype string ("<f4", "<i8", "<f8").
core::Result<void> write_npy(const std::filesystem::path& path, const std::string& descr,
                             const std::vector<std::int64_t>& shape, const void* data,
                             std::size_t bytes);
// What write_npy writes, as bytes (`path` names the array in errors).
core::Result<std::string> npy_bytes(const std::filesystem::path& path, const std::string& descr,
                                    const std::vector<std::int64_t>& shape, const void* data,
                                    std::size_t bytes);

}  // namespace hotgauge::io
