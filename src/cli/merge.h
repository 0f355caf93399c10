// `vksonar merge OUT SHARD...`: the outputs of the shards of one trajectory (render --shard, shard.h)
// into the output of the unsharded run. The checks (gaps, overlaps, mismatched runs, incomplete
// shards) are the same for every format; each format brings how to read a shard's record and how to
// write the merged output (MergeFormat). Adding a format is one more entry in merge_cmd.cpp's list.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

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
mcap::KeyValues shard_metadata(const ShardRecord& shard, const Identity& identity, const std::string& backend,
                               const std::string& device);
bool mcap_merge_accepts(const std::string& path);
bool mcap_merge_output_ok(const std::string& out);
ShardInput mcap_merge_read(const std::string& path);
void mcap_merge(const std::vector<ShardInput>& shards, const std::string& out);

} // namespace vksonar::cli
