// The Vulkan layer on its own: context creation, and the Vulkan StageBackend driven directly from a
// hand-built SceneData and a Plan (no glTF, no Renderer), under the validation layer.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "core/plan.h"
#include "core/renderer_access.h"
#include "scene/scene_data.h"
#include "sonar_shared.h"
#include "stages/cpu_stages.h"
#include "test_support.h"
#include "tolerances.h"
#include "vk/vulkan_backend.h"
#include "vk/vulkan_context.h"
#include "vksonar/context.h"

namespace vksonar::testing {
namespace {

constexpr SaveFlags kSaveAll = SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles;

// A square plate of side `size_m`, in the plane x = distance_m (world), facing the sonar at the origin.
SceneData facing_plate(double distance_m, double size_m, double backscatter_db = -20.0) {
    SceneData scene;
    const float h = static_cast<float>(size_m / 2);
    scene.positions = {0, -h, -h, 0, h, -h, 0, h, h, 0, -h, h};
    scene.indices = {0, 1, 2, 0, 2, 3};
    scene.meshes.push_back(MeshRange{0, 6, 0, 4});
    SceneDraw draw;
    draw.mesh = 0;
    draw.material = 0;
    draw.world_from_local[12] = distance_m;
    scene.draws.push_back(draw);
    AcousticMaterial material;
    material.name = "plate";
    material.backscatter_db = backscatter_db;
    scene.materials.push_back(material);
    scene.stats.triangles = 2;
    scene.stats.meshes = 1;
    scene.stats.draws = 1;
    return scene;
}

SonarConfig small_config() {
    SonarConfig config;
    config.hfov_deg = 60.0;
    // The stage contracts these tests check are written on the planar beam geometry, where the
    // profile columns are the pixel columns; line_array's own: tests/beam_geometry_test.cpp.
    config.beam_geometry = BeamGeometry::planar;
    config.vfov_deg = 20.0;
    config.beams = 48;
    config.bins = 160;
    config.range_min_m = 1.0;
    config.range_max_m = 21.0;
    config.horizontal_beamwidth_deg = 1.5;
    config.rows_per_vfov = 32;
    config.effects.speckle = EffectMode::off;
    config.effects.ambient_noise = EffectMode::off;
    config.effects.tvg = EffectMode::off;
    return config;
}

// A Vulkan backend plus a frame sized for it, for one (config, scene).
struct Harness {
    Plan plan;
    std::unique_ptr<SceneData> scene;
    std::unique_ptr<StageBackend> backend;
    Frame frame;

