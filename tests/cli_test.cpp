// The vksonar command-line tool, run as a separate process: exit codes, the one-line `error: ...`
// on stderr for each kind of bad input, no output left behind on error, and the file layout of a
// successful render (CPU backend, so no GPU is needed).
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli_support.h"
#include "config/config_keys.h"
#include "vk/vulkan_context.h"
#include "vksonar/context.h"

namespace fs = std::filesystem;

namespace {

using vksonar::testing::CliRun;
using vksonar::testing::fresh_test_dir;
using vksonar::testing::quote;
using vksonar::testing::read_text;
using vksonar::testing::remove_test_dir;
using vksonar::testing::write_text;

class Cli : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = fresh_test_dir("vksonar_cli_test_");
        write_text(dir_ / "quad.gltf", kQuadGltf);
    }
    void TearDown() override { remove_test_dir(dir_); }

    CliRun run(const std::vector<std::string>& args) const { return vksonar::testing::run_cli(dir_, args); }

    // Runs a render that must fail with exit code 2 and exactly one stderr line `error: ...` that
    // contains every string in `expected`, and must leave no output directory behind.
    void expect_bad_render(std::vector<std::string> args, const std::vector<std::string>& expected) const {
        const fs::path parent = dir_ / "never_created";
        args.insert(args.begin(), "render");
        if (std::find(args.begin(), args.end(), "--out") == args.end()) {
            args.push_back("--out");
            args.push_back((parent / "out").string());
        }
        if (std::find(args.begin(), args.end(), "--scene") == args.end()) {
            args.push_back("--scene");
            args.push_back((dir_ / "quad.gltf").string());
        }
        const CliRun r = run(args);
        std::string joined;
        for (const auto& a : args)
            joined += a + " ";
        EXPECT_EQ(r.exit_code, 2) << joined << "\nstderr: " << r.err;
        const auto lines = r.err_lines();
        ASSERT_EQ(lines.size(), 1u) << joined << "\nstderr: " << r.err;
        EXPECT_EQ(lines[0].rfind("error: ", 0), 0u) << lines[0];
        for (const auto& text : expected)
            EXPECT_NE(lines[0].find(text), std::string::npos) << lines[0];
        EXPECT_FALSE(fs::exists(parent)) << "output left behind by: " << joined;
    }

    fs::path dir_;

    // One 10 m x 6 m quad 10 m ahead of a sonar at the origin (glTF is +Y up: world = (x, -z, y)).
    static constexpr const char* kQuadGltf = R"({
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0]}],
  "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
  "buffers": [{"byteLength": 60,
               "uri": "data:application/octet-stream;base64,AAAgQQAAQMAAAKDAAAAgQQAAQMAAAKBAAAAgQQAAQEAAAKBAAAAgQQAAQEAAAKDAAAABAAIAAAACAAMA"}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                  {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                 "min": [10, -3, -5], "max": [10, 3, 5]},
                {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]
})";
};

// ---- bad input: exit 2, one line, nothing written ---------------------------------------------

TEST_F(Cli, UnknownKeySuggestsClosest) {
    expect_bad_render({"--set", "hfvo=90"}, {"unknown key 'hfvo'", "did you mean 'hfov'"});
    write_text(dir_ / "typo.json", R"({"display": {"db_mni": 1}})");
    expect_bad_render({"--config", (dir_ / "typo.json").string()},
                      {"typo.json", "'display.db_mni'", "did you mean 'display.db_min'"});
}

TEST_F(Cli, WrongType) {
    write_text(dir_ / "many.json", R"({"beams": "many"})");
    expect_bad_render({"--config", (dir_ / "many.json").string()}, {"many.json", "beams", "\"many\""});
    expect_bad_render({"--set", "bins=lots"}, {"bins", "lots"});
    write_text(dir_ / "broken.json", R"({"beams": )");
    expect_bad_render({"--config", (dir_ / "broken.json").string()}, {"broken.json", "invalid JSON"});
}

TEST_F(Cli, InvalidValues) {
    expect_bad_render({"--set", "beams=0"}, {"beams = 0"});
    expect_bad_render({"--set", "bins=0"}, {"bins = 0"});
    expect_bad_render({"--set", "range_min=10", "--set", "range_max=5"}, {"range_max = 5"});
    expect_bad_render({"--set", "range_min=-1"}, {"range_min = -1"});
    expect_bad_render({"--set", "hfov=400"}, {"hfov = 400"});
    expect_bad_render({"--set", "vfov=180"}, {"vfov = 180"});
    expect_bad_render({"--set", "hfov=nan"}, {"hfov", "nan"});
    expect_bad_render({"--set", "display.db_max=1"}, {"display.db_max = 1"});
    expect_bad_render({"--set", "accuracy.max_slice=200"}, {"accuracy.max_slice = 200"});
    // A value from a config file names the file too.
    write_text(dir_ / "zero_beams.json", R"({"beams": 0})");
    expect_bad_render({"--config", (dir_ / "zero_beams.json").string()},
                      {"invalid config: --config " + (dir_ / "zero_beams.json").string() + ": beams = 0"});
    // ... as a --sonar file, and a --set names itself; the layer named is the one whose value is wrong:
    // a later --set that mends it leaves no error, one that breaks another key is named instead.
    expect_bad_render({"--sonar", (dir_ / "zero_beams.json").string()}, {"--sonar ", "zero_beams.json", "beams = 0"});
    expect_bad_render({"--set", "range_max=-5"}, {"--set range_max=-5: range_max = -5"});
    expect_bad_render({"--sonar", (dir_ / "zero_beams.json").string(), "--set", "beams=8", "--set", "hfov=400"},
                      {"--set hfov=400: hfov = 400"});
    expect_bad_render({"--config", (dir_ / "zero_beams.json").string(), "--set", "beams=8", "--set", "bins=0"},
                      {"--set bins=0: bins = 0"});
    // A later layer that changes only the reason's wording (the legacy mode's hfov rule names max_slice's
    // value) leaves the blame with the value that is wrong.
    expect_bad_render({"--sonar", "uuv-legacy", "--set", "hfov=200", "--set", "accuracy.max_slice=120"},
                      {"--set hfov=200: hfov = 200", "(120 degrees)"});
}

// A glTF node's object id is its index + 1: a node past index 65534 cannot be labelled in 16 bits. With
// --save labels that is one line naming the node (unnamed here) and its id, exit 2; without labels the
// scene renders.
TEST_F(Cli, LabelsRefuseNodeIdsPastSixteenBits) {
    nlohmann::json doc = nlohmann::json::parse(kQuadGltf);
    nlohmann::json nodes = nlohmann::json::array();
    for (int i = 0; i < 65535; ++i)
        nodes.push_back(nlohmann::json::object());
    nodes.push_back({{"mesh", 0}});
    doc["nodes"] = nodes;
    doc["scenes"][0]["nodes"] = {65535};
    write_text(dir_ / "far_node.gltf", doc.dump());
    const std::vector<std::string> scene = {
        "--scene", (dir_ / "far_node.gltf").string(), "--backend", "cpu", "--set", "bins=32", "--set", "beams=16",
        "--set",   "horizontal_beamwidth=9"};
    std::vector<std::string> labelled = scene;
    labelled.insert(labelled.end(), {"--save", "labels"});
    expect_bad_render(labelled, {"labels: node 65535 (unnamed) has instance id 65536; labels hold ids up to 65535"});
    std::vector<std::string> plain = {"render"};
    plain.insert(plain.end(), scene.begin(), scene.end());
    plain.insert(plain.end(), {"--save", "polar", "--out", (dir_ / "far_node_polar").string()});
    const CliRun r = run(plain);
    EXPECT_EQ(r.exit_code, 0) << r.err;
}

