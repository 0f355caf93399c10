// `vksonar render`: scene + sonar config + pose(s) -> PNG/NPY/PLY/JSON files.
//
// Order matters for the "no partial output" promise: every input (config layers, scene, poses,
// trajectory, --save list) is read and validated first; only then is the output directory created,
// and it is removed again if anything fails before the first frame is on disk. Each file is written
// under a temporary name and renamed, so a reader never sees half a file.
//
// run_render (at the end) reads as the list of steps; the per-frame files are written by
// render_frame.cpp.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/dataset_h5.h"
#include "cli/dataset_mcap.h"
#include "cli/inputs.h"
#include "cli/merge.h"
#include "cli/render_frame.h"
#include "cli/shard.h"
#include "cli/write_behind.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "host/boxes.h"
#include "host/host_stages.h"
#include "host/meta_fields.h"
#include "legacy/legacy.h"
#include "vksonar/vksonar.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

constexpr const char* kUsage =
    "usage: vksonar render [--scene FILE.gltf] [--sonar PRESET|FILE.json] [--config FILE.json]\n"
    "                      [--pose x,y,z,roll,pitch,yaw | --trajectory POSES.csv] [--set key=value ...]\n"
    "                      [--quality fast|balanced|accurate] [--seed N] [--backend vulkan|cpu]\n"
    "                      [--save default,fan,polar,polar_png,polar_u16,depth,...] [--asset-root DIR]\n"
    "                      [--compress] [--shard INDEX/COUNT] [--shard-count N] [--ros-prefix /TOPIC]\n"
    "                      [--ros-frame ID] [--rate HZ] [--ros-sonar-dtype float32|uint16]\n"
    "                      --out DIR|FILE.h5|FILE.mcap\n"
    "\n"
    "  --scene       glTF scene (default: the bundled assets/scenes/default.gltf)\n"
    "  --sonar       preset name (see 'vksonar presets') or a sonar JSON file (default: preset 'default')\n"
    "  --config      JSON file of config keys applied on top (see docs/config.md)\n"
    "  --set         one config key, dotted for groups: --set effects.speckle=off --set display.db_min=50\n"
    "                precedence: preset < scene effects < --config < --quality < --set\n"
    "  --quality     accuracy preset: fast | balanced (default knobs) | accurate (README: Accuracy)\n"
    "  --pose        sonar pose: metres and degrees, R = Rz(yaw) Ry(pitch) Rx(roll), positive pitch = nose down;\n"
    "                'frame': placed so the scene's bounding box fills the field of view inside the range window\n"
    "                (default for the bundled scene: 0,0,0,0,10,0; otherwise 0,0,0,0,0,0)\n"
    "  --trajectory  CSV of poses (x,y,z,roll,pitch,yaw per line; '#' comments and a header allowed; a header\n"
    "                t,x,y,z,roll,pitch,yaw adds a time in s before each pose: meta.json time_s, the .h5 time);\n"
    "                frames go to DIR/frame_NNNNNN/ with NNNNNN the line number\n"
    "  --seed        noise seed (default 1)\n"
    "  --backend     auto (default: Vulkan on a GPU, the CPU backend where the only Vulkan device is a CPU\n"
    "                implementation such as lavapipe, or where there is none), vulkan or cpu; meta.json says\n"
    "                which and why (backend, backend_reason)\n"
    "  --save        what to write, a comma list (repeatable); meta.json is always written. Without --save:\n"
    "                fan.png, polar.npy, polar.png and polar_u16.npy (the set 'default'). With it, exactly\n"
    "                what is listed: default, fan (fan.png), polar (polar.npy), polar_png (polar.png),\n"
    "                polar_u16 (polar_u16.npy), depth (depth.npy, view range m), normals (normals.npy),\n"
    "                echo (echo.npy), cloud (cloud.ply), labels (ground truth per cell: instance.npy, class.npy,\n"
    "                instance_fraction.npy, elevation.npy, elevation_spread.npy, point.npy; on the fan image:\n"
    "                instance_fan.npy, class_fan.npy, instance_fan.png, and boxes.json: each object's box in the\n"
    "                polar and fan images, for 'vksonar export coco'; docs/labels.md, docs/datasets.md), flow\n"
    "                (with --trajectory: flow.npy [bins, beams, 2], each labelled cell's d_bin, d_beam to the\n"
    "                next frame, NaN where it leaves the window or is hidden; implies the labels stage);\n"
    "                e.g. --save polar for a dataset, --save default,depth.\n"
    "                Legacy modes (--sonar uuv-legacy|gtri-legacy, docs/legacy.md): fan.png is the legacy\n"
    "                image and polar.* the physical model of the same ping; uuv-legacy adds normals\n"
    "                (normals.png), multibeam (multibeam.png/.npy) and raw_scan (raw_scan.png/.npy)\n"
    "  --asset-root  folder that files named inside the scene (external buffers) must lie in, symlinks and\n"
    "                '..' resolved (default: the scene file's folder; config key scene.asset_root)\n"
    "  --out         output directory (created), or a FILE.h5 / FILE.hdf5: one HDF5 dataset for the whole\n"
    "                run (polar [frames, bins, beams], pose, frame_index, time, metadata; docs/datasets.md;\n"
    "                --save polar (default), polar_u16 and labels only: labels adds instance, class,\n"
    "                instance_fraction, elevation, elevation_spread [frames, bins, beams] and point [..., 3])\n"
    "                or a FILE.mcap: one ROS 2 bag (rosbag2 MCAP: ros2 bag play, Foxglove; docs/ros2.md) of\n"
    "                marine_acoustic_msgs/ProjectedSonarImage, the fan and polar sensor_msgs/Image, /tf and, with\n"
    "                --save cloud, a PointCloud2; with --save labels, PREFIX/instance: the instance ids as a\n"
    "                mono16 image laid out as the polar one (--save polar, fan, polar_u16, cloud, labels pick\n"
    "                the topics)\n"
    "  --compress    .h5: lossless shuffle + deflate on the frame arrays; .mcap: zstd chunks\n"
    "  --ros-prefix  .mcap: topic prefix (default /vksonar: /vksonar/sonar_image, /vksonar/fan, ...)\n"
    "  --ros-frame   .mcap: the sonar's frame id (default sonar; its child sonar_acoustic is Z forward, X up)\n"
    "  --rate        .mcap: frames per second when the trajectory has no time column (default 10)\n"
    "  --ros-sonar-dtype .mcap: ProjectedSonarImage data as float32 (uPa^2, default) or uint16 (display)\n"
    "  --shard       with --trajectory: render block INDEX (from 0) of COUNT contiguous blocks of the frames,\n"
    "                each keeping its frame index (and noise), so the blocks together are the whole run;\n"
    "                without it a Slurm array (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job\n"
    "                (JOB_COMPLETION_INDEX) picks the block. Re-running a shard skips the frames already\n"
    "                on disk. Merge the shards with 'vksonar merge' (docs/scale.md)\n"
    "  --shard-count with JOB_COMPLETION_INDEX: the number of shards (else VKSONAR_SHARD_COUNT)\n";

