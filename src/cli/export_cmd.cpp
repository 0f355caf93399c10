// `vksonar export coco RUN OUT.json`: the boxes of a run's frames (render --save fan,labels writes
// boxes.json beside fan.png, docs/datasets.md "Boxes and COCO export") as one COCO detection file.
//
// Every input is read and checked before OUT is touched, and OUT is written under a temporary name in
// its folder and renamed, so an error never leaves half a file (nor replaces a good one).
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/frame_files.h"
#include "core/json_depth.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

using json = nlohmann::ordered_json;

constexpr const char* kUsage =
    "usage: vksonar export coco RUN OUT.json\n"
    "\n"
    "  RUN       a render's output folder: its frame folders (frame_NNNNNN/, from --trajectory) or a single\n"
    "            frame's folder, rendered with --save fan,labels (boxes.json, fan.png and meta.json per frame)\n"
    "  OUT.json  the COCO detection file: one image per frame (file_name: its fan.png relative to RUN),\n"
    "            the scene's classes as categories, one annotation per box that has fan pixels (bbox in fan\n"
    "            pixels, plus instance_id). Written whole or not at all (docs/datasets.md)\n";

struct FrameFolder {
    fs::path dir;
    std::string file_name; // fan.png relative to RUN
    json boxes;            // boxes.json
    std::uint64_t frame_index = 0;
};

json read_json(const fs::path& path) {
    std::ifstream file(path, std::ios::binary);
    if (!file) throw BadInput(path.string() + ": cannot open");
    std::stringstream text;
    text << file.rdbuf();
    if (json_nests_too_deep(text.str()))
        throw BadInput(path.string() + ": not valid JSON (nests deeper than " + std::to_string(kMaxJsonDepth) +
                       " levels)");
    try {
        return json::parse(text.str());
    } catch (const json::exception& e) {
        throw BadInput(path.string() + ": not valid JSON (" + e.what() + ")");
    }
}

// A member of an object that must be an unsigned integer; the error names the file and the key.
std::uint64_t unsigned_at(const json& object, const char* key, const fs::path& file) {
    if (!object.is_object() || !object.contains(key) || !object[key].is_number_unsigned())
        throw BadInput(file.string() + ": '" + key + "' is missing or not an unsigned integer");
    return object[key].get<std::uint64_t>();
}

// The scene's classes from meta.json ("objects": {"classes": [{"id", "name"}, ...]}).
json classes_of(const fs::path& meta_path) {
    const json meta = read_json(meta_path);
    if (!meta.is_object() || !meta.contains("objects") || !meta["objects"].is_object() ||
        !meta["objects"].contains("classes") || !meta["objects"]["classes"].is_array())
        throw BadInput(meta_path.string() + ": no objects.classes (not a vksonar meta.json?)");
    json categories = json::array();
    for (const json& c : meta["objects"]["classes"]) {
        if (!c.is_object() || !c.contains("name") || !c["name"].is_string())
            throw BadInput(meta_path.string() + ": a class without a name");
        categories.push_back({{"id", unsigned_at(c, "id", meta_path)}, {"name", c["name"].get<std::string>()}});
    }
    return categories;
}