// Issue 25: a value outside physics is refused (exit 2, one line naming key, value and range, nothing
// written); a model outside its domain is one warning line and an entry in meta.json's "validity".
TEST_F(Cli, ValuesOutsidePhysicsAreRefused) {
    expect_bad_render({"--set", "source_level=400"}, {"source_level = 400", "[100, 260]"});
    expect_bad_render({"--set", "sound_speed=1e9"}, {"sound_speed = 1000000000", "[1400, 1650] m/s"});
    write_text(dir_ / "hot.json", R"({"temperature": 95})");
    expect_bad_render({"--config", (dir_ / "hot.json").string()}, {"hot.json", "temperature = 95", "[-2.5, 40]"});
    // A depth pass no device can hold is refused with its size before anything is allocated.
    // (planar: the pixel grid is the fan's; line_array's reaches past it and hits the column limit first)
    expect_bad_render({"--set", "bins=65536", "--set", "accuracy.pixels_per_beam=32", "--set", "beam_geometry=planar"},
                      {"range-profile buffer would hold 4.29549 GB"});
    expect_bad_render({"--set", "bins=65536", "--set", "accuracy.pixels_per_beam=32"},
                      {"pixel columns needed (accuracy.pixels_per_beam = 32", "exceeds 16384"});
    // a narrow beamwidth, not the beam count, sets the columns here: the message names it
    expect_bad_render({"--set", "horizontal_beamwidth=0.01", "--set", "beams=16"},
                      {"pixel columns needed", "per horizontal_beamwidth = 0.01 degrees"});
}

TEST_F(Cli, ModelsOutsideTheirDomainWarnAndMetaJsonListsThem) {
    auto render = [&](const std::string& name, const std::vector<std::string>& sets) {
        std::vector<std::string> args = {
            "render",  "--backend", "cpu",      "--scene", (dir_ / "quad.gltf").string(), "--set",
            "bins=32", "--set",     "beams=16", "--set",   "display.fan_width=64",        "--set",
            "hfov=16"};
        for (const auto& s : sets) {
            args.push_back("--set");
            args.push_back(s);
        }
        args.push_back("--out");
        args.push_back((dir_ / name).string());
        return run(args);
    };
    // Inside every domain: no warning, and every entry says ok.
    const CliRun inside = render("inside", {"range_min=6"});
    ASSERT_EQ(inside.exit_code, 0) << inside.err;
    EXPECT_EQ(inside.err, "");
    const auto meta = nlohmann::json::parse(read_text(dir_ / "inside" / "meta.json"));
    ASSERT_TRUE(meta["validity"].is_array());
    ASSERT_EQ(meta["validity"].size(), 3u) << meta["validity"].dump(); // + beam_sampling
    for (const auto& entry : meta["validity"]) {
        EXPECT_EQ(entry["ok"], true) << entry.dump();
        for (const char* field : {"model", "key", "value", "domain", "action"})
            EXPECT_TRUE(entry.contains(field)) << field;
    }
    // The noise terms as used: NL the water's thermal noise -15 + 20 log10(f / 1 kHz) dB/Hz over the
    // bins' band c / 2 dr (750 kHz: wind and shipping add < 0.01 dB), and each beam's floor NL - DI_j
    // with DI_j = DI + 10 log10(cos theta_j) (a line array's steered beams; 16 beams over 16 deg).
    const auto& noise = meta["noise"];
    const double band = 1500.0 / (2.0 * meta["bin_width_m"].get<double>());
    EXPECT_NEAR(noise["band_hz"].get<double>(), band, 1e-6 * band);
    EXPECT_NEAR(noise["noise_level_db"].get<double>(), -15.0 + 20.0 * std::log10(750.0) + 10.0 * std::log10(band),
                0.05);
    ASSERT_EQ(noise["floor_db_by_beam"].size(), 16u);
    // A line array's beam is as wide in sine at every steering angle: in angle asin(u + s) - asin(u - s),
    // s = sin(bw / 2), u = sin(theta) (meta's rx_beamwidths_rad, as the bag's ping_info).
    for (std::size_t j = 0; j < 16; ++j) {
        const double u = std::sin(meta["beam_angles_rad"][j].get<double>()),
                     s = std::sin(0.5 * 3.14159265358979323846 / 180.0);
        EXPECT_NEAR(meta["rx_beamwidths_rad"][j].get<double>(), std::asin(u + s) - std::asin(u - s), 1e-12);
    }
    for (std::size_t j = 0; j < 16; ++j) {
        const double di = noise["directivity_index_db"].get<double>() +
                          10.0 * std::log10(std::cos(meta["beam_angles_rad"][j].get<double>()));
        EXPECT_NEAR(noise["floor_db_by_beam"][j].get<double>(), noise["noise_level_db"].get<double>() - di, 1e-9);
    }
    // Outside two domains: one warning line per model, and the list says which.
    const CliRun outside = render("outside", {"range_min=1", "frequency=3e6"});
    ASSERT_EQ(outside.exit_code, 0) << outside.err;
    const auto lines = outside.err_lines();
    ASSERT_EQ(lines.size(), 2u) << outside.err;
    EXPECT_EQ(lines[0].rfind("warning: francois_garrison: frequency = 3e+06 ", 0), 0u) << lines[0];
    EXPECT_EQ(lines[1].rfind("warning: far_field_beam_pattern: range_min = 1 ", 0), 0u) << lines[1];
    const auto list = nlohmann::json::parse(read_text(dir_ / "outside" / "meta.json"))["validity"];
    ASSERT_EQ(list.size(), 3u);
    EXPECT_EQ(list[0]["model"], "francois_garrison");
    EXPECT_EQ(list[0]["ok"], false);
    EXPECT_EQ(list[0]["key"], "frequency");
    EXPECT_EQ(list[0]["value"], 3e6);
    EXPECT_NE(list[0]["action"].get<std::string>().find("extrapolates"), std::string::npos);
    EXPECT_EQ(list[1]["model"], "far_field_beam_pattern");
    EXPECT_EQ(list[1]["ok"], false);
}

TEST_F(Cli, SkippedPrimitivesAreReportedAsWarnings) {
    // POINTS, LINES and an all-degenerate primitive: the render succeeds and says what it skipped.
    const fs::path out = dir_ / "out";
    const CliRun r = run({"render", "--backend", "cpu", "--scene",
                          std::string(VKSONAR_TEST_DIR) + "/data/scenes/primitives.gltf", "--set",
                          "range_min=6", // past the far-field distance: the loader's are the only warnings
                          "--out", out.string()});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    std::size_t warnings = 0;
    for (const std::string& line : r.err_lines()) {
        if (line.rfind("warning: ", 0) != 0) continue;
        ++warnings;
        EXPECT_NE(line.find("primitives.gltf"), std::string::npos) << line;
    }
    for (const char* word : {"POINTS", "LINES", "degenerate"})
        EXPECT_NE(r.err.find(word), std::string::npos) << word;
    EXPECT_GE(warnings, 3u) << r.err;
    EXPECT_TRUE(fs::exists(out / "polar.npy"));
}

