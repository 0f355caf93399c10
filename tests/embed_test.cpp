// Embedding (docs/embedding.md): vksonar on a host engine's own device and depth image. The host is
// the example engine (examples/embed_host_engine.h), created by each test with its own validation
// messenger, so a validation message caused by vksonar on the borrowed device fails the test.
#ifdef VKSONAR_HAVE_EXAMPLE_ENGINE
#include <atomic>
#include <cmath>
#include <memory>
#include <thread>

#include "embed_glue.h"
#include "embed_host_engine.h"
#include "test_support.h"
#include "tolerances.h"

namespace vksonar::testing {
namespace {

host::CameraPose demo_camera() {
    host::CameraPose camera;
    camera.pitch_deg = 10.0; // nose down: seabed, box and pillar in view
    return camera;
}

// The engine options that reproduce the standalone grid of host::demo_config().
host::EngineOptions demo_engine_options() {
    const SonarConfig config = host::demo_config();
    auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
    EXPECT_TRUE(scene.ok());
    RendererOptions cpu;
    cpu.backend = Backend::cpu;
    auto grid = Renderer::create(cpu_context(), config, *scene, cpu);
    EXPECT_TRUE(grid.ok()) << (grid.ok() ? "" : grid.error().message);
    host::EngineOptions options = host::engine_options_for(config, grid->make_frame());
    options.validation = true;
    return options;
}

struct HostFixture {
    std::atomic<std::uint32_t> messages{0};
    std::unique_ptr<host::Engine> engine;
    host::EngineOptions options;
};

// Creates the engine, uploads the demo scene and renders its depth from demo_camera().
std::unique_ptr<HostFixture> make_host(host::EngineOptions options) {
    auto fixture = std::make_unique<HostFixture>();
    options.message_counter = &fixture->messages;
    fixture->options = options;
    fixture->engine = std::make_unique<host::Engine>();
    std::string error = fixture->engine->create(options);
    if (error.empty()) error = fixture->engine->upload(host::demo_scene());
    if (error.empty()) error = fixture->engine->render_depth(demo_camera());
    if (!error.empty()) {
        ADD_FAILURE() << "host engine: " << error;
        return nullptr;
    }
    return fixture;
}

class EmbedTest : public ::testing::Test {
protected:
    void SetUp() override { VKSONAR_REQUIRE_VULKAN(); }
};

TEST_F(EmbedTest, AdoptedDeviceOutlivesContextAndRenderer) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    {
        auto context = Context::adopt(host::host_vulkan(*host->engine));
        ASSERT_TRUE(context.ok()) << context.error().message;
        EXPECT_FALSE(context->owns_device());
        auto sonar = Renderer::create_for_depth(*context, host::demo_config(), host::depth_desc(host->options));
        ASSERT_TRUE(sonar.ok()) << sonar.error().message;
        Frame frame = sonar->make_frame();
        auto processed = sonar->process(host::depth_image(*host->engine), 0, frame);
        ASSERT_TRUE(processed.ok()) << processed.error().message;
        EXPECT_GT(sum(frame.clean), 0.0);
    } // Renderer, then Context: everything vksonar made is gone, nothing of the host's.
    // The host's device, queue and image still work: render again and wait.
    EXPECT_EQ(host->engine->render_depth(demo_camera()), "");
    EXPECT_EQ(host->messages.load(), 0u) << "validation messages while vksonar used the host's device";
    host->engine.reset(); // vkDestroyDevice reports any object vksonar left behind on it
    EXPECT_EQ(host->messages.load(), 0u) << "validation messages at host teardown (leaked or double-freed objects)";
}

// Standalone render vs process() of the host's own depth image of the same scene, same pixel grid.
// Both rasterize the same triangles on the same grid with different clip matrices (the host's
// projection has its own near/far and Z convention), so they differ only where a pixel centre lies
// within float rounding of a triangle edge, plus the host's depth precision: the same budgets as
// GPU-vs-CPU (tests/tolerances.h) apply.
class EmbedMatchTest : public ::testing::TestWithParam<bool> {
protected:
    void SetUp() override { VKSONAR_REQUIRE_VULKAN(); }
};

TEST_P(EmbedMatchTest, ProcessMatchesStandaloneRender) {
    host::EngineOptions options = demo_engine_options();
    options.reversed_z = GetParam();
    auto host = make_host(options);
    ASSERT_TRUE(host);
    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    const SonarConfig config = host::demo_config();
    RendererOptions renderer_options;
    renderer_options.save_mask = save_depth;
    auto sonar = Renderer::create_for_depth(*context, config, host::depth_desc(options), renderer_options);
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame embedded = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(*host->engine), 0, embedded).ok());

    auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
    ASSERT_TRUE(scene.ok());
    auto standalone = Renderer::create(*context, config, *scene, renderer_options);
    ASSERT_TRUE(standalone.ok()) << standalone.error().message;
    Frame reference = standalone->make_frame();
    ASSERT_TRUE(standalone->render(host::to_pose(demo_camera()), 0, reference).ok());
    ASSERT_EQ(embedded.columns, reference.columns);
    ASSERT_EQ(embedded.rows, reference.rows);

    // Depth: same hit/miss except on a thin band along edges; view z agrees in the interior.
    const Plan& plan = renderer_plan(*standalone);
    std::size_t hits = 0, mismatched = 0;
    double max_rel = 0, max_host_ulps = 0;
    // Standard-Z host depth resolves z only to one host depth ulp (kHostStandardZUlps): the relative
    // z step of one ulp near d = 1 at view depth z.
    const bool standard_z = !GetParam();
    const double n = options.near_m, f = options.far_m;
    auto host_ulp_rel = [&](double z) { return standard_z ? (f - n) / f * z / n * 0x1p-24 : 0.0; };
    for (std::size_t i = 0; i < reference.depth.size(); ++i) {
        const bool hit_r = reference.depth[i] > 0, hit_e = embedded.depth[i] > 0;
        hits += hit_r;
        if (hit_r != hit_e) {
            ++mismatched;
            continue;
        }
        if (!hit_r) continue;
        const double zr = plan.depth_a / (reference.depth[i] - plan.depth_b);
        const double ze = plan.depth_a / (embedded.depth[i] - plan.depth_b);
        const double rel = std::abs(ze - zr) / zr;
        if (rel > kDepthInteriorRelTol + kHostStandardZUlps * host_ulp_rel(zr)) {
            ++mismatched; // a neighbouring triangle won the pixel
        } else {
            max_rel = std::max(max_rel, rel);
            if (standard_z) max_host_ulps = std::max(max_host_ulps, rel / host_ulp_rel(zr));
        }
    }
    ASSERT_GT(hits, reference.depth.size() / 4) << "the demo scene should fill much of the image";
    EXPECT_LE(static_cast<double>(mismatched), kDepthEdgePixelBudget * hits)
        << mismatched << " of " << hits << " hit pixels differ";
    RecordProperty("depth_mismatched_pixels", static_cast<int>(mismatched));
    std::printf("[ embed ] %s-Z: depth %zu/%zu pixels differ, interior max rel z %.2e (%.1f host depth ulps)\n",
                GetParam() ? "reversed" : "standard", mismatched, hits, max_rel, max_host_ulps);

    // Whole frame in dB.
    const host::Comparison c = host::compare_clean(embedded, reference, config, kFrameDbTol);
    ASSERT_GT(c.above, 100u);
    EXPECT_LE(static_cast<double>(c.over), kFrameCellBudget * c.above)
        << c.over << " of " << c.above << " cells differ by more than " << kFrameDbTol << " dB (max " << c.max_db
        << ")";
    std::printf("[ embed ] %s-Z: %zu/%zu cells > %.1f dB, max %.3f dB\n", GetParam() ? "reversed" : "standard", c.over,
                c.above, kFrameDbTol, c.max_db);
    EXPECT_EQ(host->messages.load(), 0u);
}

