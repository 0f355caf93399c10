// Accuracy presets: named sets of the accuracy.* knobs, applied as `key=value` overrides so their
// values go through the same checks as any user setting.
#include <algorithm>
#include <array>
#include <string>
#include <string_view>

#include "vksonar/config.h"

namespace vksonar {
namespace {

struct Quality {
    std::string_view name;
    std::array<std::string_view, 6> settings;
};

// Chosen from `vksonar bench accuracy` on the bundled scenes (README, docs/benchmarks.md): rows per
// vertical beamwidth and the range kernel buy the most accuracy per millisecond, then narrower
// slices; more than 2 pixel columns per beam buys little for extended scenes (it matters for point
// targets: tests/accuracy_test.cpp).
constexpr std::array<Quality, 3> kQualities{{
    // One pixel column per beam and a 2-beamwidth side-lobe kernel; rows and the footprint kernel
    // stay (cutting them costs 9-23 dB RMSE on a grazing seabed). The tier views' ratio is to these
    // slices' pixels, twice as wide as balanced's: 3 here keeps the tier pixels as large as balanced's 4
    // (at 4 they would be twice that: default scene 0.72 -> 1.32 dB RMSE).
    {"fast",
     {"accuracy.pixels_per_beam=1", "accuracy.rows_per_vfov=64", "accuracy.range_kernel=footprint",
      "accuracy.sidelobe_kernel_beamwidths=2", "accuracy.max_slice=60", "accuracy.tier_pixel_ratio=3"}},
    // The defaults.
    {"balanced",
     {"accuracy.pixels_per_beam=2", "accuracy.rows_per_vfov=64", "accuracy.range_kernel=footprint",
      "accuracy.sidelobe_kernel_beamwidths=3", "accuracy.max_slice=60", "accuracy.tier_pixel_ratio=4"}},
    // Four columns per beam, twice the rows, 15-degree slices, a 6-beamwidth side-lobe kernel.
    {"accurate",
     {"accuracy.pixels_per_beam=4", "accuracy.rows_per_vfov=128", "accuracy.range_kernel=footprint",
      "accuracy.sidelobe_kernel_beamwidths=6", "accuracy.max_slice=15", "accuracy.tier_pixel_ratio=2"}},
}};

} // namespace

std::vector<std::string> quality_names() {
    std::vector<std::string> names;
    for (const Quality& q : kQualities)
        names.emplace_back(q.name);
    return names;
}

std::vector<std::string> quality_settings(const std::string& name) {
    std::vector<std::string> out;
    for (const Quality& q : kQualities)
        if (q.name == name)
            for (std::string_view s : q.settings)
                out.emplace_back(s);
    return out;
}

Result<SonarConfig> apply_quality(const SonarConfig& base, const std::string& name) {
    const std::vector<std::string> settings = quality_settings(name);
    if (settings.empty())
        return make_error(ErrorCode::invalid_argument,
                          "quality: '" + name + "' is not a quality (fast, balanced or accurate)");
    SonarConfig config = base;
    for (const std::string& setting : settings) {
        auto applied = apply_config_override(config, setting);
        if (!applied) return applied.error();
        config = applied.value();
    }
    // uuv-legacy draws one pinhole depth image as wide as the fan (its preset's max_slice 90 holds the
    // 88.6 deg fan): a quality's slices, narrower, would refuse every such config; it keeps the wider.
    if (config.mode == SonarMode::uuv_legacy) config.max_slice_deg = std::max(config.max_slice_deg, base.max_slice_deg);
    return config;
}

} // namespace vksonar