TEST_F(Cli, UnknownPresetListsValidOnes) {
    expect_bad_render({"--sonar", "oculus_m9000"}, {"oculus_m9000", "valid presets", "gemini_720is", "default"});
    expect_bad_render({"--sonar", (dir_ / "missing.json").string()}, {"missing.json", "no such file"});
}

TEST_F(Cli, MalformedPose) {
    expect_bad_render({"--pose", "1,2,3"}, {"--pose", "6 numbers", "got 3"});
    expect_bad_render({"--pose", "1,2,3,4,5,x"}, {"--pose", "yaw"});
    expect_bad_render({"--pose", "1,2,3,4,5,inf"}, {"--pose"});
}

// An asset root that is no folder is the user's to fix (exit 2), whichever scene, named as it was given.
TEST_F(Cli, AnAssetRootThatIsNoFolderIsBadInput) {
    const std::string missing = (dir_ / "no_such_root").string();
    expect_bad_render({"--asset-root", missing, "--set", "range_min=6"}, {"--asset-root " + missing, "not a folder"});
    expect_bad_render({"--set", "scene.asset_root=" + missing, "--set", "range_min=6"},
                      {"scene.asset_root = " + missing, "not a folder"});
    const CliRun bundled = run({"render", "--backend", "cpu", "--asset-root", missing, "--out", (dir_ / "o").string()});
    EXPECT_EQ(bundled.exit_code, 2) << bundled.err; // was 1: the bundled scene's load failing
}

// Paths that are wrong in ways "no such file" or "no folder" misnamed (an audit's): a loop of symbolic
// links, and a file where OUT's folder should be.
TEST_F(Cli, PathsSayWhatIsWrongWithThem) {
    fs::create_symlink(dir_ / "loop_b.gltf", dir_ / "loop_a.gltf");
    fs::create_symlink(dir_ / "loop_a.gltf", dir_ / "loop_b.gltf");
    expect_bad_render({"--scene", (dir_ / "loop_a.gltf").string()}, {"loop_a.gltf: a loop of symbolic links"});
    write_text(dir_ / "a_file", "x");
    expect_bad_render({"--out", (dir_ / "a_file" / "x.h5").string()}, {"a_file is not a folder"});
}

TEST_F(Cli, UnwritableOutputDirectory) {
    expect_bad_render({"--out", "/proc/vksonar_out"}, {"/proc/vksonar_out"});
    EXPECT_FALSE(fs::exists("/proc/vksonar_out"));
    write_text(dir_ / "a_file", "x");
    expect_bad_render({"--out", (dir_ / "a_file").string()}, {"a_file", "not a directory"});
    // An existing output folder with a directory where fan.png goes: exit 2, named, no stray files.
    const fs::path taken = dir_ / "taken";
    fs::create_directories(taken / "fan.png");
    const CliRun r = run({"render", "--backend", "cpu", "--scene", (dir_ / "quad.gltf").string(), "--set",
                          "range_min=6", // inside every model's domain: the error is the only line
                          "--out", taken.string()});
    EXPECT_EQ(r.exit_code, 2) << r.err;
    ASSERT_EQ(r.err_lines().size(), 1u) << r.err;
    EXPECT_NE(r.err.find("fan.png: a directory is in the way"), std::string::npos) << r.err;
    for (const auto& entry : fs::directory_iterator(taken))
        EXPECT_NE(entry.path().filename().string()[0], '.') << "temporary left: " << entry.path();
}

TEST_F(Cli, BadTrajectoryLineNamesFileAndLine) {
    write_text(dir_ / "poses.csv", "# a comment\nx,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n1,2,x,0,0,0\n");
    expect_bad_render({"--trajectory", (dir_ / "poses.csv").string()}, {"poses.csv:4"});
    write_text(dir_ / "short.csv", "0,0,0,0,10,0\n\n0,0,0\n");
    expect_bad_render({"--trajectory", (dir_ / "short.csv").string()}, {"short.csv:3", "6 numbers"});
    write_text(dir_ / "empty.csv", "# nothing\n");
    expect_bad_render({"--trajectory", (dir_ / "empty.csv").string()}, {"empty.csv", "no poses"});
    expect_bad_render({"--trajectory", (dir_ / "none.csv").string()}, {"--trajectory", "none.csv", "no such file"});
    // a folder or a FIFO is named as such (a FIFO used to block the run, /dev/zero to fill memory)
    expect_bad_render({"--trajectory", dir_.string()}, {"--trajectory", "is a directory"});
    expect_bad_render({"--trajectory", "/dev/zero"}, {"--trajectory /dev/zero", "is not a regular file"});
    // A header other than six names (or seven, time first) was dropped in silence, as was a first line
    // of words a number reads (nan); a timed file's line of six numbers blamed the wrong column count.
    write_text(dir_ / "odd_header.csv", "a,b,c\n0,0,0,0,10,0\n");
    expect_bad_render({"--trajectory", (dir_ / "odd_header.csv").string()},
                      {"odd_header.csv:1", "header 'a,b,c' has 3 columns"});
    write_text(dir_ / "nan_first.csv", "nan,nan,nan,nan,nan,nan\n0,0,0,0,10,0\n");
    expect_bad_render({"--trajectory", (dir_ / "nan_first.csv").string()}, {"nan_first.csv:1", "not a finite number"});
    write_text(dir_ / "timed_short.csv", "t,x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n");
    expect_bad_render({"--trajectory", (dir_ / "timed_short.csv").string()},
                      {"timed_short.csv:2", "needs 7 numbers t,x,y,z,roll,pitch,yaw", "got 6"});
}

TEST_F(Cli, BadOptions) {
    expect_bad_render({"--save", "depth,nromals"}, {"--save", "nromals", "did you mean 'normals'"});
    expect_bad_render({"--backend", "gpu"}, {"--backend", "gpu"});
    expect_bad_render({"--seed", "-1"}, {"--seed"});
    expect_bad_render({"--sonr", "default"}, {"unknown option '--sonr'", "did you mean '--sonar'"});
    expect_bad_render({"--scene", (dir_ / "missing.gltf").string()}, {"missing.gltf"});
    expect_bad_render({"--set", "beams"}, {"key=value"});
    expect_bad_render({"--save", ""}, {"--save: no output named"}); // it wrote meta.json alone

    const CliRun no_out = run({"render", "--scene", (dir_ / "quad.gltf").string()});
    EXPECT_EQ(no_out.exit_code, 2);
    EXPECT_EQ(no_out.err, "error: render: --out DIR is required\n");
    const CliRun empty_out = run({"render", "--scene", (dir_ / "quad.gltf").string(), "--out", ""});
    EXPECT_EQ(empty_out.exit_code, 2);
    EXPECT_EQ(empty_out.err, "error: render: --out is empty (a folder, FILE.h5 or FILE.mcap)\n");

    // options that mean nothing together or here (an audit's: each was taken in silence)
    const CliRun both = run({"presets", "--show", "default", "--keys"});
    EXPECT_EQ(both.exit_code, 2);
    EXPECT_NE(both.err.find("--show and --keys"), std::string::npos) << both.err;
    const CliRun root_alone = run({"info", "--asset-root", dir_.string()});
    EXPECT_EQ(root_alone.exit_code, 2);
    EXPECT_NE(root_alone.err.find("info: --asset-root"), std::string::npos) << root_alone.err;
    const CliRun soak = run({"bench", "speed", "--backend", "cpu", "--frames", "3", "--memory-frames", "5"});
    EXPECT_EQ(soak.exit_code, 2);
    EXPECT_NE(soak.err.find("--memory-frames 5: more than the 10 warm-up frames"), std::string::npos) << soak.err;
    write_text(dir_ / "nul.csv", std::string("x,y,z,roll,pitch,yaw\n0,0,0") + '\0' + ",0,10,0\n");
    expect_bad_render({"--trajectory", (dir_ / "nul.csv").string()}, {"nul.csv:2: a NUL byte"});

    const CliRun unknown = run({"rendr"});
    EXPECT_EQ(unknown.exit_code, 2);
    EXPECT_NE(unknown.err.find("did you mean 'render'"), std::string::npos) << unknown.err;
}

