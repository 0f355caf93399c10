#include "config/layers.h"

#include <filesystem>

namespace vksonar {

Result<SonarConfig> load_sonar_file(const std::string& path) {
    auto config = apply_config_file(SonarConfig{}, path);
    if (config && config->name == SonarConfig{}.name) config->name = std::filesystem::path(path).stem().string();
    return config;
}

std::string scene_effects_layer(const Scene& scene) {
    const std::string& effects = scene.effects_json();
    if (effects.empty() || effects == "{}" || effects == "null") return {};
    return "{\"effects\": " + effects + "}";
}

} // namespace vksonar