const std::vector<std::string> kSaveItems = {"default",  "fan",     "polar", "polar_png", "polar_u16",
                                             "depth",    "normals", "echo",  "cloud",     "multibeam",
                                             "raw_scan", "labels",  "flow"};

struct TrajectoryPose {
    Pose pose;
    std::uint64_t line = 0;
    double time_s = 0.0; // the trajectory's time column, when it has one
};

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
    for (const auto& value : values) {
        for (const auto& item : split(value, ',')) {
            if (item.empty()) continue;
            if (item == "default")
                save.fan = save.polar = save.polar_png = save.polar_u16 = true;
            else if (item == "fan")
                save.fan = true;
            else if (item == "polar")
                save.polar = true;
            else if (item == "polar_png")
                save.polar_png = true;
            else if (item == "polar_u16")
                save.polar_u16 = true;
            else if (item == "depth")
                save.depth = true;
            else if (item == "normals")
                save.normals = true;
            else if (item == "echo")
                save.echo = true;
            else if (item == "cloud")
                save.cloud = true;
            else if (item == "multibeam")
                save.multibeam = true;
            else if (item == "raw_scan")
                save.raw_scan = true;
            else if (item == "labels")
                save.labels = true;
            else if (item == "flow")
                save.flow = true;
            else
                throw BadInput("--save: unknown output '" + item + "' (did you mean '" +
                               closest_word(item, kSaveItems) +
                               "'? valid: default,fan,polar,polar_png,polar_u16,depth,normals,echo,cloud,multibeam,"
                               "raw_scan,labels,flow)");
        }
    }
    return save;
}

// The poses of a trajectory file, and whether it has a time column (header `t,x,y,z,roll,pitch,yaw`).
std::vector<TrajectoryPose> read_trajectory(const std::string& path, bool& timed) {
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
        const auto first = line.find_first_not_of(" \t");
        if (first == std::string::npos || line[first] == '#') continue;
        const std::string where = path + ":" + std::to_string(number);
        // A header is the first non-comment line when it holds no number at all ("x,y,z,roll,pitch,yaw").
        if (!seen_data && poses.empty() && line.find_first_of("0123456789") == std::string::npos) {
            seen_data = true;
            timed = header_names_time(line);
            continue;
        }
        seen_data = true;
        TrajectoryPose item;
        item.line = number;
        std::string pose_text = line;
        if (timed) {
            const std::size_t comma = line.find(',');
            item.time_s = parse_double(line.substr(0, comma), where + ": time");
            if (!poses.empty() && item.time_s < poses.back().time_s)
                throw BadInput(where + ": time " + line.substr(0, comma) + " is before the previous line's");
            pose_text = comma == std::string::npos ? std::string() : line.substr(comma + 1);
        }
        item.pose = parse_pose(pose_text, where);
        poses.push_back(item);
    }
    if (file.bad()) throw BadInput("--trajectory " + path + ": read error");
    if (poses.empty()) throw BadInput("--trajectory " + path + ": no poses in the file");
    return poses;
}

// ---- output directory --------------------------------------------------------------------------

// Creates the output directory; unless keep() is called, removes what it created when destroyed
// (an error before the first frame leaves nothing behind).
class OutputDir {
public:
    explicit OutputDir(const fs::path& dir) : dir_(dir) {
        std::error_code ec;
        if (fs::exists(dir, ec)) {
            if (!fs::is_directory(dir, ec)) throw BadInput("--out " + dir.string() + ": exists and is not a directory");
        } else {
            // Remember the first missing ancestor so cleanup removes exactly what was created.
            fs::path missing = dir;
            for (fs::path p = dir; !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
                missing = p;
                if (p == p.parent_path()) break;
            }
            if (!fs::create_directories(dir, ec) || ec)
                throw BadInput("--out " + dir.string() + ": cannot create the output directory (" +
                               (ec ? ec.message() : std::string("unknown error")) + ")");
            created_ = missing;
        }
        // Root passes access(W_OK) everywhere, so probe with a real file.
        const fs::path probe = dir / (".vksonar-probe-" + std::to_string(::getpid()));
        std::FILE* f = std::fopen(probe.c_str(), "wb");
        if (!f) {
            cleanup();
            throw BadInput("--out " + dir.string() + ": output directory is not writable");
        }
        std::fclose(f);
        fs::remove(probe, ec);
    }
    ~OutputDir() {
        if (!keep_) cleanup();
    }
    OutputDir(const OutputDir&) = delete;
    OutputDir& operator=(const OutputDir&) = delete;

