// MCAP writer (mcap_writer.h). All integers little endian; strings and byte arrays length-prefixed.
#include "cli/mcap_writer.h"

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <array>
#include <cerrno>
#include <cstring>

#ifdef VKSONAR_HAVE_ZSTD
#include <zstd.h>
#endif

namespace vksonar::cli::mcap {
namespace {

// Slicing-by-8 tables: table[0] is the bytewise table of the reflected polynomial 0xEDB88320, and
// table[k][i] is the CRC of byte i followed by k zero bytes, so eight bytes are folded per step.
std::array<std::array<std::uint32_t, 256>, 8> make_crc_tables() {
    std::array<std::array<std::uint32_t, 256>, 8> table{};
    for (std::uint32_t i = 0; i < 256; ++i) {
        std::uint32_t c = i;
        for (int k = 0; k < 8; ++k)
            c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
        table[0][i] = c;
    }
    for (std::size_t k = 1; k < 8; ++k)
        for (std::uint32_t i = 0; i < 256; ++i)
            table[k][i] = (table[k - 1][i] >> 8) ^ table[0][table[k - 1][i] & 0xFFu];
    return table;
}

// Appends little-endian fields to a byte vector.
struct Bytes {
    std::vector<std::uint8_t>& b;
    void u8(std::uint8_t v) { b.push_back(v); }
    void u16(std::uint16_t v) { le(v, 2); }
    void u32(std::uint32_t v) { le(v, 4); }
    void u64(std::uint64_t v) { le(v, 8); }
    void raw(const void* data, std::size_t n) {
        const auto* p = static_cast<const std::uint8_t*>(data);
        b.insert(b.end(), p, p + n);
    }
    void str(const std::string& s) {
        u32(static_cast<std::uint32_t>(s.size()));
        raw(s.data(), s.size());
    }
    void map(const KeyValues& kv) {
        const std::size_t at = begin_length32();
        for (const auto& [k, v] : kv) {
            str(k);
            str(v);
        }
        end_length32(at);
    }
    // A record: opcode, uint64 content length (patched by end_record), content.
    std::size_t begin_record(std::uint8_t op) {
        u8(op);
        const std::size_t at = b.size();
        u64(0);
        return at;
    }
    void end_record(std::size_t at) { patch(at, b.size() - at - 8, 8); }
    std::size_t begin_length32() {
        const std::size_t at = b.size();
        u32(0);
        return at;
    }
    void end_length32(std::size_t at) { patch(at, b.size() - at - 4, 4); }

private:
    void le(std::uint64_t v, int n) {
        for (int i = 0; i < n; ++i)
            b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    }
    void patch(std::size_t at, std::uint64_t v, int n) {
        for (int i = 0; i < n; ++i)
            b[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
    }
};

void schema_record(Bytes& out, std::uint16_t id, const std::string& name, const std::string& encoding,
                   const std::string& data) {
    const std::size_t r = out.begin_record(op_schema);
    out.u16(id);
    out.str(name);
    out.str(encoding);
    out.str(data); // uint32 length-prefixed bytes
    out.end_record(r);
}

void channel_record(Bytes& out, std::uint16_t id, std::uint16_t schema_id, const std::string& topic,
                    const std::string& encoding, const KeyValues& metadata) {
    const std::size_t r = out.begin_record(op_channel);
    out.u16(id);
    out.u16(schema_id);
    out.str(topic);
    out.str(encoding);
    out.map(metadata);
    out.end_record(r);
}

} // namespace

namespace {

// The table CRC on the raw (pre-inverted) state c: eight bytes a step (slicing-by-8).
std::uint32_t crc32_tables(const std::uint8_t* p, std::size_t size, std::uint32_t c) {
    static const std::array<std::array<std::uint32_t, 256>, 8> t = make_crc_tables();
    for (; size >= 8; size -= 8, p += 8) {
        const std::uint32_t a = c ^ (std::uint32_t(p[0]) | std::uint32_t(p[1]) << 8 | std::uint32_t(p[2]) << 16 |
                                     std::uint32_t(p[3]) << 24);
        const std::uint32_t b =
            std::uint32_t(p[4]) | std::uint32_t(p[5]) << 8 | std::uint32_t(p[6]) << 16 | std::uint32_t(p[7]) << 24;
        c = t[7][a & 0xFFu] ^ t[6][(a >> 8) & 0xFFu] ^ t[5][(a >> 16) & 0xFFu] ^ t[4][a >> 24] ^ t[3][b & 0xFFu] ^
            t[2][(b >> 8) & 0xFFu] ^ t[1][(b >> 16) & 0xFFu] ^ t[0][b >> 24];
    }
    for (; size > 0; --size, ++p)
        c = t[0][(c ^ *p) & 0xFFu] ^ (c >> 8);
    return c;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("pclmul,sse4.1"))) inline __m128i load(const std::uint8_t* at) {
    return _mm_loadu_si128(reinterpret_cast<const __m128i*>(at));
}
// x's two 64-bit halves carried forward by the constants in k's halves, plus the next 16 bytes.
__attribute__((target("pclmul,sse4.1"))) inline __m128i fold(__m128i x, __m128i k, __m128i next) {
    return _mm_xor_si128(_mm_xor_si128(_mm_clmulepi64_si128(x, k, 0x00), _mm_clmulepi64_si128(x, k, 0x11)), next);
}

// The same CRC by carry-less multiplication (PCLMULQDQ), 64 bytes a step: four 128-bit lanes folded
// forward by x^(512+-32) mod P, then into one, reduced to 64 and 32 bits and by Barrett's reduction
// (Intel, "Fast CRC Computation for Generic Polynomials Using PCLMULQDQ", with the bit-reflected
// constants of CRC-32's P = 0x104C11DB7). size >= 64, a multiple of 16; c is the raw state.
__attribute__((target("pclmul,sse4.1"))) std::uint32_t crc32_clmul(const std::uint8_t* p, std::size_t size,
                                                                   std::uint32_t c) {
    const __m128i k1k2 = _mm_set_epi64x(0x1c6e41596, 0x154442bd4);    // x^(4*128+32), x^(4*128-32) mod P
    const __m128i k3k4 = _mm_set_epi64x(0x0ccaa009e, 0x1751997d0);    // x^(128+32), x^(128-32) mod P
    const __m128i k5 = _mm_set_epi64x(0, 0x163cd6124);                // x^64 mod P
    const __m128i poly_mu = _mm_set_epi64x(0x1F7011641, 0x1DB710641); // mu = x^64 / P, P
    const __m128i mask32 = _mm_set_epi32(0, 0, 0, -1);
    __m128i x0 = _mm_xor_si128(load(p), _mm_cvtsi32_si128(static_cast<int>(c)));
    __m128i x1 = load(p + 16), x2 = load(p + 32), x3 = load(p + 48);
    p += 64;
    size -= 64;
    for (; size >= 64; size -= 64, p += 64) {
        x0 = fold(x0, k1k2, load(p));
        x1 = fold(x1, k1k2, load(p + 16));
        x2 = fold(x2, k1k2, load(p + 32));
        x3 = fold(x3, k1k2, load(p + 48));
    }
    __m128i x = fold(fold(fold(x0, k3k4, x1), k3k4, x2), k3k4, x3);
    for (; size >= 16; size -= 16, p += 16)
        x = fold(x, k3k4, load(p));
    // 128 -> 64 bits (times x^32), then -> 32 bits, then Barrett's reduction
    x = _mm_xor_si128(_mm_srli_si128(x, 8), _mm_clmulepi64_si128(k3k4, x, 0x01));
    x = _mm_xor_si128(_mm_srli_si128(x, 4), _mm_clmulepi64_si128(_mm_and_si128(x, mask32), k5, 0x00));
    __m128i t = _mm_clmulepi64_si128(_mm_and_si128(x, mask32), poly_mu, 0x10);
    t = _mm_clmulepi64_si128(_mm_and_si128(t, mask32), poly_mu, 0x00);
    return static_cast<std::uint32_t>(_mm_extract_epi32(_mm_xor_si128(x, t), 1));
}

bool has_clmul() {
    static const bool has = __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("sse4.1");
    return has;
}
#endif

} // namespace

std::uint32_t crc32(const void* data, std::size_t size, std::uint32_t crc) {
    // Every byte of a bag goes through here (twice when written, once more when merged): by carry-less
    // multiplication where the CPU has it (the MCAP writer's thread spent 3.3 ms a frame here on the
    // table), else eight bytes a table step. The same CRC either way (mcap_test).
    const auto* p = static_cast<const std::uint8_t*>(data);
    std::uint32_t c = crc ^ 0xFFFFFFFFu;
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
    if (size >= 64 && has_clmul()) {
        const std::size_t bulk = size & ~std::size_t(15);
        c = crc32_clmul(p, bulk, c);
        p += bulk;
        size -= bulk;
    }
#endif
    return crc32_tables(p, size, c) ^ 0xFFFFFFFFu;
}

bool zstd_available() {
#ifdef VKSONAR_HAVE_ZSTD
    return true;
#else
    return false;
#endif
}

Writer::~Writer() {
    if (file_) std::fclose(file_); // not closed by close(): an error path; the file stays as far as it got
}

Error Writer::fail(const std::string& what) const {
    return make_error(ErrorCode::io, "cannot write " + path_ + ": " + what);
}

Result<void> Writer::put(const std::vector<std::uint8_t>& bytes, bool data_section) {
    if (bytes.empty()) return {};
    if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size())
        return fail(std::strerror(errno ? errno : EIO));
    if (data_section) data_crc_ = crc32(bytes.data(), bytes.size(), data_crc_);
    position_ += bytes.size();
    return {};
}

