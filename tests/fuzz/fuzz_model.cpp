// Fuzzes model::parse_model (PPF model files .hgm, docs/model-file.md), the file named fuzz/in.hgm.
//
// Input: one flag byte, then the file. The file ends in a checksum that random edits would
// almost never match, so when the flag's bit 0 is set the harness reseals the file as a writer
// would (body size = bytes between header and checksum, FNV-1a 64 over the rest) and mutations
// reach the body's counts and the model's validation; with bit 0 clear the file is taken as is.
//
// Asserts: no crash, sanitizer report or exception; no allocation beyond -malloc_limit_mb (a
// count larger than the file must be an error, not a huge vector); an error names the file; a
// model it accepts is valid, model_bytes accepts it and gives back the same bytes (the format's
// bit-exact round trip).
#include <vector>

#include "fuzz_util.hpp"
#include "hotgauge/io/checksum.hpp"
#include "hotgauge/model/model_io.hpp"

using namespace hotgauge;

namespace {

constexpr std::size_t kHeader = 8 + 4 + 8;  // magic, version, body size
constexpr std::size_t kChecksum = 8;

void put_le64(std::uint8_t* p, std::uint64_t v) {
    for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    std::vector<std::uint8_t> file(data + 1, data + size);
    if ((data[0] & 1) && file.size() >= kHeader + kChecksum) {
        const std::size_t end = file.size() - kChecksum;
        put_le64(file.data() + 12, end - kHeader);
        put_le64(file.data() + end, io::fnv1a64(file.data(), end));
    }
    static const auto path = fuzz::kDir / "in.hgm";
    auto m = fuzz::no_throw("parse_model", [&] { return model::parse_model(file, path); });
    if (!m) {
        fuzz::check_error_names(m.error(), path);
        return 0;
    }
    fuzz::check(m->validate().ok(), "parse_model returned an invalid model");
    auto written = fuzz::no_throw("model_bytes", [&] { return model::model_bytes(*m, path); });
    fuzz::check(written.ok(), "model_bytes refused a model parse_model accepted");
    fuzz::check(*written == file, "model_bytes gave other bytes than the file read");
    return 0;
}