INSTANTIATE_TEST_SUITE_P(Embed, EmbedMatchTest, ::testing::Values(true, false),
                         [](const ::testing::TestParamInfo<bool>& param) {
                             return param.param ? std::string("Reversed") : std::string("Standard");
                         });

TEST_F(EmbedTest, RecordIntoHostFrameMatchesProcess) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    auto sonar = Renderer::create_for_depth(*context, host::demo_config(), host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame processed = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(*host->engine), 7, processed).ok());

    Frame recorded = sonar->make_frame();
    EXPECT_FALSE(sonar->read_back(7, recorded).ok()) << "nothing recorded yet";
    bool early_read_failed = false;
    const std::string error = host->engine->render_depth(demo_camera(), [&](VkCommandBuffer commands) {
        auto r = sonar->record(commands, host::depth_image(*host->engine));
        // Recorded, not yet submitted: reading back now must fail instead of returning stale data.
        early_read_failed = !sonar->read_back(7, recorded).ok();
        return r ? std::string() : r.error().message;
    });
    ASSERT_EQ(error, "");
    EXPECT_TRUE(early_read_failed);
    auto read = sonar->read_back(7, recorded);
    ASSERT_TRUE(read.ok()) << read.error().message;
    EXPECT_GT(sum(recorded.clean), 0.0);
    EXPECT_EQ(recorded.clean, processed.clean) << "the same GPU work recorded vs submitted by vksonar";
    EXPECT_EQ(recorded.intensity, processed.intensity);

    auto polar = sonar->polar_buffer();
    ASSERT_TRUE(polar.ok());
    EXPECT_NE(polar->buffer, VK_NULL_HANDLE);
    EXPECT_EQ(polar->size, VkDeviceSize(processed.beams) * processed.bins * sizeof(float));
    EXPECT_EQ(host->messages.load(), 0u);
}

