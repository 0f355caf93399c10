// Sharding a trajectory across the tasks of a batch engine (docs/scale.md): `vksonar render
// --trajectory poses.csv --shard i/N` renders the i-th of N contiguous blocks of the trajectory's
// frames. Without --shard the shard comes from the engine's environment: a Slurm job array
// (SLURM_ARRAY_TASK_ID with SLURM_ARRAY_TASK_MIN/MAX/STEP or SLURM_ARRAY_TASK_COUNT) or a Kubernetes
// Indexed Job (JOB_COMPLETION_INDEX, the count from --shard-count or VKSONAR_SHARD_COUNT).
//
// Frames keep their global frame index (the trajectory line, which seeds the noise), so the union
// of the N shards is the unsharded run, bit for bit. A shard records itself (ShardRecord) in its
// output: DIR/shard.json beside the frame folders, or attributes of the .h5 file; `vksonar merge`
// reads those records back and checks them for gaps, overlaps and mismatched runs.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vksonar {
class Scene;
}

namespace vksonar::cli {

// Which block of which run a shard is.
struct ShardRecord {
    std::uint64_t index = 0, count = 1; // shard index/count (0-based index)
    std::string source;                 // where it came from: "--shard", "SLURM_ARRAY_TASK_ID=5 (...)", ...
    std::uint64_t first = 0, end = 0;   // the block: frame ordinals [first, end) of the trajectory
    std::uint64_t total = 0;            // frames in the whole trajectory
    std::string trajectory;             // the trajectory file as given
    std::string trajectory_hash;        // FNV-1a 64 of its bytes, 16 hex digits
    std::string scene_hash;             // scene_fnv1a64 of the loaded scene (empty: not known)
};

// Block i of N over `total` frames: [floor(i * total / N), floor((i + 1) * total / N)), so blocks are
// contiguous, in order, and differ in size by at most one frame.
std::pair<std::uint64_t, std::uint64_t> shard_block(std::uint64_t index, std::uint64_t count, std::uint64_t total);

// Parses "INDEX/COUNT" (0 <= INDEX < COUNT). `what` names the flag or variable in the error (BadInput).
std::pair<std::uint64_t, std::uint64_t> parse_shard(const std::string& text, const std::string& what);

// The environment, as getenv: null when unset. Tests and callers may pass their own.
using EnvLookup = std::function<const char*(const char*)>;
EnvLookup process_env();

// The shard of this run: --shard (`flag`), else the engine's environment; nullopt when neither
// names one. `count_flag` is --shard-count (for JOB_COMPLETION_INDEX). Throws BadInput with one line
// naming the flag or variable for anything inconsistent. `first`/`end`/`total` are filled in for
// `total` frames; `trajectory`/`trajectory_hash` are left to the caller.
std::optional<ShardRecord> resolve_shard(const std::optional<std::string>& flag,
                                         const std::optional<std::string>& count_flag, std::uint64_t total,
                                         const EnvLookup& env);

// FNV-1a 64 of a file's bytes as 16 hex digits (identifies the trajectory a shard came from).
std::string file_fnv1a64(const std::string& path);

// ---- per-frame folders: DIR/shard.json and the done marker ------------------------------------

// What must be equal between shards of one run, and between a shard and its re-run: name -> value
// text. `vksonar merge` and the resume check report the first name that differs.
using Identity = std::vector<std::pair<std::string, std::string>>;

// "shard.json" in a shard's output folder: the record, the identity, and the frame lines of the block.
struct FolderManifest {
    ShardRecord shard;
    Identity identity;
    std::vector<std::uint64_t> lines; // trajectory line of each frame of the block, in order
    std::string backend, device;
};
// The identity of a run: the resolved config (JSON text), seed, scene, backend, the arrays saved
// (`save`, a canonical list), whether times come from the trajectory, and for a shard the
// trajectory's hash and frame count and the scene's content hash (scene_fnv1a64, when known).
Identity run_identity(const std::string& config_json, std::uint64_t seed, const std::string& scene,
                      const std::string& backend, const std::string& save, bool timed, const ShardRecord* shard);

std::string manifest_json(const FolderManifest& manifest);
// Reads DIR/shard.json; throws BadInput naming the file on anything missing or malformed.
FolderManifest read_manifest(const std::string& dir);

// The first identity entry that differs between `a` and `b`, as "NAME: A vs B" (values shortened;
// for JSON objects the first differing key); empty when they agree. The scene's path is not compared
// where both identities hold the same scene_fnv1a64 (the scene's content).
std::string identity_difference(const Identity& a, const Identity& b);

// Starts (or resumes) a shard in the output folder `dir`: when dir/shard.json is there it must be
// this shard of this run (else BadInput naming what differs), and every frame of the block whose
// folder is complete is marked in `done` (indexed by frame ordinal); then writes dir/shard.json.
// `damaged` (when given) gets the folder names of the block's frames whose meta.json is there but
// whose files are not as it says (frame_folder_check): they stay not done and are rendered again.
void start_folder_shard(const std::string& dir, const FolderManifest& manifest, std::vector<char>& done,
                        std::vector<std::string>* damaged = nullptr);

// "shard 1/4 (--shard 1/4): frames 250..499 of 1000 (lines 252..501), 20 already on disk", and
// ", 1 damaged (re-rendered): frame_000012" when a re-run found damaged frames.
std::string shard_summary(const ShardRecord& shard, std::uint64_t first_line, std::uint64_t last_line,
                          std::uint64_t already_done, const std::vector<std::string>& damaged = {});

// Where a frame folder stands. meta.json is written last, after every other file of the frame, and
// each file is renamed into place whole (docs/scale.md, "Restarting"); its "files" ({name: bytes})
// lists what was written before it. Nothing is fsynced, so after a crash of the machine (not of
// the process) meta.json can be on disk while an earlier file is empty or missing: the sizes catch that.
struct FrameFolderState {
    enum Kind { absent, complete, damaged };
    Kind kind = absent; // absent: no meta.json (never written, or cut off before it)
    // damaged: the first thing not as meta.json says, relative to the frame folder:
    // "polar.npy: 0 bytes, meta.json says 1048704", "polar.npy: missing, meta.json says 1048704",
    // "meta.json: not JSON (...)".
    std::string problem;
};
// complete: meta.json parses and every file its "files" lists is a regular file of that size. A
// meta.json without "files" (written before it was recorded) is complete as it stands, so shards of
// earlier runs still resume.
FrameFolderState frame_folder_check(const std::string& frame_dir);
bool frame_folder_done(const std::string& frame_dir); // frame_folder_check(...).kind == complete
std::string frame_dir_name(std::uint64_t line);

} // namespace vksonar::cli
