// Boxes of the labelled objects (src/host/boxes.h) and `vksonar export coco` (src/cli/export_cmd.cpp):
// the box finder on hand-made labels, where every extent, count and energy is known; then the CLI on
// the bundled scene, its boxes.json against the instance.npy and instance_fan.npy of the same frame, the
// COCO file against boxes.json and meta.json, and the export's errors (one line, exit 2, OUT untouched).
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli/npy_read.h"
#include "cli_support.h"
#include "host/boxes.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

using vksonar::testing::fresh_test_dir;
using vksonar::testing::quote;
using vksonar::testing::read_text;
using vksonar::testing::remove_test_dir;
using vksonar::testing::write_text;

// ---- the box finder on hand-made labels ------------------------------------------------------------

// A 5-bin x 4-beam frame with labels: `ids` row by row (bin 0 first), clean = 2 and fraction = 0.25
// everywhere, except where `clean` says otherwise.
vksonar::Frame labelled_frame(const std::vector<std::uint16_t>& ids, std::uint16_t class_offset = 10) {
    vksonar::Frame f;
    f.bins = 5;
    f.beams = 4;
    f.frame_index = 42;
    f.instance = ids;
    f.object_class.resize(ids.size());
    for (std::size_t i = 0; i < ids.size(); ++i)
        f.object_class[i] = ids[i] ? static_cast<std::uint16_t>(ids[i] + class_offset) : 0;
    f.instance_fraction.assign(ids.size(), 0.25f);
    f.clean.assign(ids.size(), 2.0f);
    return f;
}

TEST(Boxes, ExtentsCellsAndEnergyOfHandMadeLabels) {
    // clang-format off
    vksonar::Frame f = labelled_frame({
        0, 0, 0, 0,  // bin 0
        0, 0, 7, 0,  // bin 1
        0, 7, 7, 3,  // bin 2: instance 7 reaches its first beam only in its last bin
        0, 0, 0, 3,  // bin 3
        0, 0, 0, 0,  // bin 4
    });
    // clang-format on
    f.clean[2 * 4 + 1] = 10.0f;            // one of instance 7's cells is louder ...
    f.instance_fraction[2 * 4 + 2] = 0.5f; // ... and in another it owns half the energy
    // A 6 x 3 fan image: instance 7 on three pixels, 3 on one, and an id no cell has (ignored).
    // clang-format off
    const std::vector<std::uint16_t> fan = {
        0, 0, 0, 7, 0, 0,
        0, 7, 0, 0, 0, 9,
        0, 0, 7, 0, 3, 0,
    };
    // clang-format on
    vksonar::host::BoxFinder finder;
    std::vector<vksonar::host::Box> boxes;
    finder.find(f, fan, 6, 3, boxes);
    ASSERT_EQ(boxes.size(), 2u);
    const auto& b3 = boxes[0];
    const auto& b7 = boxes[1];
    EXPECT_EQ(b3.instance_id, 3);
    EXPECT_EQ(b3.class_id, 13);
    EXPECT_EQ(b3.bin_first, 2u);
    EXPECT_EQ(b3.bin_last, 3u);
    EXPECT_EQ(b3.beam_first, 3u);
    EXPECT_EQ(b3.beam_last, 3u);
    EXPECT_EQ(b3.cells, 2u);
    EXPECT_DOUBLE_EQ(b3.energy, 2 * 2.0 * 0.25);
    EXPECT_TRUE(b3.at_window_edge); // the last beam
    EXPECT_EQ(b3.fan_pixels, 1u);
    EXPECT_EQ(b3.x0, 4u);
    EXPECT_EQ(b3.x1, 4u);
    EXPECT_EQ(b3.y0, 2u);
    EXPECT_EQ(b3.y1, 2u);

    EXPECT_EQ(b7.instance_id, 7);
    EXPECT_EQ(b7.class_id, 17);
    EXPECT_EQ(b7.bin_first, 1u);
    EXPECT_EQ(b7.bin_last, 2u);
    EXPECT_EQ(b7.beam_first, 1u);
    EXPECT_EQ(b7.beam_last, 2u);
    EXPECT_EQ(b7.cells, 3u);
    EXPECT_DOUBLE_EQ(b7.energy, 10.0 * 0.25 + 2.0 * 0.25 + 2.0 * 0.5);
    EXPECT_FALSE(b7.at_window_edge);
    EXPECT_EQ(b7.fan_pixels, 3u);
    EXPECT_EQ(b7.x0, 1u);
    EXPECT_EQ(b7.x1, 3u);
    EXPECT_EQ(b7.y0, 0u);
    EXPECT_EQ(b7.y1, 2u);

    // The next frame reuses the finder: nothing of the first frame's boxes may carry over.
    // clang-format off
    vksonar::Frame g = labelled_frame({
        0, 0, 0, 0,
        0, 0, 0, 0,
        0, 0, 0, 0,
        0, 0, 0, 0,
        7, 0, 0, 0,
    });
    // clang-format on
    finder.find(g, {}, 0, 0, boxes);
    ASSERT_EQ(boxes.size(), 1u);
    EXPECT_EQ(boxes[0].instance_id, 7);
    EXPECT_EQ(boxes[0].cells, 1u);
    EXPECT_EQ(boxes[0].bin_first, 4u);
    EXPECT_EQ(boxes[0].beam_last, 0u);
    EXPECT_EQ(boxes[0].fan_pixels, 0u); // no fan image given
    EXPECT_TRUE(boxes[0].at_window_edge);

    // A frame without labels has no boxes.
    vksonar::Frame unlabelled;
    unlabelled.bins = 5;
    unlabelled.beams = 4;
    finder.find(unlabelled, fan, 6, 3, boxes);
    EXPECT_TRUE(boxes.empty());
}

