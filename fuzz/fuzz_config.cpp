// libFuzzer target for the config parser: apply_config_json on arbitrary text, then validate();
// a config that parses and validates must serialize and parse back to the same JSON, hold every
// numeric key inside its physical range (config_keys.cpp) and give validity warnings of one line
// each. The input's lines are also fed to apply_config_override (the --set path).
// Build: scripts/fuzz.sh (clang, -DVKSONAR_FUZZ=ON). Seeds: fuzz/corpus/config, assets/presets.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "config/config_keys.h"
#include "vksonar/config.h"
#include "vksonar/validity.h"

namespace {

// Messages are printed one per line: no newline, carriage return or other control character.
bool one_printable_line(const std::string& text) {
    return std::none_of(text.begin(), text.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; });
}

// A config that validates: every numeric key inside its range (validate() cannot have skipped one),
// and every validity entry one printable line.
void check_valid(const vksonar::SonarConfig& config) {
    for (const auto& key : vksonar::config_keys::all()) {
        const auto value = key.get(config);
        if (value.is_number() && !key.range.contains(value.get<double>())) std::abort();
    }
    for (const auto& entry : vksonar::model_validity(config))
        if (!one_printable_line(entry.warning()) || entry.domain.empty()) std::abort();
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    const vksonar::SonarConfig base;

    const auto parsed = vksonar::apply_config_json(base, text, "fuzz.json");
    if (parsed.ok()) {
        if (parsed.value().validate().ok()) {
            check_valid(parsed.value());
            const std::string json = vksonar::config_to_json(parsed.value());
            const auto again = vksonar::apply_config_json(base, json, "roundtrip.json");
            if (!again.ok() || vksonar::config_to_json(again.value()) != json) std::abort();
        }
    } else if (!one_printable_line(parsed.error().message) || parsed.error().message.rfind("fuzz.json: ", 0) != 0) {
        std::abort(); // errors are one line that starts with the file's name
    }

    std::istringstream lines(text);
    std::string line;
    vksonar::SonarConfig config;
    while (std::getline(lines, line)) {
        const auto next = vksonar::apply_config_override(config, line);
        if (next.ok()) {
            config = next.value();
            if (config.validate().ok()) check_valid(config);
        } else if (!one_printable_line(next.error().message)) {
            std::abort();
        }
    }
    return 0;
}
