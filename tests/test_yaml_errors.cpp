// A YAML syntax error names the line the mistake is on (issue 39: an unclosed bracket was named a
// line late, where yaml-cpp gave up looking for its end), over a set of broken files, through
// the reader every config and recipe uses and through the recording's reader.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "hotgauge/io/recording_io.hpp"
#include "hotgauge/io/yaml_reader.hpp"
#include "temp_dir.hpp"

using namespace hotgauge;

namespace {

struct Broken {
    const char* what;
    const char* text;
    int line;  // the line the mistake is on
};

const Broken kBroken[] = {
    {"unclosed [ in a flow sequence",
     "calibration: c.yaml\nfaces: [top, bottom\nrecipes:\n  1: hub-a.yaml\ncamera:\n  id: x\n", 2},
    {"unclosed [ at the end of a line", "a: 1\nb: 2\ncamera: [unclosed\n  id: x\n  mode: peaks\n",
     3},
    {"unclosed { in a flow map", "a: 1\nb: {x: 1, y: 2\nc: 3\nd: 4\n", 2},
    {"a bracket closed, a later one not", "a: [1, 2]\nb: '[not a bracket'\nc: [3,\nd: 4\n", 3},
    {"indented one space too far", "camera:\n  id: x\n   mode: peaks\n  width: 5\n", 3},
    {"a tab for indentation", "camera:\n  id: x\n\tmode: peaks\n", 3},
    {"a second colon in a value", "camera:\n  id: x\n  width: 2048: x\n", 3},
    {"a list item inside a mapping", "camera:\n  id: x\n  - mode: peaks\n", 3},
    // Quotes and brackets in plain scalars, quoted ones and comments are not structure.
    {"quotes and brackets in scalars and comments",
     "a: it's [1\nb: \"C:\\\\\" # [2\nc: [3, 4]\nd: [5,\ne: 6\n", 4},
};

std::string write(const std::filesystem::path& dir, const std::string& name, const char* text) {
    const auto path = dir / name;
    std::ofstream(path) << text;
    return path.string();
}

}  // namespace

TEST(YamlErrors, NameTheLineOfTheMistake) {
    test::TempDir dir;
    int i = 0;
    for (const Broken& b : kBroken) {
        const std::string file = write(dir.path, "broken-" + std::to_string(i++) + ".yaml", b.text);
        try {
            io::YamlReader(file).load();
            ADD_FAILURE() << b.what << ": loaded";
        } catch (const io::YamlError& e) {
            const std::string msg = e.what();
            EXPECT_EQ(msg.rfind(file + ":" + std::to_string(b.line) + ": YAML syntax error", 0), 0u)
                << b.what << ": " << msg;
        }
    }
}

// The recording's reader says the same line, in its own words.
TEST(YamlErrors, RecordingReaderNamesTheLineToo) {
    test::TempDir dir;
    write(dir.path, "part.yaml",
          "format: hotgauge-recording-v1\npart_id: [7\nrecipe: hub-a\nfaces: []\n");
    const auto r = io::read_recording(dir.path);
    ASSERT_FALSE(r);
    EXPECT_NE(r.error().message.find("YAML syntax error at line 2"), std::string::npos)
        << r.error().message;
}

// yaml-cpp says "end of map flow not found" for a missing comma too: the map is closed, so the
// line is yaml-cpp's, not the bracket's.
TEST(YamlErrors, AClosedCollectionKeepsTheLineYamlCppGives) {
    test::TempDir dir;
    const std::string file = write(dir.path, "comma.yaml", "a: {x: 1,\n  y: 2\n  z: 3}\nb: 4\n");
    try {
        io::YamlReader(file).load();
        ADD_FAILURE() << "loaded";
    } catch (const io::YamlError& e) {
        EXPECT_EQ(std::string(e.what()).find("not closed"), std::string::npos) << e.what();
    }
}