    void keep() { keep_ = true; }
    const fs::path& path() const { return dir_; }

private:
    void cleanup() {
        std::error_code ec;
        if (!created_.empty()) fs::remove_all(created_, ec);
        created_.clear();
    }
    fs::path dir_;
    fs::path created_;
    bool keep_ = false;
};

// ---- seeing your own scene -----------------------------------------------------------------------

// A scene far out of proportion with the range window is most often in other units: one warning
// naming the likely mistake and the key that fixes it.
void warn_if_unit_mistake(const Scene& scene, const SonarConfig& config, const std::string& scene_path) {
    const double size = scene.bounds().diagonal_m(), window = config.range_max_m;
    if (size <= 0.0 || !(window > 0.0)) return;
    char line[400];
    if (size > 200.0 * window && size > 5000.0)
        std::snprintf(line, sizeof line,
                      "%s is %.0f m across, %.0f times range_max (%.0f m): if it was modelled in millimetres "
                      "(centimetres), --set scene.scale=0.001 (0.01) brings it to metres",
                      scene_path.c_str(), size, size / window, window);
    else if (size < window / 1000.0)
        std::snprintf(line, sizeof line,
                      "%s is %.3g m across, a %.0fth of range_max (%.0f m): if it was modelled in kilometres, "
                      "--set scene.scale=1000 brings it to metres",
                      scene_path.c_str(), size, window / size, window);
    else
        return;
    std::fprintf(stderr, "warning: %s\n", line);
}

// --pose frame: the sonar looks along +x at the bounding box's centre from the distance where the
// box's width fills the horizontal field of view (not nearer than range_min, not farther than the
// middle of the range window, so a box larger than the window shows its middle), pitched down by half
// the vertical beamwidth (as sonars are usually mounted) and raised so that this pitch hits the centre.
Pose pose_framing(const Scene& scene, const SonarConfig& config, const std::string& scene_path) {
    const SceneBounds b = scene.bounds();
    if (b.empty) throw BadInput("--pose frame: " + scene_path + " has nothing to frame");
    constexpr double kPi = 3.14159265358979323846;
    const double cx = 0.5 * (b.min_m[0] + b.max_m[0]), cy = 0.5 * (b.min_m[1] + b.max_m[1]);
    const double cz = 0.5 * (b.min_m[2] + b.max_m[2]);
    const double half_width = 0.5 * std::max(b.max_m[1] - b.min_m[1], 1e-3);
    const double half_depth = 0.5 * (b.max_m[0] - b.min_m[0]);
    const double half_fov = 0.5 * std::min(config.hfov_deg, 170.0) * kPi / 180.0;
    const double fit = std::max(half_width / std::tan(half_fov), config.range_min_m * 1.05) + half_depth;
    const double distance = std::min(fit, 0.5 * (config.range_min_m + config.range_max_m));
    const double pitch = 0.5 * std::min(config.vfov_deg, 60.0) * kPi / 180.0;
    Pose pose;
    pose.x_m = cx - distance;
    pose.y_m = cy;
    pose.z_m = cz + distance * std::tan(pitch);
    pose.pitch_deg = pitch * 180.0 / kPi;
    const double far = std::hypot(distance + half_depth, pose.z_m - b.min_m[2]);
    std::fprintf(stderr, "vksonar: --pose frame: %.3f,%.3f,%.3f,0,%.2f,0 (%s)\n", pose.x_m, pose.y_m, pose.z_m,
                 pose.pitch_deg,
                 far > config.range_max_m ? "the box reaches beyond range_max: its middle is framed"
                                          : "the whole box lies inside the range window");
    return pose;
}

// ---- one dataset file ---------------------------------------------------------------------------

// The first problem SonarConfig::validate names, or empty for a usable config.
std::string config_problem(const SonarConfig& config) {
    const auto valid = config.validate();
    return valid ? std::string() : valid.error().message;
}

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
    if (!options.prefix.empty() && (options.prefix[0] != '/' || !valid_name(options.prefix, true) ||
                                    options.prefix.find("//") != std::string::npos))
        throw BadInput("--ros-prefix: '" + options.prefix +
                       "' is not a ROS topic namespace (/name/..., letters, digits, _)");
    options.frame = args.value("--ros-frame", options.frame);
    if (!valid_name(options.frame, false) || std::isdigit(static_cast<unsigned char>(options.frame[0])))
        throw BadInput("--ros-frame: '" + options.frame + "' is not a frame id (letters, digits, _)");
    const std::string dtype = args.value("--ros-sonar-dtype", "float32");
    if (dtype != "float32" && dtype != "uint16")
        throw BadInput("--ros-sonar-dtype: '" + dtype + "' (float32 or uint16)");
    options.sonar_u16 = dtype == "uint16";
    if (args.has("--rate")) {
        const double rate = parse_double(args.value("--rate"), "--rate");
        if (!(rate > 0.0)) throw BadInput("--rate: " + args.value("--rate") + " is not a positive rate (frames/s)");
    }
    if (args.has("--compress") && !mcap_zstd_available())
        throw BadInput("--compress: this build has no zstd for " + path + " (install libzstd-dev and rebuild)");
    return options;
}

// ROS time stamps (builtin_interfaces/Time: int32 s) hold 0 .. 2^31 - 1 s; --rate needs no time column.
void check_bag_times(const std::vector<TrajectoryPose>& poses, bool timed, const Args& args) {
    const std::string& path = args.value("--trajectory");
    if (timed && args.has("--rate"))
        throw BadInput("--rate: " + path + " has a time column, which sets the time stamps");
    if (!timed) return;
    for (const TrajectoryPose& p : poses)
        if (!(p.time_s >= 0.0 && p.time_s <= 2147483647.0)) {
            char value[64];
            std::snprintf(value, sizeof value, "%.17g", p.time_s);
            throw BadInput(path + ":" + std::to_string(p.line) + ": time " + value +
                           " is outside a ROS time stamp's 0 .. 2147483647 s");
        }
}

