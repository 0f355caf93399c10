// Tests of the stage table (src/stages/stage_table.h). The backends walk it with no list of their
// own and trust what each entry says: that its inputs exist by the time it runs, that it has code on
// every backend, that its shaders are built and that its dispatches reach every cell of its grid.
// These tests hold the entries to that, for plans that switch each optional pass on and off.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "core/access.h"
#include "core/plan.h"
#include "stages/stage_table.h"
#include "vksonar/config.h"
#include "vksonar/scene.h"

namespace vksonar {
namespace {

struct NamedPlan {
    std::string name;
    Plan plan;
};

// The default sonar, and one variation per optional pass or grid shape.
std::vector<NamedPlan> plans() {
    struct Variation {
        const char* name;
        void (*apply)(SonarConfig&);
    };
    const Variation variations[] = {
        {"default", [](SonarConfig&) {}},
        {"incidence off", [](SonarConfig& c) { c.effects.incidence = EffectMode::off; }},
        {"incidence on", [](SonarConfig& c) { c.effects.incidence = EffectMode::on; }},
        {"geometric normals",
         [](SonarConfig& c) {
             c.effects.incidence = EffectMode::on;
             c.normal_method = NormalMethod::geometric;
         }},
        {"no side lobes", [](SonarConfig& c) { c.effects.horizontal_pattern = EffectMode::off; }},
        {"no far side lobes",
         [](SonarConfig& c) {
             c.effects.horizontal_pattern = EffectMode::on;
             c.far_sidelobe_cell = 0.0;
         }},
        {"planar", [](SonarConfig& c) { c.beam_geometry = BeamGeometry::planar; }},
        {"full circle", [](SonarConfig& c) { c.hfov_deg = 360.0; }},
    };
    const Scene scene;
    std::vector<NamedPlan> out;
    for (const Variation& v : variations) {
        SonarConfig config;
        v.apply(config);
        auto plan = make_plan(config, scene_data(scene));
        EXPECT_TRUE(plan) << v.name << ": " << (plan ? "" : plan.error().message);
        if (plan) out.push_back({v.name, std::move(plan.value())});
    }
    // A scene with an object that can be smaller than a pixel: the depth pass lists its returns and the
    // profile step reads them with the depth and material images (core/subpixel.h).
    Scene small;
    const float box[] = {0, 0, 0, 0.05f, 0, 0, 0.05f, 0.05f, 0, 0, 0.05f, 0, 0, 0, 0.05f, 0.05f, 0, 0.05f};
    const std::uint32_t triangles[] = {0, 1, 2, 0, 2, 3, 0, 1, 5, 0, 5, 4};
    auto mesh = small.add_mesh(box, 6, triangles, 12);
    EXPECT_TRUE(mesh.ok());
    SceneDraw draw;
    draw.mesh = mesh.ok() ? mesh.value() : 0;
    draw.world_from_local = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 10, 0, 0, 1};
    EXPECT_TRUE(small.add_draw(draw).ok());
    auto plan = make_plan(SonarConfig{}, scene_data(small));
    EXPECT_TRUE(plan && plan.value().subpixel_capacity > 0);
    if (plan) out.push_back({"sub-pixel objects", std::move(plan.value())});
    return out;
}

const StageInfo& entry(StageId id) {
    return kStageTable[static_cast<std::size_t>(id)];
}

std::vector<const char*> shader_names(const VulkanStage& side) {
    std::vector<const char*> names;
    for (const char* shader : side.shaders)
        if (shader != nullptr) names.push_back(shader);
    return names;
}

TEST(StageTable, EveryStageHasCodeOnEveryBackend) {
    std::set<std::string> names, host_depth_names;
    for (const StageInfo& stage : kStageTable) {
        ASSERT_NE(stage.name, nullptr);
        SCOPED_TRACE(stage.name);
        ASSERT_NE(stage.host_depth_name, nullptr);
        EXPECT_TRUE(names.insert(stage.name).second) << "two stages report the same name";
        EXPECT_TRUE(host_depth_names.insert(stage.host_depth_name).second);
        EXPECT_NE(stage.runs, nullptr);
        EXPECT_NE(stage.reads, nullptr);
        EXPECT_NE(stage.writes, nullptr);
        // the whole stage or its rows, in both precisions
        EXPECT_NE(stage.cpu.f32 != nullptr, stage.cpu.rows_f32 != nullptr);
        EXPECT_EQ(stage.cpu.f32 != nullptr, stage.cpu.f64 != nullptr);
        EXPECT_EQ(stage.cpu.rows_f32 != nullptr, stage.cpu.rows_f64 != nullptr);
        for (const VulkanStage* side : {&stage.vulkan, &stage.host_depth}) {
            EXPECT_NE(side->record, nullptr);
            EXPECT_NE(side->dispatches, nullptr);
            EXPECT_FALSE(shader_names(*side).empty());
        }
    }
}

// What a backend would otherwise read uninitialised (or the previous frame's values).
TEST(StageTable, EveryBufferReadIsWrittenEarlier) {
    for (const NamedPlan& p : plans()) {
        SCOPED_TRACE(p.name);
        StageBuffers written = kStageInputs;
        for (const StageInfo& stage : kStageTable) {
            if (!stage.runs(p.plan)) continue;
            const StageBuffers unwritten = stage.reads(p.plan) & ~written;
            EXPECT_FALSE(any(unwritten)) << stage.name << " reads buffers 0x" << std::hex
                                         << static_cast<unsigned>(unwritten) << " that no earlier stage writes";
            EXPECT_FALSE(any(stage.writes(p.plan) & kStageInputs)) << stage.name << " overwrites an input";
            written = written | stage.writes(p.plan);
        }
        EXPECT_TRUE(any(written & StageBuffers::polar)) << "no stage writes the polar scan";
    }
}

// The host-depth path makes its first submission wait for the host's semaphore: the stage that
// reads the host's image has to be the first, and the only one.
TEST(StageTable, OnlyTheFirstStageReadsTheScene) {
    for (const NamedPlan& p : plans()) {
        SCOPED_TRACE(p.name);
        ASSERT_TRUE(kStageTable[0].runs(p.plan));
        EXPECT_TRUE(any(kStageTable[0].reads(p.plan) & StageBuffers::scene));
        for (std::size_t i = 1; i < kStageCount; ++i)
            EXPECT_FALSE(any(kStageTable[i].reads(p.plan) & StageBuffers::scene)) << kStageTable[i].name;
    }
}

TEST(StageTable, EachSavedImageComesFromTheStageThatWritesIt) {
    SaveFlags seen = SaveFlags::none;
    for (const StageInfo& stage : kStageTable) {
        SCOPED_TRACE(stage.name);
        EXPECT_NE(stage.saves, SaveFlags::none);
        EXPECT_FALSE(any(seen & stage.saves)) << "two stages fill the same saved image";
        seen = seen | stage.saves;
        EXPECT_TRUE(any(stage.saved));
        for (const NamedPlan& p : plans()) {
            if (!stage.runs(p.plan)) continue;
            EXPECT_EQ(stage.saved & ~stage.writes(p.plan), StageBuffers::none) << p.name;
        }
    }
}

// The build compiles every file of shaders/ to <build>/shaders/<name>.spv.h (CMakeLists.txt); a
// name in the table that is not one of them names a shader no backend can run.
TEST(StageTable, ShadersAreBuilt) {
    const std::filesystem::path sources = std::filesystem::path(VKSONAR_TEST_DIR) / ".." / "shaders";
    const std::filesystem::path built = std::filesystem::path(VKSONAR_BUILD_DIR) / "shaders";
    for (const StageInfo& stage : kStageTable) {
        SCOPED_TRACE(stage.name);
        for (const VulkanStage* side : {&stage.vulkan, &stage.host_depth}) {
            for (const char* shader : shader_names(*side)) {
                EXPECT_TRUE(std::filesystem::is_regular_file(sources / shader)) << shader;
                EXPECT_TRUE(std::filesystem::is_regular_file(built / (std::string(shader) + ".spv.h"))) << shader;
            }
        }
    }
}

// Each dispatch runs one of its stage's shaders, and no workgroup is beyond what every Vulkan device
// allows (maxComputeWorkGroupCount is at least 65535 per dimension).
TEST(StageTable, DispatchesRunTheStagesShaders) {
    for (const NamedPlan& p : plans()) {
        SCOPED_TRACE(p.name);
        for (const StageInfo& stage : kStageTable) {
            for (const VulkanStage* side : {&stage.vulkan, &stage.host_depth}) {
                const std::vector<const char*> shaders = shader_names(*side);
                for (const DeviceShape& shape : {kCpuDeviceShape, kGpuDeviceShape}) {
                    for (const Dispatch& d : side->dispatches(p.plan, shape)) {
                        if (d.shader == nullptr) continue;
                        bool listed = false;
                        for (const char* shader : shaders)
                            listed = listed || std::string(shader) == d.shader;
                        EXPECT_TRUE(listed) << stage.name << " dispatches " << d.shader << ", not in its shaders";
                        EXPECT_GE(d.x, 1u);
                        EXPECT_GE(d.y, 1u);
                        EXPECT_GE(d.z, 1u);
                        EXPECT_LE(d.x, 65535u);
                        EXPECT_LE(d.y, 65535u);
                        EXPECT_LE(d.z, 65535u);
                    }
                }
            }
        }
        for (const Dispatch& d : kStageTable[0].vulkan.dispatches(p.plan, kCpuDeviceShape))
            EXPECT_EQ(d.shader, nullptr) << "the depth pass draws, it does not dispatch";
    }
}

// Invocations = workgroups x kWorkgroupSize, each covering `work` cells: at least the grid, and less
// than one workgroup more (the shaders return early past the grid's end, so an extra workgroup is
// waste, and a missing one leaves cells unwritten).
void expect_covers(std::uint64_t groups, std::uint64_t work, std::uint64_t cells, const char* what) {
    const std::uint64_t per_group = std::uint64_t(shared::kWorkgroupSize) * work;
    EXPECT_GE(groups * per_group, cells) << what;
    EXPECT_LT((groups - 1) * per_group, cells) << what;
}

TEST(StageTable, DispatchesCoverThePlansGrid) {
    using namespace stage_table; // the BeamformDispatch indices
    bool some_far = false, some_planar = false;
    for (const NamedPlan& p : plans()) {
        SCOPED_TRACE(p.name);
        const Plan& plan = p.plan;
        const std::uint64_t pixels = std::uint64_t(plan.columns) * plan.rows;
        const Dispatches import = entry(StageId::depth).host_depth.dispatches(plan, kCpuDeviceShape);
        expect_covers(import[0].x, 1, pixels, "import: one pixel per invocation");

        const Dispatch normals = entry(StageId::normals).vulkan.dispatches(plan, kCpuDeviceShape)[0];
        expect_covers(normals.x, 1, plan.rows * ceil_div(plan.columns, kNormalsRun), "normals: a run of a row");

        const Dispatch echo = entry(StageId::echo).vulkan.dispatches(plan, kCpuDeviceShape)[0];
        expect_covers(echo.x, kEchoPixels, plan.columns, "echo: pixels of a row");
        EXPECT_EQ(echo.y, plan.rows) << "echo: one row of workgroups per pixel row";

        const Dispatches beamform = entry(StageId::beamform).vulkan.dispatches(plan, kCpuDeviceShape);
        expect_covers(beamform[profile].x, plan.line_array ? kConesPerInvocation : 1, plan.profile_columns, "profile");
        // a GPU: kProfileBinLanes invocations per column (line array: per cone column)
        const Dispatches gpu = entry(StageId::beamform).vulkan.dispatches(plan, kGpuDeviceShape);
        expect_covers(gpu[profile].x, 1, plan.profile_columns * std::uint64_t(kProfileBinLanes), "profile, bin lanes");
        const bool sidelobes = plan.effects.horizontal_pattern, far = sidelobes && plan.far_cells > 0;
        for (const std::size_t pass : {std::size_t(resample), std::size_t(sidelobe)}) {
            if (pass == sidelobe && !sidelobes) {
                EXPECT_EQ(beamform[pass].shader, nullptr) << "side lobes off";
                continue;
            }
            expect_covers(beamform[pass].x, 4, plan.bins, "resample/sidelobe: 4-bin quads");
            EXPECT_GE(std::uint64_t(beamform[pass].y) * kBeamsPerInvocation, plan.beams);
            EXPECT_LT(std::uint64_t(beamform[pass].y - 1) * kBeamsPerInvocation, plan.beams);
            EXPECT_GE(std::uint64_t(gpu[pass].y) * kGpuBeamsPerInvocation, plan.beams);
            EXPECT_LT(std::uint64_t(gpu[pass].y - 1) * kGpuBeamsPerInvocation, plan.beams);
        }
        some_far = some_far || far;
        some_planar = some_planar || !plan.line_array;
        EXPECT_EQ(beamform[far_deposit].shader != nullptr, far);
        EXPECT_EQ(beamform[far_convolve].shader != nullptr, far);
        if (far) {
            expect_covers(beamform[far_deposit].x, 4, plan.bins, "far deposit");
            EXPECT_EQ(beamform[far_deposit].y, plan.far_cells * plan.far_channels);
            expect_covers(beamform[far_convolve].x, 4, plan.bins, "far convolve");
            // a row per channel, or per cell past the cells one invocation may loop over (lavapipe's limit)
            const bool per_cell = plan.far_cells > stage_table::kFarCellsInOneInvocation;
            EXPECT_EQ(beamform[far_convolve].y, per_cell ? plan.far_cells * plan.far_channels : plan.far_channels);
        }
    }
    EXPECT_TRUE(some_far && some_planar) << "the plans above no longer reach every dispatch";
}

} // namespace
} // namespace vksonar