    Result<void> render(const Pose& pose = {}, SaveFlags save_mask = kSaveAll) {
        return backend->render(pose, save_mask, frame);
    }
};

std::unique_ptr<Harness> make_harness(const SonarConfig& config, SceneData scene, const RendererOptions& options = {}) {
    auto harness = std::make_unique<Harness>();
    harness->scene = std::make_unique<SceneData>(std::move(scene));
    auto plan = make_plan(config, *harness->scene);
    if (!plan) {
        ADD_FAILURE() << "make_plan: " << plan.error().message;
        return nullptr;
    }
    harness->plan = std::move(plan.value());
    auto backend = vk::make_backend(*context_vulkan(*vulkan_context()), harness->plan, *harness->scene, options);
    if (!backend) {
        ADD_FAILURE() << "make_backend: " << backend.error().message;
        return nullptr;
    }
    harness->backend = std::move(backend.value());
    const Plan& p = harness->plan;
    const std::size_t pixels = std::size_t(p.rows) * p.columns, cells = std::size_t(p.bins) * p.beams;
    Frame& f = harness->frame;
    f.clean.assign(cells, -1.0f); // the backend must overwrite every cell
    f.depth.assign(pixels, -1.0f);
    f.material.assign(pixels, 0u);
    f.normals.assign(pixels * 4, -1.0f);
    f.echo.assign(pixels * 2, -1.0f);
    f.profiles.assign(std::size_t(p.bins) * p.columns, -1.0f);
    f.beam_profiles.assign(cells, -1.0f);
    return harness;
}

double view_z(const Plan& plan, float depth) {
    return plan.depth_a / (double(depth) - plan.depth_b);
}

TEST(VkContext, CreatesDeviceWithDescription) {
    VKSONAR_REQUIRE_VULKAN();
    Context* context = vulkan_context();
    EXPECT_TRUE(context->has_vulkan());
    ASSERT_NE(context_vulkan(*context), nullptr);
    EXPECT_NE(context_vulkan(*context)->device, VK_NULL_HANDLE);
    EXPECT_NE(context_vulkan(*context)->queue, VK_NULL_HANDLE);
    EXPECT_EQ(context_vulkan(*context)->owned_device.get(), context_vulkan(*context)->device);
    EXPECT_EQ(context_vulkan(*context)->owned_instance.get(), context_vulkan(*context)->instance);
    EXPECT_FALSE(context->device_description().empty());
    EXPECT_NE(context->device_description().find("Vulkan 1."), std::string::npos) << context->device_description();
    EXPECT_EQ(context->validation_messages(), 0u);
}

// Context::create fills the whole dispatch table (src/vk/functions.h) from the loader; the getters'
// device functions go straight to the driver or layer, past the loader's trampolines.
TEST(VkContext, OwnContextLoadsEveryFunction) {
    VKSONAR_REQUIRE_VULKAN();
    const vk::Functions& fn = context_vulkan(*vulkan_context())->fn;
    std::string missing;
#define VKSONAR_TEST_NULL(name)                                                                                        \
    if (fn.name == nullptr) missing += " " #name;
    VKSONAR_VK_GLOBAL_FUNCTIONS(VKSONAR_TEST_NULL)
    VKSONAR_VK_INSTANCE_FUNCTIONS(VKSONAR_TEST_NULL)
    VKSONAR_VK_OWN_INSTANCE_FUNCTIONS(VKSONAR_TEST_NULL)
    VKSONAR_VK_DEVICE_FUNCTIONS(VKSONAR_TEST_NULL)
    VKSONAR_VK_OWN_DEVICE_FUNCTIONS(VKSONAR_TEST_NULL)
#undef VKSONAR_TEST_NULL
    EXPECT_EQ(missing, "") << "null in the table";
    EXPECT_NE(fn.vkGetDeviceProcAddr, nullptr);
    EXPECT_EQ(fn.vkGetInstanceProcAddr, &vkGetInstanceProcAddr) << "the loader's, the one bootstrap function";
}

TEST(VkContext, CpuOnlyHasNoVulkan) {
    Context context = Context::cpu_only();
    EXPECT_FALSE(context.has_vulkan());
    EXPECT_EQ(context_vulkan(context), nullptr);
    EXPECT_EQ(context.validation_messages(), 0u);
    Context moved = std::move(context);
    EXPECT_FALSE(moved.has_vulkan());
}

TEST(VkContext, MissingDeviceIndexIsNoDeviceAndSuggestsCpuBackend) {
    VKSONAR_REQUIRE_VULKAN();
    ContextOptions options;
    options.device_index = 999;
    auto context = Context::create(options);
    ASSERT_FALSE(context.ok());
    EXPECT_EQ(context.error().code, ErrorCode::no_device);
    EXPECT_NE(context.error().message.find("--backend cpu"), std::string::npos) << context.error().message;
}

TEST(VkBackend, FacingPlateLandsInItsRangeBins) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    const double distance = 10.0;
    auto h = make_harness(small_config(), facing_plate(distance, 40.0));
    ASSERT_TRUE(h);
    auto rendered = h->render();
    ASSERT_TRUE(rendered.ok()) << rendered.error().message;
    const Plan& p = h->plan;
    const Frame& f = h->frame;
    ASSERT_EQ(f.clean.size(), std::size_t(p.bins) * p.beams);
    EXPECT_TRUE(all_finite(f.clean));
    // The plate fills the view: slant ranges run from `distance` (on axis) to distance / cos(corner).
    const double farthest = distance * std::sqrt(1.0 + p.tan_half_h * p.tan_half_h + p.tan_half_v * p.tan_half_v);
    double total = 0;
    for (std::uint32_t k = 0; k < p.bins; ++k) {
        for (std::uint32_t j = 0; j < p.beams; ++j) {
            const float cell = f.clean[std::size_t(k) * p.beams + j];
            ASSERT_GE(cell, 0.0f);
            total += cell;
            if (cell > 0.0f) {
                EXPECT_GE(p.bin_range_m[k], distance - 1.5 * p.bin_width_m) << "bin " << k << " beam " << j;
                EXPECT_LE(p.bin_range_m[k], farthest + 1.5 * p.bin_width_m) << "bin " << k << " beam " << j;
            }
        }
    }
    EXPECT_GT(total, 0.0);
    // The centre beam's brightest bin is the plate's on-axis range.
    const std::uint32_t centre_beam = p.beams / 2;
    std::uint32_t peak = 0;
    for (std::uint32_t k = 1; k < p.bins; ++k) {
        if (f.clean[std::size_t(k) * p.beams + centre_beam] > f.clean[std::size_t(peak) * p.beams + centre_beam]) {
            peak = k;
        }
    }
    EXPECT_NEAR(p.bin_range_m[peak], distance, 1.5 * p.bin_width_m);
}

TEST(VkBackend, IntermediatesAreConsistent) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    const double distance = 8.0;
    auto h = make_harness(small_config(), facing_plate(distance, 6.0)); // smaller than the view: edges
    ASSERT_TRUE(h);
    auto rendered = h->render();
    ASSERT_TRUE(rendered.ok()) << rendered.error().message;
    const Plan& p = h->plan;
    const Frame& f = h->frame;
    ASSERT_TRUE(p.effects.incidence) << "a Lambert material should turn the normals pass on";
    EXPECT_TRUE(all_finite(f.depth) && all_finite(f.normals) && all_finite(f.echo) && all_finite(f.profiles) &&
                all_finite(f.beam_profiles));

