// Bad input through the command line, every path a user can feed that tests/cli_test.cpp does not
// already cover: each malformed glTF of the corpus (tests/data/bad_gltf) given to `vksonar render`,
// and the edge values of the config validator. Each must exit 2 within a bounded time (run under
// `timeout`), print exactly one `error: ...` line naming the file/field/value, and leave no output.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "cli_support.h"

namespace fs = std::filesystem;

namespace {

constexpr int kTimeoutSeconds = 60; // a bad-input run takes milliseconds; 60 s means "hung"

struct CliResult {
    int exit_code = -1;
    std::string err;
};

using vksonar::testing::fresh_test_dir;
using vksonar::testing::quote;
using vksonar::testing::read_text;
using vksonar::testing::remove_test_dir;
using vksonar::testing::write_text;

class BadInput : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fresh_test_dir("vksonar_bad_input_");
        // The smallest valid scene: one triangle 10 m ahead (buffer: 3 float VEC3, no indices).
        write_text(dir_ / "ok.gltf",
                   R"({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
  "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAgQQAAgL8AAAAAAAAgQQAAgD8AAAAAAAAgQQAAAAAAAIA/"}],
  "bufferViews": [{"buffer": 0, "byteLength": 36}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [10, -1, 0], "max": [10, 1, 1]}]})");
    }
    void TearDown() override { remove_test_dir(dir_); }

    CliResult run(const std::vector<std::string>& args) const {
        std::string command = "timeout " + std::to_string(kTimeoutSeconds) + " " + quote(VKSONAR_CLI);
        for (const auto& arg : args)
            command += " " + quote(arg);
        const fs::path err = dir_ / "stderr.txt";
        command += " > /dev/null 2> " + quote(err.string()) + " < /dev/null";
        const int status = std::system(command.c_str());
        CliResult r;
        r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
        r.err = read_text(err);
        return r;
    }

    // `vksonar render ARGS --out DIR/never/out` (plus --scene ok.gltf unless given, CPU backend) must
    // fail with exit 2 and one line `error: ...` containing every `expected` string, leaving nothing.
    void expect_bad_render(std::vector<std::string> args, const std::vector<std::string>& expected) const {
        const fs::path parent = dir_ / "never";
        args.insert(args.begin(), "render");
        args.insert(args.end(), {"--backend", "cpu", "--out", (parent / "out").string()});
        if (std::find(args.begin(), args.end(), "--scene") == args.end()) {
            args.push_back("--scene");
            args.push_back((dir_ / "ok.gltf").string());
        }
        const CliResult r = run(args);
        std::string joined;
        for (const auto& a : args)
            joined += a + " ";
        ASSERT_NE(r.exit_code, 124) << "timed out after " << kTimeoutSeconds << " s: " << joined;
        EXPECT_EQ(r.exit_code, 2) << joined << "\nstderr: " << r.err;
        ASSERT_FALSE(r.err.empty()) << joined;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "exactly one line: " << r.err;
        EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
        for (const auto& text : expected)
            EXPECT_NE(r.err.find(text), std::string::npos) << "'" << text << "' in " << r.err;
        EXPECT_FALSE(fs::exists(parent)) << "output left behind by: " << joined;
    }

    fs::path dir_;
};

TEST_F(BadInput, ValidSceneRendersSoTheFailuresBelowAreTheInputs) {
    // (spaces around a --set number are the shell's: " 16" and "32 " alike)
    const CliResult r = run({"render", "--backend", "cpu", "--scene", (dir_ / "ok.gltf").string(), "--set", "bins=32 ",
                             "--set", "beams= 16", "--set", "display.fan_width=64", "--out", (dir_ / "out").string()});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(fs::is_regular_file(dir_ / "out" / "polar.npy"));
}

TEST_F(BadInput, EveryMalformedGltfOfTheCorpusIsExit2AndOneLine) {
    int files = 0;
    for (const auto& entry : fs::directory_iterator(std::string(VKSONAR_TEST_DIR) + "/data/bad_gltf")) {
        const std::string ext = entry.path().extension().string();
        if (ext != ".gltf" && ext != ".glb") continue;
        SCOPED_TRACE(entry.path().filename().string());
        expect_bad_render({"--scene", entry.path().string()}, {entry.path().filename().string()});
        ++files;
    }
    EXPECT_GE(files, 30);
    expect_bad_render({"--scene", (dir_ / "missing.gltf").string()}, {"missing.gltf", "no such file"});
}

