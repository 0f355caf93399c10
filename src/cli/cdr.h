// The CDR encoding ROS 2 messages travel in (OMG CDR, XCDR version 1, little endian), as rosbag2 stores
// them: a 4-byte encapsulation header 00 01 00 00 (CDR_LE, options 0), then the fields in the order
// of the .msg definition. Each primitive is aligned to its own size (8 at most) counted from the
// first byte after the header; a string is a uint32 length that counts the terminating NUL, the bytes
// and the NUL; a sequence (T[]) is a uint32 element count and the elements; bool is one byte.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "CdrWriter writes CDR_LE by copying host bytes: a big-endian host needs byte swaps here"
#endif

namespace vksonar::cli {

class CdrWriter {
public:
    // Starts a message in `out` (cleared; its capacity is reused from message to message).
    explicit CdrWriter(std::vector<std::uint8_t>& out) : out_(out) {
        out_.clear();
        const std::uint8_t header[4] = {0x00, 0x01, 0x00, 0x00};
        out_.insert(out_.end(), header, header + 4);
    }

    void u8(std::uint8_t v) { out_.push_back(v); }
    void boolean(bool v) { out_.push_back(v ? 1 : 0); }
    void u32(std::uint32_t v) { primitive(v); }
    void i32(std::int32_t v) { primitive(v); }
    void f32(float v) { primitive(v); }
    void f64(double v) { primitive(v); }
    void string(const std::string& s) {
        u32(static_cast<std::uint32_t>(s.size() + 1));
        out_.insert(out_.end(), s.begin(), s.end());
        out_.push_back(0);
    }
    // A sequence's element count; the elements follow.
    void count(std::size_t n) { u32(static_cast<std::uint32_t>(n)); }
    // uint8[] (and byte[]): count, then the bytes.
    void bytes(const void* data, std::size_t n) {
        count(n);
        append(data, n);
    }
    // float32[]: count, then the values (aligned to 4 after the count, which already is).
    void floats(const float* data, std::size_t n) {
        count(n);
        append(data, n * sizeof(float));
    }
    // Raw bytes with no count (the payload of a sequence whose count was written by count()).
    void append(const void* data, std::size_t n) {
        const auto* p = static_cast<const std::uint8_t*>(data);
        out_.insert(out_.end(), p, p + n);
    }
    // Pads with zeros so the next byte is aligned to `n` (relative to the end of the header).
    void align(std::size_t n) {
        const std::size_t offset = out_.size() - 4;
        const std::size_t pad = (n - offset % n) % n;
        out_.insert(out_.end(), pad, 0);
    }
    std::size_t size() const { return out_.size(); }

private:
    template <class T> void primitive(T v) {
        static_assert(sizeof(T) <= 8, "CDR aligns at most to 8");
        align(sizeof(T));
        std::uint8_t bytes[sizeof(T)];
        std::memcpy(bytes, &v, sizeof(T)); // little-endian host (x86-64, aarch64)
        out_.insert(out_.end(), bytes, bytes + sizeof(T));
    }

    std::vector<std::uint8_t>& out_;
};

} // namespace vksonar::cli
