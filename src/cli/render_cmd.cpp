// `vksonar render`: scene + sonar config + pose(s) -> PNG/NPY/PLY/JSON files.
//
// Order matters for the "no partial output" promise: every input (config layers, scene, poses,
// trajectory, --save list) is read and validated first; only then is the output directory created,
// and it is removed again if anything fails before the first frame is on disk. Each file is written
// under a temporary name and renamed, so a reader never sees half a file; an unsharded .h5 or bag is
// written whole under a temporary name and renamed onto OUT at the end (DatasetFile).
//
// run_render (at the end) reads as the list of steps; the inputs are read and checked by
// render_job.cpp, the per-frame files written by render_frame.cpp.
//
// SIGINT and SIGTERM (Ctrl-C, a scheduler's stop) end a run at the next frame boundary, not by the
// default action: the frames already rendered are written, the output is left as described in one
// stderr line (stop_run), and the exit code is the shell's 130 / 143. A second signal while it stops
// kills at once. The handlers are the command's, installed for the run only (InterruptGuard): the
// library never installs any (an embedding engine owns its signals).
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/dataset_h5.h"
#include "cli/dataset_mcap.h"
#include "cli/frame_files.h"
#include "cli/inputs.h"
#include "cli/merge.h"
#include "cli/render_frame.h"
#include "cli/render_job.h"
#include "cli/shard.h"
#include "cli/write_behind.h"
#include "config/layers.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "core/renderer_workers.h"
#include "host/boxes.h"
#include "host/host_stages.h"
#include "host/meta_fields.h"
#include "host/workers.h"
#include "legacy/legacy.h"
#include "vksonar/vksonar.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

constexpr const char* kUsage =
    "usage: vksonar render [--scene FILE.gltf|.glb] [--sonar PRESET|FILE.json] [--config FILE.json]\n"
    "                      [--pose x,y,z,roll,pitch,yaw | --trajectory POSES.csv] [--set key=value ...]\n"
    "                      [--quality fast|balanced|accurate] [--seed N] [--frame-index N]\n"
    "                      [--backend auto|vulkan|cpu]\n"
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
    "  --seed        noise seed (default 1). The noise of a frame is keyed by (seed, frame index, beam, bin)\n"
    "                only: two renders with one seed and one frame index share their speckle whatever the pose or\n"
    "                scene. For independent noise give each render its own frame index or seed\n"
    "  --frame-index with --pose (or no pose): the frame index of the single render (default 0), as a trajectory's\n"
    "                line number is its frames'; so frame N of a trajectory is rendered again alone, bit for bit\n"
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
    "  --out         output directory (created; an unsharded run first removes an earlier run's frames\n"
    "                and files there, no others), or a FILE.h5 / FILE.hdf5: one HDF5 dataset for the whole\n"
    "                run (polar [frames, bins, beams], pose, frame_index, time, metadata; docs/datasets.md;\n"
    "                --save polar (default), polar_u16, labels and flow only: labels adds instance, class,\n"
    "                instance_fraction, elevation, elevation_spread [frames, bins, beams] and point [..., 3],\n"
    "                flow [frames, bins, beams, 2])\n"
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
    "  --shard-count with JOB_COMPLETION_INDEX: the number of shards (else VKSONAR_SHARD_COUNT)\n"
    "\n"
    "Exit codes: 0 done, 2 bad input, 1 any other failure, 130 / 143 stopped by SIGINT (Ctrl-C) / SIGTERM: the run\n"
    "stops after the frame being rendered, writes the frames already rendered and says in one line what OUT holds\n"
    "(an unsharded .h5 or bag is not written; a shard resumes when re-run); a second signal kills it at once.\n";

// ---- SIGINT and SIGTERM ---------------------------------------------------------------------------

// The signal that asked the running `render` to stop (0: none). The one exception to the project's
// rule of no global mutable state: a signal handler can reach nothing else. A lock-free atomic, so
// the handler's store is async-signal-safe and the frame loop (another thread, maybe) reads it
// without a data race; only InterruptGuard and the handler below touch it.
std::atomic<int> g_render_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler's store must be lock-free");

// Async-signal-safe only: the first signal is recorded for the frame loop (no printing here); a
// second one restores the default action and re-raises, so a run stuck while stopping still dies
// (the signal stays blocked until this handler returns, then the default action ends the process).
void on_render_signal(int signal) {
    int none = 0;
    if (g_render_signal.compare_exchange_strong(none, signal)) return;
    struct sigaction fallback {};
    fallback.sa_handler = SIG_DFL;
    sigemptyset(&fallback.sa_mask);
    ::sigaction(signal, &fallback, nullptr);
    ::raise(signal);
}