// The frame folders of RUN: RUN itself when it holds boxes.json, else its sub-folders that hold one,
// in frame order. A frame folder with only one of boxes.json and meta.json, or (a frame_NNNNNN folder)
// with neither, is refused: it is an unfinished frame (meta.json is written last) or a frame rendered
// without labels.
std::vector<FrameFolder> frame_folders(const fs::path& run) {
    std::error_code ec;
    std::vector<FrameFolder> frames;
    if (fs::is_regular_file(run / kBoxesJson, ec)) {
        frames.push_back({run, std::string(kFanPng), {}, 0});
    } else {
        bool any_boxes = false;
        try {
            for (const auto& entry : fs::directory_iterator(run)) {
                if (!entry.is_directory(ec)) continue;
                const bool boxes = fs::is_regular_file(entry.path() / kBoxesJson, ec);
                const bool meta = fs::is_regular_file(entry.path() / kMetaJson, ec);
                // A vksonar frame folder with neither is a frame cut off before its files (or emptied):
                // refused below, not skipped.
                const bool frame_named = entry.path().filename().string().rfind("frame_", 0) == 0;
                any_boxes = any_boxes || boxes;
                if (boxes || meta || frame_named)
                    frames.push_back({entry.path(), (entry.path().filename() / kFanPng).generic_string(), {}, 0});
            }
        } catch (const fs::filesystem_error& e) {
            throw BadInput(run.string() + ": cannot list the folder (" + e.code().message() + ")");
        }
        if (!any_boxes)
            throw BadInput(run.string() +
                           ": no boxes.json in it or in its frame folders (render with --save fan,labels)");
    }
    for (FrameFolder& f : frames) {
        if (!fs::is_regular_file(f.dir / kBoxesJson, ec) && !fs::is_regular_file(f.dir / kMetaJson, ec))
            throw BadInput(f.dir.string() + ": a frame folder without meta.json and boxes.json (an unfinished frame)");
        if (!fs::is_regular_file(f.dir / kBoxesJson, ec))
            throw BadInput(f.dir.string() + ": meta.json but no boxes.json (rendered without --save labels?)");
        if (!fs::is_regular_file(f.dir / kMetaJson, ec))
            throw BadInput(f.dir.string() + ": boxes.json but no meta.json (an unfinished frame)");
        if (!fs::is_regular_file(f.dir / kFanPng, ec))
            throw BadInput(f.dir.string() + ": no fan.png, the image the boxes are on (render with --save fan,labels)");
        f.boxes = read_json(f.dir / kBoxesJson);
        f.frame_index = unsigned_at(f.boxes, "frame_index", f.dir / kBoxesJson);
    }
    std::sort(frames.begin(), frames.end(), [](const FrameFolder& a, const FrameFolder& b) {
        return a.frame_index != b.frame_index ? a.frame_index < b.frame_index : a.dir < b.dir;
    });
    return frames;
}

json coco_document(const fs::path& run, const std::vector<FrameFolder>& frames, std::uint64_t& left_out) {
    json categories = classes_of(frames.front().dir / kMetaJson);
    std::vector<std::uint64_t> category_ids;
    for (const json& c : categories)
        category_ids.push_back(c["id"].get<std::uint64_t>());
    json images = json::array(), annotations = json::array();
    std::uint64_t image_id = 0, annotation_id = 0;
    left_out = 0;
    for (const FrameFolder& f : frames) {
        const fs::path boxes_path = f.dir / kBoxesJson;
        // Frames of one run share the scene: other classes mean folders of different runs.
        if (&f != &frames.front() && classes_of(f.dir / kMetaJson) != categories)
            throw BadInput((f.dir / kMetaJson).string() + ": its classes differ from " +
                           (frames.front().dir / kMetaJson).string() + "'s (frames of different scenes?)");
        if (!f.boxes.contains("image_size")) throw BadInput(boxes_path.string() + ": 'image_size' is missing");
        const std::uint64_t width = unsigned_at(f.boxes["image_size"], "width", boxes_path);
        const std::uint64_t height = unsigned_at(f.boxes["image_size"], "height", boxes_path);
        // COCO tools treat id 0 as "none" (an unmatched detection), so ids count from 1.
        ++image_id;
        images.push_back({{"id", image_id},
                          {"file_name", f.file_name},
                          {"width", width},
                          {"height", height},
                          {"frame_index", f.frame_index}});
        if (!f.boxes.contains("boxes") || !f.boxes["boxes"].is_array())
            throw BadInput(boxes_path.string() + ": 'boxes' is missing or not a list");
        for (const json& box : f.boxes["boxes"]) {
            const std::uint64_t category = unsigned_at(box, "class_id", boxes_path);
            const std::uint64_t instance = unsigned_at(box, "instance_id", boxes_path);
            if (std::find(category_ids.begin(), category_ids.end(), category) == category_ids.end())
                throw BadInput(boxes_path.string() + ": instance " + std::to_string(instance) + " has class " +
                               std::to_string(category) + ", which meta.json's objects.classes does not list");
            if (!box.contains("fan") || box["fan"].is_null()) {
                ++left_out; // cells but no fan pixel: nothing to draw on the image
                continue;
            }
            const json& fan = box["fan"];
            const std::uint64_t x0 = unsigned_at(fan, "x0", boxes_path), y0 = unsigned_at(fan, "y0", boxes_path);
            const std::uint64_t x1 = unsigned_at(fan, "x1", boxes_path), y1 = unsigned_at(fan, "y1", boxes_path);
            if (x0 > x1 || y0 > y1 || x1 >= width || y1 >= height)
                throw BadInput(boxes_path.string() + ": instance " + std::to_string(instance) +
                               "'s fan box is not inside the " + std::to_string(width) + " x " +
                               std::to_string(height) + " image");
            // Inclusive pixel bounds: the box covers pixels x0 ... x1, i.e. [x0, x1 + 1) in image coordinates.
            const std::uint64_t w = x1 - x0 + 1, h = y1 - y0 + 1;
            ++annotation_id;
            annotations.push_back({{"id", annotation_id},
                                   {"image_id", image_id},
                                   {"category_id", category},
                                   {"bbox", {x0, y0, w, h}},
                                   {"area", w * h},
                                   {"iscrowd", 0},
                                   {"instance_id", instance}});
        }
    }
    return {{"info", {{"description", "vksonar boxes on the fan image"}, {"run", run.string()}}},
            {"images", std::move(images)},
            {"annotations", std::move(annotations)},
            {"categories", std::move(categories)}};
}

