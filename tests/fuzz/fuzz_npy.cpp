// Fuzzes io::read_npy (recording arrays, NumPy .npy 1.0). Input: the whole file.
// Asserts: no crash, sanitizer report or exception; an error names the file; an accepted array
// holds exactly the bytes its shape and dtype need, and write_npy + read_npy gives it back
// unchanged (the reader accepts what the writer writes, and nothing is lost on the way).
#include <algorithm>

#include "fuzz_util.hpp"
#include "hotgauge/io/npy.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const auto& dir = fuzz::scratch_dir("npy");
    const auto in = dir / "in.npy";
    fuzz::write_file(in, data, size);
    auto arr = fuzz::no_throw("read_npy", [&] { return io::read_npy(in); });
    if (!arr) {
        fuzz::check_error_names(arr.error(), in);
        return 0;
    }
    std::uint64_t items = 1;
    for (auto d : arr->shape) {
        fuzz::check(d >= 0, "negative dimension accepted");
        items *= static_cast<std::uint64_t>(d);
    }
    fuzz::check(items == 0 ? arr->data.empty() : arr->data.size() % items == 0,
                "data size is not a multiple of the item count");
    if (arr->fortran_order) return 0;  // write_npy writes C order only

    const auto out = dir / "out.npy";
    auto written = fuzz::no_throw("write_npy", [&] {
        return io::write_npy(out, arr->descr, arr->shape, arr->data.data(), arr->data.size());
    });
    fuzz::check(written.ok(), "write_npy refused an array read_npy accepted: " +
                                  (written ? std::string() : written.error().message));
    auto again = fuzz::no_throw("read_npy", [&] { return io::read_npy(out); });
    fuzz::check(again.ok(), "read_npy refused what write_npy wrote: " +
                                (again ? std::string() : again.error().message));
    fuzz::check(again->descr == arr->descr && again->shape == arr->shape &&
                    again->data == arr->data && !again->fortran_order,
                "round trip changed the array");
    return 0;
}