// SIGINT and SIGTERM handled for the duration of a render (the earlier actions restored when it
// ends), except where one was ignored when the run began (nohup, a background job of a script):
// that one stays ignored. SA_RESTART: a file write interrupted by the signal goes on instead of
// failing with EINTR.
class InterruptGuard {
public:
    InterruptGuard() {
        g_render_signal.store(0);
        for (std::size_t k = 0; k < 2; ++k) {
            struct sigaction action {};
            action.sa_handler = on_render_signal;
            action.sa_flags = SA_RESTART;
            sigemptyset(&action.sa_mask);
            installed_[k] = ::sigaction(kSignals[k], &action, &previous_[k]) == 0;
            if (installed_[k] && previous_[k].sa_handler == SIG_IGN) ::sigaction(kSignals[k], &previous_[k], nullptr);
        }
    }
    ~InterruptGuard() {
        for (std::size_t k = 0; k < 2; ++k)
            if (installed_[k]) ::sigaction(kSignals[k], &previous_[k], nullptr);
    }
    InterruptGuard(const InterruptGuard&) = delete;
    InterruptGuard& operator=(const InterruptGuard&) = delete;

    // The signal that asked the run to stop, 0 for none.
    static int requested() { return g_render_signal.load(); }

private:
    static constexpr int kSignals[2] = {SIGINT, SIGTERM};
    struct sigaction previous_[2]{};
    bool installed_[2] = {false, false};
};

// A render stopped by a signal: which, and the end of its one line ("after 3 of 9 frames; ...").
struct Interrupted {
    int signal = 0;
    std::string what;
};

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
        if (const std::string why = folder_refuses_files(dir.string(), "out"); !why.empty()) {
            cleanup();
            throw BadInput("--out " + dir.string() + ": output directory is not writable (" + why + ")");
        }
    }
    ~OutputDir() {
        if (!keep_) cleanup();
    }
    OutputDir(const OutputDir&) = delete;
    OutputDir& operator=(const OutputDir&) = delete;

    void keep() { keep_ = true; }
    const fs::path& path() const { return dir_; }

    // An unsharded run replaces the previous run in its folder, as a .h5 or bag is replaced whole:
    // before its first frame is written, the entries an earlier run wrote there go (frame_NNNNNN
    // folders, the files a single pose writes (frame_files.h), their leftover temporaries); no other
    // file is touched. What an earlier run wrote is known by its meta.json ("format":
    // "vksonar-frame-N"): a single pose's files go only beside one, and a frame folder holding anything
    // no run writes (the user's notes, a meta.json of something else) is refused, not removed, naming it.
    // Run once, on the write-behind thread, just before the first frame: a run that fails before it
    // leaves the earlier run as it was.
    void clear_previous_run() {
        if (cleared_) return;
        cleared_ = true;
        std::error_code ec;
        std::vector<fs::path> stale;
        const auto ours = [](std::string name) { // a frame file's name, or its leftover temporary's
            if (name.rfind(".~", 0) == 0) name = name.substr(2);
            return is_frame_file(name);
        };
        const bool single_pose_run = written_by_vksonar(dir_ / kMetaJson);
        // A frame folder without meta.json (a killed run's last) is an earlier run's only beside one
        // that has it, or a single pose's: a folder of frame-named files alone is someone's own.
        std::vector<fs::path> frame_folders;
        std::vector<fs::path> set_aside; // an earlier clearing's leftovers (below): removed as we go, if we can
        bool run_seen = single_pose_run;
        for (const auto& entry : fs::directory_iterator(dir_, ec)) {
            const std::string name = entry.path().filename().string();
            if (name.rfind(kSetAside, 0) == 0) {
                set_aside.push_back(entry.path());
            } else if (name.size() > 6 && name.rfind("frame_", 0) == 0 &&
                       name.find_first_not_of("0123456789", 6) == std::string::npos && entry.is_directory(ec) &&
                       !entry.is_symlink(ec)) {
                frame_folders.push_back(entry.path());
                run_seen = run_seen || written_by_vksonar(entry.path() / kMetaJson);
            } else if (ours(name) && !entry.is_directory(ec) && (single_pose_run || name.rfind(".~", 0) == 0)) {
                stale.push_back(entry.path());
            }
        }
        for (const fs::path& folder : frame_folders) {
            const std::string name = folder.filename().string();
            const bool has_meta = fs::exists(folder / kMetaJson, ec);
            if (has_meta && !written_by_vksonar(folder / kMetaJson))
                throw BadInput("--out " + dir_.string() + ": " + name + "/" + std::string(kMetaJson) +
                               " is not a vksonar frame's; move the folder, or give another --out");
            if (!has_meta && !run_seen)
                throw BadInput("--out " + dir_.string() + ": " + name +
                               " has no meta.json, and no vksonar run's frame lies beside it; move it, or give "
                               "another --out");
            for (const auto& inside : fs::directory_iterator(folder, ec))
                if (!ours(inside.path().filename().string()) || inside.is_directory(ec))
                    throw BadInput("--out " + dir_.string() + ": " + name + " holds " +
                                   inside.path().filename().string() +
                                   ", which no vksonar run writes; move it, or give another --out");
            stale.push_back(folder);
        }
        if (ec) throw Failure("--out " + dir_.string() + ": cannot list the folder: " + ec.message());
        for (const fs::path& leftover : set_aside)
            fs::remove_all(leftover, ec);
        // All or nothing: every earlier file and frame folder is first renamed aside (a hidden name in the same
        // folder, new to it), and put back if one cannot be, so that a failure leaves the earlier run whole; only
        // then are they removed, and one that cannot be stays aside, named in the error (the next clearing tries
        // it again), with none of the earlier frames left under their names (a folder of a few of them looked
        // like a whole run). Where a folder cannot be renamed at all (an overlay filesystem's lower layer:
        // EXDEV), each is removed where it is, as before.
        std::vector<std::pair<fs::path, fs::path>> aside;
        std::uint64_t serial = 0;
        for (const fs::path& path : stale) {
            fs::path hidden;
            do {
                hidden = dir_ / (std::string(kSetAside) + std::to_string(::getpid()) + "-" + std::to_string(serial++) +
                                 "-" + path.filename().string());
            } while (fs::exists(fs::symlink_status(hidden, ec)));
            fs::rename(path, hidden, ec);
            if (ec == std::errc::cross_device_link) {
                put_back(aside);
                aside.clear();
                remove_in_place(stale);
                return;
            }
            if (ec) {
                const std::string why = ec.message();
                const std::size_t stranded = put_back(aside);
                throw Failure("cannot remove " + path.string() + " (an earlier run's): " + why +
                              (stranded == 0 ? "; the earlier run is left as it was"
                                             : "; " + std::to_string(stranded) +
                                                   " of its files could not be put back "
                                                   "and are in " +
                                                   dir_.string() + " as " + kSetAside + "*"));
            }
            aside.emplace_back(path, hidden);
        }
        std::string failed;
        for (const auto& [path, hidden] : aside) {
            fs::remove_all(hidden, ec);
            if (ec && failed.empty())
                failed = "cannot remove " + hidden.string() + " (an earlier run's " + path.filename().string() +
                         ", moved aside): " + ec.message();
        }
        if (!failed.empty()) throw Failure(failed + "; none of the earlier run's frames is left in " + dir_.string());
    }

