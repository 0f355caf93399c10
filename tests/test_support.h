// Helpers shared by the tests: a Vulkan context with validation, small hand-built scenes, and
// renders on both backends. Tolerances used across files live in tests/tolerances.h.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/access.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "vk/vulkan_context.h"
#include "vksonar/vksonar.h"

namespace vksonar::testing {

// One Vulkan context per test process (creating an instance with validation costs ~0.1 s).
// Returns null when no Vulkan device exists; tests then GTEST_SKIP.
inline Context* vulkan_context() {
    static std::unique_ptr<Context> context = [] {
        ContextOptions options;
        options.enable_validation = true;
        auto c = Context::create(options);
        return c ? std::make_unique<Context>(std::move(c.value())) : nullptr;
    }();
    return context.get();
}

// Whether the tests' Vulkan device is a CPU implementation (lavapipe, whose rasterizer follows the CPU
// backend's rule), not a GPU: the device type the backend picks its work layout by.
inline bool vulkan_device_is_cpu() {
    Context* context = vulkan_context();
    const VulkanContext* vulkan = context != nullptr ? context_vulkan(*context) : nullptr;
    return vulkan != nullptr && vulkan->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
}

inline Context& cpu_context() {
    static Context context = Context::cpu_only();
    return context;
}

// CI sets VKSONAR_REQUIRE_VULKAN=1: there a missing device or validation layer must fail, not skip.
inline bool vulkan_required() {
    const char* required = std::getenv("VKSONAR_REQUIRE_VULKAN");
    return required && required[0] == '1';
}

#define VKSONAR_REQUIRE_VULKAN()                                                                                       \
    do {                                                                                                               \
        if (::vksonar::testing::vulkan_context() == nullptr) {                                                         \
            if (::vksonar::testing::vulkan_required()) FAIL() << "no Vulkan device, and VKSONAR_REQUIRE_VULKAN=1";     \
            GTEST_SKIP() << "no Vulkan device";                                                                        \
        }                                                                                                              \
    } while (0)

// Fails the current test if the validation layer reported anything since the last call.
class ValidationGuard {
public:
    ValidationGuard() : before_(vulkan_context() ? vulkan_context()->validation_messages() : 0) {}
    ~ValidationGuard() {
        if (vulkan_context()) {
            EXPECT_EQ(vulkan_context()->validation_messages(), before_) << "Vulkan validation layer reported errors";
        }
    }

private:
    std::uint32_t before_;
};

// A test run on each backend (TEST_P over ::testing::Values(Backend::vulkan, Backend::cpu)): the
// Vulkan run skips without a device and fails on any validation message.
class BackendTest : public ::testing::TestWithParam<Backend> {
protected:
    void SetUp() override {
        if (GetParam() == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    ValidationGuard validation_;
};

// A rectangle of width x height metres, centred at `centre` (world), facing the -x direction
// (towards a sonar at the origin looking along +x), optionally rotated by yaw_deg about z.
inline void add_quad(Scene& scene, double cx, double cy, double cz, double width_m, double height_m,
                     const AcousticMaterial& material, double yaw_deg = 0.0, std::uint32_t instance = 0) {
    const float hw = static_cast<float>(width_m / 2), hh = static_cast<float>(height_m / 2);
    const float positions[] = {0, -hw, -hh, 0, hw, -hh, 0, hw, hh, 0, -hw, hh};
    const std::uint32_t indices[] = {0, 1, 2, 0, 2, 3};
    auto mesh = scene.add_mesh(positions, 4, indices, 6);
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    SceneDraw draw;
    draw.mesh = mesh.value();
    auto material_index = scene.add_material(material);
    ASSERT_TRUE(material_index.ok()) << material_index.error().message;
    draw.material = material_index.value();
    const double a = yaw_deg * 3.14159265358979323846 / 180.0;
    draw.world_from_local = {std::cos(a), std::sin(a), 0, 0, -std::sin(a), std::cos(a), 0,  0,
                             0,           0,           1, 0, cx,           cy,          cz, 1};
    draw.instance = instance;
    auto added = scene.add_draw(draw);
    ASSERT_TRUE(added.ok()) << added.error().message;
}

inline void add_quad(Scene& scene, double cx, double cy, double cz, double width_m, double height_m,
                     double backscatter_db = -20.0, double yaw_deg = 0.0,
                     AcousticMaterial::Model model = AcousticMaterial::Model::lambert) {
    AcousticMaterial material;
    material.name = "quad";
    material.backscatter_db = backscatter_db;
    material.model = model;
    add_quad(scene, cx, cy, cz, width_m, height_m, material, yaw_deg);
}

// A Lambert UV sphere of radius rs centred at (cx, cy, cz), `segments` around and segments / 2 from
// pole to pole, backscatter mu_db; its draw carries `instance` (SceneDraw::instance, for labels).
inline void add_sphere(Scene& scene, double cx, double cy, double cz, double rs, int segments, double mu_db,
                       std::uint32_t instance = 0) {
    const double pi = 3.14159265358979323846;
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    const int rings = segments / 2;
    for (int i = 0; i <= rings; ++i) {
        const double theta = pi * i / rings;
        for (int j = 0; j <= segments; ++j) {
            const double phi = 2 * pi * j / segments;
            positions.push_back(static_cast<float>(rs * std::sin(theta) * std::cos(phi)));
            positions.push_back(static_cast<float>(rs * std::sin(theta) * std::sin(phi)));
            positions.push_back(static_cast<float>(rs * std::cos(theta)));
        }
    }
    for (int i = 0; i < rings; ++i) {
        for (int j = 0; j < segments; ++j) {
            const std::uint32_t a = i * (segments + 1) + j, b = a + segments + 1;
            for (std::uint32_t v : {a, b, a + 1, a + 1, b, b + 1})
                indices.push_back(v);
        }
    }
    auto mesh = scene.add_mesh(positions.data(), positions.size() / 3, indices.data(), indices.size());
    ASSERT_TRUE(mesh.ok()) << mesh.error().message;
    AcousticMaterial material;
    material.backscatter_db = mu_db;
    SceneDraw draw;
    draw.mesh = mesh.value();
    auto material_index = scene.add_material(material);
    ASSERT_TRUE(material_index.ok()) << material_index.error().message;
    draw.material = material_index.value();
    draw.world_from_local = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, cx, cy, cz, 1};
    draw.instance = instance;
    ASSERT_TRUE(scene.add_draw(draw).ok());
}

// The default preset with every noise source off: the clean, deterministic model.
inline SonarConfig quiet_config() {
    auto c = load_preset("default");
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    SonarConfig config = c.ok() ? c.value() : SonarConfig{};
    config.effects.speckle = EffectMode::off;
    config.effects.ambient_noise = EffectMode::off;
    config.effects.tvg = EffectMode::off;
    return config;
}

// A frame sized for the plan's scan, as the host stages take it: clean, intensity and display all 0, with the
// plan's beam angles and bin ranges.
inline Frame host_stage_frame(const Plan& p) {
    Frame f;
    f.beams = p.beams;
    f.bins = p.bins;
    const std::size_t n = static_cast<std::size_t>(p.beams) * p.bins;
    f.clean.assign(n, 0.0f);
    f.intensity.assign(n, 0.0f);
    f.display.assign(n, 0.0f);
    f.beam_angles_rad = p.beam_angle_rad;
    f.bin_ranges_m = p.bin_range_m;
    return f;
}

// Every image two frames hold, compared byte for byte (an image neither saved compares as empty), with
// `what` in each failure.
inline void expect_same_images(const Frame& a, const Frame& b, const std::string& what) {
    EXPECT_EQ(a.depth, b.depth) << what;
    EXPECT_EQ(a.material, b.material) << what;
    EXPECT_EQ(a.normals, b.normals) << what;
    EXPECT_EQ(a.echo, b.echo) << what;
    EXPECT_EQ(a.profiles, b.profiles) << what;
    EXPECT_EQ(a.beam_profiles, b.beam_profiles) << what;
    EXPECT_EQ(a.clean, b.clean) << what;
    EXPECT_EQ(a.intensity, b.intensity) << what;
    EXPECT_EQ(a.display, b.display) << what;
}

struct Rendered {
    Renderer renderer;
    Frame frame;
};

inline std::unique_ptr<Rendered> render_once(Backend backend, const SonarConfig& config, const Scene& scene,
                                             const Pose& pose = {}, SaveFlags save_mask = SaveFlags::none,
                                             std::uint64_t seed = 1, const RendererOptions& paths = {}) {
    Context* context = backend == Backend::vulkan ? vulkan_context() : &cpu_context();
    if (context == nullptr) {
        ADD_FAILURE() << "no context";
        return nullptr;
    }
    RendererOptions options = paths; // the Vulkan paths (tables, resample, layout, stage_timing)
    // VKSONAR_LAYOUT=gpu runs a test's Vulkan renders in the GPU layout where it asks for none (ctest
    // vulkan_gpu_layout: lavapipe runs the layout a GPU gets through the GPU-vs-CPU tests).
    if (options.layout == WorkLayout::automatic) options.layout = renderer_options_from_env().layout;
    options.backend = backend;
    options.save_mask = save_mask;
    options.seed = seed;
    auto r = Renderer::create(*context, config, scene, options);
    if (!r) {
        ADD_FAILURE() << r.error().message;
        return nullptr;
    }
    auto out = std::make_unique<Rendered>(Rendered{std::move(r.value()), {}});
    out->frame = out->renderer.make_frame();
    auto ok = out->renderer.render(pose, 0, out->frame);
    if (!ok) {
        ADD_FAILURE() << ok.error().message;
        return nullptr;
    }
    return out;
}

// The clean scan's total energy and its energy-weighted mean range (m): two scans of the same scene
// written two ways (compressed, quantized, instanced) are compared by these.
inline std::pair<double, double> energy_and_mean_range(const Frame& f) {
    double energy = 0, weighted = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            const double e = f.clean[std::size_t(k) * f.beams + j];
            energy += e;
            weighted += e * f.bin_ranges_m[k];
        }
    return {energy, weighted / energy};
}

inline double sum(const std::vector<float>& v) {
    double s = 0;
    for (float x : v)
        s += x;
    return s;
}

inline bool all_finite(const std::vector<float>& v) {
    for (float x : v) {
        if (!std::isfinite(x)) return false;
    }
    return true;
}

// x with sinc(x)^2 = 1/2: the half-power point of a uniform line array, by bisection on [0.5, 3]
// (sinc^2 falls monotonically from 1 to 0 on (0, pi)); closed-form references build their sinc^2
// patterns on it, independently of the library's pattern constant.
inline double sinc_half_power_x() {
    double lo = 0.5, hi = 3.0;
    for (int i = 0; i < 200; ++i) {
        const double mid = 0.5 * (lo + hi);
        const double s = std::sin(mid) / mid;
        (s * s > 0.5 ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

inline double to_db(double x) {
    return 10.0 * std::log10(x);
}

} // namespace vksonar::testing