Result<void> Writer::open(const std::string& path, const WriterOptions& options) {
    path_ = path;
    options_ = options;
#ifndef VKSONAR_HAVE_ZSTD
    if (options.zstd) return make_error(ErrorCode::unsupported, "--out " + path + ": this build has no zstd");
#endif
    errno = 0;
    file_ = std::fopen(path.c_str(), "wb");
    if (!file_) return fail(std::strerror(errno ? errno : EIO));
    std::vector<std::uint8_t> head;
    Bytes out{head};
    out.raw(kMagic, sizeof kMagic);
    const std::size_t r = out.begin_record(op_header);
    out.str(options.profile);
    out.str(options.library);
    out.end_record(r);
    if (auto written = put(head, true); !written) return written;
    if (std::fflush(file_) != 0) return fail(std::strerror(errno ? errno : EIO));
    return {};
}

std::uint16_t Writer::add_schema(const std::string& name, const std::string& encoding, const std::string& data) {
    const auto id = static_cast<std::uint16_t>(schemas_.size() + 1);
    schemas_.push_back({id, name, encoding, data});
    schema_in_chunk_.push_back(false);
    return id;
}

std::uint16_t Writer::add_channel(std::uint16_t schema_id, const std::string& topic,
                                  const std::string& message_encoding, const KeyValues& metadata) {
    const auto id = static_cast<std::uint16_t>(channels_.size() + 1);
    channels_.push_back({id, schema_id, topic, message_encoding, metadata, 0});
    channel_in_chunk_.push_back(false);
    return id;
}