private:
    static constexpr const char* kSetAside = ".~earlier-"; // clear_previous_run's hidden names: .~earlier-PID-N-NAME

    // Renames each (path, hidden) of `aside` back, last first; how many could not be.
    static std::size_t put_back(const std::vector<std::pair<fs::path, fs::path>>& aside) {
        std::size_t stranded = 0;
        std::error_code ec;
        for (auto it = aside.rbegin(); it != aside.rend(); ++it) {
            fs::rename(it->second, it->first, ec);
            if (ec) ++stranded;
        }
        return stranded;
    }
    // Removes each of `stale` where it is (no rename: EXDEV), stopping at the first that cannot be.
    static void remove_in_place(const std::vector<fs::path>& stale) {
        std::error_code ec;
        for (const fs::path& path : stale) {
            fs::remove_all(path, ec);
            if (ec) throw Failure("cannot remove " + path.string() + " (an earlier run's): " + ec.message());
        }
    }

    // A meta.json a vksonar run wrote: it starts with its "format" (host::meta_json_plan_part).
    static bool written_by_vksonar(const fs::path& meta) {
        std::ifstream in(meta, std::ios::binary);
        char head[64] = {};
        in.read(head, sizeof head - 1);
        return std::string_view(head).find("\"format\": \"vksonar-frame-") != std::string_view::npos;
    }
    void cleanup() {
        std::error_code ec;
        if (!created_.empty()) fs::remove_all(created_, ec);
        created_.clear();
    }
    fs::path dir_;
    fs::path created_;
    bool keep_ = false;
    bool cleared_ = false;
};

// ---- the output file -------------------------------------------------------------------------

// OUT with the links of its last part followed: a run writes and renames onto the link's target, so a
// symlinked --out stays a link to the file that is written.
fs::path resolve_links(fs::path path) {
    std::error_code ec;
    for (int hops = 0; hops < 40 && fs::is_symlink(path, ec); ++hops) {
        const fs::path to = fs::read_symlink(path, ec);
        if (ec) break;
        path = to.is_absolute() ? to : (path.has_parent_path() ? path.parent_path() : fs::path(".")) / to;
    }
    return path;
}

// A shard's file has one writer at a time: an advisory lock (flock) on `.~NAME.lock` beside it, held
// for the run and removed at its end. A second run of the same shard is refused in one line rather
// than writing into (or truncating) the file the first one writes. The lock file's inode is checked
// after the lock is taken, so a run that took the lock of a file its holder removed tries again.
class ShardLock {
public:
    ShardLock(const fs::path& target, const std::string& out) {
        const std::string name = ".~" + target.filename().string() + ".lock";
        path_ = target.has_parent_path() ? target.parent_path() / name : fs::path(name);
        for (int attempt = 0; attempt < 16; ++attempt) {
            fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
            if (fd_ < 0)
                throw Failure("--out " + out + ": cannot create the lock file " + path_.string() + ": " +
                              std::strerror(errno));
            if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
                const int e = errno;
                ::close(std::exchange(fd_, -1));
                if (e == EWOULDBLOCK)
                    throw Failure("--out " + out + ": another vksonar run is writing this shard (it holds the lock " +
                                  path_.string() + ")");
                throw Failure("--out " + out + ": cannot lock " + path_.string() + ": " + std::strerror(e));
            }
            struct stat held {};
            struct stat named {};
            if (::fstat(fd_, &held) == 0 && ::stat(path_.c_str(), &named) == 0 && held.st_dev == named.st_dev &&
                held.st_ino == named.st_ino)
                return;
            ::close(std::exchange(fd_, -1)); // its holder removed it as we took it: take the new one
        }
        throw Failure("--out " + out + ": cannot take the lock " + path_.string());
    }
    ~ShardLock() {
        if (fd_ < 0) return;
        ::unlink(path_.c_str()); // while still held: a waiting run sees another inode and tries again
        ::close(fd_);
    }
    ShardLock(const ShardLock&) = delete;
    ShardLock& operator=(const ShardLock&) = delete;

