// make_host_depth_plan: make_plan on a stand-in scene (one Lambert surface of the config's default
// backscatter: a host depth image carries no material ids), then the pixel grid and the column tables
// are replaced by the host image's.
#include "core/host_plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "core/angles.h"
#include "core/sonar_math.hpp"
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
    if (std::abs(desc.cx_px - 0.5 * desc.width) > 1e-3 || std::abs(desc.cy_px - 0.5 * desc.height) > 1e-3) {
        return uncovered("principal point (" + fmt(desc.cx_px) + ", " + fmt(desc.cy_px) +
                         ") is not the image centre (" + fmt(0.5 * desc.width) + ", " + fmt(0.5 * desc.height) +
                         "); crop the image symmetrically about the principal point");
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
    auto made = make_plan(config, stand_in);
    if (!made) return made.error();
    Plan p = std::move(made.value());

    const double tan_half_h = 0.5 * desc.width / desc.fx_px;
    const double tan_half_v = 0.5 * desc.height / desc.fy_px;
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

    p.slices = 1;
    p.slice_columns = desc.width;
    p.columns = desc.width;
    p.rows = desc.height;
    p.slice_width_rad = 2.0 * half_h;
    p.vertical_coverage_rad = 2.0 * half_v;
    p.tan_half_h = tan_half_h;
    p.tan_half_v = tan_half_v;
    p.slice_info.assign(1, shared::SliceInfo{0.0f, 1.0f, 0.0f, 0.0f});
    // Same clip planes rule as make_plan (the corner ray reaches the range gate's near edge at the near
    // plane; the far plane at its far edge), for the import pass's conversion to vksonar's reversed-Z
    // convention: a texel nearer than the near plane is clamped to it and so falls short of the gate.
    const double corner = std::sqrt(1.0 + tan_half_h * tan_half_h + tan_half_v * tan_half_v);
    p.near_m = 0.999 * p.gate_min_m / corner;
    p.far_m = p.gate_max_m;
    p.depth_a = p.near_m * p.far_m / (p.far_m - p.near_m);
    p.depth_b = -p.near_m / (p.far_m - p.near_m);

    // Column tables as in make_plan, except that columns outside the sonar's own hfov give nothing: a
    // wide host camera sees what the sonar cannot, and make_plan would fold it into the edge beams.
    // Such a column gets column_beam = beams, which matches no beam in resample (docs/pipeline.md §4).
    const double half_fan = 0.5 * config.hfov_deg * kDegToRad;
    p.column_azimuth_rad.resize(p.columns);
    for (std::uint32_t col = 0; col < p.columns; ++col) {
        const double u = math_f64::pixel_coord(col, p.columns, tan_half_h);
        p.column_azimuth_rad[col] = math_f64::pixel_azimuth(0.0, u);
    }
    assign_columns_to_beams(p, half_fan);

    shared::SonarParams& g = p.params;
    g.columns = p.columns;
    g.rows = p.rows;
    g.slice_columns = p.slice_columns;
    g.slices = 1;
    g.tan_half_h = static_cast<float>(tan_half_h);
    g.tan_half_v = static_cast<float>(tan_half_v);
    g.depth_a = static_cast<float>(p.depth_a);
    g.depth_b = static_cast<float>(p.depth_b);
    return p;
}

} // namespace vksonar
