// `vksonar merge OUT SHARD...`: the outputs of the shards of one trajectory (render --shard, shard.h)
// into the output of the unsharded run. The checks (gaps, overlaps, mismatched runs, incomplete
// shards) are the same for every format; each format brings how to read a shard's record and how to
// write the merged output (MergeFormat). Adding a format is one more entry in merge_cmd.cpp's list.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cli/dataset_mcap.h"
#include "cli/mcap_writer.h"
#include "cli/shard.h"

namespace vksonar::cli {

// What a shard's output says about itself.
struct ShardInput {
    std::string path;
    ShardRecord shard;
    Identity identity; // must equal the other shards' (shard.h)
    std::string backend, device;
    std::uint64_t frames = 0;  // whole frames on disk
    std::string first_missing; // the first frame that is not (when frames < the block), for the error
};

struct MergeFormat {
    const char* name;                            // "frame folders", "HDF5"
    bool (*accepts)(const std::string& path);    // is this path a shard output of this format?
    bool (*output_ok)(const std::string& out);   // may OUT be written in this format?
    const char* output_hint;                     // what OUT must look like, for the error
    ShardInput (*read)(const std::string& path); // throws BadInput with one line naming the path
    // Writes OUT from `shards`, sorted by index and already checked: no gap, no overlap, one run, all
    // complete. Throws BadInput/Failure; leaves nothing at OUT on failure.
    void (*merge)(const std::vector<ShardInput>& shards, const std::string& out);
};

// HDF5 (merge_h5.cpp): shard files written by `render --out FILE.h5 --shard i/N`.
bool h5_merge_accepts(const std::string& path);
bool h5_merge_output_ok(const std::string& out);
ShardInput h5_merge_read(const std::string& path);
void h5_merge(const std::vector<ShardInput>& shards, const std::string& out);

// ROS 2 bags (merge_mcap.cpp): shard bags written by `render --out FILE.mcap --shard i/N`, which
// carry shard_metadata() as a "vksonar_shard" Metadata record.
// `zstd`: the shard's chunks are compressed (--compress), and so will the merged bag's be.
mcap::KeyValues shard_metadata(const ShardRecord& shard, const Identity& identity, const std::string& backend,
                               const std::string& device, bool zstd);
// An unsharded or a merged bag's "vksonar_run" Metadata record (kRunRecordName): the run's identity
// (what a shard's record holds as identity.*), then vksonar_version, the version that rendered it (a
// shard's record carries it too, so the merged bag names the renderer, not the merger).
mcap::KeyValues run_metadata(const Identity& identity, const std::string& vksonar_version);
bool mcap_merge_accepts(const std::string& path);
bool mcap_merge_output_ok(const std::string& out);
ShardInput mcap_merge_read(const std::string& path);
void mcap_merge(const std::vector<ShardInput>& shards, const std::string& out);

// A re-run of a bag shard whose --out bag `path` is there already. Its shard record must name this
// shard of this run (else BadInput, one line, the bag left as it is). A closed bag holding the whole
// block is complete: nothing to render (`complete`, no writer). A bag a killed run left has its whole
// chunks' frames (`frames`, the first frames of the block): they are written again into a new bag
// that replaces it and `writer` goes on after them. A bag that does not read back is started over
// (a warning; no writer, frames 0): then the caller creates the bag as a first run does.
struct BagResume {
    std::unique_ptr<McapDatasetWriter> writer;
    std::uint64_t frames = 0; // whole frames kept, the first of the block
    bool complete = false;
};
BagResume bag_shard_resume(const std::string& path, const Plan& plan, const McapOptions& options,
                           const ShardRecord& shard, const Identity& identity);

} // namespace vksonar::cli
