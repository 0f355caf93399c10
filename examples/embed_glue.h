// The glue between the example host engine (embed_host_engine.h) and vksonar: what an engine hands
// over (its Vulkan objects, its depth image and projection) and the comparison the example and
// tests/embed_test.cpp make against vksonar's standalone render of the same scene.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

#include "embed_host_engine.h"
#include "vksonar/vksonar.h"

namespace host {

// A one-slice sonar (the pixel grid's azimuths <= max_slice), so that the standalone render's pixel
// grid is a single pinhole image the host engine can reproduce exactly. Noise off: the clean,
// deterministic model. A line array (the default beam geometry), whose grid reaches past the fan.
inline vksonar::SonarConfig demo_config() {
    vksonar::SonarConfig config;
    config.name = "embed-demo";
    config.hfov_deg = 60.0;
    config.vfov_deg = 20.0;
    config.beams = 128;
    config.bins = 256;
    config.range_min_m = 0.5;
    config.range_max_m = 40.0;
    config.horizontal_beamwidth_deg = 1.0;
    config.default_backscatter_db = -30.0;
    // +-25 deg: past the sinc pattern's first null (23.1 deg for a 20-degree beam), so this, not the
    // null, sets the depth pass's vertical coverage and engine_options_for can state it in closed form.
    config.vertical_coverage = 2.5;
    config.max_slice_deg = 90.0; // the line array's grid spans 67 deg (engine_options_for): one slice
    config.effects.speckle = vksonar::EffectMode::off;
    config.effects.ambient_noise = vksonar::EffectMode::off;
    config.effects.tvg = vksonar::EffectMode::off;
    // The engine's camera is one perspective view: it cannot hold the tier views that the vertical side
    // lobes need (elevations down to the nadir), so the standalone render it is compared with has none.
    config.effects.vertical_sidelobes = vksonar::EffectMode::off;
    return config;
}

// The engine camera that sees exactly the standalone render's pixel grid (one slice). The coverage
// rules of docs/pipeline.md for a config whose vertical_coverage x vfov / 2 lies past the vertical
// pattern's first null (demo_config): vertically tan(vertical_coverage x vfov / 2), times
// sqrt(1 + tan_half_h^2) so that the slice's edge columns reach that elevation too; horizontally the
// fan, or for a line array as far as the edge beam's cone leans out at that elevation,
// asin(sin(hfov / 2) / cos(elevation)), up to 89 degrees.
inline EngineOptions engine_options_for(const vksonar::SonarConfig& config, const vksonar::Frame& standalone) {
    const double d = 3.14159265358979323846 / 180.0;
    const double half_coverage = 0.5 * std::min(config.vfov_deg * config.vertical_coverage, 170.0) * d;
    double half_h = 0.5 * config.hfov_deg * d;
    if (config.beam_geometry == vksonar::BeamGeometry::line_array) {
        const double reach = std::sin(half_h) / std::cos(half_coverage);
        half_h = std::min(reach < 1.0 ? std::asin(reach) : 90.0 * d, 89.0 * d);
    }
    EngineOptions options;
    options.width = standalone.columns;
    options.height = standalone.rows;
    options.tan_half_h = std::tan(half_h);
    options.tan_half_v = std::tan(half_coverage) * std::sqrt(1.0 + options.tan_half_h * options.tan_half_h);
    return options;
}

inline vksonar::HostVulkan host_vulkan(const Engine& engine) {
    vksonar::HostVulkan host;
    host.instance = engine.instance();
    host.physical_device = engine.physical_device();
    host.device = engine.device();
    host.queue_family = engine.queue_family();
    host.queue = engine.queue();
    host.instance_api_version = engine.options().api_version;
    return host;
}

inline vksonar::HostDepthDesc depth_desc(const EngineOptions& o) {
    vksonar::HostDepthDesc desc;
    desc.width = o.width;
    desc.height = o.height;
    desc.format = o.depth_format;
    desc.fx_px = 0.5 * o.width / o.tan_half_h;
    desc.fy_px = 0.5 * o.height / o.tan_half_v;
    desc.cx_px = 0.5 * o.width;
    desc.cy_px = 0.5 * o.height;
    desc.encoding = o.reversed_z ? vksonar::DepthEncoding::reversed_z : vksonar::DepthEncoding::standard_z;
    desc.near_m = o.near_m;
    desc.far_m = o.far_m;
    return desc;
}

inline vksonar::HostDepthImage depth_image(const Engine& engine) {
    vksonar::HostDepthImage image;
    image.image = engine.depth_image();
    image.view = engine.depth_view();
    image.layout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_READ_ONLY_OPTIMAL; // the engine's render pass final layout
    return image;
}

// The same meshes as a vksonar Scene (world coordinates: identity transforms, default material).
inline vksonar::Result<vksonar::Scene> to_scene(const std::vector<Mesh>& meshes, double backscatter_db) {
    vksonar::Scene scene;
    vksonar::AcousticMaterial material;
    material.name = "engine default";
    material.backscatter_db = backscatter_db;
    const auto material_id = scene.add_material(material);
    if (!material_id) return material_id.error();
    for (const Mesh& mesh : meshes) {
        auto id = scene.add_mesh(mesh.positions.data(), static_cast<std::uint32_t>(mesh.positions.size() / 3),
                                 mesh.indices.data(), static_cast<std::uint32_t>(mesh.indices.size()));
        if (!id) return id.error();
        vksonar::SceneDraw draw;
        draw.mesh = id.value();
        draw.material = material_id.value();
        if (auto added = scene.add_draw(draw); !added) return added.error();
    }
    return scene;
}

inline vksonar::Pose to_pose(const CameraPose& c) {
    return vksonar::Pose{c.x_m, c.y_m, c.z_m, c.roll_deg, c.pitch_deg, c.yaw_deg};
}

// Whole-frame comparison in dB over the cells above the noise floor (as tests/gpu_cpu_test.cpp's
// WholeFrameAgrees): how many differ by more than db_tolerance.
struct Comparison {
    std::size_t above = 0, over = 0;
    double max_db = 0;
};

inline Comparison compare_clean(const vksonar::Frame& a, const vksonar::Frame& b, const vksonar::SonarConfig& config,
                                double db_tolerance) {
    Comparison c;
    const double floor =
        std::pow(10.0, (config.noise_terms().floor_db() - config.source_level_db) / 10.0); // "auto" resolved
    for (std::size_t i = 0; i < a.clean.size() && i < b.clean.size(); ++i) {
        if (a.clean[i] < floor && b.clean[i] < floor) continue;
        ++c.above;
        const double d = std::abs(10.0 * std::log10(std::max<double>(a.clean[i], floor * 1e-3)) -
                                  10.0 * std::log10(std::max<double>(b.clean[i], floor * 1e-3)));
        c.max_db = std::max(c.max_db, d);
        c.over += d > db_tolerance;
    }
    return c;
}

} // namespace host