// OUT under a temporary name in its folder, then renamed over OUT.
void write_whole(const fs::path& out, const std::string& text) {
    std::error_code ec;
    const fs::path folder = out.has_parent_path() ? out.parent_path() : fs::path(".");
    if (!fs::is_directory(folder, ec)) throw BadInput(out.string() + ": no folder " + folder.string());
    if (fs::is_directory(out, ec)) throw BadInput(out.string() + ": is a directory");
    const fs::path temporary = folder / (".~" + out.filename().string() + "." + std::to_string(::getpid()));
    errno = 0;
    std::FILE* f = std::fopen(temporary.c_str(), "wb");
    if (!f) throw BadInput(out.string() + ": cannot write (" + std::strerror(errno ? errno : EIO) + ")");
    const bool written = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    const int write_errno = errno;
    const bool closed = std::fclose(f) == 0;
    if (!written || !closed) {
        const std::string why = std::strerror(write_errno ? write_errno : (errno ? errno : EIO));
        fs::remove(temporary, ec);
        throw Failure(out.string() + ": cannot write (" + why + ")");
    }
    fs::rename(temporary, out, ec);
    if (ec) {
        const std::string why = ec.message();
        fs::remove(temporary, ec);
        throw Failure(out.string() + ": cannot write (" + why + ")");
    }
}

} // namespace

int run_export(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv, {{"--help", false, false}}, "export");
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (args.positional.empty()) throw BadInput("export: needs a format (coco), a run folder and OUT.json");
    const std::string& format = args.positional[0];
    if (format != "coco")
        throw BadInput("export: unknown format '" + format + "' (did you mean '" + closest_word(format, {"coco"}) +
                       "'?)");
    if (args.positional.size() != 3)
        throw BadInput("export coco: needs RUN and OUT.json (vksonar export coco RUN OUT.json), got " +
                       std::to_string(args.positional.size() - 1) + " arguments");
    const fs::path run = args.positional[1], out = args.positional[2];
    std::error_code ec;
    if (!fs::is_directory(out, ec)) require_writable_output("export coco: OUT", out.string());
    if (!fs::is_directory(run, ec))
        throw BadInput(run.string() + (fs::exists(run, ec) ? ": not a folder (export reads a render's frame folders, "
                                                             "written with --save fan,labels)"
                                                           : ": no such folder"));

    const std::vector<FrameFolder> frames = frame_folders(run);
    // OUT must not be a file the export reads: written over boxes.json or meta.json it breaks the run
    // (the next export fails on it), over fan.png it loses the image the COCO file names.
    const fs::path out_canonical = fs::weakly_canonical(out, ec);
    for (const FrameFolder& frame : frames)
        for (const std::string_view input : {kBoxesJson, kMetaJson, kFanPng})
            if (!ec && fs::weakly_canonical(frame.dir / input, ec) == out_canonical)
                throw BadInput("export coco: OUT " + out.string() + " is " + (frame.dir / input).string() +
                               ", a file of the run it reads; write it outside the frame folders");
    std::uint64_t left_out = 0;
    const json coco = coco_document(run, frames, left_out);
    write_whole(out, coco.dump(-1, ' ', false, json::error_handler_t::replace) + "\n");
    std::printf("vksonar: export coco: %zu images, %zu annotations, %zu categories -> %s", coco["images"].size(),
                coco["annotations"].size(), coco["categories"].size(), out.c_str());
    if (left_out) std::printf(" (%llu boxes without fan pixels left out)", static_cast<unsigned long long>(left_out));
    std::printf("\n");
    return 0;
}

} // namespace vksonar::cli
