// `vksonar merge OUT.mcap SHARD.mcap...` (merge.h): ROS 2 bags written by `render --out FILE.mcap
// --shard i/N`. Each shard bag carries a "vksonar_shard" Metadata record (its ShardRecord, the run's
// identity, backend and device), written when the shard finishes: a killed shard has none and is
// refused as incomplete (a bag shard is written again whole when re-run). The merge writes the
// shards' messages, in shard order, through the same MCAP writer the unsharded run uses, with a chunk
// boundary after every frame as that run has, per-topic sequence numbers counted across the shards,
// /tf_static once (from the first shard, stamped with the run's first frame), and rosbag2's metadata
// for the whole run: the merged bag is the unsharded run's bag, byte for byte, when OUT has the
// unsharded bag's file name (rosbag2's metadata names the file).
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <map>

#include "cli/args.h"
#include "cli/dataset_mcap.h"
#include "cli/mcap_reader.h"
#include "cli/merge.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

constexpr const char* kShardRecord = "vksonar_shard";
constexpr const char* kIdentityPrefix = "identity.";

bool mcap_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext == ".mcap";
}

std::uint64_t number(const std::string& path, const std::string& key, const std::string& text) {
    try {
        std::size_t used = 0;
        const unsigned long long v = std::stoull(text, &used);
        if (used == text.size()) return v;
    } catch (const std::exception&) {
    }
    throw BadInput("merge: " + path + ": shard record " + key + " = '" + text + "' is not a count");
}

} // namespace

mcap::KeyValues shard_metadata(const ShardRecord& s, const Identity& identity, const std::string& backend,
                               const std::string& device) {
    mcap::KeyValues kv = {{"index", std::to_string(s.index)},
                          {"count", std::to_string(s.count)},
                          {"first", std::to_string(s.first)},
                          {"end", std::to_string(s.end)},
                          {"total", std::to_string(s.total)},
                          {"source", s.source},
                          {"trajectory", s.trajectory},
                          {"trajectory_hash", s.trajectory_hash},
                          {"backend", backend},
                          {"device", device}};
    for (const auto& [key, value] : identity)
        kv.emplace_back(kIdentityPrefix + key, value);
    return kv;
}

bool mcap_merge_accepts(const std::string& path) {
    std::error_code ec;
    return mcap_extension(path) && fs::is_regular_file(path, ec);
}

bool mcap_merge_output_ok(const std::string& out) {
    return mcap_extension(out);
}

ShardInput mcap_merge_read(const std::string& path) {
    ShardInput in;
    in.path = path;
    bool has_record = false;
    std::map<std::uint16_t, std::string> topics;
    mcap::ReadCallbacks cb;
    cb.channel = [&](const mcap::ReadChannel& c) { topics[c.id] = c.topic; };
    cb.message = [&](const mcap::ReadMessage& m) { in.frames += topics[m.channel_id] == "/tf"; }; // one a frame
    cb.metadata = [&](const std::string& name, const mcap::KeyValues& values) {
        if (name != kShardRecord) return;
        has_record = true;
        for (const auto& [key, value] : values) {
            if (key == "index")
                in.shard.index = number(path, key, value);
            else if (key == "count")
                in.shard.count = number(path, key, value);
            else if (key == "first")
                in.shard.first = number(path, key, value);
            else if (key == "end")
                in.shard.end = number(path, key, value);
            else if (key == "total")
                in.shard.total = number(path, key, value);
            else if (key == "source")
                in.shard.source = value;
            else if (key == "trajectory")
                in.shard.trajectory = value;
            else if (key == "trajectory_hash")
                in.shard.trajectory_hash = value;
            else if (key == "backend")
                in.backend = value;
            else if (key == "device")
                in.device = value;
            else if (key.rfind(kIdentityPrefix, 0) == 0)
                in.identity.emplace_back(key.substr(9), value);
        }
    };
    auto read = mcap::read(path, cb);
    if (!read) throw BadInput("merge: " + read.error().message);
    if (!has_record) {
        // The record is written when the shard finishes: without it the bag is a killed shard's, or
        // an unsharded run's.
        if (!read->complete)
            throw BadInput("merge: " + path + ": incomplete (the shard did not finish: " + std::to_string(in.frames) +
                           " whole frames, no shard record); run the shard again");
        throw BadInput("merge: " + path + ": not a shard (no " + std::string(kShardRecord) +
                       " record): render it with --shard");
    }
    if (in.frames < in.shard.end - in.shard.first)
        in.first_missing = "frame ordinal " + std::to_string(in.shard.first + in.frames);
    return in;
}