// The dataset file's path: its folder must exist and be writable before anything renders; the file
// is removed again unless keep() is called (a frame is in it). A shard's file that is already there
// (an earlier run of the shard) is never removed: a failed re-run must not lose its frames.
class DatasetFile {
public:
    DatasetFile(const fs::path& path, bool keep_existing) : path_(path) {
        std::error_code ec;
        keep_ = keep_existing && fs::exists(path, ec);
        const fs::path folder = path.has_parent_path() ? path.parent_path() : fs::path(".");
        if (!fs::is_directory(folder, ec)) throw BadInput("--out " + path.string() + ": no folder " + folder.string());
        if (fs::is_directory(path, ec)) throw BadInput("--out " + path.string() + ": is a directory");
        if (::access(folder.c_str(), W_OK) != 0)
            throw BadInput("--out " + path.string() + ": the folder is not writable");
    }
    ~DatasetFile() {
        std::error_code ec;
        if (!keep_) fs::remove(path_, ec);
    }
    DatasetFile(const DatasetFile&) = delete;
    DatasetFile& operator=(const DatasetFile&) = delete;
    void keep() { keep_ = true; }

private:
    fs::path path_;
    bool keep_ = false;
};

DatasetMeta dataset_meta(const Plan& plan, const std::string& scene, const std::string& backend,
                         const std::string& device, std::uint64_t seed) {
    DatasetMeta meta;
    meta.config_json = config_to_json(plan.config);
    meta.effects_json = host::effects_json(plan.effects.states).dump();
    meta.validity_json = host::validity_json(plan.validity).dump();
    meta.scene = scene;
    meta.backend = backend;
    meta.device = device;
    meta.seed = seed;
    return meta;
}

// The dataset writer: a shard whose file is already there goes on after its last whole frame (marking
// them in `done`); a file that cannot be read back is started over.
std::unique_ptr<DatasetWriter> open_dataset_writer(const std::string& path, const Plan& plan, const DatasetMeta& meta,
                                                   const DatasetOptions& options, DatasetFile& file,
                                                   std::vector<char>& done) {
    std::error_code ec;
    if (meta.shard && fs::is_regular_file(path, ec)) {
        auto resumed = DatasetWriter::resume(path, plan, meta, options);
        if (resumed) {
            file.keep(); // its frames are a result already
            for (std::uint64_t k = 0; k < resumed.value()->frames_written(); ++k)
                done[meta.shard->first + k] = 1;
            return std::move(resumed.value());
        }
        if (resumed.error().code == ErrorCode::invalid_argument) throw BadInput("--out " + resumed.error().message);
        std::fprintf(stderr, "warning: %s: starting the shard over\n", resumed.error().message.c_str());
    }
    auto created = DatasetWriter::create(path, plan, meta, options);
    if (!created) throw Failure(created.error().message);
    return std::move(created.value());
}

// The --save set as a canonical list (a shard's identity).
std::string save_list(const SaveSet& s) {
    std::string list;
    const std::pair<bool, const char*> items[] = {{s.fan, "fan"},
                                                  {s.polar, "polar"},
                                                  {s.polar_png, "polar_png"},
                                                  {s.polar_u16, "polar_u16"},
                                                  {s.depth, "depth"},
                                                  {s.normals, "normals"},
                                                  {s.echo, "echo"},
                                                  {s.cloud, "cloud"},
                                                  {s.multibeam, "multibeam"},
                                                  {s.raw_scan, "raw_scan"},
                                                  {s.labels, "labels"},
                                                  {s.flow, "flow"}};
    for (const auto& [on, name] : items)
        if (on) list += (list.empty() ? "" : ",") + std::string(name);
    return list;
}

// ---- the steps of a render (run_render below runs them in order) ----------------------------------