    std::size_t hits = 0;
    double echo_sum = 0;
    for (std::uint32_t row = 0; row < p.rows; ++row) {
        for (std::uint32_t column = 0; column < p.columns; ++column) {
            const std::size_t i = std::size_t(row) * p.columns + column;
            const float d = f.depth[i];
            ASSERT_GE(d, 0.0f);
            ASSERT_LE(d, 1.0f);
            if (d == 0.0f) {
                EXPECT_EQ(f.material[i], shared::kNoMaterial);
                EXPECT_EQ(f.echo[2 * i], 0.0f);
                EXPECT_EQ(f.normals[4 * i + 3], 0.0f);
                continue;
            }
            ++hits;
            EXPECT_EQ(f.material[i], 0u);
            EXPECT_NEAR(view_z(p, d), distance, distance * 1e-4);
            // The plate's normal is -x; cos incidence is the cosine of the ray to the x axis.
            const double range = f.echo[2 * i + 1];
            EXPECT_NEAR(f.normals[4 * i + 0], -1.0, 1e-3) << "row " << row << " column " << column;
            EXPECT_NEAR(f.normals[4 * i + 3], distance / range, 2e-3) << "row " << row << " column " << column;
            EXPECT_GT(f.echo[2 * i], 0.0f);
            echo_sum += f.echo[2 * i];
        }
    }
    EXPECT_GT(hits, 0u);
    EXPECT_LT(hits, std::size_t(p.rows) * p.columns);
    // The tent range kernel keeps energy: the column profiles hold exactly what the pixels echoed.
    EXPECT_NEAR(sum(f.profiles), echo_sum, echo_sum * 1e-4);
}

TEST(VkBackend, EmptySceneGivesAnAllZeroFrame) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    SceneData empty;
    AcousticMaterial material;
    empty.materials.push_back(material);
    auto h = make_harness(small_config(), std::move(empty));
    ASSERT_TRUE(h);
    auto rendered = h->render();
    ASSERT_TRUE(rendered.ok()) << rendered.error().message;
    EXPECT_EQ(sum(h->frame.clean), 0.0);
    EXPECT_EQ(*std::max_element(h->frame.clean.begin(), h->frame.clean.end()), 0.0f);
    EXPECT_EQ(*std::max_element(h->frame.depth.begin(), h->frame.depth.end()), 0.0f);
    EXPECT_EQ(sum(h->frame.profiles), 0.0);
    for (std::uint32_t id : h->frame.material) {
        ASSERT_EQ(id, shared::kNoMaterial);
    }
}

TEST(VkBackend, RepeatedRendersAreBitIdentical) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto h = make_harness(small_config(), facing_plate(12.0, 30.0));
    ASSERT_TRUE(h);
    ASSERT_TRUE(h->render().ok());
    const std::vector<float> first = h->frame.clean;
    Pose elsewhere;
    elsewhere.yaw_deg = 20.0;
    ASSERT_TRUE(h->render(elsewhere).ok());
    EXPECT_NE(h->frame.clean, first); // the pose reaches the depth pass
    ASSERT_TRUE(h->render().ok());
    EXPECT_EQ(h->frame.clean, first); // and coming back gives the same bits (no atomics, fixed order)
}

