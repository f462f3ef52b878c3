#pragma once
// NumPy .npy files, format version 1.0 (the version recording format v1 prescribes).
#include <cstdint>
#include <filesystem>
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

// The header only (`data` stays empty), checked against the file's size: a reader checks
// shapes before it allocates anything, then reads the data straight into its own buffer.
core::Result<NpyArray> read_npy_header(const std::filesystem::path& path);
// The data of `header` (from read_npy_header of the same file) into `out`, header.data_bytes long.
core::Result<void> read_npy_data(const std::filesystem::path& path, const NpyArray& header,
                                 void* out);

// Writes a .npy v1.0 file in C order. `descr` is a NumPy dtype string ("<f4", "<i8", "<f8").
core::Result<void> write_npy(const std::filesystem::path& path, const std::string& descr,
                             const std::vector<std::int64_t>& shape, const void* data,
                             std::size_t bytes);

}  // namespace hotgauge::io
