// The plant's disk spool on a temp folder.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "hotgauge/plant/spool.hpp"
#include "temp_dir.hpp"

namespace {

using namespace hotgauge;
namespace fs = std::filesystem;

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream all;
    all << in.rdbuf();
    return all.str();
}

void write_file(const fs::path& p, const std::string& text) {
    std::ofstream(p, std::ios::binary) << text;
}

// ---------------------------------------------------------------------------------------------
// Spool

plant::SpoolConfig spool_config(const fs::path& dir, std::uint64_t max_bytes = 1 << 20) {
    plant::SpoolConfig c;
    c.dir = dir;
    c.max_bytes = max_bytes;
    return c;
}

std::unique_ptr<plant::Spool> open_spool(const plant::SpoolConfig& c) {
    auto s = plant::Spool::open(c);
    EXPECT_TRUE(s.ok()) << (s ? "" : s.error().message);
    return s ? std::move(*s) : nullptr;
}

// Every message still in the spool, oldest first, popping them all.
std::vector<std::string> drain(plant::Spool& s) {
    std::vector<std::string> out;
    for (int guard = 0; guard < 1000; ++guard) {
        const auto m = s.front();
        if (!m) break;
        out.push_back(*m);
        EXPECT_TRUE(s.pop().ok());
    }
    return out;
}

TEST(Spool, AppendFrontPopInOrder) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_FALSE(s->front());
    for (const char* m : {"{\"a\":1}", "{\"b\":2}", "{\"c\":3}"}) ASSERT_TRUE(s->append(m).ok());
    EXPECT_EQ(s->state().depth, 3u);
    EXPECT_EQ(s->state().bytes, 24u);
    EXPECT_EQ(s->front(), "{\"a\":1}");
    EXPECT_EQ(s->front(), "{\"a\":1}");  // front() does not consume
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"{\"a\":1}", "{\"b\":2}", "{\"c\":3}"}));
    EXPECT_EQ(s->state().depth, 0u);
    EXPECT_FALSE(s->pop().ok());
    EXPECT_EQ(s->dir(), d.path);
}

TEST(Spool, ReopenAfterPopsKeepsTheRest) {
    test::TempDir d;
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        for (int i = 0; i < 5; ++i) ASSERT_TRUE(s->append("m" + std::to_string(i)).ok());
        ASSERT_TRUE(s->pop().ok());
        ASSERT_TRUE(s->pop().ok());
    }
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(s->state().depth, 3u);
    EXPECT_EQ(s->state().bytes, 9u);
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"m2", "m3", "m4"}));
}

TEST(Spool, TornLastLineIsCutAtOpen) {
    test::TempDir d;
    const std::string long_line = "{\"long\":\"" + std::string(9000, 'y') + "\"}";
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        ASSERT_TRUE(s->append("m0").ok());
        ASSERT_TRUE(s->append(long_line).ok());
    }
    // The power went here, in a line longer than the blocks the spool reads.
    std::ofstream(d.path / "spool.jsonl", std::ios::app) << "{\"torn" << std::string(10000, 'x');
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(slurp(d.path / "spool.jsonl"), "m0\n" + long_line + "\n");
    EXPECT_EQ(s->state().depth, 2u);
    ASSERT_TRUE(s->append("m2").ok());
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"m0", long_line, "m2"}));
}

TEST(Spool, CursorPastTheEndReadsAsZero) {
    test::TempDir d;
    write_file(d.path / "spool.jsonl", "a\nb\n");
    write_file(d.path / "spool.cursor", "1000\n");
    {
        auto s = open_spool(spool_config(d.path));
        ASSERT_TRUE(s);
        EXPECT_EQ(s->state().depth, 2u);
        EXPECT_EQ(s->front(), "a");
    }
    // The crash between emptying the file and writing cursor 0: nothing is sent again.
    write_file(d.path / "spool.jsonl", "");
    write_file(d.path / "spool.cursor", "4\n");
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    EXPECT_EQ(s->state().depth, 0u);
    EXPECT_FALSE(s->front());
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "0\n");
}

TEST(Spool, BoundRefusesAndCounts) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path, 10));
    ASSERT_TRUE(s);
    ASSERT_TRUE(s->append("12345").ok());    // 6 bytes with its newline
    const auto refused = s->append("1234");  // 6 + 5 > 10
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find(d.path.string()), std::string::npos)
        << refused.error().message;
    EXPECT_NE(refused.error().message.find("10 bytes"), std::string::npos)
        << refused.error().message;
    EXPECT_EQ(s->state().refused, 1u);
    EXPECT_TRUE(s->state().full);
    EXPECT_EQ(s->state().depth, 1u);
    EXPECT_EQ(slurp(d.path / "spool.jsonl"), "12345\n");  // what is spooled is untouched
    EXPECT_FALSE(s->append("with\nnewline").ok());
    EXPECT_EQ(s->state().refused, 2u);
    ASSERT_TRUE(s->append("123").ok());  // exactly 10
    EXPECT_FALSE(s->state().full);
    EXPECT_EQ(drain(*s), (std::vector<std::string>{"12345", "123"}));
    EXPECT_TRUE(s->append("1234").ok());  // room again once acknowledged
}

TEST(Spool, FullyAcknowledgedEmptiesTheFile) {
    test::TempDir d;
    auto s = open_spool(spool_config(d.path));
    ASSERT_TRUE(s);
    for (const char* m : {"x1", "x2", "x3"}) ASSERT_TRUE(s->append(m).ok());
    ASSERT_TRUE(s->pop().ok());
    ASSERT_TRUE(s->pop().ok());
    EXPECT_EQ(fs::file_size(d.path / "spool.jsonl"), 9u);  // kept while one is waiting
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "6\n");
    ASSERT_TRUE(s->pop().ok());
    EXPECT_EQ(fs::file_size(d.path / "spool.jsonl"), 0u);
    EXPECT_EQ(slurp(d.path / "spool.cursor"), "0\n");
    ASSERT_TRUE(s->append("y1").ok());
    EXPECT_EQ(s->front(), "y1");
    EXPECT_EQ(slurp(d.path / "spool.jsonl"), "y1\n");
}

}  // namespace
