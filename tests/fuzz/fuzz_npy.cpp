// Fuzzes io::parse_npy (recording arrays, NumPy .npy 1.0). Input: the whole file, named
// fuzz/in.npy. Asserts: no crash, sanitizer report or exception; an error names the file; an
// accepted array holds exactly the bytes its shape and dtype need, and npy_bytes + parse_npy
// gives it back unchanged (the reader accepts what the writer writes, and nothing is lost).
#include <algorithm>

#include "fuzz_util.hpp"
#include "hotgauge/io/npy.hpp"

using namespace hotgauge;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static const auto in = fuzz::kDir / "in.npy";
    auto arr = fuzz::no_throw("parse_npy", [&] { return io::parse_npy({data, size}, in); });
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

    auto written = fuzz::no_throw("npy_bytes", [&] {
        return io::npy_bytes(in, arr->descr, arr->shape, arr->data.data(), arr->data.size());
    });
    fuzz::check(written.ok(), "npy_bytes refused an array parse_npy accepted: " +
                                  (written ? std::string() : written.error().message));
    auto again = fuzz::no_throw("parse_npy",
                                [&] { return io::parse_npy(io::Bytes::view(*written).data, in); });
    fuzz::check(again.ok(), "parse_npy refused what npy_bytes wrote: " +
                                (again ? std::string() : again.error().message));
    fuzz::check(again->descr == arr->descr && again->shape == arr->shape &&
                    again->data == arr->data && !again->fortran_order,
                "round trip changed the array");
    return 0;
}