private:
    fs::path path_;
    int fd_ = -1;
};

// The dataset file (.h5 or .mcap): its folder must exist and be writable before anything renders.
// Nothing here removes or truncates a file this run did not create:
// - an unsharded run writes a new file under a temporary name beside OUT (`.~NAME.writing-PID`) and
//   renames it onto OUT once it is closed (publish): readers and concurrent runs never see a torn
//   file, and a failed run removes its temporary and leaves OUT as it was;
// - a shard holds its lock (ShardLock), writes a new file the same way and renames it onto OUT as soon
//   as it is made (publish), so a killed shard leaves its frames at OUT for the re-run; a resume
//   replaces OUT by rename too. A shard's file that this run did not make is never removed.
// OUT's links are followed (target()).
class DatasetFile {
public:
    DatasetFile(const fs::path& out, bool shard) : target_(resolve_links(out)) {
        std::error_code ec;
        const std::string named = out.string();
        const fs::path folder = target_.has_parent_path() ? target_.parent_path() : fs::path(".");
        if (fs::is_directory(target_, ec)) throw BadInput("--out " + named + ": is a directory");
        // its folder exists and takes a new file (a probe, which access() is not for root), where the file
        // is made: beside a link's target
        require_writable_output("--out", named, target_.string());
        const std::string name = ".~" + target_.filename().string() + ".writing-" + std::to_string(::getpid());
        temporary_ = target_.has_parent_path() ? folder / name : fs::path(name);
        if (shard) lock_.emplace(target_, named);
    }
    ~DatasetFile() {
        std::error_code ec;
        if (!published_) fs::remove(temporary_, ec); // this run's own file, not (yet) OUT
        if (published_ && removable_ && !keep_) fs::remove(target_, ec);
    }
    DatasetFile(const DatasetFile&) = delete;
    DatasetFile& operator=(const DatasetFile&) = delete;

    // A frame is in it (a shard's published file stays).
    void keep() { keep_ = true; }
    const fs::path& target() const { return target_; }
    const fs::path& temporary() const { return temporary_; }
    // Renames the temporary onto OUT's target. A shard's new file, made where no file was, is removed
    // again if the run fails before its first frame.
    void publish() {
        std::error_code ec;
        const bool was_there = fs::exists(target_, ec);
        fs::rename(temporary_, target_, ec);
        if (ec) throw Failure("cannot rename " + temporary_.string() + " to " + target_.string() + ": " + ec.message());
        published_ = true;
        removable_ = !was_there;
    }

private:
    fs::path target_, temporary_;
    std::optional<ShardLock> lock_;
    bool published_ = false, removable_ = false, keep_ = false;
};

DatasetMeta dataset_meta(const Plan& plan, const std::string& scene, const std::string& scene_hash,
                         const std::string& backend, const std::string& device, std::uint64_t seed) {
    DatasetMeta meta;
    meta.scene_hash = scene_hash;
    meta.config_json = config_to_json(plan.config);
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
    auto created = DatasetWriter::create(path, plan, meta, options, file.temporary().string());
    if (!created) throw Failure(created.error().message);
    if (meta.shard) file.publish(); // at OUT from its first flush on: a killed shard resumes from it
    return std::move(created.value());
}

// ---- the steps of a render after its inputs (run_render below runs them in order) -----------------

// Frame folders: a shard's --out and an unsharded run's are never the same folder. A re-run shard resumes
// the frames its folder holds, and `merge` takes a folder with shard.json as that shard's whole output, so
// an unsharded run there (its frames beside a stale shard.json) would be merged as the shard, and a shard
// in an unsharded run's folder would count that run's frames as its own. Refused before anything is
// written. (A .h5 or bag is one file: an unsharded run replaces it whole, and a shard refuses an
// unsharded run's file when it resumes.)
void refuse_mixed_folders(const RenderJob& job) {
    if (job.dataset || job.bag) return;
    std::error_code ec;
    const std::string& out = job.out_path;
    if (!fs::is_directory(out, ec)) return;
    const bool shard_record = fs::exists(fs::path(out) / "shard.json", ec);
    if (!job.shard && shard_record) {
        const ShardRecord held = read_manifest(out).shard;
        throw BadInput("--out " + out + " holds shard " + std::to_string(held.index) + "/" +
                       std::to_string(held.count) + " of a run (shard.json): give the unsharded run another --out");
    }
    if (!job.shard || shard_record) return;
    for (const auto& entry : fs::directory_iterator(out, ec))
        if (entry.path().filename() == kMetaJson || entry.path().filename().string().rfind("frame_", 0) == 0)
            throw BadInput("--out " + out + " holds an unsharded run, not shard " + std::to_string(job.shard->index) +
                           "/" + std::to_string(job.shard->count) + ": give each shard its own --out");
}

