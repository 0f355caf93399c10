// Accuracy presets: named sets of the accuracy.* knobs (docs/accuracy.md has the measurements
// behind them). Applied as a layer of JSON on top of a config, so their values go through the same
// checks as any user file.
#include <array>
#include <string>
#include <string_view>
#include <utility>

#include "vksonar/config.h"

namespace vksonar {
namespace {

constexpr std::array<std::pair<std::string_view, std::string_view>, 3> kQualities{{
    // One pixel column per beam spacing, half the rows, a tent range kernel: the cheapest frame
    // that still puts every target in the right beam and bin (stripes on a grazing seabed at range).
    {"fast", R"({"accuracy": {"pixels_per_beam": 1, "rows_per_vfov": 32, "range_kernel": "tent",
                 "sidelobe_kernel_beamwidths": 2, "normal_method": "sobel3"}})"},
    // The defaults.
    {"balanced", R"({"accuracy": {"pixels_per_beam": 2, "rows_per_vfov": 64, "range_kernel": "footprint",
                     "sidelobe_kernel_beamwidths": 3, "normal_method": "sobel3"}})"},
    // Four columns per beam, twice the rows, narrower slices, wider side-lobe kernel.
    {"accurate", R"({"accuracy": {"pixels_per_beam": 4, "rows_per_vfov": 128, "range_kernel": "footprint",
                     "sidelobe_kernel_beamwidths": 6, "max_slice": 30, "normal_method": "sobel3"}})"},
}};

} // namespace

std::vector<std::string> quality_names() {
    std::vector<std::string> names;
    for (const auto& [name, json] : kQualities) names.emplace_back(name);
    return names;
}

Result<SonarConfig> apply_quality(const SonarConfig& base, const std::string& name) {
    for (const auto& [quality, json] : kQualities)
        if (quality == name) return apply_config_json(base, std::string(json), "quality " + name);
    return make_error(ErrorCode::invalid_argument,
                      "quality: '" + name + "' is not a quality (fast, balanced or accurate)");
}

} // namespace vksonar