// The finder takes runs of one id along a bin (and along a fan row) at a time. Random labels made of
// runs, of single cells and of ids that come back along a row, against the box of each id worked out
// here cell by cell; the energy in the same cell order, so it must match to the bit.
TEST(Boxes, RunsOfOneIdGiveTheBoxesOfACellByCellPass) {
    std::uint64_t state = 0x9E3779B97F4A7C15ull;
    auto next = [&](std::uint32_t n) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return static_cast<std::uint32_t>((state >> 33) % n);
    };
    vksonar::Frame f;
    f.bins = 37;
    f.beams = 53;
    const std::size_t cells = std::size_t(f.bins) * f.beams;
    for (std::size_t i = 0; i < cells;) { // runs of 1 to 9 cells of id 0 to 5, crossing bins
        const std::uint16_t id = static_cast<std::uint16_t>(next(6));
        for (std::uint32_t n = 1 + next(9); n > 0 && i < cells; --n, ++i)
            f.instance.push_back(id);
    }
    f.object_class.resize(cells);
    f.instance_fraction.resize(cells);
    f.clean.resize(cells);
    for (std::size_t i = 0; i < cells; ++i) {
        f.object_class[i] = static_cast<std::uint16_t>(f.instance[i] ? 100 + f.instance[i] : 0);
        f.instance_fraction[i] = 0.1f + 0.01f * static_cast<float>(next(90));
        f.clean[i] = 1e-3f * static_cast<float>(1 + next(100000));
    }
    const std::uint32_t width = 41, height = 23;
    std::vector<std::uint16_t> fan(std::size_t(width) * height);
    for (std::size_t p = 0; p < fan.size();) {
        const std::uint16_t id = static_cast<std::uint16_t>(next(7)); // 6: an id no cell has
        for (std::uint32_t n = 1 + next(12); n > 0 && p < fan.size(); --n, ++p)
            fan[p] = id;
    }
    std::map<std::uint16_t, vksonar::host::Box> expected;
    for (std::uint32_t k = 0; k < f.bins; ++k) {
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            const std::size_t i = std::size_t(k) * f.beams + j;
            const std::uint16_t id = f.instance[i];
            if (id == 0) continue;
            auto [it, made] = expected.try_emplace(id);
            vksonar::host::Box& b = it->second;
            if (made) {
                b.instance_id = id;
                b.class_id = f.object_class[i];
                b.bin_first = k;
                b.beam_first = b.beam_last = j;
            }
            b.bin_last = k;
            b.beam_first = std::min(b.beam_first, j);
            b.beam_last = std::max(b.beam_last, j);
            ++b.cells;
            b.energy += double(f.clean[i]) * double(f.instance_fraction[i]);
        }
    }
    for (std::uint32_t y = 0; y < height; ++y) {
        for (std::uint32_t x = 0; x < width; ++x) {
            const auto it = expected.find(fan[std::size_t(y) * width + x]);
            if (it == expected.end()) continue;
            vksonar::host::Box& b = it->second;
            if (b.fan_pixels == 0) {
                b.x0 = b.x1 = x;
                b.y0 = y;
            }
            b.x0 = std::min(b.x0, x);
            b.x1 = std::max(b.x1, x);
            b.y1 = y;
            ++b.fan_pixels;
        }
    }
    vksonar::host::BoxFinder finder;
    std::vector<vksonar::host::Box> boxes;
    finder.find(f, fan, width, height, boxes);
    ASSERT_EQ(boxes.size(), expected.size());
    ASSERT_EQ(expected.size(), 5u);
    // (class, polar extent, cells, energy, fan pixels, fan extent)
    const auto fields = [](const vksonar::host::Box& b) {
        return std::tuple(b.class_id, b.bin_first, b.bin_last, b.beam_first, b.beam_last, b.cells, b.energy,
                          b.fan_pixels, b.x0, b.x1, b.y0, b.y1);
    };
    for (const vksonar::host::Box& b : boxes)
        EXPECT_EQ(fields(b), fields(expected.at(b.instance_id))) << "instance " << b.instance_id;
}