// The output directory, or the .h5 / .mcap file's place: made only once every input is valid, and
// removed again if the run fails before a frame is on disk.
struct OutputTarget {
    std::optional<OutputDir> dir;      // frame folders
    std::optional<ShardLock> dir_lock; // a frame-folder shard's lock (DIR/.~shard.json.lock)
    std::optional<DatasetFile> file;   // .h5 or .mcap
};

void create_output(const RenderJob& job, OutputTarget& target) {
    if (job.dataset || job.bag) {
        target.file.emplace(job.out_path, job.shard.has_value()); // a shard's file is resumed (or refused), not removed
        return;
    }
    target.dir.emplace(job.out_path);
    // One run of a frame-folder shard at a time too, as of a shard's file.
    if (job.shard) target.dir_lock.emplace(fs::path(job.out_path) / "shard.json", job.out_path);
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
                     LegacyState& legacy_state, const SceneAndConfig& loaded) {
    const Scene& scene = loaded.scene;
    legacy_state.mode = plan.config.mode;
    Outputs out(plan, job.save, fan);
    out.config_json = config_to_json(plan.config);
    out.config_parsed = nlohmann::ordered_json::parse(out.config_json);
    out.meta_plan_part = host::meta_json_plan_part(plan);
    out.effects = host::effects_json(
        credit_scene_requests(plan.effects.states, loaded.effects_without_scene, loaded.config.effects));
    out.scene_path = job.scene_path;
    out.scene_hash = job.scene_hash;
    out.backend = device.backend_name;
    out.backend_reason = device.backend_reason;
    out.device = device.description;
    out.legacy = plan.config.mode != SonarMode::physical ? &legacy_state : nullptr;
    out.shard = job.shard ? &*job.shard : nullptr;
    out.objects = host::objects_json(scene);
    out.class_names = scene.classes();
    return out;
}

// ---- where the frames go -----------------------------------------------------------------------

// The writers of a .h5 or .mcap run (null for frame folders) and, for a re-run shard, which of the
// trajectory's frames are already on disk (`done`: skipped).
struct Writers {
    std::unique_ptr<DatasetWriter> dataset;
    std::vector<char> done;
    std::vector<std::string> damaged; // a re-run folder shard: frames whose files are not as meta.json says
    std::unique_ptr<McapDatasetWriter> bag;
    bool bag_complete = false; // a re-run shard whose bag holds its whole block already
};

void open_dataset(const RenderJob& job, const Plan& plan, const Outputs& outputs, const Args& args, DatasetFile& file,
                  Writers& writers) {
    DatasetMeta meta = dataset_meta(plan, job.scene_path, job.scene_hash, outputs.backend, outputs.device, job.seed);
    meta.objects_json = outputs.objects.dump();
    meta.effects_json = outputs.effects.dump(); // with the scene's requests named, as meta.json's
    meta.shard = job.shard;
    DatasetOptions options;
    options.polar_u16 = job.save.polar_u16;
    options.labels = job.save.labels;
    options.flow = job.save.flow;
    options.compress = args.has("--compress");
    options.has_time = job.timed;
    writers.dataset = open_dataset_writer(file.target().string(), plan, meta, options, file, writers.done);
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
    start_folder_shard(dir.path().string(), manifest, writers.done, &writers.damaged);
}

// What a bag's messages depend on: the run's identity (shard.h) with the trajectory's hash and frame
// count and the scene's hash, and the bag's own settings. A shard's bag records it in its shard record
// (compared by `vksonar merge` and a re-run); an unsharded or merged bag in its run record, the same
// entries (an unsharded run is the one shard of itself), so that the two bags stay byte-identical.
Identity bag_identity(const Args& args, const RenderJob& job, const Outputs& outputs, const McapOptions& bag_options) {
    ShardRecord whole;
    whole.total = job.poses.size();
    whole.scene_hash = job.scene_hash;
    if (job.trajectory) whole.trajectory_hash = file_fnv1a64(args.value("--trajectory"));
    Identity identity = run_identity(outputs.config_json, job.seed, job.scene_path, outputs.backend,
                                     save_list(job.save), job.timed, job.shard ? &*job.shard : &whole);
    // One --pose: its --frame-index keys the noise (a trajectory's are its line numbers), so the record
    // that is to render the bag again holds it.
    if (!job.trajectory && job.poses.size() == 1)
        identity.emplace_back("frame_index", std::to_string(job.poses[0].line));
    // The shortest text that reads back as the same double (29.97, not 29.969999999999999).
    char rate[32];
    for (int digits = 6; digits <= 17; ++digits) {
        std::snprintf(rate, sizeof rate, "%.*g", digits, bag_options.rate);
        if (std::strtod(rate, nullptr) == bag_options.rate) break;
    }
    identity.insert(identity.end(), {{"ros_prefix", bag_options.prefix},
                                     {"ros_frame", bag_options.frame},
                                     {"ros_sonar_dtype", bag_options.sonar_u16 ? "uint16" : "float32"},
                                     {"rate", job.timed ? std::string("time column") : std::string(rate)}});
    return identity;
}

