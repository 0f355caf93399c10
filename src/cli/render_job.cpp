// `vksonar render`'s inputs, read and checked before any output exists: the command line (parse_job:
// options, --save, the output's kind, the scene file, the poses, the shard), then the config layers
// and the scene (load_scene_and_config). render_cmd.cpp runs the job.
#include "cli/render_job.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "cli/dataset_h5.h"
#include "cli/inputs.h"
#include "config/layers.h"
#include "host/meta_fields.h"
#include "host/scene_framing.h"
#include "vksonar/vksonar.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

// A trajectory's time text (already read as `seconds`) in whole nanoseconds, exactly where it is a plain
// decimal ("1700000000.923456789": the digits, rounded half up past the ninth decimal), else rounded
// from the double (an exponent; a negative time, which the bag's check refuses). A double holds an epoch
// time to about 0.2 us only: through it a ROS stamp came out up to 235 ns off the file's value.
std::uint64_t time_ns_of(const std::string& text, double seconds) {
    const std::string t = trim(text);
    const std::size_t dot = t.find('.');
    const std::string whole = t.substr(0, dot), fraction = dot == std::string::npos ? "" : t.substr(dot + 1);
    const auto digits = [](const std::string& d) {
        return std::all_of(d.begin(), d.end(), [](char c) { return c >= '0' && c <= '9'; });
    };
    if (whole.size() > 10 || (whole.empty() && fraction.empty()) || !digits(whole) || !digits(fraction) ||
        !(seconds >= 0.0))
        return seconds >= 0.0 ? static_cast<std::uint64_t>(std::llround(seconds * 1e9)) : 0;
    std::uint64_t ns = whole.empty() ? 0 : std::stoull(whole) * 1000000000ull;
    std::uint64_t scale = 100000000ull;
    for (std::size_t i = 0; i < fraction.size() && i < 9; ++i, scale /= 10)
        ns += static_cast<std::uint64_t>(fraction[i] - '0') * scale;
    if (fraction.size() > 9 && fraction[9] >= '5') ++ns;
    return ns;
}

// The --save items that name one output each, with the SaveSet member each sets, in the order a
// shard's identity lists them (save_list). One table for parsing, listing and the error's "valid:"
// list; "default" (fan, polar, polar_png, polar_u16) is the one item that names several.
constexpr std::pair<const char*, bool SaveSet::*> kSaveOutputs[] = {{"fan", &SaveSet::fan},
                                                                    {"polar", &SaveSet::polar},
                                                                    {"polar_png", &SaveSet::polar_png},
                                                                    {"polar_u16", &SaveSet::polar_u16},
                                                                    {"depth", &SaveSet::depth},
                                                                    {"normals", &SaveSet::normals},
                                                                    {"echo", &SaveSet::echo},
                                                                    {"cloud", &SaveSet::cloud},
                                                                    {"multibeam", &SaveSet::multibeam},
                                                                    {"raw_scan", &SaveSet::raw_scan},
                                                                    {"labels", &SaveSet::labels},
                                                                    {"flow", &SaveSet::flow}};

const std::vector<std::string> kSaveItems = [] {
    std::vector<std::string> items = {"default"};
    for (const auto& [name, member] : kSaveOutputs)
        items.emplace_back(name);
    return items;
}();