TEST(Boxes, JsonText) {
    vksonar::Frame f = labelled_frame({0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}, 0);
    vksonar::host::BoxFinder finder;
    std::vector<vksonar::host::Box> boxes;
    finder.find(f, {}, 0, 0, boxes);
    const json doc = json::parse(vksonar::host::boxes_json_text(f, 640, 480, boxes, {"rock", "pipe"}));
    EXPECT_EQ(doc["frame_index"], 42);
    EXPECT_EQ(doc["image_size"], (json{{"width", 640}, {"height", 480}}));
    EXPECT_EQ(doc["polar_size"], (json{{"bins", 5}, {"beams", 4}}));
    ASSERT_EQ(doc["boxes"].size(), 1u);
    const json& b = doc["boxes"][0];
    EXPECT_EQ(b["instance_id"], 2);
    EXPECT_EQ(b["class_id"], 2);
    EXPECT_EQ(b["class"], "pipe");
    EXPECT_EQ(b["polar"], (json{{"bin_first", 1}, {"bin_last", 1}, {"beam_first", 1}, {"beam_last", 1}}));
    EXPECT_EQ(b["cells"], 1);
    EXPECT_DOUBLE_EQ(b["energy"].get<double>(), 0.5);
    EXPECT_TRUE(b["fan"].is_null());
    EXPECT_EQ(b["at_window_edge"], false);
}

// ---- the CLI: boxes.json of a render, and export coco ----------------------------------------------

using vksonar::testing::CliRun;

class BoxesCli : public ::testing::Test {
protected:
    void SetUp() override { dir_ = fresh_test_dir("vksonar_boxes_test_"); }
    void TearDown() override { remove_test_dir(dir_); }

    CliRun run(const std::vector<std::string>& args) const { return vksonar::testing::run_cli(dir_, args); }

    // The bundled scene along three poses, small and on the CPU backend.
    fs::path render_run(const std::string& save = "fan,labels") const {
        write_text(dir_ / "poses.csv", "x,y,z,roll,pitch,yaw\n0,0,0,0,10,0\n0.5,0.4,0,0,10,6\n1,-0.3,0.2,0,12,-5\n");
        std::string name = "run_" + save;
        std::replace(name.begin(), name.end(), ',', '_');
        const fs::path out = dir_ / name;
        const CliRun r =
            run({"render", "--backend", "cpu", "--trajectory", (dir_ / "poses.csv").string(), "--save", save, "--set",
                 "bins=96", "--set", "beams=48", "--set", "display.fan_width=400", "--out", out.string()});
        EXPECT_EQ(r.exit_code, 0) << r.err;
        return out;
    }

