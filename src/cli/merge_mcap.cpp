// `vksonar merge OUT.mcap SHARD.mcap...` (merge.h): ROS 2 bags written by `render --out FILE.mcap
// --shard i/N`. Each shard bag carries a "vksonar_shard" Metadata record (its ShardRecord, the run's
// identity, backend, device and compression), written right after the Header, before any frame; a
// bag that was not closed (no Data End: a killed shard) holds its whole chunks' frames, and the shared
// check calls it incomplete. A re-run of such a shard goes on after those frames (bag_shard_resume).
// The merge writes the shards' messages, in shard order, through the same MCAP writer the unsharded
// run uses, with a chunk boundary after every frame as that run has, per-topic sequence numbers
// counted across the shards, /tf_static once (from the first shard with frames, stamped with the run's first
// frame), and rosbag2's metadata for the whole run: the merged bag is the unsharded run's bag, byte
// for byte, when OUT has the unsharded bag's file name (rosbag2's metadata names the file).
#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <map>

#include "cli/args.h"
#include "cli/dataset_mcap.h"
#include "cli/mcap_reader.h"
#include "cli/merge.h"
#include "host/meta_fields.h"

namespace fs = std::filesystem;

namespace vksonar::cli {
namespace {

constexpr const char* kIdentityPrefix = "identity.";

bool mcap_extension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return ext == ".mcap";
}

struct BadRecord {
    std::string what;
};

std::uint64_t number(const std::string& key, const std::string& text) {
    try {
        std::size_t used = 0;
        const unsigned long long v = std::stoull(text, &used);
        if (used == text.size()) return v;
    } catch (const std::exception&) {
    }
    throw BadRecord{"shard record " + key + " = '" + text + "' is not a count"};
}

// What one pass over a bag says: its shard record (if any), whole frames (one /tf message each) and
// whether it was closed (Data End reached).
struct BagScan {
    ShardInput in;
    bool record = false, complete = false;
    std::uint64_t messages = 0;
    std::string compression; // the record's: "zstd" or "none"
    std::string version;     // the record's vksonar_version (empty: a shard rendered before it was recorded)
};

// Fails with one line starting with the path.
Result<BagScan> scan_bag(const std::string& path) {
    BagScan scan;
    ShardInput& in = scan.in;
    in.path = path;
    std::map<std::uint16_t, std::string> topics;
    mcap::ReadCallbacks cb;
    cb.channel = [&](const mcap::ReadChannel& c) { topics[c.id] = c.topic; };
    cb.message = [&](const mcap::ReadMessage& m) {
        ++scan.messages;
        in.frames += topics[m.channel_id] == "/tf"; // one a frame
    };
    cb.metadata = [&](const std::string& name, const mcap::KeyValues& values) {
        if (name != kShardRecordName) return;
        scan.record = true;
        for (const auto& [key, value] : values) {
            if (key == "index")
                in.shard.index = number(key, value);
            else if (key == "count")
                in.shard.count = number(key, value);
            else if (key == "first")
                in.shard.first = number(key, value);
            else if (key == "end")
                in.shard.end = number(key, value);
            else if (key == "total")
                in.shard.total = number(key, value);
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
            else if (key == "compression")
                scan.compression = value;
            else if (key == "vksonar_version")
                scan.version = value;
            else if (key.rfind(kIdentityPrefix, 0) == 0)
                in.identity.emplace_back(key.substr(9), value);
        }
        if (in.shard.count == 0 || in.shard.index >= in.shard.count || in.shard.end < in.shard.first ||
            in.shard.end > in.shard.total)
            throw BadRecord{"an inconsistent shard record (shard " + std::to_string(in.shard.index) + "/" +
                            std::to_string(in.shard.count) + ", frames " + std::to_string(in.shard.first) + ".." +
                            std::to_string(in.shard.end) + " of " + std::to_string(in.shard.total) + ")"};
    };
    try {
        auto read = mcap::read(path, cb);
        if (!read) return read.error();
        scan.complete = read->complete;
    } catch (const BadRecord& e) {
        return make_error(ErrorCode::parse, path + ": " + e.what);
    }
    return scan;
}

std::string shard_text(const ShardRecord& s) {
    return std::to_string(s.index) + "/" + std::to_string(s.count);
}

} // namespace

