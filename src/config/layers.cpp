#include "config/layers.h"

#include <filesystem>

#include <nlohmann/json.hpp>

#include "config/config_keys.h"

namespace vksonar {

Result<SonarConfig> load_sonar_file(const std::string& path) {
    auto config = apply_config_file(SonarConfig{}, path);
    if (config && config->name == SonarConfig{}.name) config->name = std::filesystem::path(path).stem().string();
    return config;
}

std::vector<EffectState> credit_scene_requests(std::vector<EffectState> states, const EffectsConfig& without_scene,
                                               const EffectsConfig& with_scene) {
    // Each effect's mode through its config key, "effects.NAME" (Plan::effects' names are the keys').
    SonarConfig without, with;
    without.effects = without_scene;
    with.effects = with_scene;
    for (EffectState& state : states) {
        const config_keys::ConfigKey* key = config_keys::find("effects." + state.name);
        if (key == nullptr || key->get(without) == key->get(with)) continue;
        // "on in config" / "off in config" and what a step added after it ("; far side lobes ...")
        const std::string prefix = state.on ? "on in config" : "off in config";
        if (state.why.compare(0, prefix.size(), prefix) == 0)
            state.why = (state.on ? "on" : "off") +
                        std::string(": the scene requests it (scenes[N].extras.vksonar.effects)") +
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