// A trajectory whose header's first column is t, time or time_s has a time (s) before each pose.
bool header_names_time(const std::string& header) {
    std::string first = header.substr(0, header.find(','));
    first.erase(0, first.find_first_not_of(" \t"));
    first.erase(first.find_last_not_of(" \t") + 1);
    std::transform(first.begin(), first.end(), first.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return first == "t" || first == "time" || first == "time_s";
}

// ---- inputs ------------------------------------------------------------------------------------

SaveSet parse_save(const std::vector<std::string>& values) {
    SaveSet save;
    if (values.empty()) return save;
    save.fan = save.polar = save.polar_png = save.polar_u16 = false; // exactly what is listed
    bool listed = false;
    for (const auto& value : values) {
        for (const auto& item : split(value, ',')) {
            if (item.empty()) continue;
            listed = true;
            if (item == "default") {
                save.fan = save.polar = save.polar_png = save.polar_u16 = true;
                continue;
            }
            const auto* output = std::find_if(std::begin(kSaveOutputs), std::end(kSaveOutputs),
                                              [&](const auto& known) { return item == known.first; });
            if (output == std::end(kSaveOutputs)) {
                std::string valid; // from kSaveItems, so the message lists exactly what is accepted
                for (const std::string& known : kSaveItems)
                    valid += (valid.empty() ? "" : ",") + known;
                throw BadInput("--save: unknown output '" + item + "' (did you mean '" +
                               closest_word(item, kSaveItems) + "'? valid: " + valid + ")");
            }
            save.*(output->second) = true;
        }
    }
    // `--save ""` (a script's empty variable) wrote meta.json alone
    if (!listed) throw BadInput("--save: no output named (e.g. --save polar, or --save default)");
    return save;
}

// The poses of a trajectory file, and whether it has a time column (header `t,x,y,z,roll,pitch,yaw`).
std::vector<TrajectoryPose> read_trajectory(const std::string& path, bool& timed) {
    require_input_file("--trajectory", path);
    std::ifstream file(path);
    if (!file) throw BadInput("--trajectory " + path + ": cannot open");
    std::vector<TrajectoryPose> poses;
    std::string line;
    std::uint64_t number = 0;
    bool seen_data = false;
    timed = false;
    while (std::getline(file, line)) {
        ++number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        // A UTF-8 byte order mark (editors on Windows write one) is not part of the first line.
        if (number == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
        const auto first = line.find_first_not_of(" \t");
        if (first == std::string::npos || line[first] == '#') continue;
        const std::string where = path + ":" + std::to_string(number);
        // (a NUL cut the line's error message short where it was printed: named here instead)
        if (line.find('\0') != std::string::npos) throw BadInput(where + ": a NUL byte (is it a text file?)");
        // A header is the first non-comment line when it holds no number at all ("x,y,z,roll,pitch,yaw"),
        // nor words a number reads ("nan,nan,..." is a pose, refused below): six names, or seven with a
        // time first. Another header would drop a line in silence, or mislead the next line's message.
        const std::vector<std::string> items = split(line, ',');
        const auto all_numbers = [&items] {
            return std::all_of(items.begin(), items.end(), [](const std::string& item) {
                char* end = nullptr;
                std::strtod(item.c_str(), &end);
                return !item.empty() && end == item.c_str() + item.size();
            });
        };
        if (!seen_data && poses.empty() && line.find_first_of("0123456789") == std::string::npos && !all_numbers()) {
            seen_data = true;
            timed = header_names_time(line);
            if (items.size() != (timed ? 7u : 6u))
                throw BadInput(where + ": header '" + line + "' has " + std::to_string(items.size()) +
                               " columns: expected x,y,z,roll,pitch,yaw, or t,x,y,z,roll,pitch,yaw with a time "
                               "column (t, time or time_s)");
            continue;
        }
        seen_data = true;
        TrajectoryPose item;
        item.line = number;
        std::string pose_text = line;
        if (timed) {
            if (items.size() != 7)
                throw BadInput(where + ": '" + line +
                               "' needs 7 numbers t,x,y,z,roll,pitch,yaw (the header names a "
                               "time column), got " +
                               std::to_string(items.size()));
            const std::size_t comma = line.find(',');
            const std::string time_text = line.substr(0, comma);
            item.time_s = parse_double(time_text, where + ": time");
            item.time_ns = time_ns_of(time_text, item.time_s);
            if (!poses.empty() && item.time_s < poses.back().time_s)
                throw BadInput(where + ": time " + time_text + " is before the previous line's");
            pose_text = comma == std::string::npos ? std::string() : line.substr(comma + 1);
        }
        item.pose = parse_pose(pose_text, where);
        poses.push_back(item);
    }
    if (file.bad()) throw BadInput("--trajectory " + path + ": read error");
    if (poses.empty()) throw BadInput("--trajectory " + path + ": no poses in the file");
    return poses;
}

// ---- seeing your own scene -----------------------------------------------------------------------

// A scene far out of proportion with the range window is most often in other units: one warning
// naming the likely mistake and the key that fixes it.
void warn_if_unit_mistake(const Scene& scene, const SonarConfig& config, const std::string& scene_path) {
    const std::string line = host::unit_mistake_warning(scene, config, scene_path, "--set scene.scale=", "");
    if (!line.empty()) std::fprintf(stderr, "warning: %s\n", line.c_str());
}

// --pose frame (host::frame_pose), said on stderr.
Pose pose_framing(const Scene& scene, const SonarConfig& config, const std::string& scene_path) {
    Pose pose;
    bool whole = false;
    if (!host::frame_pose(scene, config, pose, whole))
        throw BadInput("--pose frame: " + scene_path + " has nothing to frame");
    std::fprintf(stderr, "vksonar: --pose frame: %.3f,%.3f,%.3f,0,%.2f,0 (%s)\n", pose.x_m, pose.y_m, pose.z_m,
                 pose.pitch_deg,
                 whole ? "the whole box lies inside the range window"
                       : "the box reaches beyond range_max: its middle is framed");
    return pose;
}

// ---- one dataset file ---------------------------------------------------------------------------

std::string lower_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}
bool is_dataset_path(const std::string& path) {
    const std::string ext = lower_extension(path);
    return ext == ".h5" || ext == ".hdf5";
}
bool is_mcap_path(const std::string& path) {
    return lower_extension(path) == ".mcap";
}

// A bag holds the sonar image, the fan, the polar display, the cloud and the instance ids; the rest
// needs folders.
McapOptions check_mcap_save(SaveSet& save, bool listed, const std::string& path) {
    if (!listed) save = SaveSet{true, true, false, true};
    const char* other = save.depth       ? "depth"
                        : save.normals   ? "normals"
                        : save.echo      ? "echo"
                        : save.multibeam ? "multibeam"
                        : save.raw_scan  ? "raw_scan"
                        : save.flow      ? "flow"
                                         : nullptr;
    if (other)
        throw BadInput(std::string("--save ") + other + ": a ROS 2 bag (" + path +
                       ") holds polar, fan, polar_u16 (or polar_png), cloud and labels; write per-frame folders "
                       "(--out DIR) for the rest");
    McapOptions options;
    options.sonar_image = save.polar;
    options.fan = save.fan;
    options.polar = save.polar_u16 || save.polar_png;
    options.cloud = save.cloud;
    options.instance = save.labels;
    if (!options.sonar_image && !options.fan && !options.polar && !options.cloud && !options.instance)
        throw BadInput("--save: nothing for the bag " + path + " (polar, fan, polar_u16, cloud, labels)");
    return options;
}

// A dataset holds the polar arrays and the labels beside them; images and per-pixel intermediates go
// to per-frame folders.
void check_dataset_save(SaveSet& save, bool listed, const std::string& path) {
    if (!listed) save = SaveSet{false, true, false, false};
    const char* other = save.fan         ? "fan"
                        : save.polar_png ? "polar_png"
                        : save.depth     ? "depth"
                        : save.normals   ? "normals"
                        : save.echo      ? "echo"
                        : save.cloud     ? "cloud"
                        : save.multibeam ? "multibeam"
                        : save.raw_scan  ? "raw_scan"
                                         : nullptr;
    if (other)
        throw BadInput(std::string("--save ") + other + ": a dataset file (" + path +
                       ") holds polar, polar_u16, labels and flow only; write per-frame folders (--out DIR) for the "
                       "rest");
    if (!save.polar && !save.polar_u16)
        throw BadInput("--save: nothing for the dataset file " + path +
                       " (polar, polar_u16; labels and flow go beside them)");
    if (!hdf5_available())
        throw BadInput("--out " + path + ": this build has no HDF5 (install libhdf5-dev and rebuild)");
}

// --out FILE.mcap: the topics (--save), names (--ros-prefix, --ros-frame) and dtype of the bag.
McapOptions mcap_options(const Args& args, SaveSet& save, const std::string& path) {
    McapOptions options = check_mcap_save(save, !args.values("--save").empty(), path);
    options.prefix = args.value("--ros-prefix", options.prefix);
    while (options.prefix.size() > 1 && options.prefix.back() == '/')
        options.prefix.pop_back();
    auto valid_name = [](const std::string& name, bool slashes) {
        if (name.empty()) return false;
        for (unsigned char c : name)
            if (!(std::isalnum(c) || c == '_' || (slashes && c == '/'))) return false;
        return true;
    };
    if (options.prefix == "/") options.prefix.clear();
    // ROS 2 names: tokens of letters, digits and _, none starting with a digit (ros2 bag play refuses
    // /1abc); tf2 frame ids may start with a digit, but not be the world frame the bag's /tf hangs from.
    bool digit_token = false;
    for (std::size_t i = 0; i + 1 < options.prefix.size(); ++i)
        digit_token |= options.prefix[i] == '/' && std::isdigit(static_cast<unsigned char>(options.prefix[i + 1]));
    if (!options.prefix.empty() && (options.prefix[0] != '/' || !valid_name(options.prefix, true) ||
                                    options.prefix.find("//") != std::string::npos || digit_token))
        throw BadInput("--ros-prefix: '" + options.prefix +
                       "' is not a ROS topic namespace (/name/..., letters, digits, _; no name starts with a digit)");
    options.frame = args.value("--ros-frame", options.frame);
    if (!valid_name(options.frame, false))
        throw BadInput("--ros-frame: '" + options.frame + "' is not a frame id (letters, digits, _)");
    if (options.frame == options.world_frame)
        throw BadInput("--ros-frame: '" + options.frame + "' is the world frame the bag's /tf places the sonar in");
    const std::string dtype = args.value("--ros-sonar-dtype", "float32");
    if (dtype != "float32" && dtype != "uint16")
        throw BadInput("--ros-sonar-dtype: '" + dtype + "' (float32 or uint16)");
    options.sonar_u16 = dtype == "uint16";
    if (args.has("--ros-sonar-dtype") && !options.sonar_image)
        throw BadInput(
            "--ros-sonar-dtype: the sonar_image topic it sets comes with --save polar, which is not asked for");
    if (args.has("--rate")) {
        options.rate = parse_double(args.value("--rate"), "--rate");
        if (!(options.rate > 0.0))
            throw BadInput("--rate: " + args.value("--rate") + " is not a positive rate (frames/s)");
    }
    if (args.has("--compress") && !mcap_zstd_available())
        throw BadInput("--compress: this build has no zstd for " + path + " (install libzstd-dev and rebuild)");
    return options;
}

// ROS time stamps (builtin_interfaces/Time: int32 s) hold 0 .. 2^31 - 1 s; --rate needs no time column.
void check_bag_times(const std::vector<TrajectoryPose>& poses, bool timed, const Args& args, double rate) {
    const std::string& path = args.value("--trajectory");
    if (timed && args.has("--rate"))
        throw BadInput("--rate: " + path + " has a time column, which sets the time stamps");
    if (!timed) { // frame i at i / rate s: the last one inside the range, frames at least 1 ns apart
        const double last_s = poses.empty() ? 0.0 : static_cast<double>(poses.size() - 1) / rate;
        if (rate > 1e9)
            throw BadInput("--rate: " + args.value("--rate") +
                           " frames/s puts frames less than 1 ns apart, a ROS time stamp's step (at most 1e9)");
        if (!(last_s <= 2147483647.0))
            throw BadInput("--rate: " + args.value("--rate") + " frames/s stamps the last of " +
                           std::to_string(poses.size()) + " frames past a ROS time stamp's 2147483647 s");
        return;
    }
    for (const TrajectoryPose& p : poses)
        if (!(p.time_s >= 0.0 && p.time_s <= 2147483647.0)) {
            char value[64];
            std::snprintf(value, sizeof value, "%.17g", p.time_s);
            throw BadInput(path + ":" + std::to_string(p.line) + ": time " + value +
                           " is outside a ROS time stamp's 0 .. 2147483647 s");
        }
}

} // namespace