// ---- presets, compare, bench --------------------------------------------------------------------

TEST_F(Cli, PresetsListShowAndKeys) {
    const CliRun list = run({"presets"});
    EXPECT_EQ(list.exit_code, 0) << list.err;
    for (const char* name : {"default", "oculus_m750d_lf", "gemini_720is", "aris_explorer_3000"})
        EXPECT_NE(list.out.find(name), std::string::npos) << name;

    const CliRun show = run({"presets", "--show", "blueview_p900_130"});
    ASSERT_EQ(show.exit_code, 0) << show.err;
    const auto json = nlohmann::json::parse(show.out);
    EXPECT_EQ(json["beams"], 768);
    EXPECT_EQ(json["display"]["colormap"], "sonar");
    EXPECT_EQ(json["effects"]["speckle"], "auto");

    const CliRun missing = run({"presets", "--show", "nope"});
    EXPECT_EQ(missing.exit_code, 2);
    EXPECT_EQ(missing.err_lines().size(), 1u);
    EXPECT_NE(missing.err.find("valid presets"), std::string::npos);

    const CliRun keys = run({"presets", "--keys"});
    ASSERT_EQ(keys.exit_code, 0);
    EXPECT_EQ(keys.out, vksonar::config_keys::reference_markdown());
}

void write_npy_f32(const fs::path& path, const std::vector<float>& values, std::uint32_t rows, std::uint32_t cols) {
    std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': (" + std::to_string(rows) + ", " +
                         std::to_string(cols) + "), }";
    while ((10 + header.size() + 1) % 64 != 0)
        header += ' ';
    header += '\n';
    std::ofstream file(path, std::ios::binary);
    file.write("\x93NUMPY\x01\x00", 8);
    const char length[2] = {static_cast<char>(header.size() & 0xff), static_cast<char>(header.size() >> 8)};
    file.write(length, 2);
    file << header;
    file.write(reinterpret_cast<const char*>(values.data()), static_cast<std::streamsize>(values.size() * 4));
}

TEST_F(Cli, Compare) {
    write_npy_f32(dir_ / "a.npy", {1e6f, 1e8f, 1e10f, 0.0f, 1e10f, 1e9f}, 2, 3);
    write_npy_f32(dir_ / "b.npy", {1e6f, 1e8f, 1e10f, 0.0f, 1e10f, 2e9f}, 2, 3); // +3.01 dB in one cell
    write_npy_f32(dir_ / "c.npy", {1, 2, 3}, 1, 3);

    const CliRun same = run({"compare", (dir_ / "a.npy").string(), (dir_ / "a.npy").string()});
    EXPECT_EQ(same.exit_code, 0) << same.out << same.err;
    EXPECT_NE(same.out.find("max_abs:      0"), std::string::npos) << same.out;
    EXPECT_NE(same.out.find("psnr:         inf"), std::string::npos) << same.out;

    const CliRun over = run({"compare", (dir_ / "a.npy").string(), (dir_ / "b.npy").string(), "--tol", "1"});
    EXPECT_EQ(over.exit_code, 1) << over.out << over.err;
    EXPECT_NE(over.out.find("max_db_diff:  3.01"), std::string::npos) << over.out;
    EXPECT_NE(over.out.find("rmse"), std::string::npos);
    EXPECT_NE(over.out.find("psnr"), std::string::npos);

    const CliRun within = run({"compare", (dir_ / "a.npy").string(), (dir_ / "b.npy").string(), "--tol", "3.1"});
    EXPECT_EQ(within.exit_code, 0) << within.out;
    // The differing cell (90 dB) is below a 95 dB floor, so it does not count.
    const CliRun floored = run({"compare", (dir_ / "a.npy").string(), (dir_ / "b.npy").string(), "--floor", "95"});
    EXPECT_EQ(floored.exit_code, 0) << floored.out;

    const CliRun shapes = run({"compare", (dir_ / "a.npy").string(), (dir_ / "c.npy").string()});
    EXPECT_EQ(shapes.exit_code, 2);
    EXPECT_NE(shapes.err.find("shapes differ"), std::string::npos) << shapes.err;
    write_text(dir_ / "junk.npy", "not numpy");
    const CliRun junk = run({"compare", (dir_ / "a.npy").string(), (dir_ / "junk.npy").string()});
    EXPECT_EQ(junk.exit_code, 2);
    EXPECT_EQ(junk.err_lines().size(), 1u);
}

// A .npy file with `dict` as its header (padded as NumPy pads it) and `data` after it.
void write_npy_raw(const fs::path& path, std::string dict, const std::string& data) {
    while ((10 + dict.size() + 1) % 64 != 0)
        dict += ' ';
    dict += '\n';
    std::ofstream file(path, std::ios::binary);
    file.write("\x93NUMPY\x01\x00", 8);
    const char length[2] = {static_cast<char>(dict.size() & 0xff), static_cast<char>(dict.size() >> 8)};
    file.write(length, 2);
    file << dict << data;
}

// Crafted .npy headers are bad input (exit 2, one line naming the file), not "error: internal": a
// shape with no tuple (substr past the end before), and a shape whose element count overflows 64 bits
// (it wrapped to 0 before, so an empty data section passed as a huge array).
TEST_F(Cli, CompareRefusesCraftedNpyHeaders) {
    write_npy_f32(dir_ / "a.npy", {1, 2, 3}, 1, 3);
    const std::string a = (dir_ / "a.npy").string();
    struct Case {
        const char* file;
        std::string dict, data, expected;
    };
    const std::vector<Case> cases = {
        {"no_tuple.npy", "{'descr': '<f4', 'fortran_order': False, 'shape':}", "", "'shape' is not a tuple"},
        {"open_tuple.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': 3, }", std::string(12, '\0'),
         "'shape' is not a tuple"},
        {"overflow.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 16), }", "",
         "more than 2^64 elements"},
        {"overflow_bytes.npy", "{'descr': '<f8', 'fortran_order': False, 'shape': (2147483648, 2147483648), }", "",
         "more than 2^64 data bytes"},
        // (an audit's: a dict without its closing brace was read)
        {"unclosed_dict.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 3), ", std::string(12, '\0'),
         "not one {...} dict"},
        {"after_dict.npy", "{'descr': '<f4', 'fortran_order': False, 'shape': (1, 3), } x", std::string(12, '\0'),
         "not one {...} dict"},
    };
    for (const Case& c : cases) {
        write_npy_raw(dir_ / c.file, c.dict, c.data);
        const CliRun r = run({"compare", a, (dir_ / c.file).string()});
        EXPECT_EQ(r.exit_code, 2) << c.file << ": " << r.err;
        ASSERT_EQ(r.err_lines().size(), 1u) << c.file << ": " << r.err;
        EXPECT_NE(r.err.find(c.file), std::string::npos) << r.err;
        EXPECT_NE(r.err.find(c.expected), std::string::npos) << r.err;
    }
}

