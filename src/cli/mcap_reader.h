// A reader of the MCAP files vksonar writes (mcap_writer.h), for `vksonar merge` of sharded bags: a
// linear pass over the data section, chunk by chunk (zstd or uncompressed), that hands each Schema,
// Channel, Message and Metadata record to a callback in file order and stops at Data End. Every
// length is checked against what is left of its record; a file cut short ends the pass after its last
// whole chunk (`complete` says whether Data End was reached). Memory: one chunk at a time.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "cli/mcap_writer.h"
#include "vksonar/result.h"

namespace vksonar::cli::mcap {

struct ReadSchema {
    std::uint16_t id = 0;
    std::string name, encoding, data;
};
struct ReadChannel {
    std::uint16_t id = 0, schema_id = 0;
    std::string topic, encoding;
    KeyValues metadata;
};
struct ReadMessage {
    std::uint16_t channel_id = 0;
    std::uint32_t sequence = 0;
    std::uint64_t log_time = 0, publish_time = 0;
    const std::uint8_t* data = nullptr; // valid during the callback only
    std::size_t size = 0;
};

struct ReadCallbacks {
    std::function<void(const ReadSchema&)> schema;
    std::function<void(const ReadChannel&)> channel;
    std::function<void(const ReadMessage&)> message;
    std::function<void(const std::string& name, const KeyValues&)> metadata;
};

struct ReadSummary {
    std::string profile, library; // the Header's
    bool zstd = false;            // some chunk was zstd-compressed
    bool complete = false;        // Data End was reached
};

// Fails with one line naming the file and what is wrong (not MCAP, a record that overruns, a chunk
// that does not decompress or whose CRC differs).
Result<ReadSummary> read(const std::string& path, const ReadCallbacks& callbacks);

} // namespace vksonar::cli::mcap
