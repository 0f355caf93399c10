// Device presets: assets/presets/*.json embedded at build time (cmake/embed_presets_script.cmake),
// applied on top of the SonarConfig defaults and validated.
#include <string_view>
#include <utility>
#include <vector>

#include "vksonar/config.h"

namespace vksonar {

// Generated into the build tree from assets/presets/*.json; the name is the file stem.
const std::vector<std::pair<std::string_view, std::string_view>>& embedded_presets();

std::vector<std::string> preset_names() {
    std::vector<std::string> names;
    for (const auto& [name, text] : embedded_presets())
        names.emplace_back(name);
    return names; // sorted by the generator
}

Result<SonarConfig> load_preset(const std::string& name) {
    for (const auto& [preset_name, text] : embedded_presets()) {
        if (preset_name != name) continue;
        const std::string origin = "preset '" + name + "'";
        auto config = apply_config_json(SonarConfig{}, std::string(text), origin);
        if (!config) return config;
        if (config->name.empty() || config->name == SonarConfig{}.name) config->name = name;
        if (auto valid = config->validate(); !valid)
            return make_error(ErrorCode::internal, origin + " is invalid: " + valid.error().message);
        return config;
    }
    std::string valid;
    for (const auto& preset_name : preset_names())
        valid += (valid.empty() ? "" : ", ") + preset_name;
    return make_error(ErrorCode::invalid_argument, "unknown preset '" + name + "' (valid presets: " + valid + ")");
}

} // namespace vksonar