TEST(VkBackend, MovingTheSonarMovesTheEcho) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto h = make_harness(small_config(), facing_plate(12.0, 30.0));
    ASSERT_TRUE(h);
    const Plan& p = h->plan;
    auto peak_range = [&] {
        std::uint32_t peak = 0;
        const std::uint32_t j = p.beams / 2;
        for (std::uint32_t k = 1; k < p.bins; ++k) {
            if (h->frame.clean[std::size_t(k) * p.beams + j] > h->frame.clean[std::size_t(peak) * p.beams + j])
                peak = k;
        }
        return p.bin_range_m[peak];
    };
    ASSERT_TRUE(h->render().ok());
    const double before = peak_range();
    Pose closer;
    closer.x_m = 4.0;
    ASSERT_TRUE(h->render(closer).ok());
    EXPECT_NEAR(before - peak_range(), 4.0, 2 * p.bin_width_m);
}

TEST(VkBackend, ReportsStagesAndTimes) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto h = make_harness(small_config(), facing_plate(10.0, 20.0));
    ASSERT_TRUE(h);
    ASSERT_TRUE(h->render().ok());
    ASSERT_TRUE(h->render().ok()); // times and stages are replaced, not appended
    const std::vector<std::string> expected{"depth", "normals", "echo", "beamform"};
    EXPECT_EQ(h->frame.stages_run, expected);
    ASSERT_EQ(h->frame.times.size(), expected.size());
    for (std::size_t i = 0; i < expected.size(); ++i) {
        EXPECT_EQ(h->frame.times[i].stage, expected[i]);
        EXPECT_GE(h->frame.times[i].ms, 0.0);
        EXPECT_LT(h->frame.times[i].ms, 10000.0);
    }
}

TEST(VkBackend, DisabledEffectsSkipTheirPasses) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    SonarConfig config = small_config();
    config.effects.incidence = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    auto h = make_harness(config, facing_plate(10.0, 20.0));
    ASSERT_TRUE(h);
    ASSERT_FALSE(h->plan.effects.incidence);
    ASSERT_FALSE(h->plan.effects.horizontal_pattern);
    ASSERT_TRUE(h->render().ok());
    const std::vector<std::string> expected{"depth", "echo", "beamform"};
    EXPECT_EQ(h->frame.stages_run, expected);
    // Without side lobes the polar scan is the beam profiles; without normals they read back as zeros.
    EXPECT_EQ(h->frame.clean, h->frame.beam_profiles);
    EXPECT_GT(sum(h->frame.clean), 0.0);
    EXPECT_EQ(*std::max_element(h->frame.normals.begin(), h->frame.normals.end()), 0.0f);

    // Incidence off: every facing pixel echoes as if cos(theta) = 1, so the total can only grow.
    auto with = make_harness(small_config(), facing_plate(10.0, 20.0));
    ASSERT_TRUE(with);
    ASSERT_TRUE(with->render().ok());
    EXPECT_GT(sum(h->frame.beam_profiles), sum(with->frame.beam_profiles));
}

TEST(VkBackend, WideFanCoversEverySlice) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    config.beams = 96;
    auto h = make_harness(config, facing_plate(6.0, 60.0)); // reaches +-78 deg at 6 m
    ASSERT_TRUE(h);
    const Plan& p = h->plan;
    ASSERT_GT(p.slices, 1u);
    ASSERT_TRUE(h->render().ok());
    const std::uint32_t middle_row = p.rows / 2;
    for (std::uint32_t column = 0; column < p.slices * p.slice_columns; ++column) { // the slices (not the tier views)
        const float d = h->frame.depth[std::size_t(middle_row) * p.columns + column];
        ASSERT_GT(d, 0.0f) << "column " << column << " (slice " << column / p.slice_columns << ") saw nothing";
        // Each slice reconstructs the same plane x = 6 in its own frame.
        const std::uint32_t slice = column / p.slice_columns;
        const double u = (2.0 * (column % p.slice_columns + 0.5) / p.slice_columns - 1.0) * p.tan_half_h;
        const double x = view_z(p, d) * (p.slice_info[slice].forward_x + u * p.slice_info[slice].right_x);
        EXPECT_NEAR(x, 6.0, 6.0 * 2e-4) << "column " << column;
    }
    EXPECT_TRUE(all_finite(h->frame.clean));
}