Args parse_render_args(const std::vector<std::string>& argv) {
    return parse_args(argv,
                      {{"--scene", true, false},
                       {"--sonar", true, false},
                       {"--config", true, false},
                       {"--pose", true, false},
                       {"--trajectory", true, false},
                       {"--set", true, true},
                       {"--quality", true, false},
                       {"--seed", true, false},
                       {"--backend", true, false},
                       {"--save", true, true},
                       {"--out", true, false},
                       {"--asset-root", true, false},
                       {"--compress", false, false},
                       {"--ros-prefix", true, false},
                       {"--ros-frame", true, false},
                       {"--rate", true, false},
                       {"--ros-sonar-dtype", true, false},
                       {"--shard", true, false},
                       {"--shard-count", true, false},
                       {"--help", false, false}},
                      "render");
}

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
    bool trajectory = false; // --trajectory (poses holds its lines)
    std::vector<TrajectoryPose> poses;
    bool timed = false;      // the trajectory has a time column
    bool frame_pose = false; // --pose frame
    std::optional<ShardRecord> shard;
    std::size_t first = 0, end = 0; // the block of poses this run renders (all of them without a shard)
};

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
    if (job.trajectory) {
        job.poses = read_trajectory(args.value("--trajectory"), job.timed);
        if (job.bag) check_bag_times(job.poses, job.timed, args);
    } else if (args.has("--pose") && args.value("--pose") == "frame") {
        job.frame_pose = true;
        job.poses.push_back({Pose{}, 0});
    } else if (args.has("--pose")) {
        job.poses.push_back({parse_pose(args.value("--pose"), "--pose"), 0});
    } else {
        Pose pose;
        if (job.default_scene) pose.pitch_deg = 10.0; // nose down: the seabed at z = -5 m fills the lower beams
        job.poses.push_back({pose, 0});
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

// Everything the command line says, checked in the order the errors are reported: options, scene
// file, poses, shard. The config layers and the scene itself come next (load_scene_and_config).
RenderJob parse_job(const Args& args) {
    if (!args.positional.empty())
        throw BadInput("render: unexpected argument '" + args.positional[0] + "' (see vksonar render --help)");
    if (!args.has("--out") || args.value("--out").empty()) throw BadInput("render: --out DIR is required");
    if (args.has("--pose") && args.has("--trajectory")) throw BadInput("render: give --pose or --trajectory, not both");
    RenderJob job;
    parse_options(args, job);
    job.default_scene = !args.has("--scene");
    job.scene_path = job.default_scene ? find_default_scene().string() : args.value("--scene");
    if (!job.default_scene) {
        std::error_code ec;
        if (!fs::is_regular_file(job.scene_path, ec)) throw BadInput("--scene " + job.scene_path + ": no such file");
    }
    read_poses(args, job);
    pick_shard(args, job);
    return job;
}

// The user's config layers on top of `config`: --config < --quality < --set, then the checks of the
// result. Run twice (load_scene_and_config): once on the preset, before the (possibly slow) scene
// load, and again above the scene's effects.
SonarConfig apply_user_layers(const Args& args, const SaveSet& save, SonarConfig config) {
    // A value the config file made invalid (and no later layer changed) is reported with the file.
    std::string file_problem, file_path;
    if (args.has("--config")) {
        std::error_code ec;
        const std::string path = args.value("--config");
        if (!fs::is_regular_file(path, ec)) throw BadInput("--config " + path + ": no such file");
        const std::string before = config_problem(config);
        auto layered = apply_config_file(config, path);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
        if (std::string after = config_problem(config); after != before) {
            file_problem = std::move(after);
            file_path = path;
        }
    }
    if (args.has("--quality")) {
        auto layered = apply_quality(config, args.value("--quality"));
        if (!layered) throw BadInput("--quality: " + layered.error().message);
        config = layered.value();
    }
    for (const auto& item : args.values("--set")) {
        auto layered = apply_config_override(config, item);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
    }
    if (std::string problem = config_problem(config); !problem.empty()) {
        const bool from_file = !file_problem.empty() && problem == file_problem;
        throw BadInput("invalid config: " + (from_file ? file_path + ": " : std::string()) + problem);
    }
    if ((save.multibeam || save.raw_scan) && config.mode != SonarMode::uuv_legacy)
        throw BadInput(std::string("--save ") + (save.multibeam ? "multibeam" : "raw_scan") +
                       ": only mode uuv-legacy has this output (use --sonar uuv-legacy or --set mode=uuv-legacy)");
    return config;
}

struct SceneAndConfig {
    Scene scene;
    SonarConfig config;
};

// The config layers (preset < scene effects < --config < --quality < --set) and the scene; fills in
// a --pose frame pose. Still nothing on disk.
SceneAndConfig load_scene_and_config(const Args& args, RenderJob& job) {
    const SonarConfig preset = sonar_base_config(args.value("--sonar", "default"));
    SonarConfig config = apply_user_layers(args, job.save, preset);
    const std::string asset_root = args.value("--asset-root", config.scene_asset_root);
    auto scene = Scene::load_gltf(job.scene_path, SceneLoadOptions{asset_root, config.scene_scale});
    if (!scene) {
        if (job.default_scene) throw Failure(scene.error().message);
        throw BadInput(scene.error().message);
    }
    // What the loader skipped or ignored (points and lines, unknown material keys, skins) is the
    // user's to know: one line each, before any frame.
    for (const std::string& warning : scene->stats().warnings)
        std::fprintf(stderr, "warning: %s\n", warning.c_str());
    const std::string& scene_effects = scene->effects_json();
    if (!scene_effects.empty() && scene_effects != "{}" && scene_effects != "null") {
        auto layered = apply_config_json(preset, "{\"effects\": " + scene_effects + "}",
                                         job.scene_path + " (scene extras vksonar.effects)");
        if (!layered) throw BadInput(layered.error().message);
        config = apply_user_layers(args, job.save, layered.value());
    }
    config.scene_asset_root = asset_root; // meta.json's config says which folder the scene's files came from
    if (job.bag && config.mode != SonarMode::physical)
        throw BadInput("--out " + job.out_path + ": a ROS 2 bag holds the physical model only (not --sonar " +
                       (config.mode == SonarMode::uuv_legacy ? "uuv-legacy" : "gtri-legacy") + ")");
    warn_if_unit_mistake(scene.value(), config, job.scene_path);
    if (job.frame_pose) job.poses = {{pose_framing(scene.value(), config, job.scene_path), 0, 0.0}};
    return {std::move(scene.value()), std::move(config)};
}

// The output directory, or the .h5 / .mcap file's place: made only once every input is valid, and
// removed again if the run fails before a frame is on disk.
struct OutputTarget {
    std::optional<OutputDir> dir;    // frame folders
    std::optional<DatasetFile> file; // .h5 or .mcap
};

void create_output(const RenderJob& job, OutputTarget& target) {
    if (job.dataset || job.bag)
        target.file.emplace(job.out_path, job.shard.has_value()); // a shard's file is resumed (or refused), not removed
    else
        target.dir.emplace(job.out_path);
}

// The device and which backend runs on it; meta.json says which and why.
struct Device {
    Context context;
    Backend backend = Backend::vulkan;
    std::string backend_name;   // vulkan or cpu (auto resolved)
    std::string backend_reason; // --backend, or what auto saw
    std::string description;    // the Vulkan device, or "cpu"
};

// --backend auto (the default) picks by the device (choose_backend).
Device open_device(const RenderJob& job) {
    Backend backend = job.backend;
    std::string reason = "--backend " + job.backend_name;
    Context context = job.backend_name == "auto" ? choose_backend(backend, reason) : make_context(backend);
    std::string name = job.backend_name;
    if (name == "auto") name = backend == Backend::cpu ? "cpu" : "vulkan";
    std::string description = backend == Backend::vulkan ? context.device_description() : "cpu";
    return {std::move(context), backend, std::move(name), std::move(reason), std::move(description)};
}

Renderer make_renderer(Device& device, const SonarConfig& config, const Scene& scene, const RenderJob& job) {
    RendererOptions renderer_options = renderer_options_from_env();
    renderer_options.backend = device.backend;
    renderer_options.seed = job.seed;
    // Legacy modes start from the depth pass (and its material ids, for the GTRI retro).
    renderer_options.save_mask =
        job.save.mask() | (config.mode != SonarMode::physical ? SaveFlags::depth : SaveFlags::none);
    auto renderer = Renderer::create(device.context, config, scene, renderer_options);
    if (!renderer) {
        const Error& e = renderer.error();
        if (e.code == ErrorCode::invalid_argument || e.code == ErrorCode::parse || e.code == ErrorCode::unsupported)
            throw BadInput(e.message);
        throw Failure(e.message + (device.backend == Backend::vulkan ? " (try --backend cpu)" : ""));
    }
    // A model taken outside its domain: one line each, before any frame (meta.json lists them all).
    for (const ModelValidity& v : renderer->validity())
        if (!v.ok) std::fprintf(stderr, "warning: %s\n", v.warning().c_str());
    return std::move(renderer.value());
}

// What the per-frame writers need (render_frame.h), made once for the whole run.
Outputs make_outputs(const Plan& plan, const RenderJob& job, const Device& device, const host::FanRenderer& fan,
                     LegacyState& legacy_state, const Scene& scene) {
    legacy_state.mode = plan.config.mode;
    const std::string config_text = config_to_json(plan.config);
    return Outputs{plan,
                   job.save,
                   fan,
                   config_text,
                   nlohmann::ordered_json::parse(config_text),
                   host::meta_json_plan_part(plan),
                   job.scene_path,
                   device.backend_name,
                   device.backend_reason,
                   device.description,
                   {},
                   {},
                   {},
                   plan.config.mode != SonarMode::physical ? &legacy_state : nullptr,
                   job.shard ? &*job.shard : nullptr,
                   host::objects_json(scene),
                   {},
                   scene.classes(),
                   {},
                   {},
                   {}};
}

// ---- where the frames go -----------------------------------------------------------------------

// The writers of a .h5 or .mcap run (null for frame folders) and, for a re-run shard, which of the
// trajectory's frames are already on disk (`done`: skipped).
struct Writers {
    std::unique_ptr<DatasetWriter> dataset;
    std::vector<char> done;
    std::unique_ptr<McapDatasetWriter> bag;
    bool bag_complete = false; // a re-run shard whose bag holds its whole block already
    double bag_rate = 10.0;    // --rate
};

void open_dataset(const RenderJob& job, const Plan& plan, const Outputs& outputs, const Args& args, DatasetFile& file,
                  Writers& writers) {
    DatasetMeta meta = dataset_meta(plan, job.scene_path, outputs.backend, outputs.device, job.seed);
    meta.objects_json = outputs.objects.dump();
    meta.shard = job.shard;
    DatasetOptions options;
    options.polar_u16 = job.save.polar_u16;
    options.labels = job.save.labels;
    options.flow = job.save.flow;
    options.compress = args.has("--compress");
    options.has_time = job.timed;
    writers.dataset = open_dataset_writer(job.out_path, plan, meta, options, file, writers.done);
}

// A shard of frame folders: its manifest (which lines, which run) in the output directory; a re-run
// marks the frames already there in `done`.
void start_folder_manifest(const RenderJob& job, const Outputs& outputs, const OutputDir& dir, Writers& writers) {
    FolderManifest manifest{*job.shard,
                            run_identity(outputs.config_json, job.seed, job.scene_path, outputs.backend,
                                         save_list(job.save), job.timed, &*job.shard),
                            {},
                            outputs.backend,
                            outputs.device};
    for (std::size_t i = job.first; i < job.end; ++i)
        manifest.lines.push_back(job.poses[i].line);
    start_folder_shard(dir.path().string(), manifest, writers.done);
}

// A shard's bag: its record and the run's identity, for `vksonar merge` and a re-run
// (merge_mcap.cpp); the identity also names what the bag's messages depend on. A re-run goes on
// after the frames already in the bag.
void resume_bag_shard(const RenderJob& job, const Plan& plan, const Outputs& outputs, McapOptions& bag_options,
                      Writers& writers) {
    const ShardRecord& shard = *job.shard;
    Identity identity = run_identity(outputs.config_json, job.seed, job.scene_path, outputs.backend,
                                     save_list(job.save), job.timed, &shard);
    char rate[32];
    std::snprintf(rate, sizeof rate, "%.17g", writers.bag_rate);
    identity.insert(identity.end(), {{"ros_prefix", bag_options.prefix},
                                     {"ros_frame", bag_options.frame},
                                     {"ros_sonar_dtype", bag_options.sonar_u16 ? "uint16" : "float32"},
                                     {"rate", job.timed ? std::string("time column") : std::string(rate)}});
    bag_options.shard = shard_metadata(shard, identity, outputs.backend, outputs.device, bag_options.zstd);
    BagResume resumed = bag_shard_resume(job.out_path, plan, bag_options, shard, identity);
    for (std::uint64_t k = 0; k < resumed.frames; ++k)
        writers.done[job.first + k] = 1;
    writers.bag = std::move(resumed.writer);
    writers.bag_complete = resumed.complete;
}

void open_bag(const Args& args, RenderJob& job, const Plan& plan, const Outputs& outputs, Writers& writers) {
    McapOptions& bag_options = *job.bag_options;
    bag_options.zstd = args.has("--compress");
    bag_options.library = "vksonar 0.1.0 (its own MCAP writer)";
    if (job.shard) resume_bag_shard(job, plan, outputs, bag_options, writers);
    if (!writers.bag && !writers.bag_complete) {
        auto created = McapDatasetWriter::create(job.out_path, plan, bag_options);
        if (!created) throw Failure(created.error().message);
        writers.bag = std::move(created.value());
    }
}

Writers open_writers(const Args& args, RenderJob& job, const Plan& plan, const Outputs& outputs, OutputTarget& target) {
    Writers writers;
    writers.done.assign(job.poses.size(), 0);
    if (job.dataset)
        open_dataset(job, plan, outputs, args, *target.file, writers);
    else if (job.shard && !job.bag)
        start_folder_manifest(job, outputs, *target.dir, writers);
    writers.bag_rate = args.has("--rate") ? parse_double(args.value("--rate"), "--rate") : 10.0;
    if (job.bag) open_bag(args, job, plan, outputs, writers);
    return writers;
}

// ---- writing one frame (on the write-behind thread) ----------------------------------------------

void write_bag_frame(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs, Writers& writers) {
    const McapOptions& bag_options = *job.bag_options;
    const bool u16 = bag_options.polar || bag_options.sonar_u16;
    if (u16) host::quantize_display(slot.frame, outputs.quantized);
    if (bag_options.fan) outputs.fan.render(slot.frame, outputs.image);
    // Without a time column, time_s is the frame's ordinal in the whole trajectory (a shard's
    // first frame is `first`): the stamps are ordinal / rate, in a shard's bag as in the
    // unsharded run's.
    const double seconds = job.timed ? slot.time_s : slot.time_s / writers.bag_rate;
    const auto stamp_ns = static_cast<std::uint64_t>(std::llround(seconds * 1e9));
    auto appended =
        writers.bag->append(slot.frame, slot.pose, stamp_ns, &outputs.image, u16 ? outputs.quantized.data() : nullptr);
    if (!appended) throw Failure(appended.error().message);
}

void write_dataset_frame(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs, Writers& writers) {
    const SaveSet& save = job.save;
    const std::uint16_t* u16 = nullptr;
    if (save.polar_u16) {
        host::quantize_display(slot.frame, outputs.quantized);
        u16 = outputs.quantized.data();
    }
    auto appended =
        writers.dataset->append(slot.frame, slot.pose, slot.time_s, u16, save.flow ? slot.flow.data() : nullptr,
                                save.labels ? &frame_boxes(outputs, slot.frame) : nullptr);
    if (!appended) throw Failure(appended.error().message);
}

// A trajectory's frame goes to DIR/frame_NNNNNN/ (NNNNNN its line), a single pose's to DIR itself.
void write_folder_frame(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs,
                        const OutputDir& out_dir) {
    fs::path dir = out_dir.path();
    if (job.trajectory) {
        dir /= frame_dir_name(slot.line);
        std::error_code ec;
        fs::create_directories(dir, ec);
        if (ec) throw Failure("cannot create " + dir.string() + ": " + ec.message());
    }
    write_frame(outputs, dir, slot.frame, slot.pose, job.timed ? &slot.time_s : nullptr,
                job.save.flow ? &slot.flow : nullptr); // meta.json last: done
}

// The write-behind thread's function. Once a whole frame is on disk the output is kept (only this
// thread calls keep(); it is read after the join). A complete bag shard has no writer, and no frame
// comes here.
void write_slot(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs, Writers& writers,
                OutputTarget& target) {
    if (job.bag) {
        write_bag_frame(slot, job, outputs, writers);
        target.file->keep();
    } else if (writers.dataset) {
        write_dataset_frame(slot, job, outputs, writers);
        target.file->keep();
    } else {
        write_folder_frame(slot, job, outputs, *target.dir);
        target.dir->keep();
    }
}

// ---- the frame loop ------------------------------------------------------------------------------

// "N/M frames written, R frames/s, S s left" on a terminal during a trajectory, at most 4 times a second.
class Progress {
public:
    Progress(const WriteBehind& writer, std::size_t todo, bool shown) : writer_(writer), todo_(todo), shown_(shown) {}

    void show(bool final) {
        const auto now = std::chrono::steady_clock::now();
        if (!shown_ || (!final && now - last_ < std::chrono::milliseconds(250))) return;
        last_ = now;
        const std::uint64_t written = writer_.written();
        const double seconds = std::chrono::duration<double>(now - start_).count();
        const double rate = seconds > 0 ? static_cast<double>(written) / seconds : 0.0;
        const double left = rate > 0 ? static_cast<double>(todo_ - written) / rate : 0.0;
        std::fprintf(stderr, "\rvksonar: %llu/%zu frames written, %.1f frames/s, %.0f s left   ",
                     static_cast<unsigned long long>(written), todo_, rate, left);
        std::fflush(stderr);
    }
    // The line ends once the run is done.
    void finish() {
        show(true);
        if (shown_) std::fputc('\n', stderr);
    }
    double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }

private:
    const WriteBehind& writer_;
    std::size_t todo_;
    bool shown_;
    std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
    std::chrono::steady_clock::time_point last_ = start_;
};

