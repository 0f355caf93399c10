// Inputs shared by `vksonar render` and `vksonar bench`: the bundled default scene and --sonar.
#pragma once

#include <filesystem>
#include <string>
#include <utility>

#include "vksonar/vksonar.h"

namespace vksonar::cli {

// The bundled default scene: the source tree's assets (VKSONAR_ASSET_DIR), then an installed tree
// (../share/vksonar/assets, ../assets next to the executable). Throws Failure if none exists.
std::filesystem::path find_default_scene();

// --sonar: a preset name, or a JSON file (a path, a name ending in .json, or an existing file that
// is not a preset name). A file's config is named after the file unless it names itself.
// Throws BadInput naming the file or the preset.
SonarConfig sonar_base_config(const std::string& sonar);

// Which config layer made the config invalid: the last one that changed SonarConfig::validate's answer
// (a later layer may mend an earlier one's value, or break another key), so that the error names the
// file or the --set that holds the value as well as the key.
class ProblemOrigin {
public:
    // `config`'s values came from `origin` ("--sonar NAME_OR_FILE")
    ProblemOrigin(const SonarConfig& config, std::string origin);
    // `config` is the one after the layer `layer` ("--set key=value", "--config FILE"); the layer is
    // blamed where it changed what is invalid (validate()'s "KEY = VALUE"), not only its reason's wording
    void after(const SonarConfig& config, const std::string& layer);
    const std::string& origin() const { return origin_; }
    // BadInput "invalid config: ORIGIN: KEY = VALUE: why" where the last config given was invalid
    void throw_if_invalid() const;

private:
    std::string problem_; // validate()'s message, empty for a usable config
    std::string origin_;
};

// A context for `backend` (validation only through VKSONAR_VALIDATION); for vulkan, throws Failure
// when no device exists, with the hint to use --backend cpu.
Context make_context(Backend backend);
// --backend auto: Vulkan on a GPU; the CPU backend where no Vulkan device works or the only one is a
// CPU implementation (lavapipe/llvmpipe), where the CPU backend renders as fast or faster (measured:
// docs/benchmarks.md, "How cost grows": faster at all 18 points, by 4 to 6x on the full frame).
// Sets backend and why (for meta.json); never fails.
Context choose_backend(Backend& backend, std::string& why);

} // namespace vksonar::cli
