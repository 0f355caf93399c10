// make_host_depth_plan: make_plan's steps on the host image's pixel grid (HostPixelGrid) and a stand-in
// scene (one Lambert surface of the config's default backscatter: a host depth image carries no
// material ids). Every derived value, the fp16 echo scale included, follows from the host grid.
#include "core/host_plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "core/angles.h"
#include "scene/scene_data.h"

namespace vksonar {
namespace {

std::string fmt(double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

Error bad(const std::string& what) {
    return make_error(ErrorCode::invalid_argument, "HostDepthDesc: " + what);
}

Error uncovered(const std::string& what) {
    return make_error(ErrorCode::unsupported, "HostDepthDesc: " + what);
}

} // namespace

Result<Plan> make_host_depth_plan(const SonarConfig& config, const HostDepthDesc& desc) {
    if (config.normal_method == NormalMethod::geometric) {
        return make_error(ErrorCode::unsupported,
                          "accuracy.normal_method = geometric needs the scene's triangles, and a host depth image "
                          "has none: use sobel3 or sobel5");
    }
    if (desc.width < 3 || desc.height < 3) {
        return bad("width x height = " + std::to_string(desc.width) + " x " + std::to_string(desc.height) +
                   " (at least 3 x 3: the normals stage needs neighbours)");
    }
    for (double v : {desc.fx_px, desc.fy_px}) {
        if (!(v > 0.0) || !std::isfinite(v)) return bad("fx_px / fy_px = " + fmt(v) + " (must be > 0)");
    }
    // The stages place pixel centres symmetrically about the optical axis (docs/pipeline.md); an
    // off-centre principal point would shift every ray, so it is refused rather than approximated.
    // (written so that a NaN fails it)
    if (!(std::abs(desc.cx_px - 0.5 * desc.width) <= 1e-3) || !(std::abs(desc.cy_px - 0.5 * desc.height) <= 1e-3)) {
        return uncovered("principal point (" + fmt(desc.cx_px) + ", " + fmt(desc.cy_px) +
                         ") is not the image centre (" + fmt(0.5 * desc.width) + ", " + fmt(0.5 * desc.height) +
                         "); crop the image symmetrically about the principal point");
    }
    if (!(desc.encoding == DepthEncoding::standard_z || desc.encoding == DepthEncoding::reversed_z ||
          desc.encoding == DepthEncoding::linear_m)) {
        // a number no encoding has: the shader's switch would read every pixel as no hit
        return bad("encoding = " + std::to_string(static_cast<int>(desc.encoding)) +
                   " (expected standard_z, reversed_z or linear_m)");
    }
    if (desc.encoding != DepthEncoding::linear_m) {
        if (!(desc.near_m > 0.0) || !std::isfinite(desc.near_m)) return bad("near_m = " + fmt(desc.near_m));
        const bool infinite_ok = desc.encoding == DepthEncoding::reversed_z && std::isinf(desc.far_m);
        if (!(desc.far_m > desc.near_m) || (std::isinf(desc.far_m) && !infinite_ok)) {
            return bad("far_m = " + fmt(desc.far_m) + " (must exceed near_m = " + fmt(desc.near_m) +
                       "; +inf only for reversed_z)");
        }
    }

    // Stand-in scene: one draw of one Lambert material, so `auto` effects resolve as for a scene whose
    // surfaces all have the default backscatter (incidence on).
    SceneData stand_in;
    AcousticMaterial material;
    material.name = "host depth (default backscatter)";
    material.backscatter_db = config.default_backscatter_db;
    stand_in.materials.push_back(material);
    stand_in.draws.push_back(SceneDraw{});
    const double tan_half_h = 0.5 * desc.width / desc.fx_px;
    const double tan_half_v = 0.5 * desc.height / desc.fy_px;
    const HostPixelGrid grid{desc.width, desc.height, tan_half_h, tan_half_v};
    auto made = make_plan(config, stand_in, &grid);
    if (!made) return made.error();
    Plan p = std::move(made.value());

    const double half_h = std::atan(tan_half_h);
    const double half_v = std::atan(tan_half_v);
    const double widest_beam = std::max(std::abs(p.beam_angle_rad.front()), std::abs(p.beam_angle_rad.back()));
    if (widest_beam > half_h) {
        return uncovered("the host image covers +-" + fmt(half_h * kRadToDeg) +
                         " deg horizontally but the sonar's beams reach +-" + fmt(widest_beam * kRadToDeg) +
                         " deg (hfov " + fmt(config.hfov_deg) + "); widen the host camera or narrow the sonar");
    }
    if (0.5 * config.vfov_deg * kDegToRad > half_v) {
        return uncovered("the host image covers +-" + fmt(half_v * kRadToDeg) +
                         " deg vertically but the sonar's -3 dB vertical beamwidth is +-" + fmt(0.5 * config.vfov_deg) +
                         " deg");
    }
    return p;
}

} // namespace vksonar