void mcap_merge(const std::vector<ShardInput>& shards, const std::string& out) {
    // Pass 1, first shard: its schemas and channels, registered in id order as the writer did.
    std::map<std::uint16_t, mcap::ReadSchema> schemas;
    std::map<std::uint16_t, mcap::ReadChannel> channels;
    mcap::ReadCallbacks first;
    first.schema = [&](const mcap::ReadSchema& s) { schemas.emplace(s.id, s); };
    first.channel = [&](const mcap::ReadChannel& c) { channels.emplace(c.id, c); };
    auto head = mcap::read(shards[0].path, first);
    if (!head) throw BadInput("merge: " + head.error().message);

    const fs::path target(out);
    const fs::path temporary =
        (target.has_parent_path() ? target.parent_path() : fs::path(".")) / ("." + target.filename().string() + ".tmp");
    std::error_code ec;
    try {
        mcap::Writer writer;
        mcap::WriterOptions options;
        options.profile = head->profile;
        options.library = head->library;
        options.zstd = head->zstd;
        if (auto opened = writer.open(temporary.string(), options); !opened) throw Failure(opened.error().message);
        std::map<std::uint16_t, std::uint16_t> schema_of; // shard id -> merged id (the same, checked)
        for (const auto& [id, s] : schemas) {
            schema_of[id] = writer.add_schema(s.name, s.encoding, s.data);
            if (schema_of[id] != id) throw Failure("merge: " + shards[0].path + ": schema ids are not 1, 2, ...");
        }
        std::map<std::uint16_t, BagTopic> bag_topics;
        for (const auto& [id, c] : channels) {
            if (!schema_of.count(c.schema_id))
                throw BadInput("merge: " + shards[0].path + ": channel " + c.topic + " has no schema");
            if (writer.add_channel(schema_of[c.schema_id], c.topic, c.encoding, c.metadata) != id)
                throw Failure("merge: " + shards[0].path + ": channel ids are not 1, 2, ...");
            std::string qos;
            for (const auto& [key, value] : c.metadata)
                if (key == "offered_qos_profiles") qos = value.substr(0, value.size() - (value.empty() ? 0 : 1));
            bag_topics[id] = BagTopic{c.topic, schemas[c.schema_id].name, qos, 0};
        }

        // Pass 2: every shard's messages in order.
        std::map<std::uint16_t, std::uint32_t> sequence;
        bool any_frame = false;
        std::uint64_t first_ns = 0, last_ns = 0;
        Result<void> failed;
        for (std::size_t k = 0; k < shards.size(); ++k) {
            std::map<std::uint16_t, std::string> topic_of;
            mcap::ReadCallbacks cb;
            cb.channel = [&](const mcap::ReadChannel& c) {
                topic_of[c.id] = c.topic;
                const auto mine = channels.find(c.id);
                if (mine == channels.end() || mine->second.topic != c.topic || mine->second.schema_id != c.schema_id)
                    throw BadInput("merge: " + shards[k].path + ": its topics differ from " + shards[0].path +
                                   "'s (channel " + std::to_string(c.id) + " " + c.topic + ")");
            };
            cb.message = [&](const mcap::ReadMessage& m) {
                if (!failed) return;
                const std::string& topic = topic_of[m.channel_id];
                if (topic == "/tf_static" && k > 0) return; // once, from the run's first frame
                if (topic == "/tf") {                       // a frame begins: the one before is whole
                    if (any_frame) failed = writer.end_batch();
                    if (!any_frame) first_ns = m.log_time;
                    any_frame = true;
                }
                if (topic == "/tf_static" && !any_frame) first_ns = m.log_time;
                last_ns = m.log_time;
                const std::uint32_t seq = sequence[m.channel_id]++;
                ++bag_topics[m.channel_id].messages;
                if (failed) failed = writer.write(m.channel_id, seq, m.log_time, m.publish_time, m.data, m.size);
            };
            auto r = mcap::read(shards[k].path, cb);
            if (!r) throw BadInput("merge: " + r.error().message);
            if (!failed) throw Failure("merge: " + failed.error().message);
        }
        if (auto e = writer.end_batch(); !e) throw Failure("merge: " + e.error().message);
        std::vector<BagTopic> topics;
        for (const auto& [id, t] : bag_topics)
            topics.push_back(t);
        writer.add_metadata("rosbag2",
                            {{"serialized_metadata", rosbag2_metadata_yaml(target.filename().string(), topics, first_ns,
                                                                           last_ns, writer.message_count())}});
        if (auto closed = writer.close(); !closed) throw Failure("merge: " + closed.error().message);
    } catch (...) {
        fs::remove(temporary, ec);
        throw;
    }
    fs::rename(temporary, target, ec);
    if (ec) {
        fs::remove(temporary, ec);
        throw Failure("merge: cannot write " + out + ": " + ec.message());
    }
}

} // namespace vksonar::cli