// A shard's bag: its record and the run's identity, for `vksonar merge` and a re-run
// (merge_mcap.cpp). A re-run goes on after the frames already in the bag.
void resume_bag_shard(const Args& args, const RenderJob& job, const Plan& plan, const Outputs& outputs,
                      McapOptions& bag_options, const fs::path& target, Writers& writers) {
    const ShardRecord& shard = *job.shard;
    const Identity identity = bag_identity(args, job, outputs, bag_options);
    bag_options.shard = shard_metadata(shard, identity, outputs.backend, outputs.device, bag_options.zstd);
    BagResume resumed = bag_shard_resume(target.string(), plan, bag_options, shard, identity);
    for (std::uint64_t k = 0; k < resumed.frames; ++k)
        writers.done[job.first + k] = 1;
    writers.bag = std::move(resumed.writer);
    writers.bag_complete = resumed.complete;
}

void open_bag(const Args& args, RenderJob& job, const Plan& plan, const Outputs& outputs, DatasetFile& file,
              Writers& writers) {
    McapOptions& bag_options = *job.bag_options;
    bag_options.zstd = args.has("--compress");
    bag_options.library = std::string("vksonar ") + host::vksonar_version() + " (its own MCAP writer)";
    if (job.shard)
        resume_bag_shard(args, job, plan, outputs, bag_options, file.target(), writers);
    else
        bag_options.run = run_metadata(bag_identity(args, job, outputs, bag_options), host::vksonar_version());
    if (!writers.bag && !writers.bag_complete) {
        // Named as OUT's target in the bag (rosbag2's metadata), written under the temporary name.
        auto created = McapDatasetWriter::create(file.target().string(), plan, bag_options, file.temporary().string());
        if (!created) throw Failure(created.error().message);
        writers.bag = std::move(created.value());
        if (job.shard) file.publish(); // at OUT from its first record on: a killed shard resumes from it
    }
}

Writers open_writers(const Args& args, RenderJob& job, const Plan& plan, const Outputs& outputs, OutputTarget& target) {
    Writers writers;
    writers.done.assign(job.poses.size(), 0);
    if (job.dataset)
        open_dataset(job, plan, outputs, args, *target.file, writers);
    else if (job.shard && !job.bag)
        start_folder_manifest(job, outputs, *target.dir, writers);
    if (job.bag) open_bag(args, job, plan, outputs, *target.file, writers);
    return writers;
}

// ---- writing one frame (on the write-behind thread) ----------------------------------------------

void write_bag_frame(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs, Writers& writers) {
    const McapOptions& bag_options = *job.bag_options;
    const bool u16 = bag_options.polar || bag_options.sonar_u16;
    if (u16) host::quantize_display(slot.frame, outputs.quantized);
    if (bag_options.fan) outputs.fan.render(slot.frame, outputs.image, outputs.image_workers);
    // Without a time column, time_s is the frame's ordinal in the whole trajectory (a shard's
    // first frame is `first`): the stamps are ordinal / rate, in a shard's bag as in the
    // unsharded run's.
    const auto stamp_ns =
        job.timed ? slot.time_ns : static_cast<std::uint64_t>(std::llround(slot.time_s / bag_options.rate * 1e9));
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

// Removes a frame folder's frame files and leftover temporaries, meta.json first: a crash while
// clearing leaves a folder without meta.json, which a re-run renders again. Other names are left.
void clear_frame_folder(const fs::path& dir) {
    std::error_code ec;
    fs::remove(dir / kMetaJson, ec);
    if (ec) throw Failure("cannot remove " + (dir / kMetaJson).string() + " (a damaged frame's): " + ec.message());
    std::vector<fs::path> stale;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
        const std::string name = entry.path().filename().string();
        if ((is_frame_file(name) || name.rfind(".~", 0) == 0) && !entry.is_directory(ec)) stale.push_back(entry.path());
    }
    if (ec) throw Failure("cannot list " + dir.string() + ": " + ec.message());
    for (const fs::path& path : stale) {
        fs::remove(path, ec);
        if (ec) throw Failure("cannot remove " + path.string() + " (a damaged frame's): " + ec.message());
    }
}