// Renders the block [first, end) into the write-behind ring, skipping the frames already on disk.
// --save flow: frame i is held back until frame i + 1 is rendered, its flow computed, then submitted.
// The next frame is rendered for it even where it is not this run's to write (a re-run shard's
// frame already on disk, the first frame of the next shard), so every shard's flow is the
// unsharded run's; the trajectory's last frame has no next one: its flow is all NaN.
class FrameLoop {
public:
    FrameLoop(const Args& args, const RenderJob& job, Renderer& renderer, WriteBehind& writer)
        : args_(args), job_(job), renderer_(renderer), writer_(writer) {}

    void run(const std::vector<char>& done, Progress& progress) {
        for (std::size_t i = job_.first; i < job_.end; ++i) {
            if (done[i] && !held_) continue;                          // a re-run shard: this frame is complete on disk
            WriteBehind::Slot& slot = writer_.acquire(held_ ? 1 : 0); // rethrows a write error: the run stops there
            render_into(i, slot);
            if (held_) submit_held(&slot);
            if (done[i]) continue; // rendered for the previous frame's flow only; the slot is reused
            if (job_.save.flow) {
                held_ = &slot;
            } else {
                writer_.submit();
            }
            progress.show(false);
        }
        if (!held_) return;
        if (job_.end < job_.poses.size()) { // the next shard's first frame
            WriteBehind::Slot& next = writer_.acquire(1);
            render_into(job_.end, next);
            submit_held(&next);
        } else {
            submit_held(nullptr);
        }
    }

private:
    void render_into(std::size_t i, WriteBehind::Slot& slot) {
        const TrajectoryPose& item = job_.poses[i];
        auto rendered = renderer_.render(item.pose, item.line, slot.frame);
        if (!rendered) {
            const std::string where =
                job_.trajectory ? args_.value("--trajectory") + ":" + std::to_string(item.line) + ": " : std::string();
            throw Failure(where + rendered.error().message);
        }
        slot.pose = item.pose;
        slot.line = item.line;
        slot.time_s = job_.timed ? item.time_s : static_cast<double>(i); // the .h5 time: the global ordinal
    }