    // An export that must fail: exit 2, one stderr line `error: ...` containing `expected`.
    void expect_bad_export(const std::vector<std::string>& args, const std::string& expected) const {
        std::vector<std::string> full = {"export"};
        full.insert(full.end(), args.begin(), args.end());
        const CliRun r = run(full);
        EXPECT_EQ(r.exit_code, 2) << r.err;
        EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
        EXPECT_EQ(r.err.rfind("error: ", 0), 0u) << r.err;
        EXPECT_NE(r.err.find(expected), std::string::npos) << "expected '" << expected << "' in: " << r.err;
    }

    fs::path dir_;
};

// The width and height in a PNG's IHDR chunk (bytes 16..23, big-endian).
std::pair<std::uint32_t, std::uint32_t> png_size(const fs::path& path) {
    const std::string bytes = read_text(path);
    EXPECT_GE(bytes.size(), 24u) << path;
    if (bytes.size() < 24) return {0, 0};
    auto be32 = [&](std::size_t at) {
        std::uint32_t v = 0;
        for (std::size_t i = 0; i < 4; ++i)
            v = v << 8 | static_cast<unsigned char>(bytes[at + i]);
        return v;
    };
    return {be32(16), be32(20)};
}

TEST_F(BoxesCli, BoxesJsonIsTightOnTheLabelsAndCocoMatchesIt) {
    const fs::path run_dir = render_run();
    const std::vector<std::string> frames = {"frame_000002", "frame_000003", "frame_000004"};
    std::size_t total_boxes = 0;
    std::map<std::string, json> boxes_of;
    for (const std::string& name : frames) {
        const fs::path frame = run_dir / name;
        ASSERT_TRUE(fs::is_regular_file(frame / "boxes.json")) << frame;
        const json doc = json::parse(read_text(frame / "boxes.json"));
        boxes_of[name] = doc;
        const auto instance = vksonar::cli::read_npy((frame / "instance.npy").string());
        const auto instance_fan = vksonar::cli::read_npy((frame / "instance_fan.npy").string());
        ASSERT_EQ(instance.shape.size(), 2u);
        const std::size_t bins = instance.shape[0], beams = instance.shape[1];
        EXPECT_EQ(doc["polar_size"], (json{{"bins", bins}, {"beams", beams}}));
        const std::size_t width = doc["image_size"]["width"], height = doc["image_size"]["height"];
        EXPECT_EQ(png_size(frame / "fan.png"), std::make_pair(std::uint32_t(width), std::uint32_t(height)));
        ASSERT_EQ(instance_fan.shape, (std::vector<std::size_t>{height, width}));
        EXPECT_EQ(doc["frame_index"], std::stoul(name.substr(6)));

        // Every instance in instance.npy has exactly one box, in increasing id.
        std::vector<std::uint64_t> ids;
        for (double v : instance.values)
            if (v != 0) ids.push_back(static_cast<std::uint64_t>(v));
        std::sort(ids.begin(), ids.end());
        ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
        std::vector<std::uint64_t> box_ids;
        for (const json& b : doc["boxes"])
            box_ids.push_back(b["instance_id"]);
        EXPECT_EQ(box_ids, ids) << name;
        EXPECT_GE(ids.size(), 3u) << name << ": the bundled scene shows several objects";
        total_boxes += doc["boxes"].size();

        for (const json& b : doc["boxes"]) {
            const std::uint64_t id = b["instance_id"];
            const json& p = b["polar"];
            const std::size_t k0 = p["bin_first"], k1 = p["bin_last"], j0 = p["beam_first"], j1 = p["beam_last"];
            ASSERT_LE(k0, k1);
            ASSERT_LE(j0, j1);
            ASSERT_LT(k1, bins);
            ASSERT_LT(j1, beams);
            // Contains every cell of the instance, and each bound is attained by one of them.
            std::uint64_t cells = 0;
            bool at_k0 = false, at_k1 = false, at_j0 = false, at_j1 = false;
            for (std::size_t k = 0; k < bins; ++k)
                for (std::size_t j = 0; j < beams; ++j) {
                    if (instance.values[k * beams + j] != static_cast<double>(id)) continue;
                    ++cells;
                    EXPECT_TRUE(k >= k0 && k <= k1 && j >= j0 && j <= j1)
                        << name << " instance " << id << ": cell (" << k << ", " << j << ") outside its box";
                    at_k0 = at_k0 || k == k0;
                    at_k1 = at_k1 || k == k1;
                    at_j0 = at_j0 || j == j0;
                    at_j1 = at_j1 || j == j1;
                }
            EXPECT_TRUE(at_k0 && at_k1 && at_j0 && at_j1) << name << " instance " << id << ": box not tight";
            EXPECT_EQ(b["cells"], cells) << name << " instance " << id;
            EXPECT_GT(b["energy"].get<double>(), 0.0) << name << " instance " << id;
            EXPECT_EQ(b["at_window_edge"], k0 == 0 || j0 == 0 || k1 + 1 == bins || j1 + 1 == beams);

            // The fan box: inside the image, and exactly the extent of the instance in instance_fan.npy.
            std::uint64_t pixels = 0;
            std::size_t x0 = width, y0 = height, x1 = 0, y1 = 0;
            for (std::size_t y = 0; y < height; ++y)
                for (std::size_t x = 0; x < width; ++x)
                    if (instance_fan.values[y * width + x] == static_cast<double>(id)) {
                        ++pixels;
                        x0 = std::min(x0, x);
                        y0 = std::min(y0, y);
                        x1 = std::max(x1, x);
                        y1 = std::max(y1, y);
                    }
            if (pixels == 0) {
                EXPECT_TRUE(b["fan"].is_null()) << name << " instance " << id;
                continue;
            }
            const json& fan = b["fan"];
            ASSERT_TRUE(fan.is_object()) << name << " instance " << id;
            EXPECT_EQ(fan, (json{{"x0", x0}, {"y0", y0}, {"x1", x1}, {"y1", y1}, {"pixels", pixels}}))
                << name << " instance " << id;
            EXPECT_LT(fan["x1"].get<std::size_t>(), width);
            EXPECT_LT(fan["y1"].get<std::size_t>(), height);
        }
    }

    // export coco
    const fs::path coco_path = dir_ / "coco.json";
    const CliRun r = run({"export", "coco", run_dir.string(), coco_path.string()});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const json coco = json::parse(read_text(coco_path));
    ASSERT_EQ(coco["images"].size(), 3u);
    const json meta = json::parse(read_text(run_dir / frames[0] / "meta.json"));
    json categories = json::array();
    for (const json& c : meta["objects"]["classes"])
        categories.push_back({{"id", c["id"]}, {"name", c["name"]}});
    EXPECT_EQ(coco["categories"], categories);
    EXPECT_GE(categories.size(), 3u);

    std::size_t with_fan = 0;
    for (const auto& [name, doc] : boxes_of)
        for (const json& b : doc["boxes"])
            with_fan += b["fan"].is_null() ? 0 : 1;
    EXPECT_EQ(with_fan, total_boxes) << "every object of this scene and size covers fan pixels";
    ASSERT_EQ(coco["annotations"].size(), with_fan);

    std::map<std::uint64_t, std::string> frame_of_image;
    for (std::size_t i = 0; i < 3; ++i) {
        const json& image = coco["images"][i];
        EXPECT_EQ(image["file_name"], frames[i] + "/fan.png");
        EXPECT_TRUE(fs::is_regular_file(run_dir / image["file_name"].get<std::string>()));
        EXPECT_EQ(image["width"], boxes_of[frames[i]]["image_size"]["width"]);
        EXPECT_EQ(image["height"], boxes_of[frames[i]]["image_size"]["height"]);
        EXPECT_GT(image["id"].get<std::uint64_t>(), 0u);
        frame_of_image[image["id"]] = frames[i];
    }
    ASSERT_EQ(frame_of_image.size(), 3u) << "image ids are unique";
    std::vector<std::uint64_t> annotation_ids;
    for (const json& a : coco["annotations"]) {
        annotation_ids.push_back(a["id"]);
        ASSERT_EQ(frame_of_image.count(a["image_id"]), 1u) << a.dump();
        const json& doc = boxes_of[frame_of_image[a["image_id"]]];
        const auto box = std::find_if(doc["boxes"].begin(), doc["boxes"].end(),
                                      [&](const json& b) { return b["instance_id"] == a["instance_id"]; });
        ASSERT_NE(box, doc["boxes"].end()) << a.dump();
        const json& fan = (*box)["fan"];
        const std::uint64_t x0 = fan["x0"], y0 = fan["y0"], x1 = fan["x1"], y1 = fan["y1"];
        EXPECT_EQ(a["bbox"], (json{x0, y0, x1 - x0 + 1, y1 - y0 + 1})) << a.dump();
        EXPECT_EQ(a["area"], (x1 - x0 + 1) * (y1 - y0 + 1));
        EXPECT_EQ(a["category_id"], (*box)["class_id"]);
        EXPECT_EQ(a["iscrowd"], 0);
        const std::uint64_t category = a["category_id"];
        EXPECT_TRUE(
            std::any_of(categories.begin(), categories.end(), [&](const json& c) { return c["id"] == category; }));
    }
    std::sort(annotation_ids.begin(), annotation_ids.end());
    EXPECT_EQ(std::adjacent_find(annotation_ids.begin(), annotation_ids.end()), annotation_ids.end());
    EXPECT_GT(annotation_ids.front(), 0u) << "COCO tools read id 0 as none";

    // A single frame's folder is a run of one image, its fan.png beside boxes.json.
    const fs::path one = dir_ / "one.json";
    ASSERT_EQ(run({"export", "coco", (run_dir / frames[1]).string(), one.string()}).exit_code, 0);
    const json single = json::parse(read_text(one));
    ASSERT_EQ(single["images"].size(), 1u);
    EXPECT_EQ(single["images"][0]["file_name"], "fan.png");
    EXPECT_EQ(single["annotations"].size(), boxes_of[frames[1]]["boxes"].size());

    // ---- errors: one line naming the path, exit 2, OUT neither written nor replaced ----
    const fs::path kept = dir_ / "kept.json";
    write_text(kept, "{\"old\": true}\n");
    expect_bad_export({"coco", (dir_ / "no_such_run").string(), kept.string()}, "no_such_run: no such folder");
    write_text(dir_ / "run.h5", "not a folder");
    expect_bad_export({"coco", (dir_ / "run.h5").string(), kept.string()},
                      "run.h5: not a folder (export reads a render's frame folders");
    fs::create_directories(dir_ / "empty");
    expect_bad_export({"coco", (dir_ / "empty").string(), kept.string()}, "empty: no boxes.json");
    expect_bad_export({"coco", run_dir.string(), (dir_ / "missing" / "out.json").string()}, "no folder");
    EXPECT_FALSE(fs::exists(dir_ / "missing"));
    fs::create_directories(dir_ / "a_folder");
    expect_bad_export({"coco", run_dir.string(), (dir_ / "a_folder").string()}, "a_folder: is a directory");
    expect_bad_export({"yolo", run_dir.string(), kept.string()}, "unknown format 'yolo'");
    // OUT over a file the export reads (an audit's: written over boxes.json it broke the next export)
    for (const char* input : {"boxes.json", "meta.json", "fan.png"}) {
        const std::string before = read_text(run_dir / frames[1] / input);
        expect_bad_export({"coco", run_dir.string(), (run_dir / frames[1] / input).string()},
                          "a file of the run it reads");
        EXPECT_EQ(read_text(run_dir / frames[1] / input), before) << input;
    }
    expect_bad_export({"coco", run_dir.string()}, "needs RUN and OUT.json");

    // A run rendered without labels; a frame of a labelled run that lost its boxes.json.
    const fs::path plain = render_run("fan");
    expect_bad_export({"coco", plain.string(), kept.string()}, "no boxes.json");
    // A frame folder cut off before any of its files was skipped; it is refused.
    fs::create_directories(run_dir / "frame_999999");
    expect_bad_export({"coco", run_dir.string(), kept.string()},
                      "frame_999999: a frame folder without meta.json and boxes.json");
    fs::remove(run_dir / "frame_999999");
    fs::remove(run_dir / frames[2] / "boxes.json");
    expect_bad_export({"coco", run_dir.string(), kept.string()}, frames[2] + ": meta.json but no boxes.json");
    // A frame without its image.
    fs::remove(run_dir / frames[1] / "fan.png");
    expect_bad_export({"coco", (run_dir / frames[1]).string(), kept.string()}, frames[1] + ": no fan.png");
    // A broken boxes.json is named.
    write_text(run_dir / frames[0] / "boxes.json", "{\"frame_index\": ");
    expect_bad_export({"coco", (run_dir / frames[0]).string(), kept.string()}, "boxes.json: not valid JSON");

    EXPECT_EQ(read_text(kept), "{\"old\": true}\n");
    for (const auto& entry : fs::directory_iterator(dir_))
        EXPECT_NE(entry.path().filename().string().rfind(".~", 0), 0u) << "temporary left: " << entry.path();
}

} // namespace

