// The nesting of JSON text from a file someone else wrote, checked before it is parsed. nlohmann parses
// iteratively, but printing a value (dump(), for an error message or a record) and tinygltf's extras
// conversion recurse: a config file nesting 100,000 arrays deep crashed vksonar (SIGSEGV) where one
// line naming the file was due. No file of ours nests past a dozen levels.
#pragma once

#include <cstddef>
#include <string_view>

namespace vksonar {

inline constexpr int kMaxJsonDepth = 128;
// The most keys a config file may hold, all its objects together (apply_config_json): the default preset
// has about 200, and the ordered objects' inserts cost time quadratic in an object's keys.
inline constexpr std::size_t kMaxConfigKeys = 8192;

// True when the text opens more than max_depth objects or arrays inside each other (brackets inside
// strings and comments do not count: config files are read with // and /* */ comments, and a quote in
// one must not hide the brackets after it; the text need not be valid JSON).
inline bool json_nests_too_deep(std::string_view text, int max_depth = kMaxJsonDepth) {
    int depth = 0;
    bool in_string = false, escaped = false;
    for (std::size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (!in_string && c == '/' && i + 1 < text.size() && (text[i + 1] == '/' || text[i + 1] == '*')) {
            const bool line = text[i + 1] == '/';
            const std::size_t end = line ? text.find('\n', i + 2) : text.find("*/", i + 2);
            if (end == std::string_view::npos) break; // the comment runs to the end
            i = line ? end : end + 1;
            continue;
        }
        if (in_string) {
            if (escaped)
                escaped = false;
            else if (c == '\\')
                escaped = true;
            else if (c == '"')
                in_string = false;
        } else if (c == '"') {
            in_string = true;
        } else if (c == '{' || c == '[') {
            if (++depth > max_depth) return true;
        } else if (c == '}' || c == ']') {
            --depth;
        }
    }
    return false;
}

} // namespace vksonar