// One submission for the whole frame (timestamps) or one per stage (host timing): the same frame.
// StageTiming::passes adds the beamform stage's passes and the host's steps to Frame::times, after the
// stages, and changes nothing else.
TEST(VkBackend, TimingModesGiveTheSameFrame) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    RendererOptions timestamps, host, passes;
    timestamps.stage_timing = StageTiming::timestamps;
    host.stage_timing = StageTiming::host;
    passes.stage_timing = StageTiming::passes;
    auto timestamped = make_harness(small_config(), facing_plate(9.0, 20.0), timestamps);
    auto host_timed = make_harness(small_config(), facing_plate(9.0, 20.0), host);
    auto by_pass = make_harness(small_config(), facing_plate(9.0, 20.0), passes);
    ASSERT_TRUE(timestamped && host_timed && by_pass);
    ASSERT_TRUE(timestamped->render().ok());
    ASSERT_TRUE(host_timed->render().ok());
    ASSERT_TRUE(by_pass->render().ok());
    EXPECT_EQ(host_timed->frame.clean, timestamped->frame.clean);
    EXPECT_EQ(host_timed->frame.echo, timestamped->frame.echo);
    EXPECT_EQ(host_timed->frame.stages_run, timestamped->frame.stages_run);
    EXPECT_EQ(by_pass->frame.clean, timestamped->frame.clean);
    EXPECT_EQ(by_pass->frame.stages_run, timestamped->frame.stages_run);
    ASSERT_EQ(host_timed->frame.times.size(), 4u);
    for (const StageTime& t : host_timed->frame.times)
        EXPECT_GT(t.ms, 0.0) << t.stage;
    for (const StageTime& t : timestamped->frame.times)
        EXPECT_GE(t.ms, 0.0) << t.stage;

    const std::vector<StageTime>& times = by_pass->frame.times;
    const std::size_t stages = timestamped->frame.times.size();
    if (timestamped->frame.times.empty() || times.size() == stages) GTEST_SKIP() << "no timestamp queries here";
    for (std::size_t i = 0; i < stages; ++i)
        EXPECT_EQ(times[i].stage, timestamped->frame.times[i].stage);
    std::vector<std::string> extra;
    for (std::size_t i = stages; i < times.size(); ++i) {
        extra.push_back(times[i].stage);
        EXPECT_GE(times[i].ms, 0.0) << times[i].stage;
    }
    // small_config: horizontal pattern on (the side-lobe pass), far side lobes as the plan has them
    ASSERT_GE(extra.size(), 6u);
    EXPECT_EQ(extra.front(), "bf:profile");
    EXPECT_EQ(extra[1], "bf:resample");
    const std::vector<std::string> host_steps{"host:prepare", "host:record", "host:gpu_wait", "host:copy"};
    EXPECT_EQ(std::vector<std::string>(extra.end() - 4, extra.end()), host_steps);
    EXPECT_EQ(extra[extra.size() - 5], "bf:sidelobe");
}

// The Renderer leaves the scan in the Vulkan backend's readback for the noise stage to copy out on its
// threads (StageBackend::defer_clean): its frame.clean must be the bytes the backend copies itself.
TEST(VkBackend, RendererCopiesTheScanOutOnTheNoiseThreads) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 10.0;
    RendererOptions threads;
    threads.host_threads = 3;
    auto rendered = render_once(Backend::vulkan, small_config(), scene.value(), pose, SaveFlags::none, 1, threads);
    ASSERT_TRUE(rendered);
    const Plan& plan = renderer_plan(rendered->renderer);
    auto backend = vk::make_backend(*context_vulkan(*vulkan_context()), plan, scene_data(scene.value()));
    ASSERT_TRUE(backend.ok()) << backend.error().message;
    EXPECT_EQ(backend.value()->pending_clean(), nullptr); // not deferred: render fills frame.clean
    Frame direct = rendered->renderer.make_frame();
    ASSERT_TRUE(backend.value()->render(pose, SaveFlags::none, direct).ok());
    ASSERT_EQ(direct.clean.size(), rendered->frame.clean.size());
    EXPECT_EQ(direct.clean, rendered->frame.clean);
    EXPECT_GT(std::count_if(direct.clean.begin(), direct.clean.end(), [](float v) { return v > 0.0f; }), 1000);
}

// The backend records the stages' command buffers once and re-records only the depth pass's (its draws
// follow the pose): a renderer that moves must give each pose the bytes a fresh renderer gives it.
TEST(VkBackend, KeptCommandBuffersFollowThePose) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose a, b;
    a.pitch_deg = 10.0;
    b.pitch_deg = 20.0;
    b.yaw_deg = 15.0;
    b.x_m = 1.0;
    const SaveFlags saves = SaveFlags::depth | SaveFlags::echo;
    auto moving = render_once(Backend::vulkan, small_config(), scene.value(), a, saves);
    auto fresh_b = render_once(Backend::vulkan, small_config(), scene.value(), b, saves);
    ASSERT_TRUE(moving && fresh_b);
    const std::vector<float> first_a = moving->frame.clean, first_a_depth = moving->frame.depth;
    ASSERT_TRUE(moving->renderer.render(b, 1, moving->frame).ok());
    EXPECT_EQ(moving->frame.clean, fresh_b->frame.clean) << "pose b after pose a";
    EXPECT_EQ(moving->frame.depth, fresh_b->frame.depth) << "pose b after pose a";
    ASSERT_TRUE(moving->renderer.render(a, 2, moving->frame).ok());
    EXPECT_EQ(moving->frame.clean, first_a) << "back at pose a";
    EXPECT_EQ(moving->frame.depth, first_a_depth) << "back at pose a";
    EXPECT_NE(first_a, fresh_b->frame.clean); // the poses see different scans
}