TEST_F(BadInput, ConfigValuesAtAndBeyondTheEdges) {
    expect_bad_render({"--set", "hfov=0"}, {"hfov = 0"});
    expect_bad_render({"--set", "hfov=-5"}, {"hfov = -5"});
    expect_bad_render({"--set", "vfov=0"}, {"vfov = 0"});
    expect_bad_render({"--set", "vfov=-1"}, {"vfov = -1"});
    expect_bad_render({"--set", "range_min=0"}, {"range_min = 0"});
    expect_bad_render({"--set", "range_min=5", "--set", "range_max=5"}, {"range_max = 5"}); // empty window
    expect_bad_render({"--set", "range_min=-3", "--set", "range_max=-1"}, {"range_min = -3"});
    expect_bad_render({"--set", "range_max=inf"}, {"range_max", "inf"});
    expect_bad_render({"--set", "range_min=nan"}, {"range_min", "nan"});
    expect_bad_render({"--set", "beams=-1"}, {"beams", "-1"});
    // a whole-number key given nan or inf names it (it said "got null", JSON's spelling of them)
    expect_bad_render({"--set", "beams=nan"}, {"beams", "got nan"});
    expect_bad_render({"--set", "bins=1e999"}, {"bins", "got inf"});
    // hexadecimal, which strtod reads, is no number a person means (beams=0x10 rendered 16 beams)
    expect_bad_render({"--set", "beams=0x10"}, {"beams", "0x10"});
    expect_bad_render({"--set", "frequency=0x1p20"}, {"frequency", "0x1p20"});
    expect_bad_render({"--pose", "0x1p3,0,0,0,0,0"}, {"--pose", "0x1p3"});
    // finite as a double, not as the float the renderer's transforms hold
    expect_bad_render({"--pose", "1e39,0,0,0,0,0"}, {"--pose", "x = '1e39' is past a float's range"});
    expect_bad_render({"--set", "bins=1e12"}, {"bins"});
    expect_bad_render({"--set", "hfov=360.0001"}, {"hfov = 360.0001"});
    // JSON cannot spell NaN/Inf, but 1e999 overflows the parser's double (it used to escape as an
    // uncaught exception: exit 1, "error: internal: ...").
    write_text(dir_ / "huge.json", R"({"range_max": 1e999})");
    expect_bad_render({"--config", (dir_ / "huge.json").string()}, {"huge.json", "1e999"});
    expect_bad_render({"--set", "range_max=1e999"}, {"range_max"});
    write_text(dir_ / "null.json", R"({"beams": null})");
    expect_bad_render({"--config", (dir_ / "null.json").string()}, {"null.json", "beams"});
    write_text(dir_ / "empty.json", "");
    expect_bad_render({"--config", (dir_ / "empty.json").string()}, {"empty.json"});
    // Nested 100,000 deep (an audit's): printing the value for the error recursed until the stack ran
    // out (SIGSEGV, no message). Refused before parsing, as a glTF file's JSON is.
    const std::string deep = "{\"name\": " + std::string(100000, '[') + std::string(100000, ']') + "}";
    write_text(dir_ / "deep.json", deep);
    expect_bad_render({"--config", (dir_ / "deep.json").string()}, {"deep.json", "nests deeper than 128 levels"});
    expect_bad_render({"--sonar", (dir_ / "deep.json").string()}, {"deep.json", "nests deeper than 128 levels"});
    // a quote inside a comment (config files take them) must not hide the brackets after it
    write_text(dir_ / "commented.json", "/* \" */ " + deep);
    expect_bad_render({"--config", (dir_ / "commented.json").string()},
                      {"commented.json", "nests deeper than 128 levels"});
    // A key twice in one object: JSON keeps the last in silence ({"hfov": 400, "hfov": 90} rendered).
    write_text(dir_ / "twice.json", R"({"hfov": 400, "effects": {"speckle": "off"}, "hfov": 90})");
    expect_bad_render({"--config", (dir_ / "twice.json").string()}, {"twice.json", "key 'hfov' is given twice"});
    // Files that are not files: named as what they are (they all said "no such file").
    expect_bad_render({"--config", dir_.string()}, {"--config", "is a directory"});
    expect_bad_render({"--config", "/dev/null"}, {"--config /dev/null", "is not a regular file"});
    expect_bad_render({"--scene", dir_.string()}, {"--scene", "is a directory"});
}