// The --save set as a canonical list (a shard's identity).
std::string save_list(const SaveSet& s) {
    std::string list;
    for (const auto& [name, member] : kSaveOutputs)
        if (s.*member) list += (list.empty() ? "" : ",") + std::string(name);
    return list;
}

// ---- the command line, in the order its errors are reported ------------------------------------------

Args parse_render_args(const std::vector<std::string>& argv) {
    return parse_args(
        argv, {{"--scene", true, false},      {"--sonar", true, false},       {"--config", true, false},
               {"--pose", true, false},       {"--trajectory", true, false},  {"--set", true, true},
               {"--quality", true, false},    {"--seed", true, false},        {"--frame-index", true, false},
               {"--backend", true, false},    {"--save", true, true},         {"--out", true, false},
               {"--asset-root", true, false}, {"--compress", false, false},   {"--ros-prefix", true, false},
               {"--ros-frame", true, false},  {"--rate", true, false},        {"--ros-sonar-dtype", true, false},
               {"--shard", true, false},      {"--shard-count", true, false}, {"--help", false, false}},
        "render");
}

namespace {

// Options that need no files: the backend, seed, --save and the output format's own options.
void parse_options(const Args& args, RenderJob& job) {
    job.backend_name = args.value("--backend", "auto");
    if (job.backend_name == "cpu")
        job.backend = Backend::cpu;
    else if (job.backend_name != "vulkan" && job.backend_name != "auto")
        throw BadInput("--backend: '" + job.backend_name + "' is not a backend (auto, vulkan or cpu)");
    job.seed = args.has("--seed") ? parse_u64(args.value("--seed"), "--seed") : 1;
    job.save = parse_save(args.values("--save"));
    if (job.save.flow && !args.has("--trajectory"))
        throw BadInput("--save flow: flow goes from each frame of a trajectory to the next; give --trajectory");
    job.out_path = args.value("--out");
    job.dataset = is_dataset_path(job.out_path);
    job.bag = is_mcap_path(job.out_path);
    if (job.dataset) check_dataset_save(job.save, !args.values("--save").empty(), job.out_path);
    if (job.bag) job.bag_options = mcap_options(args, job.save, job.out_path);
    for (const char* option : {"--ros-prefix", "--ros-frame", "--rate", "--ros-sonar-dtype"})
        if (args.has(option) && !job.bag)
            throw BadInput(std::string(option) + ": only for a ROS 2 bag (--out FILE.mcap)");
    if (args.has("--compress") && !job.dataset && !job.bag)
        throw BadInput("--compress: only a .h5 dataset or a .mcap bag is compressed (--out FILE.h5|FILE.mcap)");
}

// The poses: the trajectory's lines, one --pose, or the default pose. --pose frame is a placeholder
// here: load_scene_and_config computes it once the scene is loaded.
void read_poses(const Args& args, RenderJob& job) {
    job.trajectory = args.has("--trajectory");
    if (job.trajectory && args.has("--frame-index"))
        throw BadInput("--frame-index: a trajectory's frames are its line numbers; --frame-index is for one --pose");
    // The frame index keys the noise (with the seed): a single render takes it from here.
    const std::uint64_t frame = args.has("--frame-index") ? parse_u64(args.value("--frame-index"), "--frame-index") : 0;
    if (job.trajectory) {
        job.poses = read_trajectory(args.value("--trajectory"), job.timed);
        if (job.bag) check_bag_times(job.poses, job.timed, args, job.bag_options->rate);
    } else if (args.has("--pose") && args.value("--pose") == "frame") {
        job.frame_pose = true;
        job.poses.push_back({Pose{}, frame});
    } else if (args.has("--pose")) {
        job.poses.push_back({parse_pose(args.value("--pose"), "--pose"), frame});
    } else {
        Pose pose;
        if (job.default_scene) pose.pitch_deg = 10.0; // nose down: the seabed at z = -5 m fills the lower beams
        job.poses.push_back({pose, frame});
    }
}

// The shard: a block of the trajectory's frames (shard.h), from --shard or the engine's environment.
void pick_shard(const Args& args, RenderJob& job) {
    if (job.trajectory) {
        auto flag = [&](const char* name) { return args.has(name) ? std::optional(args.value(name)) : std::nullopt; };
        job.shard = resolve_shard(flag("--shard"), flag("--shard-count"), job.poses.size(), process_env());
        if (job.shard) {
            job.shard->trajectory = args.value("--trajectory");
            job.shard->trajectory_hash = file_fnv1a64(job.shard->trajectory);
        }
    } else if (args.has("--shard") || args.has("--shard-count")) {
        throw BadInput(std::string(args.has("--shard") ? "--shard" : "--shard-count") +
                       ": shards split a trajectory; give --trajectory POSES.csv");
    }
    job.first = job.shard ? job.shard->first : 0;
    job.end = job.shard ? job.shard->end : job.poses.size();
}

} // namespace

