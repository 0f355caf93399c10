// One HDF5 file per trajectory (`vksonar render --out run.h5`): the frames as arrays a Python user
// reads with h5py, the constant metadata once. Layout (docs/datasets.md), names as in meta.json:
//   /polar        float32 [frames, bins, beams]  received intensity, uPa^2 (polar.npy of each frame)
//   /polar_u16    uint16  [frames, bins, beams]  display value x 65535 (only with --save polar_u16)
//   with --save labels (Frame's label arrays, docs/labels.md, and the boxes), all or none:
//   /instance, /class                        uint16  [frames, bins, beams]
//   /instance_fraction, /elevation, /elevation_spread  float32 [frames, bins, beams]
//   /point                                   float32 [frames, bins, beams, 3]
//   /boxes         UTF-8 text of variable length [frames]  the frame's boxes.json, character for character
//   /pose         float64 [frames, 6]            x_m, y_m, z_m, roll_deg, pitch_deg, yaw_deg
//   /frame_index  uint64  [frames]               the trajectory line: the noise stream of the frame
//   /time         float64 [frames]               s, from the trajectory's time column, else the ordinal
//   /beam_angles_rad [beams], /ranges_m [bins]
//   attributes of /: format, frames_written, complete, beams, bins, bin_width_m, range_min_m, ...,
//   config, effects, validity (JSON text), seed, backend, device, scene; a shard (`--shard`, shard.h)
//   adds shard_index, shard_count, shard_source, shard_first, shard_end, trajectory_frames,
//   trajectory and trajectory_fnv1a64.
// Each frame is one chunk; the file is flushed after every frame and `frames_written` says how many
// are whole, so a run that is killed leaves a readable file of the frames before it. `complete` turns
// 1 only when the run ends without an error. The file's 512-byte user block holds the commit record a
// resume trusts instead of frames_written (dataset_h5.cpp, read_commit).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "cli/shard.h"

#include "core/plan.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"

namespace vksonar::cli {

struct DatasetOptions {
    bool polar_u16 = false; // also write /polar_u16
    bool labels = false;    // also write the label arrays (/instance ... /point)
    bool flow = false;      // also write /flow (--save flow: each labelled cell's d_bin, d_beam to the next frame)
    bool compress = false;  // shuffle + deflate level 4 on the frame arrays (lossless)
    bool has_time = false;  // /time holds the trajectory's times, else the frame ordinal
};

// Everything meta.json holds that does not change between frames, as JSON text per attribute.
struct DatasetMeta {
    std::string config_json, effects_json, validity_json;
    std::string objects_json; // the scene's objects and classes (meta.json "objects")
    std::string scene, backend, device;
    std::string scene_hash; // scene_fnv1a64, written with the general attributes (a shard reads it back from there)
    std::uint64_t seed = 0;
    std::optional<ShardRecord> shard; // a shard of a trajectory: written as attributes
};

// What must be equal between the shards of one run (shard.h's Identity), from what the writer is given.
Identity dataset_identity(const DatasetMeta& meta, const DatasetOptions& options);

// What a dataset file says about itself, for `vksonar merge` and for resuming a shard.
struct DatasetInfo {
    std::optional<ShardRecord> shard; // absent: not written with --shard
    Identity identity;
    std::string backend, device;
    std::uint64_t frames_written = 0;
    bool complete = false;
};
// Fails (ErrorCode::io) with one line naming the file when it cannot be read as a vksonar dataset.
Result<DatasetInfo> read_dataset_info(const std::string& path);

// True when this build can write HDF5 (Debian's libhdf5-dev was found at configure time).
bool hdf5_available();
// For a process that exits after its datasets (the CLI), before any other HDF5 call: no HDF5 clean-up at
// exit. A writer whose flush failed (a full disk, a file size limit) could not close its file, and HDF5
// 1.10's exit handler closed it again and crashed (H5F__close_cb, SIGSEGV after the run's one-line error);
// the writers close every file they finish themselves, and an abandoned one is removed.
void skip_hdf5_exit_cleanup();

class DatasetWriter {
public:
    // Creates `path`, or `write_to` when given (a new file the caller renames to `path`; messages name
    // `path`). Never truncates a file that is there: an existing one is an error. Fails with one line
    // naming the file and why (a held HDF5 file lock: another process has it open).
    static Result<std::unique_ptr<DatasetWriter>> create(const std::string& path, const Plan& plan,
                                                         const DatasetMeta& meta, const DatasetOptions& options,
                                                         const std::string& write_to = std::string());
    // Goes on with `path`, written by an earlier run of the same shard, after the frames of its last
    // flush that returned (frames_written()): they are copied into a new file, checked against the
    // hashes recorded with them, and the new file replaces `path`; anything the kill cut off is dropped.
    // ErrorCode::io: the file cannot be read as a dataset, or its frames do not match their record
    // (start over); ErrorCode::invalid_argument: it holds another run or shard (the file is untouched).
    static Result<std::unique_ptr<DatasetWriter>> resume(const std::string& path, const Plan& plan,
                                                         const DatasetMeta& meta, const DatasetOptions& options);
    virtual ~DatasetWriter() = default;
    virtual std::uint64_t frames_written() const = 0;
    // Appends one frame; `display_u16` is the quantized display (bins * beams) when polar_u16 is on,
    // `flow` the frame's flow (bins * beams * 2) when flow is on, `boxes_json` the frame's boxes.json
    // text (host::boxes_json_text) when labels is on: the caller makes it, as it owns the fan image
    // the boxes' fan extents are read off.
    virtual Result<void> append(const Frame& frame, const Pose& pose, double time_s, const std::uint16_t* display_u16,
                                const float* flow = nullptr, const std::string* boxes_json = nullptr) = 0;
    // Marks the file complete and closes it.
    virtual Result<void> close() = 0;
};

} // namespace vksonar::cli
