// Config layers both front ends (the CLI's render_job.cpp / inputs.cpp and the Python module) build the
// same way: a sonar file as `--sonar FILE.json` reads it, and a scene's effect requests as a layer
// (layers.cpp).
#pragma once

#include <string>
#include <vector>

#include "vksonar/config.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"

namespace vksonar {

// A sonar config file: its keys over the built-in defaults (SonarConfig{}), named by the file's stem
// unless it names itself. Errors as apply_config_file's.
[[nodiscard]] Result<SonarConfig> load_sonar_file(const std::string& path);

// The scene's effect requests (its glTF scenes[N].extras.vksonar.effects) as config JSON text,
// {"effects": {...}}, for apply_config_json over the base and under the user's layers; empty when the
// scene requests nothing.
std::string scene_effects_layer(const Scene& scene);

// The plan's effect states (meta.json's "effects") with the scene's part named: an effect whose mode
// the scene's request decided says "off: the scene requests it (scenes[N].extras.vksonar.effects)"
// instead of "off in config". `without_scene`: the effects of the same layers with no scene layer;
// `with_scene`: those the renderer ran. The request decided a mode where the two differ: nothing after
// the scene's layer overrode it. (Where they agree the config says the same, and "in config" holds; a
// request for auto leaves the plan's "auto: ..." reason.)
std::vector<EffectState> credit_scene_requests(std::vector<EffectState> states, const EffectsConfig& without_scene,
                                               const EffectsConfig& with_scene);

} // namespace vksonar
