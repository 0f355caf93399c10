// The one table of SonarConfig keys. The JSON loader, the --set parser, config_to_json, validate()'s
// finiteness check and the config reference (docs/config.md, `vksonar presets --keys`) all walk it,
// so a key cannot exist in one of them and not in the others.
#pragma once

#include <cstddef>
#include <limits>
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

// The physical range of a numeric key: validate() refuses a value outside it ("source_level = 400: must
// be in [100, 260] dB re 1 uPa at 1 m"), and the config reference prints it with its reason. Counts and
// "auto"-or-number keys are checked the same way (the auto value is not a number and is not checked).
struct KeyRange {
    double min = -std::numeric_limits<double>::infinity();
    double max = std::numeric_limits<double>::infinity();
    bool min_open = false, max_open = false; // true: the bound itself is outside ("(0, 360]")
    const char* reason = "";                 // one line: the physics or the source behind the bounds
    bool contains(double x) const { return (min_open ? x > min : x >= min) && (max_open ? x < max : x <= max); }
    bool bounded() const {
        return min > -std::numeric_limits<double>::infinity() || max < std::numeric_limits<double>::infinity();
    }
};
// "[100, 260]", "(0, 360]", ">= 0".
std::string range_text(const KeyRange& range);

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
    KeyRange range{}; // numeric keys only; unbounded for text and choice keys
};

// The first key whose numeric value lies outside its range, as "key = value: must be in [lo, hi] unit",
// or empty. NaN and infinities fail every range.
std::string check_ranges(const SonarConfig& config);

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