    // `next`: the frame after the held one, or null where the trajectory ends.
    void submit_held(const WriteBehind::Slot* next) {
        if (next) {
            auto flowed = renderer_.label_flow(held_->frame, held_->pose, next->frame, next->pose, held_->flow);
            if (!flowed) throw Failure(flowed.error().message);
        } else {
            held_->flow.assign(std::size_t(2) * held_->frame.bins * held_->frame.beams,
                               std::numeric_limits<float>::quiet_NaN());
        }
        writer_.submit();
        held_ = nullptr;
    }

    const Args& args_;
    const RenderJob& job_;
    Renderer& renderer_;
    WriteBehind& writer_;
    WriteBehind::Slot* held_ = nullptr;
};

// The frame ring: up to three frames, so rendering goes on while the previous frames are written
// (--save flow holds a frame back until the next one is rendered: at least two slots).
std::vector<Frame> make_slots(const RenderJob& job, Renderer& renderer) {
    std::vector<Frame> slots;
    const std::size_t count =
        std::min<std::size_t>(3, std::max<std::size_t>(job.end - job.first, job.save.flow ? 2 : 1));
    for (std::size_t i = 0; i < count; ++i)
        slots.push_back(renderer.make_frame());
    return slots;
}

// Waits for the writes, closes the .h5 / .mcap, ends the progress line; a shard says what it did.
void finish_run(const RenderJob& job, WriteBehind& writer, Writers& writers, OutputTarget& target, Progress& progress,
                std::size_t todo) {
    writer.finish();
    if (writers.dataset)
        if (auto closed = writers.dataset->close(); !closed) throw Failure(closed.error().message);
    if (writers.bag)
        if (auto closed = writers.bag->close(); !closed) throw Failure(closed.error().message);
    progress.finish();
    if (!job.shard) return;
    // A shard's output is its result even when its block is empty or was already complete.
    if (target.file) target.file->keep();
    if (target.dir) target.dir->keep();
    const double seconds = progress.seconds();
    std::fprintf(stderr, "vksonar: shard %llu/%llu: %zu frames rendered in %.2f s (%.2f frames/s)\n",
                 static_cast<unsigned long long>(job.shard->index), static_cast<unsigned long long>(job.shard->count),
                 todo, seconds, seconds > 0 ? static_cast<double>(todo) / seconds : 0.0);
}

} // namespace