Result<void> Writer::write(std::uint16_t channel_id, std::uint32_t sequence, std::uint64_t log_time,
                           std::uint64_t publish_time, const std::uint8_t* data, std::size_t size) {
    Bytes out{chunk_};
    Channel& channel = channels_.at(channel_id - 1u);
    // The schema and channel go into every chunk that uses them: each chunk is readable on its own.
    if (channel.schema_id && !schema_in_chunk_[channel.schema_id - 1u]) {
        const Schema& s = schemas_[channel.schema_id - 1u];
        schema_record(out, s.id, s.name, s.encoding, s.data);
        schema_in_chunk_[channel.schema_id - 1u] = true;
    }
    if (!channel_in_chunk_[channel_id - 1u]) {
        channel_record(out, channel.id, channel.schema_id, channel.topic, channel.encoding, channel.metadata);
        channel_in_chunk_[channel_id - 1u] = true;
    }
    chunk_index_[channel_id].emplace_back(log_time, chunk_.size());
    const std::size_t r = out.begin_record(op_message);
    out.u16(channel_id);
    out.u32(sequence);
    out.u64(log_time);
    out.u64(publish_time);
    out.raw(data, size);
    out.end_record(r);
    if (!chunk_has_messages_ || log_time < chunk_start_) chunk_start_ = log_time;
    if (!chunk_has_messages_ || log_time > chunk_end_) chunk_end_ = log_time;
    if (message_count_ == 0 || log_time < start_time_) start_time_ = log_time;
    if (message_count_ == 0 || log_time > end_time_) end_time_ = log_time;
    chunk_has_messages_ = true;
    ++channel.messages;
    ++message_count_;
    return {};
}

