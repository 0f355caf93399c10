// Inputs shared by `vksonar render` and `vksonar bench`: the bundled default scene and --sonar.
#pragma once

#include <filesystem>
#include <string>

#include "vksonar/vksonar.h"

namespace vksonar::cli {

// The bundled default scene: the source tree's assets (VKSONAR_ASSET_DIR), then an installed tree
// (../share/vksonar/assets, ../assets next to the executable). Throws Failure if none exists.
std::filesystem::path find_default_scene();

// --sonar: a preset name, or a JSON file (a path, a name ending in .json, or an existing file that
// is not a preset name). A file's config is named after the file unless it names itself.
// Throws BadInput naming the file or the preset.
SonarConfig sonar_base_config(const std::string& sonar);

// A context for `backend` (validation only through VKSONAR_VALIDATION); for vulkan, throws Failure
// when no device exists, with the hint to use --backend cpu.
Context make_context(Backend backend);
// --backend auto: Vulkan on a GPU; the CPU backend where no Vulkan device works or the only one is a
// CPU implementation (lavapipe/llvmpipe), where the CPU backend renders as fast or faster (measured:
// docs/benchmarks.md, "How cost grows": faster at 16 of 18 points, at most 5 % slower at the others).
// Sets backend and why (for meta.json); never fails.
Context choose_backend(Backend& backend, std::string& why);

} // namespace vksonar::cli