TEST_F(BadInput, SetWithBytesThatAreNotUtf8) {
    // Found by fuzz/fuzz_config.cpp: such a value reached the JSON serializer and escaped as an
    // uncaught type_error (exit 1, "error: internal: ...") for numbers, enums and strings alike.
    expect_bad_render({"--set", "beams=\xd1"}, {"--set", "not valid UTF-8"});
    expect_bad_render({"--set", "name=abc\xff"}, {"--set", "not valid UTF-8"});
    expect_bad_render({"--set", "beam_spacing=\xc3"}, {"--set", "not valid UTF-8"});
    expect_bad_render({"--set", "\xd1=1"}, {"--set", "not valid UTF-8"});
}

TEST_F(BadInput, NonFinitePosesAndTrajectoryValues) {
    expect_bad_render({"--pose", "0,0,nan,0,0,0"}, {"--pose"});
    expect_bad_render({"--pose", "0,0,0,0,1e999,0"}, {"--pose"});
    write_text(dir_ / "nan.csv", "0,0,0,0,10,0\n0,0,0,0,nan,0\n");
    expect_bad_render({"--trajectory", (dir_ / "nan.csv").string()}, {"nan.csv:2"});
    write_text(dir_ / "extra.csv", "0,0,0,0,10,0,7\n");
    expect_bad_render({"--trajectory", (dir_ / "extra.csv").string()}, {"extra.csv:1"});
}

// An output in a folder that takes no new file (/proc, even for root, whom access() tells yes) or an
// empty name: exit 2 and one line naming the option and the path, not a temporary file's name (the
// write failed later, exit 1, naming `.~x.mcap.writing-PID`).
TEST_F(BadInput, UnwritableOutputsAreOneLineNamingTheOption) {
    const auto expect_bad = [&](const std::vector<std::string>& args, const std::vector<std::string>& expected) {
        const CliResult r = run(args);
        std::string joined;
        for (const auto& a : args)
            joined += a + " ";
        EXPECT_EQ(r.exit_code, 2) << joined << "\nstderr: " << r.err;
        EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << "exactly one line: " << r.err;
        EXPECT_EQ(r.err.find(".~"), std::string::npos) << "a temporary's name: " << r.err;
        for (const auto& text : expected)
            EXPECT_NE(r.err.find(text), std::string::npos) << "'" << text << "' in " << r.err;
    };
    const std::string scene = (dir_ / "ok.gltf").string();
    write_text(dir_ / "two.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,0,0\n0,0,0,0,0,1\n");
    // (a .mcap: every build writes bags; a .h5 goes through the same check where the build has HDF5)
    expect_bad({"render", "--backend", "cpu", "--scene", scene, "--trajectory", (dir_ / "two.csv").string(), "--out",
                "/proc/vksonar_never.mcap"},
               {"--out /proc/vksonar_never.mcap", "cannot write in /proc"});
    // --out a link to such a place: the file is made beside the link's target, so that folder is probed
    fs::create_symlink("/proc/vksonar_never.mcap", dir_ / "link.mcap");
    expect_bad({"render", "--backend", "cpu", "--scene", scene, "--trajectory", (dir_ / "two.csv").string(), "--out",
                (dir_ / "link.mcap").string()},
               {"link.mcap", "cannot write in /proc"});
    expect_bad({"merge", "/proc/vksonar_never", (dir_ / "none").string()},
               {"merge: OUT /proc/vksonar_never", "cannot write in /proc"});
    expect_bad({"merge", "", (dir_ / "none").string()}, {"merge: OUT is empty"});
    expect_bad({"export", "coco", dir_.string(), "/proc/vksonar_never.json"},
               {"export coco: OUT /proc/vksonar_never.json", "cannot write in /proc"});
    expect_bad({"export", "coco", dir_.string(), ""}, {"export coco: OUT", "empty"});
}

} // namespace