TEST_F(Cli, BenchDispatch) {
    const CliRun usage = run({"bench"});
    EXPECT_EQ(usage.exit_code, 2);
    EXPECT_NE(usage.err.find("vksonar bench: speed|effects|accuracy"), std::string::npos);
    for (const char* mode : {"speed", "effects", "accuracy"}) {
        const CliRun help = run({"bench", mode, "--help"});
        EXPECT_EQ(help.exit_code, 0) << mode << ": " << help.err;
        EXPECT_NE(help.out.find(std::string("usage: vksonar bench ") + mode), std::string::npos) << help.out;
        const CliRun typo = run({"bench", mode, "--frame", "3"});
        EXPECT_EQ(typo.exit_code, 2);
        EXPECT_NE(typo.err.find("did you mean '--frames'"), std::string::npos) << typo.err;
    }
    // --labels: the labels stage in every frame, with its own row
    const CliRun labels = run({"bench", "speed", "--backend", "cpu", "--frames", "3", "--memory-frames", "12",
                               "--labels", "--scene", (dir_ / "quad.gltf").string(), "--set", "bins=64", "--set",
                               "beams=48", "--set", "horizontal_beamwidth=3"});
    EXPECT_EQ(labels.exit_code, 0) << labels.err;
    EXPECT_NE(labels.out.find("| labels |"), std::string::npos) << labels.out;
    const CliRun extra = run({"bench", "accuracy", "extra"});
    EXPECT_EQ(extra.exit_code, 2);
    EXPECT_EQ(extra.err_lines().size(), 1u);
    const CliRun bad = run({"bench", "sped"});
    EXPECT_EQ(bad.exit_code, 2);
    // an invalid value names the --set that gave it, as render does
    const CliRun invalid = run({"bench", "speed", "--backend", "cpu", "--frames", "1", "--set", "bins=0"});
    EXPECT_EQ(invalid.exit_code, 2);
    ASSERT_EQ(invalid.err_lines().size(), 1u) << invalid.err;
    EXPECT_NE(invalid.err.find("invalid config: --set bins=0: bins = 0"), std::string::npos) << invalid.err;
    // The quad behind the sonar: an accuracy sweep with nothing to compare is an error, not zeros.
    const CliRun empty = run({"bench", "accuracy", "--no-vulkan", "--frames", "1", "--scene",
                              (dir_ / "quad.gltf").string(), "--pose", "0,0,0,0,0,180"});
    EXPECT_EQ(empty.exit_code, 2) << empty.err;
    EXPECT_NE(empty.err.find("nothing is in view"), std::string::npos) << empty.err;
}

// ---- successful renders (CPU backend) --------------------------------------------------------

std::vector<std::size_t> npy_shape(const fs::path& path) {
    const std::string text = read_text(path);
    const auto open = text.find("'shape': (");
    if (open == std::string::npos) return {};
    const auto close = text.find(')', open);
    std::vector<std::size_t> shape;
    std::stringstream items(text.substr(open + 10, close - open - 10));
    std::string item;
    while (std::getline(items, item, ','))
        if (item.find_first_of("0123456789") != std::string::npos) shape.push_back(std::stoul(item));
    return shape;
}