namespace {

// --save flow along a 4-frame trajectory: flow.npy [bins, beams, 2] in every frame; finite exactly on
// labelled cells that stay in view; the last frame (no next one) all NaN; two shards write the same
// flow as the whole run (a shard renders the next shard's first frame for its last frame's flow); and
// flow without a trajectory, or into a bag, is refused with one line.
TEST_F(BoxesCli, FlowAlongATrajectoryAndAcrossShards) {
    write_text(dir_ / "fwd.csv", "0,0,0,0,10,0\n0.3,0,0,0,10,0\n0.6,0,0,0,10,2\n0.9,0,0,0,10,4\n");
    const std::vector<std::string> common = {
        "render", "--backend", "cpu",    "--trajectory", (dir_ / "fwd.csv").string(), "--set", "bins=96",
        "--set",  "beams=48",  "--save", "labels,flow"};
    auto render = [&](const fs::path& out, const std::vector<std::string>& extra) {
        std::vector<std::string> args = common;
        args.insert(args.end(), extra.begin(), extra.end());
        args.insert(args.end(), {"--out", out.string()});
        const CliRun r = run(args);
        EXPECT_EQ(r.exit_code, 0) << r.err;
    };
    render(dir_ / "whole", {});
    render(dir_ / "shard0", {"--shard", "0/2"});
    render(dir_ / "shard1", {"--shard", "1/2"});
    for (int k = 1; k <= 4; ++k) {
        char name[32];
        std::snprintf(name, sizeof name, "frame_%06d", k);
        const auto flow = vksonar::cli::read_npy((dir_ / "whole" / name / "flow.npy").string());
        const auto instance = vksonar::cli::read_npy((dir_ / "whole" / name / "instance.npy").string());
        ASSERT_EQ(flow.shape, (std::vector<std::size_t>{96, 48, 2}));
        std::size_t labelled = 0, finite = 0, finite_unlabelled = 0;
        for (std::size_t i = 0; i < instance.values.size(); ++i) {
            const bool has = std::isfinite(flow.values[2 * i]) && std::isfinite(flow.values[2 * i + 1]);
            labelled += instance.values[i] != 0;
            finite += has;
            finite_unlabelled += has && instance.values[i] == 0;
        }
        EXPECT_EQ(finite_unlabelled, 0u) << name;
        if (k < 4)
            EXPECT_GT(finite, labelled / 2) << name; // forward 0.3 m: nearly everything stays in view
        else
            EXPECT_EQ(finite, 0u) << name; // the trajectory's last frame has no next one
        const fs::path shard = dir_ / (k <= 2 ? "shard0" : "shard1") / name / "flow.npy";
        const auto sharded = vksonar::cli::read_npy(shard.string());
        ASSERT_EQ(sharded.values.size(), flow.values.size());
        for (std::size_t i = 0; i < flow.values.size(); ++i)
            ASSERT_TRUE(flow.values[i] == sharded.values[i] ||
                        (std::isnan(flow.values[i]) && std::isnan(sharded.values[i])))
                << name << " value " << i;
    }
    const CliRun single = run({"render", "--backend", "cpu", "--save", "flow", "--out", (dir_ / "one").string()});
    EXPECT_EQ(single.exit_code, 2);
    EXPECT_NE(single.err.find("--trajectory"), std::string::npos) << single.err;
    const CliRun bag = run({"render", "--backend", "cpu", "--trajectory", (dir_ / "fwd.csv").string(), "--save",
                            "polar,flow", "--out", (dir_ / "run.mcap").string()});
    EXPECT_EQ(bag.exit_code, 2);
    EXPECT_NE(bag.err.find("flow"), std::string::npos) << bag.err;
}

} // namespace