TEST(VkBackend, RejectsDrawOfMissingMesh) {
    VKSONAR_REQUIRE_VULKAN();
    SceneData scene = facing_plate(10.0, 20.0);
    Plan plan;
    {
        auto made = make_plan(small_config(), scene);
        ASSERT_TRUE(made.ok()) << made.error().message;
        plan = std::move(made.value());
    }
    scene.draws[0].mesh = 7;
    auto backend = vk::make_backend(*context_vulkan(*vulkan_context()), plan, scene);
    ASSERT_FALSE(backend.ok());
    EXPECT_EQ(backend.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(backend.error().message.find("mesh 7"), std::string::npos) << backend.error().message;
}

} // namespace
} // namespace vksonar::testing

namespace vksonar::testing {
namespace {

// The ValidationGuard in every test above is only worth something if messages are really counted.
TEST(VkContext, CountsValidationMessages) {
    VKSONAR_REQUIRE_VULKAN();
    ContextOptions options;
    options.enable_validation = true;
    auto created = Context::create(options);
    ASSERT_TRUE(created.ok()) << created.error().message;
    const VulkanContext& vk = *context_vulkan(*created);
    if (!vk.validation) {
        // CI installs the layer: without it every test would pass unvalidated.
        if (vulkan_required()) FAIL() << "VK_LAYER_KHRONOS_validation is not installed";
        GTEST_SKIP() << "VK_LAYER_KHRONOS_validation is not installed";
    }
    EXPECT_EQ(created->validation_messages(), 0u);
    VkBufferCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
    info.size = 0; // VUID-VkBufferCreateInfo-size-00912
    info.usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT;
    ::testing::internal::CaptureStderr();
    VkBuffer buffer = VK_NULL_HANDLE;
    // Through the context's table: the layer must see the calls vksonar makes through it.
    if (vk.fn.vkCreateBuffer(vk.device, &info, nullptr, &buffer) == VK_SUCCESS)
        vk.fn.vkDestroyBuffer(vk.device, buffer, nullptr);
    const std::string printed = ::testing::internal::GetCapturedStderr();
    EXPECT_GE(created->validation_messages(), 1u);
    EXPECT_NE(printed.find("validation error"), std::string::npos) << printed;
    EXPECT_EQ(std::count(printed.begin(), printed.end(), '\n'), std::ptrdiff_t(created->validation_messages()))
        << "one line per message: " << printed;
}

} // namespace
} // namespace vksonar::testing

namespace vksonar::testing {
namespace {

// A tilted plate with a small block in front of it: slopes, silhouettes and an occlusion edge.
SceneData edgy_scene() {
    SceneData scene = facing_plate(10.0, 12.0);
    const double yaw = 0.5, c = std::cos(yaw), s = std::sin(yaw);
    scene.draws[0].world_from_local = {c, s, 0, 0, -s, c, 0, 0, 0, 0, 1, 0, 10.0, 0.5, -0.3, 1};
    // second draw of the same mesh, small and closer, as a second material
    SceneDraw block = scene.draws[0];
    block.material = 1;
    block.world_from_local = {0.2, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 0.2, 0, 6.0, -0.4, 0.2, 1};
    scene.draws.push_back(block);
    AcousticMaterial bright;
    bright.name = "bright";
    bright.backscatter_db = -10.0;
    bright.model = AcousticMaterial::Model::constant;
    scene.materials.push_back(bright);
    return scene;
}

double rel_error(double a, double b, double floor) {
    return std::abs(a - b) / std::max({std::abs(b), floor, 1e-30});
}

class VkStageMatch : public ::testing::TestWithParam<int> {};

// Param 0: 48 beams, a short side-lobe kernel, tent range kernel. Param 1: 200 beams over 60 deg with
// 1.5 deg beams (more taps than sidelobe.comp's run of beams), nearest range kernel, 2 slices.
TEST_P(VkStageMatch, EachStageMatchesTheCpuReferenceOnTheSameInput) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    SonarConfig config = small_config();
    config.range_kernel = RangeKernel::tent;
    if (GetParam() == 1) {
        config.beams = 200;
        config.bins = 300;
        config.range_kernel = RangeKernel::nearest;
        config.max_slice_deg = 35.0;
    }
    auto h = make_harness(config, edgy_scene());
    ASSERT_TRUE(h);
    ASSERT_TRUE(h->render().ok());
    const Plan& p = h->plan;
    const Frame& g = h->frame;
    const std::size_t pixels = std::size_t(p.rows) * p.columns, cells = std::size_t(p.bins) * p.beams;