mcap::KeyValues shard_metadata(const ShardRecord& s, const Identity& identity, const std::string& backend,
                               const std::string& device, bool zstd) {
    mcap::KeyValues kv = {{"index", std::to_string(s.index)},
                          {"count", std::to_string(s.count)},
                          {"first", std::to_string(s.first)},
                          {"end", std::to_string(s.end)},
                          {"total", std::to_string(s.total)},
                          {"source", s.source},
                          {"trajectory", s.trajectory},
                          {"trajectory_hash", s.trajectory_hash},
                          {"backend", backend},
                          {"device", device},
                          {"compression", zstd ? "zstd" : "none"},
                          {"vksonar_version", host::vksonar_version()}};
    for (const auto& [key, value] : identity)
        kv.emplace_back(kIdentityPrefix + key, value);
    return kv;
}

mcap::KeyValues run_metadata(const Identity& identity, const std::string& vksonar_version) {
    mcap::KeyValues kv(identity.begin(), identity.end());
    if (!vksonar_version.empty()) kv.emplace_back("vksonar_version", vksonar_version);
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
    auto scan = scan_bag(path);
    if (!scan) throw BadInput("merge: " + scan.error().message);
    ShardInput& in = scan->in;
    if (!scan->record)
        throw BadInput("merge: " + path + ": not a shard (no " + std::string(kShardRecordName) +
                       " record): render it with --shard");
    // Closed (Data End) or not, the frames on disk are whole: a bag that was not closed is a killed
    // shard's, and the shared check calls it incomplete unless every frame of its block is there.
    if (in.frames > in.shard.end - in.shard.first)
        throw BadInput("merge: " + path + ": " + std::to_string(in.frames) + " frames, more than shard " +
                       shard_text(in.shard) + "'s " + std::to_string(in.shard.end - in.shard.first));
    if (in.frames < in.shard.end - in.shard.first)
        in.first_missing = "frame ordinal " + std::to_string(in.shard.first + in.frames) +
                           (scan->complete ? "" : " (the bag was not closed: a killed run)");
    return in;
}

BagResume bag_shard_resume(const std::string& path, const Plan& plan, const McapOptions& options,
                           const ShardRecord& shard, const Identity& identity) {
    BagResume out;
    std::error_code ec;
    if (!fs::is_regular_file(path, ec)) return out;
    auto scan = scan_bag(path);
    if (!scan) {
        std::fprintf(stderr, "warning: %s: starting the shard over\n", scan.error().message.c_str());
        return out;
    }
    const ShardInput& old = scan->in;
    if (!scan->record) {
        if (scan->messages == 0) return out; // killed before its first frame: nothing to keep
        throw BadInput("--out " + path + " holds an unsharded run, not shard " + shard_text(shard) +
                       ": give each shard its own --out");
    }
    if (old.shard.index != shard.index || old.shard.count != shard.count || old.shard.first != shard.first ||
        old.shard.end != shard.end)
        throw BadInput("--out " + path + " holds shard " + shard_text(old.shard) + ", not shard " + shard_text(shard) +
                       ": give each shard its own --out");
    if (std::string d = identity_difference(old.identity, identity); !d.empty())
        throw BadInput("--out " + path + " holds another run (" + d + "): remove it or give another --out");
    const std::uint64_t block = shard.end - shard.first;
    if (old.frames > block)
        throw BadInput("--out " + path + ": " + std::to_string(old.frames) + " frames, more than the shard's " +
                       std::to_string(block));
    out.frames = old.frames;
    if (scan->complete && old.frames == block) {
        out.complete = true; // nothing to render; the bag stays as it is
        return out;
    }
    if (old.frames == 0) return out;

    // Its whole frames are written again, through a writer that then goes on with the next frame,
    // into a temporary file that replaces the bag once they are on disk: the bag is a readable shard
    // bag at every moment.
    const fs::path target(path);
    const fs::path temporary =
        (target.has_parent_path() ? target.parent_path() : fs::path(".")) / (".~" + target.filename().string());
    auto created = McapDatasetWriter::create(path, plan, options, temporary.string());
    if (!created) throw Failure(created.error().message);
    std::unique_ptr<McapDatasetWriter> writer = std::move(created.value());
    std::map<std::uint16_t, std::string> topic_of;
    Result<void> replayed;
    mcap::ReadCallbacks cb;
    cb.channel = [&](const mcap::ReadChannel& c) { topic_of[c.id] = c.topic; };
    cb.message = [&](const mcap::ReadMessage& m) {
        if (replayed) replayed = writer->replay(topic_of[m.channel_id], m.log_time, m.publish_time, m.data, m.size);
    };
    auto read = mcap::read(path, cb);
    if (read && replayed) replayed = writer->flush();
    if (!read || !replayed || writer->frames() != old.frames) {
        writer.reset();
        fs::remove(temporary, ec);
        std::fprintf(stderr, "warning: %s: its frames do not read back (%s): starting the shard over\n", path.c_str(),
                     !read       ? read.error().message.c_str()
                     : !replayed ? replayed.error().message.c_str()
                                 : "a count");
        out.frames = 0;
        return out;
    }
    fs::rename(temporary, target, ec);
    if (ec) {
        writer.reset();
        fs::remove(temporary, ec);
        throw Failure("--out " + path + ": cannot replace it: " + ec.message());
    }
    out.writer = std::move(writer);
    return out;
}

