// mcap::read (mcap_reader.h): the records of the MCAP specification that vksonar's writer emits.
#include "cli/mcap_reader.h"

#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

#ifdef VKSONAR_HAVE_ZSTD
#include <zstd.h>
#endif

namespace vksonar::cli::mcap {
namespace {

// A record or chunk larger than this is refused rather than allocated (the writer's chunks are ~1 MiB;
// a frame's messages are bins x beams x 4 bytes and a fan image).
constexpr std::uint64_t kMaxRecord = std::uint64_t(1) << 32;

struct Bad {
    std::string what;
};

// A bounds-checked little-endian cursor over one record's bytes.
class Cursor {
public:
    Cursor(const std::uint8_t* data, std::size_t size) : p_(data), end_(data + size) {}
    std::size_t left() const { return static_cast<std::size_t>(end_ - p_); }
    template <class T> T number(const char* what) {
        if (left() < sizeof(T)) throw Bad{std::string("a record ends inside its ") + what};
        T v = 0;
        for (std::size_t i = 0; i < sizeof(T); ++i)
            v |= T(p_[i]) << (8 * i);
        p_ += sizeof(T);
        return v;
    }
    std::string text(const char* what) {
        const std::uint32_t n = number<std::uint32_t>(what);
        if (left() < n) throw Bad{std::string("a record's ") + what + " overruns it"};
        std::string s(reinterpret_cast<const char*>(p_), n);
        p_ += n;
        return s;
    }
    KeyValues map(const char* what) {
        const std::uint32_t bytes = number<std::uint32_t>(what);
        if (left() < bytes) throw Bad{std::string("a record's ") + what + " overruns it"};
        Cursor inner(p_, bytes);
        p_ += bytes;
        KeyValues out;
        while (inner.left() > 0) {
            std::string key = inner.text(what);
            out.emplace_back(std::move(key), inner.text(what));
        }
        return out;
    }
    const std::uint8_t* take(std::size_t n, const char* what) {
        if (left() < n) throw Bad{std::string("a record's ") + what + " overruns it"};
        const std::uint8_t* at = p_;
        p_ += n;
        return at;
    }
    const std::uint8_t* here() const { return p_; }

private:
    const std::uint8_t* p_;
    const std::uint8_t* end_;
};

void dispatch(std::uint8_t op, Cursor c, const ReadCallbacks& cb) {
    switch (op) {
    case op_schema: {
        ReadSchema s;
        s.id = c.number<std::uint16_t>("schema id");
        s.name = c.text("schema name");
        s.encoding = c.text("schema encoding");
        s.data = c.text("schema data");
        if (cb.schema) cb.schema(s);
        break;
    }
    case op_channel: {
        ReadChannel ch;
        ch.id = c.number<std::uint16_t>("channel id");
        ch.schema_id = c.number<std::uint16_t>("channel schema id");
        ch.topic = c.text("channel topic");
        ch.encoding = c.text("channel encoding");
        ch.metadata = c.map("channel metadata");
        if (cb.channel) cb.channel(ch);
        break;
    }
    case op_message: {
        ReadMessage m;
        m.channel_id = c.number<std::uint16_t>("message channel id");
        m.sequence = c.number<std::uint32_t>("message sequence");
        m.log_time = c.number<std::uint64_t>("message log time");
        m.publish_time = c.number<std::uint64_t>("message publish time");
        m.size = c.left();
        m.data = c.take(m.size, "message data");
        if (cb.message) cb.message(m);
        break;
    }
    case op_metadata: {
        const std::string name = c.text("metadata name");
        const KeyValues values = c.map("metadata");
        if (cb.metadata) cb.metadata(name, values);
        break;
    }
    default: // message indexes, statistics, ...: not needed to merge
        break;
    }
}

// The records of a chunk's (uncompressed) content, in order.
void walk(const std::uint8_t* data, std::size_t size, const ReadCallbacks& cb) {
    Cursor c(data, size);
    while (c.left() > 0) {
        const std::uint8_t op = c.number<std::uint8_t>("opcode");
        const std::uint64_t length = c.number<std::uint64_t>("record length");
        if (length > c.left()) throw Bad{"a record inside a chunk overruns it"};
        dispatch(op, Cursor(c.take(length, "record"), length), cb);
    }
}

struct FileCloser {
    void operator()(std::FILE* f) const { std::fclose(f); }
};

} // namespace

Result<ReadSummary> read(const std::string& path, const ReadCallbacks& callbacks) {
    std::unique_ptr<std::FILE, FileCloser> file(std::fopen(path.c_str(), "rb"));
    if (!file) return make_error(ErrorCode::io, path + ": cannot open for reading");
    ReadSummary summary;
    try {
        std::uint8_t magic[8];
        if (std::fread(magic, 1, 8, file.get()) != 8 || std::memcmp(magic, kMagic, 8) != 0)
            throw Bad{"not an MCAP file (no magic)"};
        std::vector<std::uint8_t> record, plain;
        bool first = true;
        for (;;) {
            std::uint8_t head[9];
            if (std::fread(head, 1, 9, file.get()) != 9) break; // cut short: the whole records so far
            Cursor h(head, 9);
            const std::uint8_t op = h.number<std::uint8_t>("opcode");
            const std::uint64_t length = h.number<std::uint64_t>("record length");
            if (length > kMaxRecord) throw Bad{"a record claims " + std::to_string(length) + " bytes"};
            record.resize(length);
            if (length > 0 && std::fread(record.data(), 1, length, file.get()) != length) break; // cut short
            Cursor c(record.data(), record.size());
            if (first) {
                if (op != op_header) throw Bad{"the first record is not a Header"};
                summary.profile = c.text("header profile");
                summary.library = c.text("header library");
                first = false;
                continue;
            }
            if (op == op_data_end || op == op_footer) {
                summary.complete = op == op_data_end;
                break;
            }
            if (op != op_chunk) {
                dispatch(op, c, callbacks);
                continue;
            }
            c.number<std::uint64_t>("chunk start time");
            c.number<std::uint64_t>("chunk end time");
            const std::uint64_t plain_size = c.number<std::uint64_t>("chunk size");
            const std::uint32_t plain_crc = c.number<std::uint32_t>("chunk crc");
            const std::string compression = c.text("chunk compression");
            const std::uint64_t stored = c.number<std::uint64_t>("chunk records length");
            const std::uint8_t* records = c.take(stored, "chunk records");
            if (plain_size > kMaxRecord) throw Bad{"a chunk claims " + std::to_string(plain_size) + " bytes"};
            const std::uint8_t* content = records;
            if (compression == "zstd") {
#ifdef VKSONAR_HAVE_ZSTD
                summary.zstd = true;
                plain.resize(plain_size);
                const std::size_t got = ZSTD_decompress(plain.data(), plain.size(), records, stored);
                if (ZSTD_isError(got) || got != plain_size) throw Bad{"a zstd chunk does not decompress"};
                content = plain.data();
#else
                throw Bad{"a zstd chunk, and this build has no zstd (install libzstd-dev and rebuild)"};
#endif
            } else if (!compression.empty()) {
                throw Bad{"chunk compression '" + compression + "' (vksonar writes none or zstd)"};
            } else if (stored != plain_size) {
                throw Bad{"an uncompressed chunk's size disagrees with its records"};
            }
            if (plain_crc != 0 && crc32(content, plain_size) != plain_crc) throw Bad{"a chunk's CRC does not match"};
            walk(content, plain_size, callbacks);
        }
        if (first) throw Bad{"no Header record"};
    } catch (const Bad& e) {
        return make_error(ErrorCode::parse, path + ": " + e.what);
    }
    return summary;
}

} // namespace vksonar::cli::mcap