// Everything the command line says, checked in the order the errors are reported: options, scene
// file, poses, shard. The config layers and the scene itself come next (load_scene_and_config).
RenderJob parse_job(const Args& args) {
    if (!args.positional.empty())
        throw BadInput("render: unexpected argument '" + args.positional[0] + "' (see vksonar render --help)");
    if (!args.has("--out")) throw BadInput("render: --out DIR is required");
    if (args.value("--out").empty()) throw BadInput("render: --out is empty (a folder, FILE.h5 or FILE.mcap)");
    if (args.has("--pose") && args.has("--trajectory")) throw BadInput("render: give --pose or --trajectory, not both");
    RenderJob job;
    parse_options(args, job);
    job.default_scene = !args.has("--scene");
    job.scene_path = job.default_scene ? find_default_scene().string() : args.value("--scene");
    if (!job.default_scene) require_input_file("--scene", job.scene_path);
    read_poses(args, job);
    pick_shard(args, job);
    return job;
}

namespace {

// The user's config layers on top of `config` (whose values came from `origin`): --config < --quality
// < --set, then the checks of the result. Run twice (load_scene_and_config): once on the preset, before
// the (possibly slow) scene load, and again above the scene's effects.
SonarConfig apply_user_layers(const Args& args, const SaveSet& save, SonarConfig config, const std::string& origin) {
    ProblemOrigin problem(config, origin);
    if (args.has("--config")) {
        std::error_code ec;
        const std::string path = args.value("--config");
        require_input_file("--config", path);
        auto layered = apply_config_file(config, path);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
        problem.after(config, "--config " + path);
    }
    if (args.has("--quality")) {
        auto layered = apply_quality(config, args.value("--quality"));
        if (!layered) throw BadInput("--quality: " + layered.error().message);
        config = layered.value();
        problem.after(config, "--quality " + args.value("--quality"));
    }
    for (const auto& item : args.values("--set")) {
        auto layered = apply_config_override(config, item);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
        problem.after(config, "--set " + item);
    }
    problem.throw_if_invalid();
    if ((save.multibeam || save.raw_scan) && config.mode != SonarMode::uuv_legacy)
        throw BadInput(std::string("--save ") + (save.multibeam ? "multibeam" : "raw_scan") +
                       ": only mode uuv-legacy has this output (use --sonar uuv-legacy or --set mode=uuv-legacy)");
    return config;
}

} // namespace