// Two sonars on one context, used from two threads at once, give what each gives alone.
TEST_F(EmbedTest, TwoRenderersOnOneContextMatchEachAlone) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    const SonarConfig config = host::demo_config();
    SonarConfig narrow = config; // a second, different sonar on the same host image
    narrow.hfov_deg = 40.0;
    narrow.beams = 64;
    narrow.range_max_m = 25.0;
    auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
    ASSERT_TRUE(scene.ok());
    const HostDepthImage image = host::depth_image(*host->engine);

    Frame alone_a, alone_b;
    {
        auto a = Renderer::create_for_depth(*context, narrow, host::depth_desc(host->options));
        ASSERT_TRUE(a.ok()) << a.error().message;
        alone_a = a->make_frame();
        ASSERT_TRUE(a->process(image, 3, alone_a).ok());
    }
    {
        auto b = Renderer::create(*context, config, *scene);
        ASSERT_TRUE(b.ok()) << b.error().message;
        alone_b = b->make_frame();
        ASSERT_TRUE(b->render(host::to_pose(demo_camera()), 3, alone_b).ok());
    }
    auto a = Renderer::create_for_depth(*context, narrow, host::depth_desc(host->options));
    auto b = Renderer::create(*context, config, *scene);
    ASSERT_TRUE(a.ok() && b.ok());
    Frame frame_a = a->make_frame(), frame_b = b->make_frame();
    std::atomic<int> failures{0}, mismatches{0};
    std::thread thread_a([&] {
        for (int i = 0; i < 4; ++i) {
            if (!a->process(image, 3, frame_a).ok()) ++failures;
            if (frame_a.clean != alone_a.clean) ++mismatches;
        }
    });
    std::thread thread_b([&] {
        for (int i = 0; i < 4; ++i) {
            if (!b->render(host::to_pose(demo_camera()), 3, frame_b).ok()) ++failures;
            if (frame_b.clean != alone_b.clean) ++mismatches;
        }
    });
    thread_a.join();
    thread_b.join();
    EXPECT_EQ(failures.load(), 0);
    EXPECT_EQ(mismatches.load(), 0);
    EXPECT_NE(alone_a.clean.size(), alone_b.clean.size()) << "the two sonars should differ";
    EXPECT_EQ(host->messages.load(), 0u);
}

TEST_F(EmbedTest, MissingRequirementsGiveClearErrors) {
    // A host instance created for Vulkan 1.0: refused with the version named.
    host::EngineOptions old_api = demo_engine_options();
    old_api.api_version = VK_API_VERSION_1_0;
    auto old_host = make_host(old_api);
    ASSERT_TRUE(old_host);
    auto refused = Context::adopt(host::host_vulkan(*old_host->engine));
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::unsupported);
    EXPECT_NE(refused.error().message.find("Vulkan 1.1"), std::string::npos) << refused.error().message;

    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    HostVulkan bad_family = host::host_vulkan(*host->engine);
    bad_family.queue_family = 99;
    auto no_family = Context::adopt(bad_family);
    ASSERT_FALSE(no_family.ok());
    EXPECT_NE(no_family.error().message.find("queue_family = 99"), std::string::npos) << no_family.error().message;
    HostVulkan no_device = host::host_vulkan(*host->engine);
    no_device.device = VK_NULL_HANDLE;
    EXPECT_EQ(Context::adopt(no_device).error().code, ErrorCode::invalid_argument);

    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok());
    const SonarConfig config = host::demo_config();
    // A host camera narrower than the sonar's beams.
    HostDepthDesc narrow = host::depth_desc(host->options);
    narrow.fx_px *= 3.0;
    narrow.fy_px *= 3.0; // also too short vertically, but the horizontal check comes first
    auto uncovered = Renderer::create_for_depth(*context, config, narrow);
    ASSERT_FALSE(uncovered.ok());
    EXPECT_EQ(uncovered.error().code, ErrorCode::unsupported);
    EXPECT_NE(uncovered.error().message.find("beams reach"), std::string::npos) << uncovered.error().message;
    // An off-centre principal point.
    HostDepthDesc shifted = host::depth_desc(host->options);
    shifted.cx_px += 3.0;
    auto off_centre = Renderer::create_for_depth(*context, config, shifted);
    ASSERT_FALSE(off_centre.ok());
    EXPECT_NE(off_centre.error().message.find("principal point"), std::string::npos);
    // A format that is no depth.
    HostDepthDesc colour = host::depth_desc(host->options);
    colour.format = VK_FORMAT_R8G8B8A8_UNORM;
    auto not_depth = Renderer::create_for_depth(*context, config, colour);
    ASSERT_FALSE(not_depth.ok());
    EXPECT_EQ(not_depth.error().code, ErrorCode::unsupported);
    // An image in a layout that cannot be sampled.
    auto sonar = Renderer::create_for_depth(*context, config, host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame frame = sonar->make_frame();
    HostDepthImage attachment = host::depth_image(*host->engine);
    attachment.layout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
    auto unreadable = sonar->process(attachment, 0, frame);
    ASSERT_FALSE(unreadable.ok());
    EXPECT_NE(unreadable.error().message.find("cannot be sampled"), std::string::npos);
    // The scene-renderer entry points on a depth renderer and vice versa.
    EXPECT_FALSE(sonar->render(Pose{}, 0, frame).ok());
    EXPECT_EQ(host->messages.load(), 0u);
    EXPECT_EQ(old_host->messages.load(), 0u);
}

} // namespace
} // namespace vksonar::testing
#endif
