#include "host/scene_framing.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace vksonar::host {

bool frame_pose(const Scene& scene, const SonarConfig& config, Pose& pose, bool& whole_box_in_window) {
    const SceneBounds b = scene.bounds();
    if (b.empty) return false;
    constexpr double kPi = 3.14159265358979323846;
    const double cx = 0.5 * (b.min_m[0] + b.max_m[0]), cy = 0.5 * (b.min_m[1] + b.max_m[1]);
    const double cz = 0.5 * (b.min_m[2] + b.max_m[2]);
    const double half_width = 0.5 * std::max(b.max_m[1] - b.min_m[1], 1e-3);
    const double half_depth = 0.5 * (b.max_m[0] - b.min_m[0]);
    const double half_fov = 0.5 * std::min(config.hfov_deg, 170.0) * kPi / 180.0;
    const double fit = std::max(half_width / std::tan(half_fov), config.range_min_m * 1.05) + half_depth;
    const double distance = std::min(fit, 0.5 * (config.range_min_m + config.range_max_m));
    const double pitch = 0.5 * std::min(config.vfov_deg, 60.0) * kPi / 180.0;
    pose = Pose{};
    pose.x_m = cx - distance;
    pose.y_m = cy;
    pose.z_m = cz + distance * std::tan(pitch);
    pose.pitch_deg = pitch * 180.0 / kPi;
    const double far = std::hypot(distance + half_depth, pose.z_m - b.min_m[2]);
    whole_box_in_window = !(far > config.range_max_m);
    return true;
}

std::string unit_mistake_warning(const Scene& scene, const SonarConfig& config, const std::string& scene_name,
                                 const std::string& fix_before, const std::string& fix_after) {
    const double size = scene.bounds().diagonal_m(), window = config.range_max_m;
    if (size <= 0.0 || !(window > 0.0)) return {};
    const auto fix = [&](const char* scale) { return fix_before + scale + fix_after; };
    char numbers[160];
    if (size > 200.0 * window && size > 5000.0) {
        std::snprintf(numbers, sizeof numbers, " is %.0f m across, %.0f times range_max (%.0f m)", size, size / window,
                      window);
        return scene_name + numbers + ": if it was modelled in millimetres (centimetres), " + fix("0.001") +
               " (0.01) brings it to metres";
    }
    if (size < window / 1000.0) {
        std::snprintf(numbers, sizeof numbers, " is %.3g m across, a %.0fth of range_max (%.0f m)", size, window / size,
                      window);
        return scene_name + numbers + ": if it was modelled in kilometres, " + fix("1000") + " brings it to metres";
    }
    return {};
}

} // namespace vksonar::host