// Order matters for the "no partial output" promise (top of the file): everything that can be
// checked is checked before create_output.
int run_render(const std::vector<std::string>& argv) {
    const Args args = parse_render_args(argv);
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    RenderJob job = parse_job(args);
    const SceneAndConfig loaded = load_scene_and_config(args, job);
    OutputTarget target;
    create_output(job, target);

    Device device = open_device(job);
    Renderer renderer = make_renderer(device, loaded.config, loaded.scene, job);
    const Plan& plan = renderer_plan(renderer);
    const host::FanRenderer fan(plan);
    LegacyState legacy_state;
    Outputs outputs = make_outputs(plan, job, device, fan, legacy_state, loaded.scene);
    std::vector<Frame> slots = make_slots(job, renderer);
    Writers writers = open_writers(args, job, plan, outputs, target);

    // Frames are rendered here and written on a background thread (write_behind.h).
    WriteBehind writer(std::move(slots),
                       [&](const WriteBehind::Slot& slot) { write_slot(slot, job, outputs, writers, target); });
    const std::size_t todo =
        static_cast<std::size_t>(std::count(writers.done.begin() + job.first, writers.done.begin() + job.end, 0));
    if (job.shard)
        std::fprintf(stderr, "vksonar: %s\n",
                     shard_summary(*job.shard, job.end > job.first ? job.poses[job.first].line : 0,
                                   job.end > job.first ? job.poses[job.end - 1].line : 0, job.end - job.first - todo)
                         .c_str());
    Progress progress(writer, todo, job.trajectory && ::isatty(::fileno(stderr)));
    FrameLoop(args, job, renderer, writer).run(writers.done, progress);
    finish_run(job, writer, writers, target, progress, todo);
    return 0;
}

} // namespace vksonar::cli
