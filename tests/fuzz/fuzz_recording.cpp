// Fuzzes io::read_recording (recording format v1, a folder of YAML and .npy files) on files in
// memory: the folder is named fuzz/in, its files are the input's pieces.
//
// Input: a small container, so that one input is a whole recording and mutations reach the deep
// checks: pieces separated by the line "%%hotgauge%%" (kSep below). Piece 0 is part.yaml; pieces
// 1-6 are face folder a's face.yaml, profiles.npy, profile_times.npy, profile_positions.npy,
// accel.npy, accel_times.npy, and pieces 7-12 the same for face b (further pieces are ignored).
// A piece that is absent (fewer separators) is a missing file, an empty piece an empty file.
// The seeds (make_seeds.py) list faces [a] or [a, b].
//
// Asserts: no crash, sanitizer report or exception; an error names a file under the folder; a
// recording it accepts is accepted by recording_files (write_recording's files: the writer
// refuses only what the reader rejects) and reads back identical from them.
#include <cstring>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "fuzz_util.hpp"
#include "hotgauge/io/recording_io.hpp"

using namespace hotgauge;
namespace fs = std::filesystem;

namespace {

constexpr std::string_view kSep = "\n%%hotgauge%%\n";
constexpr const char* kFaceFiles[] = {"face.yaml",         "profiles.npy",
                                      "profile_times.npy", "profile_positions.npy",
                                      "accel.npy",         "accel_times.npy"};

std::vector<std::string_view> split(std::string_view in) {
    std::vector<std::string_view> pieces;
    for (;;) {
        const auto at = in.find(kSep);
        pieces.push_back(in.substr(0, at));
        if (at == std::string_view::npos) return pieces;
        in.remove_prefix(at + kSep.size());
    }
}

template <class T>
bool same_bytes(const std::vector<T>& a, const std::vector<T>& b) {  // NaN payloads included
    return a.size() == b.size() &&
           (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

bool same_face(const core::FaceScan& a, const core::FaceScan& b) {
    return a.name == b.name && a.T_world_camera.matrix() == b.T_world_camera.matrix() &&
           a.scan_direction == b.scan_direction && a.R_camera_accel == b.R_camera_accel &&
           a.travel_scale == b.travel_scale && a.clock_offset_ns == b.clock_offset_ns &&
           a.width == b.width && same_bytes(a.profiles_mm, b.profiles_mm) &&
           a.profile_times_ns == b.profile_times_ns &&
           same_bytes(a.profile_positions_mm, b.profile_positions_mm) &&
           same_bytes(a.accel_mps2, b.accel_mps2) && a.accel_times_ns == b.accel_times_ns;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const fs::path dir = fuzz::kDir / "in";
    static const std::vector<fs::path> slots = [] {
        std::vector<fs::path> s = {dir / "part.yaml"};
        for (const char* face : {"a", "b"})
            for (const char* file : kFaceFiles) s.push_back(dir / face / file);
        return s;
    }();
    const auto pieces = split(fuzz::text_of(data, size));
    const io::FileSource files = [&](const fs::path& path) -> core::Result<io::FileParts> {
        for (std::size_t i = 0; i < slots.size() && i < pieces.size(); ++i)
            if (path == slots[i]) return io::FileParts::of(io::Bytes::view(pieces[i]));
        return core::make_error(path.string() + ": missing");
    };
    auto rec = fuzz::no_throw("read_recording", [&] { return io::read_recording(dir, files); });
    if (!rec) {
        fuzz::check_error_names(rec.error(), dir);
        return 0;
    }
    fuzz::check(!rec->faces.empty(), "a recording without faces was accepted");

    const fs::path copy = fuzz::kDir / "copy";
    std::vector<std::pair<fs::path, std::string>> written;
    auto ok = fuzz::no_throw("recording_files", [&] {
        return io::recording_files(*rec, copy, [&](const fs::path& p, std::string&& bytes) {
            written.emplace_back(p, std::move(bytes));
            return core::Result<void>{};
        });
    });
    fuzz::check(ok.ok(), "recording_files refused a recording read_recording accepted: " +
                             (ok ? std::string() : ok.error().message));
    const io::FileSource written_files = [&](const fs::path& path) -> core::Result<io::FileParts> {
        for (const auto& [p, bytes] : written)
            if (p == path) return io::FileParts::of(io::Bytes::view(bytes));
        return core::make_error(path.string() + ": missing");
    };
    auto again =
        fuzz::no_throw("read_recording", [&] { return io::read_recording(copy, written_files); });
    fuzz::check(again.ok(), "read_recording refused what recording_files wrote: " +
                                (again ? std::string() : again.error().message));
    bool same =
        again->part_id == rec->part_id && again->recipe == rec->recipe &&
        again->captured_at == rec->captured_at && again->temperature_c == rec->temperature_c &&
        again->faces.size() == rec->faces.size() && again->warnings.size() == rec->warnings.size();
    for (std::size_t i = 0; same && i < rec->faces.size(); ++i)
        same = same_face(rec->faces[i], again->faces[i]);
    fuzz::check(same, "the recording changed in a recording_files + read_recording round trip");
    return 0;
}