Result<void> Writer::flush_chunk() {
    if (chunk_.empty()) return {};
    const std::uint32_t chunk_crc = crc32(chunk_.data(), chunk_.size());
    const std::uint8_t* records = chunk_.data();
    std::size_t records_size = chunk_.size();
    std::string compression;
#ifdef VKSONAR_HAVE_ZSTD
    if (options_.zstd) {
        compressed_.resize(ZSTD_compressBound(chunk_.size()));
        const std::size_t n =
            ZSTD_compress(compressed_.data(), compressed_.size(), chunk_.data(), chunk_.size(), options_.zstd_level);
        if (ZSTD_isError(n)) return fail(std::string("zstd: ") + ZSTD_getErrorName(n));
        records = compressed_.data();
        records_size = n;
        compression = "zstd";
    }
#endif
    ChunkIndex index{};
    index.start_time = chunk_has_messages_ ? chunk_start_ : 0;
    index.end_time = chunk_has_messages_ ? chunk_end_ : 0;
    index.offset = position_;
    index.compressed_size = records_size;
    index.uncompressed_size = chunk_.size();

    scratch_.clear();
    Bytes out{scratch_};
    const std::size_t r = out.begin_record(op_chunk);
    out.u64(index.start_time);
    out.u64(index.end_time);
    out.u64(chunk_.size());
    out.u32(chunk_crc);
    out.str(compression);
    out.u64(records_size);
    out.raw(records, records_size);
    out.end_record(r);
    index.length = scratch_.size();
    // One Message Index per channel of the chunk, in channel order.
    for (const auto& [channel, entries] : chunk_index_) {
        index.message_index_offsets.emplace_back(channel, position_ + scratch_.size());
        const std::size_t m = out.begin_record(op_message_index);
        out.u16(channel);
        out.u32(static_cast<std::uint32_t>(entries.size() * 16));
        for (const auto& [time, offset] : entries) {
            out.u64(time);
            out.u64(offset);
        }
        out.end_record(m);
    }
    index.message_index_length = scratch_.size() - index.length;
    if (auto written = put(scratch_, true); !written) return written;
    chunk_indexes_.push_back(std::move(index));

    chunk_.clear();
    chunk_index_.clear();
    chunk_has_messages_ = false;
    std::fill(schema_in_chunk_.begin(), schema_in_chunk_.end(), false);
    std::fill(channel_in_chunk_.begin(), channel_in_chunk_.end(), false);
    return {};
}

Result<void> Writer::end_batch() {
    if (chunk_.size() >= options_.chunk_size)
        if (auto flushed = flush_chunk(); !flushed) return flushed;
    if (std::fflush(file_) != 0) return fail(std::strerror(errno ? errno : EIO));
    return {};
}

void Writer::add_metadata(const std::string& name, const KeyValues& values) {
    metadata_.emplace_back(name, values);
}

Result<void> Writer::write_metadata(const std::string& name, const KeyValues& values) {
    if (!file_) return fail("the file is not open");
    if (auto flushed = flush_chunk(); !flushed) return flushed;
    scratch_.clear();
    Bytes out{scratch_};
    const std::size_t r = out.begin_record(op_metadata);
    out.str(name);
    out.map(values);
    out.end_record(r);
    metadata_indexes_.push_back({position_, scratch_.size(), name});
    if (auto written = put(scratch_, true); !written) return written;
    if (std::fflush(file_) != 0) return fail(std::strerror(errno ? errno : EIO));
    return {};
}

Result<void> Writer::flush() {
    if (auto flushed = flush_chunk(); !flushed) return flushed;
    if (std::fflush(file_) != 0) return fail(std::strerror(errno ? errno : EIO));
    return {};
}

