// `vksonar render`'s inputs (render_job.cpp): the command line read and checked before any output
// exists (parse_job), then the config layers and the scene (load_scene_and_config). Each throws BadInput
// (exit 2) or Failure (exit 1) with a one-line message naming the file, option or value at fault.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/dataset_mcap.h"
#include "cli/render_frame.h"
#include "cli/shard.h"
#include "vksonar/vksonar.h"

namespace vksonar::cli {

struct TrajectoryPose {
    Pose pose;
    std::uint64_t line = 0;
    double time_s = 0.0;       // the trajectory's time column, when it has one
    std::uint64_t time_ns = 0; // the same, exactly as written where it is a plain decimal (ROS stamps)
};

// What the command line asks for, read and checked before any output exists (parse_job), completed
// by the scene (load_scene_and_config: a --pose frame pose).
struct RenderJob {
    std::string backend_name = "auto"; // --backend: auto, vulkan or cpu
    Backend backend = Backend::vulkan;
    std::uint64_t seed = 1;
    SaveSet save;
    std::string out_path;
    bool dataset = false;                   // --out FILE.h5 (or .hdf5)
    bool bag = false;                       // --out FILE.mcap
    std::optional<McapOptions> bag_options; // open_bag adds compression and the shard record
    bool default_scene = false;             // no --scene: the bundled one
    std::string scene_path;
    std::string scene_hash;  // scene_fnv1a64 of the loaded scene (load_scene_and_config)
    bool trajectory = false; // --trajectory (poses holds its lines)
    std::vector<TrajectoryPose> poses;
    bool timed = false;      // the trajectory has a time column
    bool frame_pose = false; // --pose frame
    std::optional<ShardRecord> shard;
    std::size_t first = 0, end = 0; // the block of poses this run renders (all of them without a shard)
};

struct SceneAndConfig {
    Scene scene;
    SonarConfig config;
    // The effects of the same layers without the scene's effect requests (credit_scene_requests).
    EffectsConfig effects_without_scene;
};

Args parse_render_args(const std::vector<std::string>& argv);
// Everything the command line says, checked in the order the errors are reported: options, scene
// file, poses, shard.
RenderJob parse_job(const Args& args);
// The config layers (preset < scene effects < --config < --quality < --set) and the scene; fills in
// a --pose frame pose. Still nothing on disk.
SceneAndConfig load_scene_and_config(const Args& args, RenderJob& job);
// The --save set as a canonical list (a shard's identity).
std::string save_list(const SaveSet& s);

} // namespace vksonar::cli