void mcap_merge(const std::vector<ShardInput>& shards, const std::string& out) {
    // Pass 1, the first shard with frames (a bag's Schema and Channel records are in the chunks that
    // use them, and a shard whose block is empty has none): its schemas and channels, registered in
    // id order as the writer did.
    std::size_t h = 0;
    while (h + 1 < shards.size() && shards[h].frames == 0)
        ++h;
    const std::string& head_path = shards[h].path;
    std::map<std::uint16_t, mcap::ReadSchema> schemas;
    std::map<std::uint16_t, mcap::ReadChannel> channels;
    mcap::ReadCallbacks first;
    first.schema = [&](const mcap::ReadSchema& s) { schemas.emplace(s.id, s); };
    first.channel = [&](const mcap::ReadChannel& c) { channels.emplace(c.id, c); };
    auto head = mcap::read(head_path, first);
    if (!head) throw BadInput("merge: " + head.error().message);
    auto record = scan_bag(shards[0].path); // compressed as shard 0 was (--compress)
    if (!record) throw BadInput("merge: " + record.error().message);

    const fs::path target(out);
    const fs::path temporary =
        (target.has_parent_path() ? target.parent_path() : fs::path(".")) / ("." + target.filename().string() + ".tmp");
    std::error_code ec;
    try {
        mcap::Writer writer;
        mcap::WriterOptions options;
        options.profile = head->profile;
        options.library = head->library;
        options.zstd = record->compression == "zstd";
        if (auto opened = writer.open(temporary.string(), options); !opened) throw Failure(opened.error().message);
        std::map<std::uint16_t, std::uint16_t> schema_of; // shard id -> merged id (the same, checked)
        for (const auto& [id, s] : schemas) {
            schema_of[id] = writer.add_schema(s.name, s.encoding, s.data);
            if (schema_of[id] != id) throw Failure("merge: " + head_path + ": schema ids are not 1, 2, ...");
        }
        std::map<std::uint16_t, BagTopic> bag_topics;
        for (const auto& [id, c] : channels) {
            if (!schema_of.count(c.schema_id))
                throw BadInput("merge: " + head_path + ": channel " + c.topic + " has no schema");
            if (writer.add_channel(schema_of[c.schema_id], c.topic, c.encoding, c.metadata) != id)
                throw Failure("merge: " + head_path + ": channel ids are not 1, 2, ...");
            std::string qos;
            for (const auto& [key, value] : c.metadata)
                if (key == "offered_qos_profiles") qos = value.substr(0, value.size() - (value.empty() ? 0 : 1));
            bag_topics[id] = BagTopic{c.topic, schemas[c.schema_id].name, qos, 0};
        }

        // Pass 2: every shard's messages in order.
        std::map<std::uint16_t, std::uint32_t> sequence;
        bool any_frame = false, tf_static = false;
        std::uint64_t first_ns = 0, last_ns = 0;
        Result<void> failed;
        for (std::size_t k = 0; k < shards.size(); ++k) {
            std::map<std::uint16_t, std::string> topic_of;
            mcap::ReadCallbacks cb;
            cb.channel = [&](const mcap::ReadChannel& c) {
                topic_of[c.id] = c.topic;
                const auto mine = channels.find(c.id);
                if (mine == channels.end() || mine->second.topic != c.topic || mine->second.schema_id != c.schema_id)
                    throw BadInput("merge: " + shards[k].path + ": its topics differ from " + head_path +
                                   "'s (channel " + std::to_string(c.id) + " " + c.topic + ")");
            };
            cb.message = [&](const mcap::ReadMessage& m) {
                if (!failed) return;
                const std::string& topic = topic_of[m.channel_id];
                if (topic == "/tf_static" && tf_static) return; // once, from the run's first frame
                if (topic == "/tf_static") tf_static = true;
                if (topic == "/tf") { // a frame begins: the one before is whole
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
        // The run record of the unsharded run: shard 0's identity (the shards' agree: checked) and the
        // version that rendered it.
        writer.add_metadata(kRunRecordName, run_metadata(shards[0].identity, record->version));
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