// --asset-root naming a folder whose name is not UTF-8 (Latin-1 "caf\xe9"): the render works and
// meta.json holds the name with U+FFFD for the bad byte (before: meta.json's config dump threw, and
// the CLI printed "error: internal").
TEST_F(Cli, AssetRootThatIsNotUtf8StillRenders) {
    const fs::path root = dir_ / "caf\xe9";
    fs::create_directories(root);
    fs::copy_file(dir_ / "quad.gltf", root / "quad.gltf");
    const fs::path out = dir_ / "out";
    const CliRun r =
        run({"render", "--scene", (root / "quad.gltf").string(), "--asset-root", root.string(), "--backend", "cpu",
             "--set", "bins=64", "--set", "beams=48", "--set", "horizontal_beamwidth=3", "--out", out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto meta = nlohmann::json::parse(read_text(out / "meta.json"));
    const std::string written = meta["config"]["scene"]["asset_root"].get<std::string>();
    EXPECT_NE(written.find("caf\xef\xbf\xbd"), std::string::npos) << written;
}

TEST_F(Cli, RenderWritesEveryOutput) {
    const fs::path out = dir_ / "out" / "nested";
    const CliRun r = run({"render",
                          "--scene",
                          (dir_ / "quad.gltf").string(),
                          "--backend",
                          "cpu",
                          "--set",
                          "bins=64",
                          "--set",
                          "beams=48",
                          "--set",
                          "horizontal_beamwidth=3",
                          "--set",
                          "display.fan_width=128",
                          "--set",
                          "effects.speckle=off",
                          "--save",
                          "default,depth,normals",
                          "--save",
                          "echo,cloud",
                          "--pose",
                          "0,0,0,0,0,0",
                          "--seed",
                          "7",
                          "--out",
                          out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    // Nothing on stderr but the one validity warning every default-based render prints (range_min
    // inside the far-field distance; assets/presets/default.json says why).
    ASSERT_EQ(r.err_lines().size(), 1u) << r.err;
    EXPECT_EQ(r.err_lines()[0].rfind("warning: far_field_beam_pattern: range_min = 0.5 ", 0), 0u) << r.err;
    for (const char* name : {"fan.png", "polar.png", "polar.npy", "polar_u16.npy", "meta.json", "depth.npy",
                             "normals.npy", "echo.npy", "cloud.ply"})
        EXPECT_TRUE(fs::is_regular_file(out / name)) << name;
    EXPECT_EQ(npy_shape(out / "polar.npy"), (std::vector<std::size_t>{64, 48}));
    EXPECT_EQ(npy_shape(out / "polar_u16.npy"), (std::vector<std::size_t>{64, 48}));
    EXPECT_EQ(npy_shape(out / "normals.npy").size(), 3u);
    EXPECT_EQ(npy_shape(out / "normals.npy").back(), 4u);
    EXPECT_EQ(npy_shape(out / "echo.npy").back(), 2u);
    EXPECT_EQ(npy_shape(out / "depth.npy").size(), 2u);
    for (const auto& entry : fs::directory_iterator(out))
        EXPECT_NE(entry.path().filename().string()[0], '.') << "temporary file left: " << entry.path();

    const auto meta = nlohmann::json::parse(read_text(out / "meta.json"));
    EXPECT_EQ(meta["config"]["bins"], 64);
    EXPECT_EQ(meta["config"]["effects"]["speckle"], "off");
    EXPECT_EQ(meta["backend"], "cpu");
    EXPECT_EQ(meta["device"], "cpu");
    EXPECT_EQ(meta["scene"], (dir_ / "quad.gltf").string());
    EXPECT_TRUE(meta.contains("pose"));
}

TEST_F(Cli, PrecedencePresetSceneEffectsConfigSet) {
    // The scene asks for speckle off and TVG on; a config file turns TVG back off; --set wins last.
    std::string scene = kQuadGltf;
    const std::string from = R"("scenes": [{"nodes": [0]}])";
    scene.replace(scene.find(from), from.size(),
                  R"("scenes": [{"nodes": [0], "extras": {"vksonar": {"effects": {"speckle": "off", "tvg": "on",
                  "spreading": "off"}}}}])");
    write_text(dir_ / "extras.gltf", scene);
    write_text(dir_ / "cfg.json", R"({"effects": {"tvg": "off", "spreading": "on"}, "bins": 40})");
    const fs::path out = dir_ / "out";
    const CliRun r = run({"render", "--scene", (dir_ / "extras.gltf").string(), "--backend", "cpu", "--sonar",
                          "oculus_m750d_hf", "--config", (dir_ / "cfg.json").string(), "--set", "beams=20", "--set",
                          "display.fan_width=64", "--set", "effects.spreading=off", "--out", out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto config = nlohmann::json::parse(read_text(out / "meta.json"))["config"];
    EXPECT_EQ(config["frequency"], 1.2e6);            // preset
    EXPECT_EQ(config["effects"]["speckle"], "off");   // scene over preset
    EXPECT_EQ(config["effects"]["tvg"], "off");       // config file over scene
    EXPECT_EQ(config["bins"], 40);                    // config file over preset
    EXPECT_EQ(config["effects"]["spreading"], "off"); // --set over config file
    EXPECT_EQ(config["beams"], 20);
}

TEST_F(Cli, SceneEffectsAndSetReachTheResolvedEffects) {
    // The resolved effects in meta.json (not only the config echo): the scene's speckle "off" beats the
    // preset's auto, and --set beats the scene; each "why" says which layer decided. The bundled quad's default
    // material is Lambert, so the normals pass runs unless incidence is switched off.
    std::string scene = kQuadGltf;
    const std::string from = R"("scenes": [{"nodes": [0]}])";
    scene.replace(
        scene.find(from), from.size(),
        R"("scenes": [{"nodes": [0], "extras": {"vksonar": {"effects": {"speckle": "off", "incidence": "off"}}}}])");
    write_text(dir_ / "extras.gltf", scene);
    const std::vector<std::string> common = {"render",
                                             "--scene",
                                             (dir_ / "extras.gltf").string(),
                                             "--backend",
                                             "cpu",
                                             "--set",
                                             "beams=16",
                                             "--set",
                                             "horizontal_beamwidth=9",
                                             "--set",
                                             "bins=32",
                                             "--set",
                                             "display.fan_width=64"};
    auto meta_of = [&](std::vector<std::string> args, const std::string& name) {
        args.insert(args.begin(), common.begin(), common.end());
        const fs::path out = dir_ / name;
        args.push_back("--out");
        args.push_back(out.string());
        const CliRun r = run(args);
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return nlohmann::json::parse(read_text(out / "meta.json"));
    };
    const auto scene_only = meta_of({}, "scene_only");
    EXPECT_EQ(scene_only["effects"]["speckle"]["on"], false);
    // meta names the scene as what decided it (not "off in config": no config layer switched it off)
    EXPECT_EQ(scene_only["effects"]["speckle"]["why"], "off: the scene requests it (scenes[N].extras.vksonar.effects)");
    EXPECT_EQ(scene_only["effects"]["incidence"]["on"], false);
    EXPECT_EQ(scene_only["stages_run"], (nlohmann::json{"depth", "echo", "beamform", "noise"}));
    const auto with_set = meta_of({"--set", "effects.speckle=on", "--set", "effects.incidence=auto"}, "with_set");
    EXPECT_EQ(with_set["effects"]["speckle"]["on"], true);
    EXPECT_EQ(with_set["effects"]["speckle"]["why"], "on in config");
    EXPECT_EQ(with_set["effects"]["incidence"]["on"], true);
    EXPECT_EQ(with_set["stages_run"], (nlohmann::json{"depth", "normals", "echo", "beamform", "noise"}));
}

TEST_F(Cli, DefaultSceneAndPose) {
    // No --scene: the bundled scene from the default preset, sonar pitched 10 deg nose-down.
    for (const char* backend : {"cpu", "vulkan"}) {
        if (std::string(backend) == "vulkan" && run({"info"}).exit_code != 0) continue; // no Vulkan device
        const fs::path out = dir_ / backend;
        const CliRun r = run({"render", "--backend", backend, "--out", out.string()});
        ASSERT_EQ(r.exit_code, 0) << backend << ": " << r.err;
        const auto meta = nlohmann::json::parse(read_text(out / "meta.json"));
        EXPECT_EQ(meta["pose"]["pitch_deg"], 10.0);
        EXPECT_EQ(meta["config"]["name"], "default");
        EXPECT_NE(meta["scene"].get<std::string>().find("default.gltf"), std::string::npos);
        EXPECT_EQ(npy_shape(out / "polar.npy"), (std::vector<std::size_t>{512, 512}));
    }
}

// --backend auto, the default: Vulkan on a GPU, the CPU backend where the device is a CPU implementation
// (lavapipe) or where there is none; meta.json says which and why. Explicit choices are reported too.
TEST_F(Cli, BackendAutoPicksByTheDeviceAndSaysWhy) {
    std::string expected = "cpu";
    if (auto context = vksonar::Context::create(vksonar::ContextOptions{});
        context && context_vulkan(*context) &&
        context_vulkan(*context)->properties.deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU)
        expected = "vulkan";
    const fs::path out = dir_ / "auto";
    const CliRun r = run({"render", "--save", "polar", "--out", out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto meta = nlohmann::json::parse(read_text(out / "meta.json"));
    EXPECT_EQ(meta["backend"], expected);
    const std::string why = meta["backend_reason"].get<std::string>();
    EXPECT_EQ(why.rfind("auto: ", 0), 0u) << why;
    EXPECT_NE(why.find(expected == "cpu" ? "CPU" : "GPU"), std::string::npos) << why;
    const fs::path cpu = dir_ / "explicit";
    ASSERT_EQ(run({"render", "--backend", "cpu", "--save", "polar", "--out", cpu.string()}).exit_code, 0);
    EXPECT_EQ(nlohmann::json::parse(read_text(cpu / "meta.json"))["backend_reason"], "--backend cpu");
    const CliRun bad = run({"render", "--backend", "gpu", "--out", (dir_ / "never").string()});
    EXPECT_EQ(bad.exit_code, 2);
    EXPECT_NE(bad.err.find("--backend: 'gpu' is not a backend (auto, vulkan or cpu)"), std::string::npos) << bad.err;
    // A device the user named (VKSONAR_DEVICE) that is not there is an error, not a quiet fall-back to
    // the CPU (an audit's: a mistyped index on a multi-GPU machine went unnoticed, exit 0).
    for (const char* device : {"abc", "99"}) {
        ::setenv("VKSONAR_DEVICE", device, 1);
        const CliRun named = run({"render", "--save", "polar", "--out", (dir_ / "never").string()});
        ::unsetenv("VKSONAR_DEVICE");
        EXPECT_EQ(named.exit_code, 2) << device << ": " << named.err;
        EXPECT_EQ(named.err_lines().size(), 1u) << named.err;
        EXPECT_NE(named.err.find("VKSONAR_DEVICE names it"), std::string::npos) << named.err;
        EXPECT_FALSE(fs::exists(dir_ / "never"));
    }
}

TEST_F(Cli, TrajectoryWritesOneDirectoryPerLine) {
    write_text(dir_ / "poses.csv", "x,y,z,roll,pitch,yaw\n# comment\n0,0,0,0,0,0\n0.5,0,0,0,0,5\n");
    const fs::path out = dir_ / "traj";
    const CliRun r = run({"render", "--scene", (dir_ / "quad.gltf").string(), "--backend", "cpu", "--set", "bins=32",
                          "--set", "beams=16", "--set", "horizontal_beamwidth=9", "--set", "display.fan_width=64",
                          "--trajectory", (dir_ / "poses.csv").string(), "--out", out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    // Progress must only be shown on a terminal: stderr holds nothing (a 9 deg beam's far field starts
    // at 6 cm: no model warning either).
    EXPECT_EQ(r.err, "");
    EXPECT_TRUE(fs::is_regular_file(out / "frame_000003" / "polar.npy"));
    EXPECT_TRUE(fs::is_regular_file(out / "frame_000004" / "meta.json"));
    EXPECT_FALSE(fs::exists(out / "frame_000001"));
    const auto meta = nlohmann::json::parse(read_text(out / "frame_000004" / "meta.json"));
    EXPECT_EQ(meta["frame_index"], 4);
}

// --frame-index renders one frame of a trajectory again alone, bit for bit: the noise is keyed by
// (seed, frame index), and a single pose used to be frame 0 always (its speckle never matched the
// trajectory's frame). meta.json records what wrote the frame and the scene by content.
TEST_F(Cli, FrameIndexRendersATrajectoryFrameAlone) {
    write_text(dir_ / "poses.csv", "x,y,z,roll,pitch,yaw\n# comment\n0,0,0,0,0,0\n0.5,0,0.2,1,2,5\n");
    const std::vector<std::string> common = {"--scene",   (dir_ / "quad.gltf").string(),
                                             "--backend", "cpu",
                                             "--seed",    "77",
                                             "--set",     "bins=32",
                                             "--set",     "beams=16",
                                             "--set",     "horizontal_beamwidth=9",
                                             "--save",    "polar"};
    auto args = [&](std::vector<std::string> more) {
        std::vector<std::string> all = {"render"};
        all.insert(all.end(), common.begin(), common.end());
        all.insert(all.end(), more.begin(), more.end());
        return all;
    };
    const fs::path traj = dir_ / "traj", alone = dir_ / "alone", frame0 = dir_ / "frame0";
    ASSERT_EQ(run(args({"--trajectory", (dir_ / "poses.csv").string(), "--out", traj.string()})).exit_code, 0);
    const CliRun r = run(args({"--pose", "0.5,0,0.2,1,2,5", "--frame-index", "4", "--out", alone.string()}));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    ASSERT_EQ(run(args({"--pose", "0.5,0,0.2,1,2,5", "--out", frame0.string()})).exit_code, 0);
    const std::string polar = read_text(traj / "frame_000004" / "polar.npy");
    ASSERT_FALSE(polar.empty());
    EXPECT_EQ(read_text(alone / "polar.npy"), polar) << "frame 4 rendered alone differs from the trajectory's";
    EXPECT_NE(read_text(frame0 / "polar.npy"), polar) << "frame 0's noise should differ from frame 4's";
    const auto meta = nlohmann::json::parse(read_text(alone / "meta.json"));
    EXPECT_EQ(meta["frame_index"], 4);
    EXPECT_EQ(meta["vksonar_version"].get<std::string>().empty(), false);
    const auto traj_meta = nlohmann::json::parse(read_text(traj / "frame_000003" / "meta.json"));
    ASSERT_TRUE(meta.contains("scene_fnv1a64"));
    EXPECT_EQ(meta["scene_fnv1a64"].get<std::string>().size(), 16u);
    EXPECT_EQ(meta["scene_fnv1a64"], traj_meta["scene_fnv1a64"]);
    expect_bad_render({"--trajectory", (dir_ / "poses.csv").string(), "--frame-index", "3"},
                      {"--frame-index", "trajectory"});
    expect_bad_render({"--frame-index", "-1"}, {"--frame-index"});
}

// Issue 20: --save selects exactly what is written (meta.json always); without it, the default set.
TEST_F(Cli, SaveWritesExactlyWhatIsListed) {
    auto files_of = [&](const std::vector<std::string>& save) {
        const fs::path out = dir_ / ("save_" + std::to_string(save.size()) + (save.empty() ? "" : save[0]));
        std::vector<std::string> args = {"render",
                                         "--scene",
                                         (dir_ / "quad.gltf").string(),
                                         "--backend",
                                         "cpu",
                                         "--set",
                                         "bins=32",
                                         "--set",
                                         "beams=16",
                                         "--set",
                                         "horizontal_beamwidth=9",
                                         "--set",
                                         "display.fan_width=64",
                                         "--out",
                                         out.string()};
        for (const std::string& item : save) {
            args.push_back("--save");
            args.push_back(item);
        }
        const CliRun r = run(args);
        EXPECT_EQ(r.exit_code, 0) << r.err;
        std::set<std::string> names;
        for (const auto& entry : fs::directory_iterator(out))
            names.insert(entry.path().filename().string());
        return names;
    };
    using Names = std::set<std::string>;
    EXPECT_EQ(files_of({}), (Names{"fan.png", "meta.json", "polar.npy", "polar.png", "polar_u16.npy"}));
    EXPECT_EQ(files_of({"polar"}), (Names{"meta.json", "polar.npy"}));
    EXPECT_EQ(files_of({"depth"}), (Names{"depth.npy", "meta.json"}));
    EXPECT_EQ(files_of({"polar_u16,fan", "polar_png"}), (Names{"fan.png", "meta.json", "polar.png", "polar_u16.npy"}));
    EXPECT_EQ(files_of({"default", "echo"}),
              (Names{"echo.npy", "fan.png", "meta.json", "polar.npy", "polar.png", "polar_u16.npy"}));
}

// Frames are written on a background thread: every line of the trajectory is on disk, in its own
// folder, equal to the same pose rendered alone (the frame index is the line, so the noise is too).
TEST_F(Cli, TrajectoryFramesAreWrittenWholeAndInOrder) {
    std::string poses = "x,y,z,roll,pitch,yaw\n";
    for (int i = 0; i < 8; ++i)
        poses += std::to_string(0.1 * i) + ",0,0,0,0," + std::to_string(i) + "\n";
    write_text(dir_ / "poses.csv", poses);
    const std::vector<std::string> common = {
        "--scene", (dir_ / "quad.gltf").string(), "--backend", "cpu",  "--set", "bins=32", "--set", "beams=16",
        "--set",   "horizontal_beamwidth=9",      "--save",    "polar"};
    std::vector<std::string> args = {"render", "--trajectory", (dir_ / "poses.csv").string(), "--out",
                                     (dir_ / "traj").string()};
    args.insert(args.end(), common.begin(), common.end());
    ASSERT_EQ(run(args).exit_code, 0);
    for (int i = 0; i < 8; ++i) {
        const fs::path frame = dir_ / "traj" / ("frame_00000" + std::to_string(i + 2));
        ASSERT_TRUE(fs::is_regular_file(frame / "polar.npy")) << frame;
        EXPECT_EQ(nlohmann::json::parse(read_text(frame / "meta.json"))["frame_index"], i + 2);
    }
    // Line 6 alone: the single-pose path numbers its frame 0, so render it as a one-line trajectory.
    write_text(dir_ / "one.csv", "x,y,z,roll,pitch,yaw\n\n\n\n\n" + std::to_string(0.1 * 4) + ",0,0,0,0,4\n");
    args = {"render", "--trajectory", (dir_ / "one.csv").string(), "--out", (dir_ / "one").string()};
    args.insert(args.end(), common.begin(), common.end());
    ASSERT_EQ(run(args).exit_code, 0);
    EXPECT_EQ(read_text(dir_ / "one" / "frame_000006" / "polar.npy"),
              read_text(dir_ / "traj" / "frame_000006" / "polar.npy"));
}

// A frame that cannot be written stops the run with one line; the frames before it stay whole.
TEST_F(Cli, AWriteErrorStopsTheTrajectoryAndKeepsWhatWasWritten) {
    std::string poses;
    for (int i = 0; i < 6; ++i)
        poses += "0,0,0,0,0," + std::to_string(i) + "\n";
    write_text(dir_ / "poses.csv", poses);
    fs::create_directories(dir_ / "traj");
    write_text(dir_ / "traj" / "frame_000004", "a file where frame 4's folder goes");
    const CliRun r = run({"render", "--trajectory", (dir_ / "poses.csv").string(), "--out", (dir_ / "traj").string(),
                          "--scene", (dir_ / "quad.gltf").string(), "--backend", "cpu", "--set", "bins=32", "--set",
                          "beams=16", "--set", "horizontal_beamwidth=9", "--save", "polar", "--set", "range_min=6"});
    EXPECT_NE(r.exit_code, 0);
    ASSERT_EQ(r.err_lines().size(), 1u) << r.err;
    EXPECT_NE(r.err.find("frame_000004"), std::string::npos) << r.err;
    for (int line = 1; line <= 3; ++line) {
        const fs::path frame = dir_ / "traj" / ("frame_00000" + std::to_string(line));
        EXPECT_TRUE(fs::is_regular_file(frame / "polar.npy")) << frame;
        EXPECT_TRUE(fs::is_regular_file(frame / "meta.json")) << frame;
    }
    EXPECT_FALSE(fs::exists(dir_ / "traj" / "frame_000005"));
    EXPECT_FALSE(fs::exists(dir_ / "traj" / "frame_000006"));
}

// Issue 28: seeing your own scene. `info SCENE` prints what the scene holds; a scene far out of
// proportion with the range window gets one warning naming scene.scale; --pose frame finds it.
TEST_F(Cli, InfoScaleAndFramingForAStrangersScene) {
    const CliRun info = run({"info", (dir_ / "quad.gltf").string()});
    ASSERT_EQ(info.exit_code, 0) << info.err;
    EXPECT_NE(info.out.find("x 10.000 .. 10.000, y -5.000 .. 5.000, z -3.000 .. 3.000"), std::string::npos) << info.out;
    EXPECT_NE(info.out.find("triangles: 2 drawn"), std::string::npos) << info.out;
    EXPECT_NE(info.out.find("extensions: none"), std::string::npos) << info.out;
    EXPECT_EQ(run({"info", (dir_ / "none.gltf").string()}).exit_code, 2);
    // Without a scene: the device, and the backend render's default (auto) runs on it, as meta.json says
    const CliRun device = run({"info"});
    if (device.exit_code == 0) { // (a machine without a Vulkan device exits 1)
        EXPECT_NE(device.out.find("Vulkan: "), std::string::npos) << device.out;
        const bool cpu_device = device.out.find(", CPU)") != std::string::npos;
        EXPECT_NE(device.out.find(cpu_device ? "render --backend auto: cpu (auto: the Vulkan device is a CPU"
                                             : "render --backend auto: vulkan (auto: a GPU"),
                  std::string::npos)
            << device.out;
    }
    const CliRun harbour = run({"info", VKSONAR_ASSET_DIR "/scenes/harbour.gltf"});
    EXPECT_NE(harbour.out.find("objects: 12 in 5 classes: seabed (1), wall (1), pier (1), piling (8), crate (1)"),
              std::string::npos)
        << harbour.out;

    // The quad as if modelled in millimetres (x 1000: 11.7 km across): one warning naming the fix.
    const std::vector<std::string> common = {
        "render",   "--scene", (dir_ / "quad.gltf").string(), "--backend", "cpu",         "--set",  "bins=32", "--set",
        "beams=16", "--set",   "horizontal_beamwidth=9",      "--set",     "range_min=6", "--save", "polar"};
    auto with = [&](std::vector<std::string> extra, const char* out) {
        std::vector<std::string> args = common;
        args.insert(args.end(), extra.begin(), extra.end());
        args.push_back("--out");
        args.push_back((dir_ / out).string());
        return run(args);
    };
    const CliRun huge = with({"--set", "scene.scale=1000"}, "huge");
    ASSERT_EQ(huge.exit_code, 0) << huge.err;
    ASSERT_EQ(huge.err_lines().size(), 1u) << huge.err;
    EXPECT_NE(huge.err.find("scene.scale=0.001"), std::string::npos) << huge.err;
    const CliRun fine = with({"--set", "scene.scale=1"}, "fine");
    EXPECT_EQ(fine.err_lines().size(), 0u) << fine.err;

    // Scaled to 10 km away the quad is out of view from the origin; --pose frame brings it in.
    auto energy = [&](const char* out) {
        const std::string bytes = read_text(dir_ / out / "polar.npy");
        const std::size_t header = bytes.find('\n') + 1;
        double total = 0;
        for (std::size_t i = header; i + 4 <= bytes.size(); i += 4) {
            float v;
            std::memcpy(&v, bytes.data() + i, 4);
            total += v;
        }
        return total;
    };
    const CliRun framed =
        with({"--set", "scene.scale=1000", "--set", "effects.ambient_noise=off", "--pose", "frame"}, "framed");
    ASSERT_EQ(framed.exit_code, 0) << framed.err;
    EXPECT_NE(framed.err.find("--pose frame: "), std::string::npos) << framed.err;
    const CliRun unframed = with({"--set", "scene.scale=1000", "--set", "effects.ambient_noise=off"}, "unframed");
    ASSERT_EQ(unframed.exit_code, 0) << unframed.err;
    EXPECT_GT(energy("framed"), 0.0);
    EXPECT_EQ(energy("unframed"), 0.0);
}

// bench load on a small grid: every form loads (gltfpack's two where it is installed) and says so.
TEST_F(Cli, BenchLoadTimesEachForm) {
    const CliRun r = run({"bench", "load", "--grid", "40"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("| plain (float) |"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("| quantized (KHR_mesh_quantization) |"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("| meshopt (EXT_meshopt_compression) |"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("| peak RSS growth MiB | peak / arrays |"), std::string::npos) << r.out;
    EXPECT_EQ(run({"bench", "load", "--grid", "1"}).exit_code, 2);
}

TEST_F(Cli, QualityPresetSetsTheAccuracyKnobsAndSetStillWins) {
    const fs::path out = dir_ / "accurate";
    const CliRun r = run({"render", "--scene", (dir_ / "quad.gltf").string(), "--backend", "cpu", "--set", "bins=32",
                          "--set", "beams=16", "--set", "horizontal_beamwidth=9", "--quality", "accurate", "--set",
                          "accuracy.rows_per_vfov=96", "--out", out.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto accuracy = nlohmann::json::parse(read_text(out / "meta.json"))["config"]["accuracy"];
    EXPECT_EQ(accuracy["pixels_per_beam"], 4.0); // from the quality preset
    EXPECT_EQ(accuracy["max_slice"], 15.0);
    EXPECT_EQ(accuracy["rows_per_vfov"], 96); // --set is applied after --quality

    const CliRun bad = run(
        {"render", "--scene", (dir_ / "quad.gltf").string(), "--quality", "ultra", "--out", (dir_ / "bad").string()});
    EXPECT_EQ(bad.exit_code, 2);
    ASSERT_EQ(bad.err_lines().size(), 1u) << bad.err;
    EXPECT_NE(bad.err.find("'ultra'"), std::string::npos) << bad.err;
    EXPECT_FALSE(fs::exists(dir_ / "bad" / "meta.json"));
}

} // namespace
