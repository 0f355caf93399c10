// A writer of MCAP files (the container `ros2 bag` records into and Foxglove opens), after the MCAP
// format specification, major version 0: magic, Header, a data section of Chunks (each followed by
// one Message Index record per channel in it) and Metadata records, Data End, then a summary section
// (Schema, Channel, Statistics, Chunk Index and Metadata Index groups), Summary Offset records, the
// Footer and the magic again. Every chunk carries the Schema and Channel records its messages need,
// so a file cut short (a killed run) is readable record by record up to its last whole chunk. CRC-32
// (the zlib polynomial) over each chunk's uncompressed records, the data section (from the first
// magic byte to the Data End record) and the summary (from its first record through the Footer's
// summary_offset_start). Chunks may be compressed with zstd (Debian's libzstd-dev).
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "vksonar/result.h"

namespace vksonar::cli::mcap {

// The file's magic (start and end) and the record opcodes of the specification that vksonar uses.
inline constexpr std::uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', '0', '\r', '\n'};
enum Op : std::uint8_t {
    op_header = 0x01,
    op_footer = 0x02,
    op_schema = 0x03,
    op_channel = 0x04,
    op_message = 0x05,
    op_chunk = 0x06,
    op_message_index = 0x07,
    op_chunk_index = 0x08,
    op_statistics = 0x0B,
    op_metadata = 0x0C,
    op_metadata_index = 0x0D,
    op_summary_offset = 0x0E,
    op_data_end = 0x0F,
};

// CRC-32 (IEEE 802.3, reflected, init and final xor 0xFFFFFFFF) of `size` bytes, continuing `crc`
// (0 to start): crc32(b, crc32(a)) == crc32(a followed by b).
std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc = 0);

// True when this build can compress chunks with zstd.
bool zstd_available();

using KeyValues = std::vector<std::pair<std::string, std::string>>; // serialized in this order

struct WriterOptions {
    std::string profile;              // Header profile, e.g. "ros2"
    std::string library;              // Header library, free text
    bool zstd = false;                // compress chunks with zstd
    int zstd_level = 1;               // zstd's fast end: chunks are written at render speed
    std::size_t chunk_size = 1 << 20; // a chunk is closed at the first end_batch() after this many bytes
};

class Writer {
public:
    Writer() = default;
    ~Writer();
    Writer(const Writer&) = delete;
    Writer& operator=(const Writer&) = delete;

    // Creates (or truncates) `path` and writes the magic and the Header.
    Result<void> open(const std::string& path, const WriterOptions& options);
    // Registers a schema / channel (ids from 1); they are written into each chunk that uses them and
    // into the summary.
    std::uint16_t add_schema(const std::string& name, const std::string& encoding, const std::string& data);
    std::uint16_t add_channel(std::uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                              const KeyValues& metadata);
    // Appends a Message record to the open chunk. Times are ns; log times should not decrease.
    Result<void> write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                       std::uint64_t publish_time, const std::uint8_t* data, std::size_t size);
    // A point where a reader may be cut off: closes the chunk if it holds chunk_size bytes or more and
    // hands what was written to the operating system (a killed process leaves it in the file).
    Result<void> end_batch();
    // A Metadata record (written in the data section at close(), indexed in the summary).
    void add_metadata(const std::string& name, const KeyValues& values);
    // A Metadata record written now, after the open chunk (closed first), and flushed: a file cut
    // short keeps it (a shard bag's record, written before its first frame).
    Result<void> write_metadata(const std::string& name, const KeyValues& values);
    // Closes the open chunk, whatever its size, and hands the file to the operating system.
    Result<void> flush();
    // Writes the last chunk, the metadata, Data End, the summary and the Footer; closes the file.
    Result<void> close();

    std::uint64_t message_count() const { return message_count_; }

private:
    struct Schema {
        std::uint16_t id;
        std::string name, encoding, data;
    };
    struct Channel {
        std::uint16_t id, schema_id;
        std::string topic, encoding;
        KeyValues metadata;
        std::uint64_t messages = 0;
    };
    struct ChunkIndex {
        std::uint64_t start_time, end_time, offset, length;
        std::vector<std::pair<std::uint16_t, std::uint64_t>> message_index_offsets;
        std::uint64_t message_index_length, compressed_size, uncompressed_size;
    };
    struct MetadataIndex {
        std::uint64_t offset, length;
        std::string name;
    };

    Result<void> flush_chunk();
    Result<void> put(const std::vector<std::uint8_t>& bytes, bool data_section);
    Error fail(const std::string& what) const;

    std::string path_;
    WriterOptions options_;
    std::FILE* file_ = nullptr;
    std::uint64_t position_ = 0;  // bytes written so far
    std::uint32_t data_crc_ = 0;  // CRC of the data section so far
    std::vector<Schema> schemas_; // id = index + 1
    std::vector<Channel> channels_;
    std::vector<std::pair<std::string, KeyValues>> metadata_;
    std::vector<MetadataIndex> metadata_indexes_; // of those written so far
    // The open chunk.
    std::vector<std::uint8_t> chunk_;
    std::vector<bool> schema_in_chunk_, channel_in_chunk_;
    std::map<std::uint16_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>>
        chunk_index_; // channel -> (time, offset)
    std::uint64_t chunk_start_ = 0, chunk_end_ = 0;
    bool chunk_has_messages_ = false;
    // The summary.
    std::vector<ChunkIndex> chunk_indexes_;
    std::uint64_t message_count_ = 0, start_time_ = 0, end_time_ = 0;
    std::vector<std::uint8_t> scratch_, compressed_;
};

} // namespace vksonar::cli::mcap
