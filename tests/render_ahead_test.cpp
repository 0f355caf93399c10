// Render-ahead (Renderer::render with a NextFrame): the device renders the next frame into a second
// readback buffer while the host finishes this one, and the next frame's noise draws are made then.
// Every frame must be the bytes a plain render() gives for its pose, frame index and seed, whether the
// next call asks for the announced frame, another frame index, another pose, or a plain render.
#include <algorithm>
#include <cstring>

#include "test_support.h"

namespace vksonar::testing {
namespace {

struct AheadCase {
    const char* name;
    Backend backend;
    StageTiming
        timing; // host: start() submits and waits stage by stage; timestamps: one submission, waited in finish()
};

class RenderAhead : public ::testing::TestWithParam<AheadCase> {
protected:
    void SetUp() override {
        if (GetParam().backend == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    // The case's backend and stage timing.
    RendererOptions case_options() const {
        RendererOptions options;
        options.backend = GetParam().backend;
        options.stage_timing = GetParam().timing;
        return options;
    }
    ValidationGuard validation_;
};

std::string case_name(const ::testing::TestParamInfo<AheadCase>& info) {
    return info.param.name;
}

SonarConfig noisy_config() {
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on; // the draws made ahead
    config.effects.ambient_noise = EffectMode::on;
    return config;
}

void expect_same_frame(const Frame& ahead, const Frame& plain, const std::string& step) {
    expect_same_images(ahead, plain, step);
    EXPECT_EQ(ahead.frame_index, plain.frame_index) << step;
    EXPECT_EQ(ahead.stages_run, plain.stages_run) << step;
}

TEST_P(RenderAhead, EveryFrameIsAPlainRendersBytes) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    std::array<Pose, 4> poses{};
    for (std::size_t i = 0; i < poses.size(); ++i) { // four poses that see four different scans
        poses[i].pitch_deg = 10.0 + 4.0 * double(i);
        poses[i].yaw_deg = 5.0 * double(i);
    }
    const RendererOptions options = case_options();
    const SaveFlags saves = SaveFlags::depth | SaveFlags::echo | SaveFlags::profiles;
    auto ahead = render_once(options.backend, noisy_config(), scene.value(), poses[3], saves, 1, options);
    auto plain = render_once(options.backend, noisy_config(), scene.value(), poses[3], saves, 1, options);
    ASSERT_TRUE(ahead && plain);
    Renderer& a = ahead->renderer;
    Renderer& p = plain->renderer;

    struct Step {
        const char* what;
        std::size_t pose;
        std::uint64_t index;
        bool next;
        std::size_t next_pose;
        std::uint64_t next_index;
    };
    const std::array<Step, 6> steps{{
        {"first frame, announcing the second", 0, 0, true, 1, 1},
        {"the announced frame", 1, 1, true, 2, 2},
        {"the announced pose under another frame index", 2, 7, true, 3, 3},
        {"another pose than announced", 0, 4, true, 1, 5},
        {"the announced frame by a plain render", 1, 5, false, 0, 0},
        {"a plain render after it", 2, 6, false, 0, 0},
    }};
    std::vector<float> previous;
    for (const Step& step : steps) {
        SCOPED_TRACE(step.what);
        const Pose& pose = poses[step.pose];
        if (step.next) {
            ASSERT_TRUE(a.render(pose, step.index, ahead->frame, NextFrame{poses[step.next_pose], step.next_index}));
        } else {
            ASSERT_TRUE(a.render(pose, step.index, ahead->frame));
        }
        ASSERT_TRUE(p.render(pose, step.index, plain->frame));
        expect_same_frame(ahead->frame, plain->frame, step.what);
        EXPECT_NE(plain->frame.intensity, previous) << "each step a different frame";
        previous = plain->frame.intensity;
    }
    // A new seed between the announcement and the frame: the draws are made anew.
    ASSERT_TRUE(a.render(poses[3], 8, ahead->frame, NextFrame{poses[0], 9}));
    a.set_seed(5);
    p.set_seed(5);
    ASSERT_TRUE(a.render(poses[0], 9, ahead->frame, NextFrame{poses[1], 10}));
    ASSERT_TRUE(p.render(poses[0], 9, plain->frame));
    expect_same_frame(ahead->frame, plain->frame, "a new seed after the announcement");
}

// The same bytes, as bits (NaN where a cell has no label).
template <class T> bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

// With labels: the labels stage reads the sub-pixel returns of the frame it labels, which render-ahead
// keeps per frame slot while the next frame's are built.
TEST_P(RenderAhead, LabelsAreAPlainRendersBytes) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/harbour.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    const RendererOptions options = case_options();
    std::array<Pose, 3> poses{};
    for (std::size_t i = 0; i < poses.size(); ++i) {
        poses[i].pitch_deg = 8.0 + 3.0 * double(i);
        poses[i].yaw_deg = -10.0 + 10.0 * double(i);
    }
    auto ahead = render_once(options.backend, noisy_config(), scene.value(), poses[2], SaveFlags::labels, 1, options);
    auto plain = render_once(options.backend, noisy_config(), scene.value(), poses[2], SaveFlags::labels, 1, options);
    ASSERT_TRUE(ahead && plain);
    std::size_t labelled = 0;
    for (std::size_t i = 0; i < poses.size(); ++i) {
        SCOPED_TRACE(i);
        const NextFrame next{poses[(i + 1) % poses.size()], i + 1};
        ASSERT_TRUE(ahead->renderer.render(poses[i], i, ahead->frame, next));
        ASSERT_TRUE(plain->renderer.render(poses[i], i, plain->frame));
        const Frame& a = ahead->frame;
        const Frame& p = plain->frame;
        expect_same_images(a, p, "labels run");
        EXPECT_EQ(a.instance, p.instance);
        EXPECT_EQ(a.object_class, p.object_class);
        EXPECT_TRUE(same_bits(a.instance_fraction, p.instance_fraction));
        EXPECT_TRUE(same_bits(a.elevation, p.elevation));
        EXPECT_TRUE(same_bits(a.elevation_spread, p.elevation_spread));
        EXPECT_TRUE(same_bits(a.point, p.point));
        ASSERT_EQ(a.visibility.size(), p.visibility.size());
        for (std::size_t v = 0; v < a.visibility.size(); ++v) {
            EXPECT_EQ(a.visibility[v].instance, p.visibility[v].instance);
            EXPECT_EQ(a.visibility[v].pixels, p.visibility[v].pixels);
            EXPECT_EQ(a.visibility[v].hidden, p.visibility[v].hidden);
        }
        labelled +=
            std::size_t(std::count_if(a.instance.begin(), a.instance.end(), [](std::uint16_t id) { return id; }));
    }
    EXPECT_GT(labelled, 0u) << "the harbour's objects are labelled";
}

TEST_P(RenderAhead, RejectsANonFiniteNextPose) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    const RendererOptions options = case_options();
    auto r = render_once(options.backend, quiet_config(), scene.value(), {}, SaveFlags::none, 1, options);
    ASSERT_TRUE(r);
    NextFrame next;
    next.pose.yaw_deg = std::nan("");
    auto rendered = r->renderer.render(Pose{}, 1, r->frame, next);
    ASSERT_FALSE(rendered.ok());
    EXPECT_EQ(rendered.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(rendered.error().message.find("next pose"), std::string::npos) << rendered.error().message;
    ASSERT_TRUE(r->renderer.render(Pose{}, 1, r->frame)) << "the renderer goes on";
    // finite as a double but not as the float the view transforms hold
    Pose far;
    far.x_m = 1e39;
    rendered = r->renderer.render(far, 2, r->frame);
    ASSERT_FALSE(rendered.ok());
    EXPECT_EQ(rendered.error().code, ErrorCode::invalid_argument);
    ASSERT_TRUE(r->renderer.render(Pose{}, 3, r->frame)) << "the renderer goes on";
}

INSTANTIATE_TEST_SUITE_P(Backends, RenderAhead,
                         ::testing::Values(AheadCase{"vulkan_host_timed", Backend::vulkan, StageTiming::host},
                                           AheadCase{"vulkan_timestamps", Backend::vulkan, StageTiming::timestamps},
                                           AheadCase{"cpu", Backend::cpu, StageTiming::automatic}),
                         case_name);

} // namespace
} // namespace vksonar::testing