// The config layers (preset < scene effects < --config < --quality < --set) and the scene; fills in
// a --pose frame pose. Still nothing on disk.
SceneAndConfig load_scene_and_config(const Args& args, RenderJob& job) {
    const std::string sonar = args.value("--sonar", "default");
    const SonarConfig preset = sonar_base_config(sonar);
    SonarConfig config = apply_user_layers(args, job.save, preset, "--sonar " + sonar);
    const std::string asset_root = args.value("--asset-root", config.scene_asset_root);
    // the user's folder, whatever the scene (the bundled one's load failing is ours: exit 1)
    if (std::error_code ec; !asset_root.empty() && !fs::is_directory(asset_root, ec))
        throw BadInput((args.has("--asset-root") ? "--asset-root " : "scene.asset_root = ") + asset_root +
                       ": not a folder" + (ec ? " (" + ec.message() + ")" : std::string()));
    auto scene = Scene::load_gltf(job.scene_path, SceneLoadOptions{asset_root, config.scene_scale});
    if (!scene) {
        if (job.default_scene) throw Failure(scene.error().message);
        throw BadInput(scene.error().message);
    }
    // What the loader skipped or ignored (points and lines, unknown material keys, skins) is the
    // user's to know: one line each, before any frame.
    for (const std::string& warning : scene->stats().warnings)
        std::fprintf(stderr, "warning: %s\n", warning.c_str());
    const EffectsConfig effects_without_scene = config.effects;
    if (const std::string scene_effects = scene_effects_layer(scene.value()); !scene_effects.empty()) {
        const std::string scene_origin = job.scene_path + " (scene extras vksonar.effects)";
        auto layered = apply_config_json(preset, scene_effects, scene_origin);
        if (!layered) throw BadInput(layered.error().message);
        ProblemOrigin base(preset, "--sonar " + sonar);
        base.after(layered.value(), scene_origin);
        config = apply_user_layers(args, job.save, layered.value(), base.origin());
    }
    config.scene_asset_root = asset_root; // meta.json's config says which folder the scene's files came from
    if (job.bag && config.mode != SonarMode::physical)
        throw BadInput("--out " + job.out_path + ": a ROS 2 bag holds the physical model only (not --sonar " +
                       (config.mode == SonarMode::uuv_legacy ? "uuv-legacy" : "gtri-legacy") + ")");
    warn_if_unit_mistake(scene.value(), config, job.scene_path);
    // The scene by its content, not only its path: every output records it, and a re-run shard must
    // be the same run.
    job.scene_hash = host::scene_fnv1a64(scene.value());
    if (job.shard) job.shard->scene_hash = job.scene_hash;
    if (job.frame_pose) job.poses = {{pose_framing(scene.value(), config, job.scene_path), job.poses[0].line, 0.0}};
    return {std::move(scene.value()), std::move(config), effects_without_scene};
}

} // namespace vksonar::cli
