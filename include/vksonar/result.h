// Errors as values: nothing in the public API throws. Every call that can fail returns
// Result<T>; on failure it carries a code, the VkResult (if Vulkan failed) and one line of text
// naming the file, field and value at fault.
#pragma once

#include <string>
#include <utility>
#include <variant>

#include <vulkan/vulkan_core.h>

namespace vksonar {

// What kind of failure an Error is.
enum class ErrorCode {
    invalid_argument, // a config value, pose or CLI argument makes no sense
    io,               // a file could not be read or written
    parse,            // a file is malformed (glTF, JSON, CSV)
    unsupported,      // valid input that vksonar does not handle (e.g. a required glTF extension)
    vulkan,           // a Vulkan call failed; see vk_result
    no_device,        // no suitable Vulkan device
    internal,         // a bug in vksonar
};

// A failure: what kind, one line of text for a person, and the VkResult of a failed Vulkan call.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct Error {
    ErrorCode code = ErrorCode::internal;
    std::string message; // one line, names file/field/value
    VkResult vk_result = VK_SUCCESS;
};

// Either a T or an Error (as std::expected). Check ok() (or bool) first: value(), * and -> need ok(),
// error() needs !ok() (the wrong one is a precondition violation: std::get throws
// std::bad_variant_access). Owns its T or Error; moves out of it with std::move(result).value().
// Thread-safety: a plain value (as T): safe to read from many threads at once, to write from one.
template <class T> class [[nodiscard]] Result {
public:
    Result(T value) : value_(std::move(value)) {}
    Result(Error error) : value_(std::move(error)) {}

    bool ok() const { return value_.index() == 0; }
    explicit operator bool() const { return ok(); }
    T& value() & { return std::get<0>(value_); }
    const T& value() const& { return std::get<0>(value_); }
    T&& value() && { return std::get<0>(std::move(value_)); }
    T* operator->() { return &std::get<0>(value_); }
    const T* operator->() const { return &std::get<0>(value_); }
    T& operator*() & { return std::get<0>(value_); }
    const T& operator*() const& { return std::get<0>(value_); }
    const Error& error() const { return std::get<1>(value_); }

private:
    std::variant<T, Error> value_;
};

// Success or an Error. error() is meaningful only when !ok() (else a default Error: code internal,
// empty message).
template <> class [[nodiscard]] Result<void> {
public:
    Result() = default;
    Result(Error error) : error_(std::move(error)), ok_(false) {}
    bool ok() const { return ok_; }
    explicit operator bool() const { return ok_; }
    const Error& error() const { return error_; }

private:
    Error error_;
    bool ok_ = true;
};

namespace detail {
// The length of the well-formed UTF-8 sequence of 2 to 4 bytes at text[at] (no overlong form, no
// surrogate, at most U+10FFFF), or 0; `code` its code point.
inline std::string::size_type utf8_sequence_at(const std::string& text, std::string::size_type at, unsigned& code) {
    const auto lead = static_cast<unsigned char>(text[at]);
    std::string::size_type n = 0;
    code = 0;
    if (lead >= 0xc2 && lead <= 0xdf) {
        n = 2, code = lead & 0x1fu;
    } else if (lead >= 0xe0 && lead <= 0xef) {
        n = 3, code = lead & 0x0fu;
    } else if (lead >= 0xf0 && lead <= 0xf4) {
        n = 4, code = lead & 0x07u;
    } else {
        return 0;
    }
    if (text.size() - at < n) return 0;
    for (std::string::size_type i = 1; i < n; ++i) {
        const auto next = static_cast<unsigned char>(text[at + i]);
        if ((next & 0xc0u) != 0x80u) return 0;
        code = code << 6 | (next & 0x3fu);
    }
    if ((n == 3 && code < 0x800) || (n == 4 && (code < 0x10000 || code > 0x10ffff)) ||
        (code >= 0xd800 && code <= 0xdfff))
        return 0;
    return n;
}

// Messages quote names and values taken from the input (a glTF material name, a JSON key, a URI), and
// those may hold a newline or other control characters, or bytes that are not UTF-8 (a Latin-1 or UTF-16
// file). Escape them C-style (\n, \xNN) so that a message stays one printable line of UTF-8 whatever the
// input held; well-formed UTF-8 (a name in any script) is kept as it is, but for the code points that break
// or reorder a line (C1 controls U+0080-U+009F, U+2028/U+2029, the bidi embeddings, overrides and isolates
// U+202A-U+202E, U+2066-U+2069), written \uNNNN.
inline std::string escape_control_chars(std::string text) {
    std::string::size_type at = 0;
    while (at < text.size() && static_cast<unsigned char>(text[at]) >= 0x20 &&
           static_cast<unsigned char>(text[at]) < 0x7f)
        ++at;
    if (at == text.size()) return text; // the common case: nothing to escape, no copy
    std::string out = text.substr(0, at);
    static const char hex[] = "0123456789abcdef";
    for (; at < text.size(); ++at) {
        const auto c = static_cast<unsigned char>(text[at]);
        if (c >= 0x80) {
            unsigned code = 0;
            if (const std::string::size_type n = utf8_sequence_at(text, at, code); n > 0) {
                if (code <= 0x9f || code == 0x2028 || code == 0x2029 || (code >= 0x202a && code <= 0x202e) ||
                    (code >= 0x2066 && code <= 0x2069)) {
                    out += "\\u";
                    for (int shift = 12; shift >= 0; shift -= 4)
                        out += hex[(code >> shift) & 15];
                } else {
                    out.append(text, at, n);
                }
                at += n - 1;
            } else {
                out += "\\x";
                out += hex[c >> 4];
                out += hex[c & 15];
            }
        } else if (c >= 0x20 && c != 0x7f) {
            out += static_cast<char>(c);
        } else if (c == '\n') {
            out += "\\n";
        } else if (c == '\r') {
            out += "\\r";
        } else if (c == '\t') {
            out += "\\t";
        } else {
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        }
    }
    return out;
}
} // namespace detail

// An Error with `message` made one printable line (control characters escaped C-style). Pure.
inline Error make_error(ErrorCode code, std::string message, VkResult vk_result = VK_SUCCESS) {
    return Error{code, detail::escape_control_chars(std::move(message)), vk_result};
}

} // namespace vksonar
