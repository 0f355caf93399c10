// `vksonar render`'s per-frame outputs: one rendered frame -> the files of its folder (PNG, NPY, PLY,
// boxes.json, meta.json), each written under a temporary name and renamed, so a reader never sees
// half a file. render_job.cpp parses and validates, render_cmd.cpp loops over the poses; this file writes.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/shard.h"
#include "core/plan.h"
#include "host/boxes.h"
#include "host/host_stages.h"
#include "legacy/legacy.h"
#include "vksonar/vksonar.h"

namespace vksonar::cli {

// What a render writes. meta.json always (it says what the arrays are); the rest as --save lists it,
// or, without --save, the default set.
struct SaveSet {
    bool fan = true, polar = true, polar_png = true, polar_u16 = true; // the default set
    bool depth = false, normals = false, echo = false, cloud = false;
    bool multibeam = false, raw_scan = false; // uuv-legacy intermediates
    bool labels = false;                      // ground truth per cell and on the fan (docs/labels.md)
    bool flow = false;                        // labels' flow to the next frame of the trajectory
    SaveFlags mask() const {
        return (depth ? SaveFlags::depth : SaveFlags::none) | (normals ? SaveFlags::normals : SaveFlags::none) |
               (echo ? SaveFlags::echo : SaveFlags::none) | (labels || flow ? SaveFlags::labels : SaveFlags::none);
    }
};

// Writes through `write(temporary path)`, then renames onto `path`.
template <class WriteFn> void write_atomically(const std::filesystem::path& path, WriteFn&& write) {
    const std::filesystem::path temporary = path.parent_path() / (".~" + path.filename().string());
    Result<void> written = write(temporary.string());
    std::error_code ec;
    if (!written) {
        std::filesystem::remove(temporary, ec);
        throw Failure(written.error().message);
    }
    std::filesystem::rename(temporary, path, ec);
    if (ec) {
        const std::string why = ec.message(); // before remove() reuses ec
        std::filesystem::remove(temporary, ec);
        // A directory where an output file goes is the user's to move (bad input); anything else is ours.
        if (std::filesystem::is_directory(path, ec))
            throw BadInput("cannot write " + path.string() + ": a directory is in the way");
        throw Failure("cannot write " + path.string() + ": " + why);
    }
}

// ---- per-frame outputs -------------------------------------------------------------------------

// Legacy modes: the legacy chain's buffers, reused across frames.
struct LegacyState {
    SonarMode mode = SonarMode::physical;
    std::vector<float> depth; // metres along the optical axis, 0 = no hit
    legacy::UuvImages uuv;
    legacy::GtriImages gtri;
    std::vector<legacy::GtriPoint> cloud;
    host::Image gray; // single-channel intermediates as grey PNGs
};

struct Outputs {
    // The run's plan, --save set and fan renderer; the rest is set by name (make_outputs), so a new
    // member is one more line there, not a position in a list.
    Outputs(const Plan& plan_, const SaveSet& save_, const host::FanRenderer& fan_)
        : plan(plan_), save(save_), fan(fan_) {}

    const Plan& plan;
    const SaveSet& save;
    const host::FanRenderer& fan;
    std::string config_json;
    nlohmann::ordered_json config_parsed; // config_json parsed once (meta.json's "config" every frame)
    std::string meta_plan_part;           // host::meta_json_plan_part(plan), made once
    // meta.json's "effects": the plan's, with what the scene requested named (credit_scene_requests)
    nlohmann::ordered_json effects;
    std::string scene_path;
    std::string scene_hash; // scene_fnv1a64: the scene by its content (the path may mean another file later)
    std::string backend;
    std::string backend_reason; // why this backend (--backend, or what auto saw)
    std::string device;
    // Scratch reused across frames.
    host::Image image;
    std::vector<std::uint16_t> quantized;
    std::vector<float> view_range;
    LegacyState* legacy = nullptr;        // set in legacy modes
    const ShardRecord* shard = nullptr;   // a shard of the trajectory: meta.json says which
    nlohmann::ordered_json objects;       // host::objects_json(scene), made once
    std::vector<std::uint16_t> fan_ids;   // --save labels: instance or class ids on the fan image
    std::vector<std::string> class_names; // Scene::classes(): boxes.json's class names
    host::BoxFinder box_finder;           // --save labels: boxes.json, its scratch kept across frames
    std::vector<host::Box> boxes;
    std::string boxes_text; // the frame's boxes.json (frame_boxes)
    // The files write_frame wrote for this frame so far, name -> bytes: meta.json's "files".
    std::vector<std::pair<std::string, std::uintmax_t>> written;
    // Threads for the fan image (image_workers in run_render; null: the writer thread alone).
    host::Workers* image_workers = nullptr;
};

// The frame's boxes.json text, for the frame folder and the dataset file alike, so the two never differ.
// Leaves Frame::instance on the fan image (instance_fan.npy) in out.fan_ids: the boxes' fan extents are
// read off those ids, so the two files always agree.
const std::string& frame_boxes(Outputs& out, const Frame& frame);

// Writes the frame's files into `dir` as out.save asks, meta.json last (its presence marks the frame
// done). `time_s`: the trajectory's time column, or null when it has none; `flow`: --save flow's
// d_bin, d_beam per cell toward the next frame (null without it).
void write_frame(Outputs& out, const std::filesystem::path& dir, const Frame& frame, const Pose& pose,
                 const double* time_s, const std::vector<float>* flow);

} // namespace vksonar::cli