    // Depth: identical away from triangle edges.
    std::vector<shared::DepthPush> pushes;
    compose_depth_draws(p, *h->scene, Pose{}, pushes);
    std::vector<float> depth(pixels);
    std::vector<std::uint32_t> material(pixels);
    cpu::depth_pass(p, *h->scene, pushes, depth.data(), material.data());
    std::size_t hits = 0, mismatched = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        hits += g.depth[i] > 0;
        if ((g.depth[i] > 0) != (depth[i] > 0) || g.material[i] != material[i]) {
            ++mismatched;
        } else if (depth[i] > 0) {
            EXPECT_LE(rel_error(view_z(p, g.depth[i]), view_z(p, depth[i]), 0), kDepthInteriorRelTol) << "pixel " << i;
        }
    }
    ASSERT_GT(hits, 0u);
    EXPECT_LE(double(mismatched), kDepthEdgePixelBudget * hits) << mismatched << " of " << hits;

    // Every later stage from the GPU's own input.
    std::vector<float> normals(pixels * 4), echo(pixels * 2), profiles(std::size_t(p.bins) * p.columns),
        beam_profiles(cells), polar(cells);
    cpu::normals<float>(p, g.depth.data(), normals.data());
    cpu::echo<float>(p, g.depth.data(), g.material.data(), g.normals.data(), echo.data());
    cpu::beamform<float>(p, g.echo.data(), profiles.data(), beam_profiles.data(), polar.data());
    double max_angle_deg = 0, max_cos = 0, max_echo_rel = 0, max_range = 0;
    const double echo_peak = *std::max_element(g.echo.begin(), g.echo.end());
    for (std::size_t i = 0; i < pixels; ++i) {
        const float* a = &g.normals[4 * i];
        const float* b = &normals[4 * i];
        const double dot = double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2];
        const double cx = double(a[1]) * b[2] - double(a[2]) * b[1], cy = double(a[2]) * b[0] - double(a[0]) * b[2],
                     cz = double(a[0]) * b[1] - double(a[1]) * b[0];
        if (g.depth[i] > 0) { // atan2 of |a x b| and a . b: acos near 1 would measure its own rounding
            const double angle = std::atan2(std::sqrt(cx * cx + cy * cy + cz * cz), dot);
            max_angle_deg = std::max(max_angle_deg, angle * 180.0 / shared::kPi);
        }
        max_cos = std::max(max_cos, double(std::abs(a[3] - b[3])));
        max_echo_rel = std::max(max_echo_rel, rel_error(g.echo[2 * i], echo[2 * i], kEchoRelFloor * echo_peak));
        max_range = std::max(max_range, double(std::abs(g.echo[2 * i + 1] - echo[2 * i + 1])));
    }
    std::printf("[vk-vs-cpu] %zu hit pixels, %zu depth/material mismatches; normals max %.2g deg, cos %.2g; "
                "echo max rel %.2g, range %.2g m\n",
                hits, mismatched, max_angle_deg, max_cos, max_echo_rel, max_range);
    EXPECT_LE(max_angle_deg, kNormalAngleTolDeg);
    EXPECT_LE(max_cos, kNormalCosTol);
    EXPECT_LE(max_echo_rel, kEchoRelTol);
    EXPECT_LE(max_range, kRangeAbsTolM);
    auto compare = [&](const std::vector<float>& gpu, const std::vector<float>& cpu, const char* what) {
        const double peak = *std::max_element(cpu.begin(), cpu.end());
        ASSERT_GT(peak, 0.0) << what;
        double worst = 0;
        for (std::size_t i = 0; i < cpu.size(); ++i)
            worst = std::max(worst, rel_error(gpu[i], cpu[i], kBeamformRelFloor * peak));
        std::printf("[vk-vs-cpu] %s: max rel %.2g\n", what, worst);
        EXPECT_LE(worst, vulkan_device_is_cpu() ? kBeamformRelTol : kBeamformGpuRelTol) << what; // tolerances.h
    };
    compare(g.profiles, profiles, "profiles");
    compare(g.beam_profiles, beam_profiles, "beam profiles");
    compare(g.clean, polar, "polar");
    if (GetParam() == 1) {
        EXPECT_GT(p.near_column_taps, 32u) << "a beam's columns should outnumber a run of beams";
        EXPECT_GT(p.slices, 1u);
    }
}