// A trajectory's frame goes to DIR/frame_NNNNNN/ (NNNNNN its line), a single pose's to DIR itself.
void write_folder_frame(const WriteBehind::Slot& slot, const RenderJob& job, Outputs& outputs, OutputDir& out_dir) {
    if (!job.shard) out_dir.clear_previous_run(); // a shard resumes the frames its folder holds
    fs::path dir = out_dir.path();
    bool made = false; // this run made the frame's folder
    if (job.trajectory) {
        // The run's folder was made once (OutputDir); a frame's folder is made in it, never the path
        // to it again: a folder removed during the run stops it with one line instead of being made
        // anew with the earlier frames missing.
        std::error_code ec;
        if (!fs::is_directory(out_dir.path(), ec))
            throw Failure("--out " + out_dir.path().string() + ": the output folder is gone (removed during the run)");
        dir /= frame_dir_name(slot.line);
        made = fs::create_directory(dir, ec);
        if (ec) throw Failure("cannot create " + dir.string() + ": " + ec.message());
        // A shard's frame folder that is already there is one the re-run found damaged or cut off:
        // its files go first, so it ends up holding exactly this frame's files (a file the earlier
        // run left that this one does not write would otherwise stay, and merge refuse the frame).
        if (!made && job.shard) clear_frame_folder(dir);
    }
    // An unsharded trajectory's frame that fails half written goes again (its folder holds part of it), and the
    // error says what OUT holds: the frames before it, each whole (with none, OutputDir removes the run's
    // folder). A shard keeps its folder for the re-run, which redoes a frame without meta.json.
    const auto leaves = [&](const std::exception& failed) {
        std::string what = failed.what();
        if (!job.trajectory || job.shard || !made) return what;
        std::error_code ec;
        fs::remove_all(dir, ec);
        std::size_t before = 0;
        while (job.first + before < job.poses.size() && job.poses[job.first + before].line != slot.line)
            ++before;
        if (before == 0 || job.first + before == job.poses.size()) return what;
        return what + "; " + out_dir.path().string() + " holds this run's first " + std::to_string(before) +
               " frames, each whole (" + frame_dir_name(job.poses[job.first].line) + " to " +
               frame_dir_name(job.poses[job.first + before - 1].line) + ")";
    };
    try {
        write_frame(outputs, dir, slot.frame, slot.pose, job.timed ? &slot.time_s : nullptr,
                    job.save.flow ? &slot.flow : nullptr); // meta.json last: done
    } catch (const BadInput& e) {
        throw BadInput(leaves(e));
    } catch (const Failure& e) {
        throw Failure(leaves(e));
    }
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

    // False: a signal stopped it at a frame boundary (InterruptGuard) before every frame was
    // submitted; a frame held back for its flow is then dropped, not written.
    bool run(const std::vector<char>& done, Progress& progress) {
        for (std::size_t i = job_.first; i < job_.end; ++i) {
            if (done[i] && !held_) continue; // a re-run shard: this frame is complete on disk
            if (InterruptGuard::requested()) return false;
            WriteBehind::Slot& slot = writer_.acquire(held_ ? 1 : 0); // rethrows a write error: the run stops there
            render_into(i, slot, next_rendered(i, done));
            if (held_) submit_held(&slot);
            if (done[i]) continue; // rendered for the previous frame's flow only; the slot is reused
            if (job_.save.flow) {
                held_ = &slot;
            } else {
                writer_.submit();
            }
            progress.show(false);
        }
        if (!held_) return true;
        if (InterruptGuard::requested()) return false;
        if (job_.end < job_.poses.size()) { // the next shard's first frame
            WriteBehind::Slot& next = writer_.acquire(1);
            render_into(job_.end, next);
            submit_held(&next);
        } else {
            submit_held(nullptr);
        }
        return true;
    }

private:
    // The frame this loop renders after frame i, where it knows one: announced to render() so that a
    // GPU renders it while the host finishes frame i (a wrong guess costs time, never bytes).
    const TrajectoryPose* next_rendered(std::size_t i, const std::vector<char>& done) const {
        const std::size_t next = i + 1;
        if (next >= job_.poses.size()) return nullptr;
        if (next < job_.end && (!done[next] || (job_.save.flow && !done[i]))) return &job_.poses[next];
        if (next == job_.end && job_.save.flow) return &job_.poses[next]; // the next shard's first frame
        return nullptr;
    }

    void render_into(std::size_t i, WriteBehind::Slot& slot, const TrajectoryPose* next = nullptr) {
        const TrajectoryPose& item = job_.poses[i];
        auto rendered = next ? renderer_.render(item.pose, item.line, slot.frame, NextFrame{next->pose, next->line})
                             : renderer_.render(item.pose, item.line, slot.frame);
        if (!rendered) {
            const std::string where =
                job_.trajectory ? args_.value("--trajectory") + ":" + std::to_string(item.line) + ": " : std::string();
            throw Failure(where + rendered.error().message);
        }
        slot.pose = item.pose;
        slot.line = item.line;
        slot.time_s = job_.timed ? item.time_s : static_cast<double>(i); // the .h5 time: the global ordinal
        slot.time_ns = item.time_ns;
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
    // An unsharded .h5 or bag replaces OUT only now, whole.
    if (target.file && !job.shard && (writers.dataset || writers.bag)) target.file->publish();
    if (!job.shard) return;
    // A shard's output is its result even when its block is empty or was already complete.
    if (target.file) target.file->keep();
    if (target.dir) target.dir->keep();
    const double seconds = progress.seconds();
    std::fprintf(stderr, "vksonar: shard %llu/%llu: %zu frames rendered in %.2f s (%.2f frames/s)\n",
                 static_cast<unsigned long long>(job.shard->index), static_cast<unsigned long long>(job.shard->count),
                 todo, seconds, seconds > 0 ? static_cast<double>(todo) / seconds : 0.0);
}

// A signal stopped the frame loop at a frame boundary. The frames it had rendered are written first
// (the ring holds at most three, each written whole, in a few ms): so what is on disk is the run's
// first frames, every one whole, and no rendered frame is thrown away; a write that hangs is what the
// second signal is for. Then each output is left as a re-run expects it:
// - a shard's .h5 is closed without `complete` (each frame was flushed with its commit record: the
//   re-run resumes after the last), its bag closed with every frame written (a resume copies them);
//   a frame folder holds its whole frames and shard.json. Its lock goes when `target` does.
// - an unsharded .h5 or bag is abandoned: its temporary is removed with `target`, OUT stays as it was.
// - an unsharded frame-folder run keeps the frames written (an earlier run's frames went before the
//   first; with none written the folder is as it was, or removed when this run made it).
Interrupted stop_run(const RenderJob& job, WriteBehind& writer, Writers& writers, Progress& progress, std::size_t todo,
                     int signal) {
    writer.finish(); // rethrows a write error: that is the run's outcome then
    const std::uint64_t written = writer.written();
    progress.finish();
    const std::string& out = job.out_path;
    std::string state;
    if (job.shard) {
        if (writers.bag)
            if (auto closed = writers.bag->close(); !closed) throw Failure(closed.error().message);
        writers.bag.reset();
        writers.dataset.reset(); // not close(): that would mark it complete
        const std::size_t block = job.end - job.first;
        state = "shard " + out + " keeps " + std::to_string(block - todo + written) + " of its " +
                std::to_string(block) + " frames, re-run the same command to resume";
    } else if (job.dataset || job.bag) {
        writers.bag.reset();
        writers.dataset.reset();
        state = out + " was not written";
    } else if (written == 0) {
        state = "nothing was written to " + out;
    } else {
        state = out + " holds this run's first " + std::to_string(written) + " frames, each whole (" +
                frame_dir_name(job.poses[job.first].line) + " to " +
                frame_dir_name(job.poses[job.first + written - 1].line) + ")";
    }
    return {signal, "after " + std::to_string(written) + " of " + std::to_string(todo) + " frames; " + state};
}

// Order matters for the "no partial output" promise (top of the file): everything that can be
// checked is checked before create_output. Returns the stop a signal asked for; every output is
// closed, and a temporary removed, by the time it returns.
std::optional<Interrupted> render(const Args& args) {
    RenderJob job = parse_job(args);
    const SceneAndConfig loaded = load_scene_and_config(args, job);
    if (const int signal = InterruptGuard::requested())
        return Interrupted{signal, "before the first frame; nothing was written"};
    refuse_mixed_folders(job);
    OutputTarget target;
    create_output(job, target);

    Device device = open_device(job);
    Renderer renderer = make_renderer(device, loaded.config, loaded.scene, job);
    const Plan& plan = renderer_plan(renderer);
    const host::FanRenderer fan(plan, renderer_workers(renderer)); // the renderer's threads, idle until its first frame
    LegacyState legacy_state;
    Outputs outputs = make_outputs(plan, job, device, fan, legacy_state, loaded);
    // The writer thread draws a fan image a frame for .mcap and fan.png (about 5 ms here at the default,
    // more than a GPU's frame): with half the cores, where there are four or more, it shares the rows out
    // (the rest are the renderer's; a 2-core machine's cores are busy rendering).
    const unsigned cores = host::usable_cpus();
    host::Workers image_workers(cores >= 4 ? std::min(8u, cores / 2) : 1u);
    outputs.image_workers = &image_workers;
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
                                   job.end > job.first ? job.poses[job.end - 1].line : 0, job.end - job.first - todo,
                                   writers.damaged)
                         .c_str());
    Progress progress(writer, todo, job.trajectory && ::isatty(::fileno(stderr)));
    if (!FrameLoop(args, job, renderer, writer).run(writers.done, progress))
        return stop_run(job, writer, writers, progress, todo, InterruptGuard::requested());
    finish_run(job, writer, writers, target, progress, todo);
    return std::nullopt;
}

} // namespace

// A signal's stop is one line once every output is closed (render returned), exit 130 (SIGINT) or
// 143 (SIGTERM), as a shell reports a process its signal ended. A signal that comes after the last
// frame was rendered lets the run finish as usual.
int run_render(const std::vector<std::string>& argv) {
    const Args args = parse_render_args(argv);
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    const InterruptGuard guard;
    const std::optional<Interrupted> stopped = render(args);
    if (!stopped) return 0;
    std::fprintf(stderr, "vksonar render: interrupted (%s) %s\n", stopped->signal == SIGINT ? "SIGINT" : "SIGTERM",
                 detail::escape_control_chars(stopped->what).c_str());
    return 128 + stopped->signal;
}

} // namespace vksonar::cli
