#pragma once
// PPF model files (`.hgm`, docs/model-file.md): a match::Model saved by `hotgauge model build`
// so that the daemon starts without rebuilding the table. Binary, little-endian, versioned,
// checksummed; a round trip is bit-exact.
#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "hotgauge/core/result.hpp"
#include "hotgauge/match/model.hpp"

namespace hotgauge::model {

inline constexpr std::uint32_t kModelFormatVersion = 2;

// Refuses a model that fails model.validate(); writes FILE.tmp, then renames it over `path`, so
// a reader never sees a half-written file.
core::Result<void> write_model(const match::Model& model, const std::filesystem::path& path);
// What write_model writes, as bytes (`path` names the model in errors).
core::Result<std::vector<unsigned char>> model_bytes(const match::Model& model,
                                                     const std::filesystem::path& path);

// Every failure (not a model file, another format version, truncated, checksum mismatch, counts
// larger than the file, invalid model) is an Error naming the file; garbage never crashes.
core::Result<match::Model> read_model(const std::filesystem::path& path);
// The same on the file's bytes, `path` naming it in errors.
core::Result<match::Model> parse_model(std::span<const unsigned char> file,
                                       const std::filesystem::path& path);

}  // namespace hotgauge::model
