// main() for the libFuzzer harnesses in builds without libFuzzer: make test's GCC builds, where
// every harness runs as the ctest fuzz_replay_<harness> (label unit, so under ASan/UBSan too).
// Each corpus file is fed as it is, then deterministic variants of it (a byte flipped, set to an
// edge value, a run cut out, repeated or inserted, the tail cut off): `--mutants` in all, shared
// evenly by the files, so that a corpus that grows with every `make fuzz` does not make the
// replay longer. Every regression input in the corpus therefore runs in every make test, and
// every harness sees damaged input there; coverage-guided search is `make fuzz` (clang, libFuzzer).
//   fuzz_<harness>_replay [--mutants N] [--seed S] FILE|FOLDER ...
// A failed harness check or a sanitizer report aborts; the input is then written to
// ./fuzz-replay-crash (reproduce with `make fuzz`'s harness binary and that file).
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);
// The sanitizers' hook for their reports (absent, hence weak, in a build without them).
extern "C" void __sanitizer_set_death_callback(void (*callback)(void)) __attribute__((weak));

namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

// What runs now, for the crash handlers: plain globals, as a signal handler may only write().
const Bytes* g_input = nullptr;
char g_label[512] = "";

void save_input() {
    static const char kMessage[] = "fuzz replay: failing input written to ./fuzz-replay-crash: ";
    (void)!::write(2, kMessage, sizeof kMessage - 1);
    (void)!::write(2, g_label, std::strlen(g_label));
    (void)!::write(2, "\n", 1);
    if (!g_input) return;
    const int fd = ::open("fuzz-replay-crash", O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd < 0) return;
    (void)!::write(fd, g_input->data(), g_input->size());
    ::close(fd);
}

void on_abort(int) {
    save_input();
    std::signal(SIGABRT, SIG_DFL);
    std::raise(SIGABRT);
}

Bytes mutate(const Bytes& in, std::mt19937_64& rng) {
    Bytes out = in;
    const auto pick = [&](std::size_t n) { return n ? std::size_t(rng() % n) : std::size_t(0); };
    static const std::uint8_t kEdge[] = {0x00, 0x01, 0x7f, 0x80, 0xff, '-', '9', '\n', ':', '{'};
    switch (rng() % 6) {
        case 0:  // flip one bit
            if (!out.empty()) out[pick(out.size())] ^= std::uint8_t(1u << (rng() % 8));
            break;
        case 1:  // an edge value
            if (!out.empty()) out[pick(out.size())] = kEdge[pick(sizeof kEdge)];
            break;
        case 2: {  // cut a run out
            const std::size_t at = pick(out.size()), n = std::min(out.size() - at, 1 + pick(16));
            out.erase(out.begin() + at, out.begin() + at + n);
            break;
        }
        case 3: {  // repeat a run
            const std::size_t at = pick(out.size()), n = std::min(out.size() - at, 1 + pick(64));
            const Bytes run(out.begin() + at, out.begin() + at + n);
            out.insert(out.begin() + at, run.begin(), run.end());
            break;
        }
        case 4: {  // insert random bytes
            Bytes run(1 + pick(8));
            for (auto& b : run) b = std::uint8_t(rng());
            out.insert(out.begin() + pick(out.size() + 1), run.begin(), run.end());
            break;
        }
        default:  // cut the tail off
            out.resize(pick(out.size() + 1));
    }
    return out;
}

void run(const Bytes& input, const std::string& label) {
    g_input = &input;
    std::snprintf(g_label, sizeof g_label, "%s", label.c_str());
    LLVMFuzzerTestOneInput(input.data(), input.size());
}

std::vector<fs::path> inputs(const std::vector<std::string>& args) {
    std::vector<fs::path> files;
    for (const auto& a : args) {
        if (fs::is_directory(a)) {
            for (const auto& e : fs::directory_iterator(a))
                if (e.is_regular_file()) files.push_back(e.path());
        } else {
            files.emplace_back(a);
        }
    }
    std::sort(files.begin(), files.end());
    return files;
}

}  // namespace

int main(int argc, char** argv) {
    int mutants = 0;
    std::uint64_t seed = 1;
    std::vector<std::string> args;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if ((a == "--mutants" || a == "--seed") && i + 1 < argc) {
            (a == "--mutants" ? void(mutants = std::atoi(argv[++i]))
                              : void(seed = std::strtoull(argv[++i], nullptr, 10)));
        } else {
            args.push_back(a);
        }
    }
    const auto files = inputs(args);
    if (files.empty()) {
        std::fprintf(stderr, "usage: %s [--mutants N] [--seed S] FILE|FOLDER ...\n", argv[0]);
        return 2;
    }
    std::signal(SIGABRT, on_abort);
    if (__sanitizer_set_death_callback) __sanitizer_set_death_callback(save_input);
    long runs = 0;
    for (std::size_t k = 0; k < files.size(); ++k) {
        std::ifstream f(files[k], std::ios::binary);
        const Bytes seed_input((std::istreambuf_iterator<char>(f)), {});
        run(seed_input, files[k].string());
        std::mt19937_64 rng(seed * 0x9e3779b97f4a7c15ull + k);
        Bytes m = seed_input;
        // The file's share of the mutants: as many each, the remainder to the first files.
        const long share = mutants / static_cast<long>(files.size()) +
                           (static_cast<long>(k) < mutants % static_cast<long>(files.size()));
        for (long j = 0; j < share; ++j) {
            m = j % 4 == 0 ? mutate(seed_input, rng) : mutate(m, rng);  // stacked, then afresh
            run(m, files[k].string() + ", mutant " + std::to_string(j + 1));
        }
        runs += 1 + share;
    }
    std::printf("%ld inputs from %zu corpus files, no finding\n", runs, files.size());
    return 0;
}