Result<void> Writer::close() {
    if (!file_) return fail("the file is not open");
    if (auto flushed = flush_chunk(); !flushed) return flushed;

    // Metadata records, then Data End with the CRC of everything before it.
    std::vector<MetadataIndex>& metadata_indexes = metadata_indexes_; // those written already, then these
    scratch_.clear();
    Bytes out{scratch_};
    for (const auto& [name, values] : metadata_) {
        const std::size_t start = scratch_.size();
        const std::size_t r = out.begin_record(op_metadata);
        out.str(name);
        out.map(values);
        out.end_record(r);
        metadata_indexes.push_back({position_ + start, scratch_.size() - start, name});
    }
    if (auto written = put(scratch_, true); !written) return written;
    scratch_.clear();
    {
        const std::size_t r = out.begin_record(op_data_end);
        out.u32(data_crc_);
        out.end_record(r);
    }
    if (auto written = put(scratch_, false); !written) return written;

    // Summary: groups of one opcode each, then a Summary Offset per group.
    const std::uint64_t summary_start = position_;
    std::vector<std::uint8_t> summary;
    Bytes s{summary};
    struct Group {
        std::uint8_t op;
        std::uint64_t start, length;
    };
    std::vector<Group> groups;
    auto group = [&](std::uint8_t op, auto&& write_records) {
        const std::size_t start = summary.size();
        write_records();
        if (summary.size() > start) groups.push_back({op, summary_start + start, summary.size() - start});
    };
    group(op_schema, [&] {
        for (const Schema& x : schemas_)
            schema_record(s, x.id, x.name, x.encoding, x.data);
    });
    group(op_channel, [&] {
        for (const Channel& x : channels_)
            channel_record(s, x.id, x.schema_id, x.topic, x.encoding, x.metadata);
    });
    group(op_statistics, [&] {
        const std::size_t r = s.begin_record(op_statistics);
        s.u64(message_count_);
        s.u16(static_cast<std::uint16_t>(schemas_.size()));
        s.u32(static_cast<std::uint32_t>(channels_.size()));
        s.u32(0); // attachments
        s.u32(static_cast<std::uint32_t>(metadata_indexes.size()));
        s.u32(static_cast<std::uint32_t>(chunk_indexes_.size()));
        s.u64(message_count_ ? start_time_ : 0);
        s.u64(message_count_ ? end_time_ : 0);
        const std::size_t m = s.begin_length32();
        for (const Channel& x : channels_) {
            s.u16(x.id);
            s.u64(x.messages);
        }
        s.end_length32(m);
        s.end_record(r);
    });
    group(op_chunk_index, [&] {
        for (const ChunkIndex& x : chunk_indexes_) {
            const std::size_t r = s.begin_record(op_chunk_index);
            s.u64(x.start_time);
            s.u64(x.end_time);
            s.u64(x.offset);
            s.u64(x.length);
            const std::size_t m = s.begin_length32();
            for (const auto& [channel, offset] : x.message_index_offsets) {
                s.u16(channel);
                s.u64(offset);
            }
            s.end_length32(m);
            s.u64(x.message_index_length);
            s.str(options_.zstd ? "zstd" : "");
            s.u64(x.compressed_size);
            s.u64(x.uncompressed_size);
            s.end_record(r);
        }
    });
    group(op_metadata_index, [&] {
        for (const MetadataIndex& x : metadata_indexes) {
            const std::size_t r = s.begin_record(op_metadata_index);
            s.u64(x.offset);
            s.u64(x.length);
            s.str(x.name);
            s.end_record(r);
        }
    });
    const std::uint64_t summary_offset_start = summary_start + summary.size();
    for (const Group& g : groups) {
        const std::size_t r = s.begin_record(op_summary_offset);
        s.u8(g.op);
        s.u64(g.start);
        s.u64(g.length);
        s.end_record(r);
    }
    // Footer; its CRC covers the summary and the Footer up to summary_offset_start.
    s.u8(op_footer);
    s.u64(8 + 8 + 4); // the length is known before the CRC that covers it
    s.u64(summary_start);
    s.u64(summary_offset_start);
    s.u32(crc32(summary.data(), summary.size()));
    s.raw(kMagic, sizeof kMagic);
    if (auto written = put(summary, false); !written) return written;
    std::FILE* f = file_;
    file_ = nullptr;
    if (std::fclose(f) != 0) return fail(std::strerror(errno ? errno : EIO));
    return {};
}

} // namespace vksonar::cli::mcap
