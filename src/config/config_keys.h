// The one table of SonarConfig keys. The JSON loader, the --set parser, config_to_json, validate()'s
// finiteness check and the config reference (docs/config.md, `vksonar presets --keys`) all walk it,
// so a key cannot exist in one of them and not in the others.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "vksonar/config.h"

namespace vksonar::config_keys {

using Json = nlohmann::ordered_json;

enum class KeyType {
    number,         // a finite double
    count,          // an unsigned 32-bit integer
    text,           // a string
    choice,         // one of `choices`
    number_list,    // an array of numbers
    number_or_auto, // a number, or the string "auto"
};

struct ConfigKey {
    const char* name; // JSON key, dotted for nested groups ("display.db_min")
    KeyType type;
    const char* unit;    // "deg", "m", "Hz", "dB re 1 uPa at 1 m", ... or "" for none
    const char* choices; // "box|sinc|hann|gaussian" for choice keys, else ""
    const char* doc;     // one line for the reference table
    Json (*get)(const SonarConfig&);
    // Stores `value` into the config. Returns an empty string, or what is wrong with the value
    // ("expected a number, got \"many\"").
    std::string (*set)(SonarConfig&, const Json& value);
};

// The table, in reference order.
const std::vector<ConfigKey>& all();
// The key called `name` (dotted), or nullptr.
const ConfigKey* find(std::string_view name);
// True if `prefix` names a group ("display", "effects", "accuracy", "cpu").
bool is_group(std::string_view prefix);
// The valid key closest to `name` by edit distance (for "did you mean" hints).
std::string closest(std::string_view name);

// Levenshtein distance: single-character insertions, deletions and substitutions.
std::size_t edit_distance(std::string_view a, std::string_view b);
// Turns the text of a --set value into the JSON value the key's setter expects
// ("512" -> 512, "nan" -> NaN, "auto" -> "auto", "1,2,3" -> [1,2,3]).
Json parse_override_value(const ConfigKey& key, const std::string& text);
// The config reference as a Markdown table (docs/config.md is this output).
std::string reference_markdown();

} // namespace vksonar::config_keys
