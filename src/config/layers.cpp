#include "config/layers.h"

#include <filesystem>
#include <utility>

namespace vksonar {

Result<SonarConfig> load_sonar_file(const std::string& path) {
    auto config = apply_config_file(SonarConfig{}, path);
    if (config && config->name == SonarConfig{}.name) config->name = std::filesystem::path(path).stem().string();
    return config;
}

std::vector<EffectState> credit_scene_requests(std::vector<EffectState> states, const EffectsConfig& without_scene,
                                               const EffectsConfig& with_scene) {
    // Plan::effects' names (plan.cpp, resolve) and the EffectsConfig member each reads.
    static constexpr std::pair<const char*, EffectMode EffectsConfig::*> kModes[] = {
        {"incidence", &EffectsConfig::incidence},
        {"vertical_pattern", &EffectsConfig::vertical_pattern},
        {"vertical_sidelobes", &EffectsConfig::vertical_sidelobes},
        {"horizontal_pattern", &EffectsConfig::horizontal_pattern},
        {"spreading", &EffectsConfig::spreading},
        {"absorption", &EffectsConfig::absorption},
        {"speckle", &EffectsConfig::speckle},
        {"ambient_noise", &EffectsConfig::ambient_noise},
        {"tvg", &EffectsConfig::tvg}};
    for (EffectState& state : states)
        for (const auto& [name, mode] : kModes) {
            if (state.name != name || without_scene.*mode == with_scene.*mode) continue;
            // "on in config" / "off in config" and what a step added after it ("; far side lobes ...")
            const std::string prefix = state.on ? "on in config" : "off in config";
            if (state.why.compare(0, prefix.size(), prefix) == 0)
                state.why = (state.on ? "on" : "off") +
                            std::string(": the scene requests it "
                                        "(scenes[N].extras.vksonar.effects)") +
                            state.why.substr(prefix.size());
        }
    return states;
}

std::string scene_effects_layer(const Scene& scene) {
    const std::string& effects = scene.effects_json();
    if (effects.empty() || effects == "{}" || effects == "null") return {};
    return "{\"effects\": " + effects + "}";
}

} // namespace vksonar