INSTANTIATE_TEST_SUITE_P(Configs, VkStageMatch, ::testing::Values(0, 1));

// Vulkan failures injected through the context's function table (the backend calls through it): a
// failing vkQueueSubmit, an vkEndCommandBuffer that records but reports failure. Restored on scope exit.
struct FailingCalls {
    static inline PFN_vkEndCommandBuffer real_end = nullptr;
    static inline int end_calls_before_failure = -1; // < 0: never fail

    static VKAPI_ATTR VkResult VKAPI_CALL submit(VkQueue, std::uint32_t, const VkSubmitInfo*, VkFence) {
        return VK_ERROR_OUT_OF_DEVICE_MEMORY;
    }
    static VKAPI_ATTR VkResult VKAPI_CALL end(VkCommandBuffer commands) {
        const VkResult result = real_end(commands); // the buffer is recorded; the call reports a failure
        if (end_calls_before_failure >= 0 && end_calls_before_failure-- == 0) return VK_ERROR_OUT_OF_DEVICE_MEMORY;
        return result;
    }

    vk::Functions& fn;
    vk::Functions saved;
    explicit FailingCalls(vk::Functions& functions) : fn(functions), saved(functions) {
        real_end = fn.vkEndCommandBuffer;
    }
    ~FailingCalls() { fn = saved; }
};

// A failed vkQueueSubmit leaves the frame slot's fence unsignalled (it was reset for the submission):
// the render fails with ErrorCode::vulkan, and destroying the backend must not wait on that fence
// (before the fix it waited for it forever: this test then hangs until ctest's timeout).
TEST(VkBackend, FailedSubmitIsReportedAndDestructionDoesNotHang) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    RendererOptions options;
    options.stage_timing = StageTiming::host; // one submission per stage
    auto h = make_harness(small_config(), facing_plate(8.0, 40.0), options);
    ASSERT_TRUE(h);
    {
        FailingCalls failing(context_vulkan(*vulkan_context())->fn);
        failing.fn.vkQueueSubmit = &FailingCalls::submit;
        auto rendered = h->render();
        ASSERT_FALSE(rendered.ok());
        EXPECT_EQ(rendered.error().code, ErrorCode::vulkan);
        EXPECT_EQ(rendered.error().vk_result, VK_ERROR_OUT_OF_DEVICE_MEMORY);
    }
    h.reset(); // ~VulkanBackend
    SUCCEED();
}

// A save-mask change re-records a slot's kept command buffers; if that fails partway (here the
// readback's vkEndCommandBuffer), the slot must not stay "kept" with the old mask: the next render with
// that mask would submit the readback recorded for the failed mask and return stale intermediates.
TEST(VkBackend, FailedReRecordIsNotKept) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard guard;
    auto h = make_harness(small_config(), facing_plate(8.0, 40.0));
    auto reference = make_harness(small_config(), facing_plate(8.0, 40.0));
    ASSERT_TRUE(h && reference);
    ASSERT_TRUE(h->render().ok());                              // kSaveAll, from the origin: kept
    const std::size_t buffers = h->frame.stages_run.size() + 1; // the stages and the readback
    {
        FailingCalls failing(context_vulkan(*vulkan_context())->fn);
        failing.fn.vkEndCommandBuffer = &FailingCalls::end;
        FailingCalls::end_calls_before_failure = static_cast<int>(buffers) - 1; // the readback's
        auto rendered = h->render({}, SaveFlags::none);
        FailingCalls::end_calls_before_failure = -1;
        ASSERT_FALSE(rendered.ok());
        EXPECT_EQ(rendered.error().code, ErrorCode::vulkan);
    }
    Pose closer;
    closer.x_m = 3.0;
    ASSERT_TRUE(h->render(closer).ok());
    ASSERT_TRUE(reference->render(closer).ok());
    EXPECT_EQ(h->frame.clean, reference->frame.clean);
    EXPECT_EQ(h->frame.depth, reference->frame.depth) << "the readback of the failed re-record was submitted";
    EXPECT_EQ(h->frame.echo, reference->frame.echo);
}

} // namespace
} // namespace vksonar::testing
