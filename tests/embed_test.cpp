// Embedding (docs/embedding.md): vksonar on a host engine's own device and depth image. The host is
// the example engine (examples/embed_host_engine.h), created by each test with its own validation
// messenger, so a validation message caused by vksonar on the borrowed device fails the test.
#ifdef VKSONAR_HAVE_EXAMPLE_ENGINE
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <mutex>
#include <new>
#include <set>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "embed_glue.h"
#include "embed_host_engine.h"
#include "test_support.h"
#include "tolerances.h"
#include "vk/vulkan_context.h"

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
        // Borrowed: no owner holds the host's instance or device, so ~VulkanContext destroys nothing.
        EXPECT_FALSE(context_vulkan(*context)->owned_device);
        EXPECT_FALSE(context_vulkan(*context)->owned_instance);
        auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options));
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
    renderer_options.save_mask = SaveFlags::depth;
    auto sonar = HostDepthRenderer::create(*context, config, host::depth_desc(options), renderer_options);
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

    // The host camera is the standalone grid's (host::engine_options_for states its coverage rule).
    const Plan& plan = renderer_plan(*standalone);
    ASSERT_EQ(plan.slices, 1u);
    ASSERT_NEAR(options.tan_half_h, plan.tan_half_h, 1e-12 * plan.tan_half_h);
    ASSERT_NEAR(options.tan_half_v, plan.tan_half_v, 1e-12 * plan.tan_half_v);

    // Depth: same hit/miss except on a thin band along edges; view z agrees in the interior.
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
    auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame processed = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(*host->engine), 7, processed).ok());

    Frame recorded = sonar->make_frame();
    EXPECT_FALSE(sonar->read_back(7, recorded).ok()) << "nothing recorded yet";
    bool early_read_failed = false, early_second_refused = false;
    const std::string error = host->engine->render_depth(demo_camera(), [&](VkCommandBuffer commands) {
        auto r = sonar->record(commands, host::depth_image(*host->engine));
        // Recorded, not yet submitted: reading back now must fail instead of returning stale data, and a
        // second record or a process would rewrite what the recorded ping is about to use.
        early_read_failed = !sonar->read_back(7, recorded).ok();
        auto again = sonar->record(commands, host::depth_image(*host->engine));
        auto meanwhile = sonar->process(host::depth_image(*host->engine), 7, processed);
        const char* why = "has not finished executing";
        early_second_refused = !again && again.error().message.find(why) != std::string::npos && !meanwhile &&
                               meanwhile.error().message.find(why) != std::string::npos;
        return r ? std::string() : r.error().message;
    });
    ASSERT_EQ(error, "");
    EXPECT_TRUE(early_read_failed);
    EXPECT_TRUE(early_second_refused);
    auto read = sonar->read_back(7, recorded);
    ASSERT_TRUE(read.ok()) << read.error().message;
    EXPECT_GT(sum(recorded.clean), 0.0);
    EXPECT_EQ(recorded.clean, processed.clean) << "the same GPU work recorded vs submitted by vksonar";
    EXPECT_EQ(recorded.intensity, processed.intensity);

    const GpuBufferView polar = sonar->polar_buffer();
    EXPECT_NE(polar.buffer, VK_NULL_HANDLE);
    EXPECT_EQ(polar.size, VkDeviceSize(processed.beams) * processed.bins * sizeof(float));
    EXPECT_EQ(host->messages.load(), 0u);
}

// StageTiming::passes on the host-depth path: process() and record() write the beamform stage's pass
// timestamps, so they must reset those queries themselves (start() never runs there). Two pings each,
// under the host's validation messenger, and the pass times come back where the queue has timestamps.
TEST_F(EmbedTest, PassTimingOnHostDepthIsValidAndReported) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    RendererOptions options;
    options.stage_timing = StageTiming::passes;
    auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options), options);
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    const VulkanContext& vulkan = *context_vulkan(*context);
    const bool timestamps = vulkan.timestamp_valid_bits > 0 && vulkan.properties.limits.timestampPeriod > 0.0f;
    auto passes_listed = [](const Frame& frame) {
        std::size_t n = 0;
        for (const StageTime& t : frame.times) {
            if (t.stage.rfind("bf:", 0) != 0) continue;
            EXPECT_GE(t.ms, 0.0) << t.stage;
            ++n;
        }
        return n;
    };
    Frame frame = sonar->make_frame();
    for (std::uint64_t ping = 0; ping < 2; ++ping) {
        auto processed = sonar->process(host::depth_image(*host->engine), ping, frame);
        ASSERT_TRUE(processed.ok()) << processed.error().message;
        if (timestamps) {
            EXPECT_GE(passes_listed(frame), 2u) << "bf:profile and bf:resample at least";
        }
    }
    for (std::uint64_t ping = 2; ping < 4; ++ping) {
        const std::string error = host->engine->render_depth(demo_camera(), [&](VkCommandBuffer commands) {
            auto r = sonar->record(commands, host::depth_image(*host->engine));
            return r ? std::string() : r.error().message;
        });
        ASSERT_EQ(error, "");
        auto read = sonar->read_back(ping, frame);
        ASSERT_TRUE(read.ok()) << read.error().message;
        if (timestamps) {
            EXPECT_GE(passes_listed(frame), 2u);
        }
    }
    EXPECT_GT(sum(frame.clean), 0.0);
    EXPECT_EQ(host->messages.load(), 0u) << "validation messages (e.g. timestamps into queries never reset)";
}

// The host's own objects for the frame after its depth pass, made and destroyed with the host's own
// (null) allocator; destroyed before the engine.
struct HostFrame {
    VkDevice device = VK_NULL_HANDLE;
    VkCommandPool pool = VK_NULL_HANDLE;
    VkCommandBuffer sonar_commands = VK_NULL_HANDLE, display_commands = VK_NULL_HANDLE;
    VkSemaphore depth_done = VK_NULL_HANDLE, sonar_done = VK_NULL_HANDLE;
    VkFence fence = VK_NULL_HANDLE;
    VkBuffer copy = VK_NULL_HANDLE; // host-visible: where the host copies vksonar's GPU result
    VkDeviceMemory copy_memory = VK_NULL_HANDLE;

    ~HostFrame() {
        if (device == VK_NULL_HANDLE) return;
        vkDeviceWaitIdle(device);
        vkDestroyBuffer(device, copy, nullptr);
        vkFreeMemory(device, copy_memory, nullptr);
        vkDestroyFence(device, fence, nullptr);
        vkDestroySemaphore(device, sonar_done, nullptr);
        vkDestroySemaphore(device, depth_done, nullptr);
        vkDestroyCommandPool(device, pool, nullptr);
    }
};

// The host's command pool on the engine's queue family and its sonar (and display) command buffers.
VkResult make_commands(HostFrame& f, const host::Engine& engine, bool display) {
    f.device = engine.device();
    VkCommandPoolCreateInfo pool_info{};
    pool_info.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
    pool_info.queueFamilyIndex = engine.queue_family();
    if (const VkResult r = vkCreateCommandPool(f.device, &pool_info, nullptr, &f.pool); r != VK_SUCCESS) return r;
    VkCommandBufferAllocateInfo allocate{};
    allocate.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO;
    allocate.commandPool = f.pool;
    allocate.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    allocate.commandBufferCount = display ? 2 : 1;
    VkCommandBuffer buffers[2] = {};
    const VkResult r = vkAllocateCommandBuffers(f.device, &allocate, buffers);
    f.sonar_commands = buffers[0];
    f.display_commands = buffers[1];
    return r;
}

VkResult submit(VkQueue queue, VkCommandBuffer commands, VkSemaphore wait, VkPipelineStageFlags wait_stage,
                VkSemaphore signal, VkFence fence) {
    VkSubmitInfo info{};
    info.sType = VK_STRUCTURE_TYPE_SUBMIT_INFO;
    info.waitSemaphoreCount = wait != VK_NULL_HANDLE ? 1 : 0;
    info.pWaitSemaphores = &wait;
    info.pWaitDstStageMask = &wait_stage;
    info.commandBufferCount = 1;
    info.pCommandBuffers = &commands;
    info.signalSemaphoreCount = signal != VK_NULL_HANDLE ? 1 : 0;
    info.pSignalSemaphores = &signal;
    return vkQueueSubmit(queue, 1, &info, fence);
}

// One ping in flight: a recorded ping that has not run blocks record() and process() (they would rewrite
// what it uses); a recording the host drops without submitting is let go with discard_recorded(), after
// which process() runs and read_back() says nothing was recorded. The dropped command buffer is freed
// unsubmitted, as a host would on a swapchain rebuild.
TEST_F(EmbedTest, ADroppedRecordingIsDiscarded) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    host::Engine& engine = *host->engine;
    auto context = Context::adopt(host::host_vulkan(engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame expected = sonar->make_frame(), frame = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(engine), 5, expected).ok());

    HostFrame f;
    ASSERT_EQ(make_commands(f, engine, false), VK_SUCCESS);
    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    ASSERT_EQ(vkBeginCommandBuffer(f.sonar_commands, &begin), VK_SUCCESS);
    ASSERT_TRUE(sonar->record(f.sonar_commands, host::depth_image(engine)).ok());
    ASSERT_EQ(vkEndCommandBuffer(f.sonar_commands), VK_SUCCESS);
    auto blocked = sonar->process(host::depth_image(engine), 5, frame);
    ASSERT_FALSE(blocked);
    EXPECT_NE(blocked.error().message.find("discard_recorded()"), std::string::npos) << blocked.error().message;
    vkFreeCommandBuffers(f.device, f.pool, 1, &f.sonar_commands); // dropped, never submitted
    f.sonar_commands = VK_NULL_HANDLE;
    sonar->discard_recorded();
    auto processed = sonar->process(host::depth_image(engine), 5, frame);
    ASSERT_TRUE(processed.ok()) << processed.error().message;
    EXPECT_EQ(frame.clean, expected.clean);
    auto read = sonar->read_back(5, frame);
    ASSERT_FALSE(read);
    EXPECT_NE(read.error().message.find("nothing was recorded"), std::string::npos) << read.error().message;
    EXPECT_EQ(host->messages.load(), 0u);
}

// One host frame of three submissions chained by semaphores, with no CPU wait between them:
// the engine's depth pass (signals depth_done) -> vksonar's work recorded by HostDepthRenderer::record into the
// host's command buffer (waits depth_done, signals sonar_done) -> the host's "display" pass, which
// copies HostDepthRenderer::polar_buffer() into its own host-visible buffer (waits sonar_done, signals the
// fence, the only thing the CPU waits for). Both results equal process() bit for bit.
TEST_F(EmbedTest, SemaphoreChainedFrameMatchesProcess) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    host::Engine& engine = *host->engine;
    auto context = Context::adopt(host::host_vulkan(engine));
    ASSERT_TRUE(context.ok()) << context.error().message;
    auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame processed = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(engine), 5, processed).ok());
    const GpuBufferView polar = sonar->polar_buffer();
    ASSERT_EQ(polar.size, VkDeviceSize(processed.clean.size()) * sizeof(float));

    HostFrame f;
    ASSERT_EQ(make_commands(f, engine, true), VK_SUCCESS);
    VkSemaphoreCreateInfo semaphore_info{};
    semaphore_info.sType = VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO;
    ASSERT_EQ(vkCreateSemaphore(f.device, &semaphore_info, nullptr, &f.depth_done), VK_SUCCESS);
    ASSERT_EQ(vkCreateSemaphore(f.device, &semaphore_info, nullptr, &f.sonar_done), VK_SUCCESS);
    VkFenceCreateInfo fence_info{};
    fence_info.sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO;
    ASSERT_EQ(vkCreateFence(f.device, &fence_info, nullptr, &f.fence), VK_SUCCESS);
    ASSERT_EQ(engine.create_buffer(polar.size, VK_BUFFER_USAGE_TRANSFER_DST_BIT, f.copy, f.copy_memory), "");
    VkCommandBufferBeginInfo begin{};
    begin.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    begin.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;

    // 1. The engine's depth pass, submitted without waiting for it.
    ASSERT_EQ(engine.submit_depth(demo_camera(), f.depth_done), "");
    // 2. vksonar's work in the host's command buffer, after the depth pass on the GPU.
    ASSERT_EQ(vkBeginCommandBuffer(f.sonar_commands, &begin), VK_SUCCESS);
    auto recorded_ok = sonar->record(f.sonar_commands, host::depth_image(engine));
    ASSERT_TRUE(recorded_ok.ok()) << recorded_ok.error().message;
    ASSERT_EQ(vkEndCommandBuffer(f.sonar_commands), VK_SUCCESS);
    ASSERT_EQ(submit(engine.queue(), f.sonar_commands, f.depth_done, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, f.sonar_done,
                     VK_NULL_HANDLE),
              VK_SUCCESS);
    // 3. The host reads the GPU result (as a draw would sample it): a copy into its own buffer.
    ASSERT_EQ(vkBeginCommandBuffer(f.display_commands, &begin), VK_SUCCESS);
    const VkBufferCopy region{polar.offset, 0, polar.size};
    vkCmdCopyBuffer(f.display_commands, polar.buffer, f.copy, 1, &region);
    VkMemoryBarrier to_host{};
    to_host.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
    to_host.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    to_host.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
    vkCmdPipelineBarrier(f.display_commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &to_host,
                         0, nullptr, 0, nullptr);
    ASSERT_EQ(vkEndCommandBuffer(f.display_commands), VK_SUCCESS);
    ASSERT_EQ(submit(engine.queue(), f.display_commands, f.sonar_done, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_NULL_HANDLE,
                     f.fence),
              VK_SUCCESS);
    // The CPU waits once, for the end of the frame.
    ASSERT_EQ(vkWaitForFences(f.device, 1, &f.fence, VK_TRUE, UINT64_MAX), VK_SUCCESS);

    Frame recorded = sonar->make_frame();
    auto read = sonar->read_back(5, recorded);
    ASSERT_TRUE(read.ok()) << read.error().message;
    EXPECT_GT(sum(recorded.clean), 0.0);
    EXPECT_EQ(recorded.clean, processed.clean) << "semaphore-chained record() vs process()";
    EXPECT_EQ(recorded.intensity, processed.intensity);
    // The GPU buffer as the host sees it is the clean polar scan, float[bins][beams] like Frame::clean
    // (speckle, noise and gain are host stages, and speckle is off here anyway).
    std::vector<float> gpu(processed.clean.size());
    void* mapped = nullptr;
    ASSERT_EQ(vkMapMemory(f.device, f.copy_memory, 0, VK_WHOLE_SIZE, 0, &mapped), VK_SUCCESS);
    std::memcpy(gpu.data(), mapped, gpu.size() * sizeof(float));
    vkUnmapMemory(f.device, f.copy_memory);
    EXPECT_EQ(polar.beams, processed.beams);
    EXPECT_EQ(polar.bins, processed.bins);
    EXPECT_EQ(gpu, recorded.clean) << "polar_buffer() read back by the host vs Frame::clean";
    EXPECT_EQ(host->messages.load(), 0u);
}

// VkAllocationCallbacks that count what goes through them (thread-safe: vksonar and the driver may
// call them from any thread) and honour the requested alignment, also in reallocation.
class CountingAllocator {
public:
    CountingAllocator() {
        callbacks_.pUserData = this;
        callbacks_.pfnAllocation = [](void* user, std::size_t size, std::size_t alignment,
                                      VkSystemAllocationScope) -> void* {
            return static_cast<CountingAllocator*>(user)->allocate(size, alignment);
        };
        callbacks_.pfnReallocation = [](void* user, void* original, std::size_t size, std::size_t alignment,
                                        VkSystemAllocationScope) -> void* {
            return static_cast<CountingAllocator*>(user)->reallocate(original, size, alignment);
        };
        callbacks_.pfnFree = [](void* user, void* memory) { static_cast<CountingAllocator*>(user)->free(memory); };
    }
    CountingAllocator(const CountingAllocator&) = delete;
    CountingAllocator& operator=(const CountingAllocator&) = delete;

    const VkAllocationCallbacks* callbacks() const { return &callbacks_; }
    std::size_t allocations() const { return allocations_.load(); }     // ever made
    std::size_t unknown_frees() const { return unknown_frees_.load(); } // pointers never returned here
    std::size_t live() const {                                          // not yet freed
        std::lock_guard<std::mutex> lock(mutex_);
        return blocks_.size();
    }

private:
    struct Block {
        std::size_t size, alignment;
    };

    void* allocate(std::size_t size, std::size_t alignment) {
        // Like malloc(0), size 0 gets a unique pointer: lavapipe asks for it and takes null as out of memory.
        size = std::max<std::size_t>(size, 1);
        alignment = std::max(alignment, alignof(std::max_align_t));
        void* memory = ::operator new(size, std::align_val_t(alignment), std::nothrow);
        if (memory == nullptr) return nullptr;
        allocations_.fetch_add(1);
        std::lock_guard<std::mutex> lock(mutex_);
        blocks_[memory] = Block{size, alignment};
        return memory;
    }
    void* reallocate(void* original, std::size_t size, std::size_t alignment) {
        if (original == nullptr) return allocate(size, alignment);
        if (size == 0) {
            free(original);
            return nullptr;
        }
        std::size_t old_size = 0;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            old_size = blocks_.at(original).size;
        }
        void* memory = allocate(size, alignment);
        if (memory == nullptr) return nullptr; // the original stays valid
        std::memcpy(memory, original, std::min(old_size, size));
        free(original);
        return memory;
    }
    void free(void* memory) {
        if (memory == nullptr) return;
        std::size_t alignment = 0;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            auto it = blocks_.find(memory);
            if (it == blocks_.end()) {
                unknown_frees_.fetch_add(1);
                return;
            }
            alignment = it->second.alignment;
            blocks_.erase(it);
        }
        ::operator delete(memory, std::align_val_t(alignment));
    }

    VkAllocationCallbacks callbacks_{};
    std::atomic<std::size_t> allocations_{0};
    mutable std::mutex mutex_;
    std::unordered_map<void*, Block> blocks_;
    std::atomic<std::size_t> unknown_frees_{0};
};

// HostVulkan::allocator: every object vksonar makes on the host's device goes through the host's
// callbacks, and all of it is freed when the Renderer and Context are gone. The host's own objects
// keep the host's (null) allocator.
TEST_F(EmbedTest, HostAllocationCallbacksSeeEveryAllocationFreed) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    CountingAllocator counter; // outlives the Context
    const std::size_t live_before = counter.live();
    {
        HostVulkan host_vulkan = host::host_vulkan(*host->engine);
        host_vulkan.allocator = counter.callbacks();
        auto context = Context::adopt(host_vulkan);
        ASSERT_TRUE(context.ok()) << context.error().message;
        auto sonar = HostDepthRenderer::create(*context, host::demo_config(), host::depth_desc(host->options));
        ASSERT_TRUE(sonar.ok()) << sonar.error().message;
        Frame frame = sonar->make_frame();
        ASSERT_TRUE(sonar->process(host::depth_image(*host->engine), 0, frame).ok());
        EXPECT_GT(sum(frame.clean), 0.0);
        // A scene renderer on the same context: render pass, framebuffer, graphics pipeline too.
        const SonarConfig config = host::demo_config();
        auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
        ASSERT_TRUE(scene.ok());
        auto standalone = Renderer::create(*context, config, *scene);
        ASSERT_TRUE(standalone.ok()) << standalone.error().message;
        Frame reference = standalone->make_frame();
        ASSERT_TRUE(standalone->render(host::to_pose(demo_camera()), 0, reference).ok());
        EXPECT_GT(counter.allocations(), 0u) << "the driver made no allocation through the host's callbacks";
        EXPECT_GT(counter.live(), live_before);
        std::printf("[ embed ] host allocation callbacks: %zu allocations, %zu live with two renderers\n",
                    counter.allocations(), counter.live());
    }
    EXPECT_EQ(counter.live(), live_before) << "allocations made through the host's callbacks were not freed";
    EXPECT_EQ(counter.unknown_frees(), 0u);
    // The host's device still works, and tears down without validation messages (nothing leaked).
    EXPECT_EQ(host->engine->render_depth(demo_camera()), "");
    EXPECT_EQ(host->messages.load(), 0u);
    host->engine.reset();
    EXPECT_EQ(host->messages.load(), 0u);
}

// ContextOptions::allocator: the same for an instance and device vksonar creates itself.
TEST(EmbedAllocatorTest, ContextCreateUsesAllocationCallbacks) {
    VKSONAR_REQUIRE_VULKAN();
    CountingAllocator counter;
    {
        ContextOptions options;
        options.allocator = counter.callbacks();
        auto context = Context::create(options);
        ASSERT_TRUE(context.ok()) << context.error().message;
        const SonarConfig config = host::demo_config();
        auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
        ASSERT_TRUE(scene.ok());
        auto sonar = Renderer::create(*context, config, *scene);
        ASSERT_TRUE(sonar.ok()) << sonar.error().message;
        Frame frame = sonar->make_frame();
        ASSERT_TRUE(sonar->render(host::to_pose(demo_camera()), 0, frame).ok());
        EXPECT_GT(counter.allocations(), 0u);
        EXPECT_EQ(context->validation_messages(), 0u);
    }
    EXPECT_EQ(counter.live(), 0u) << "allocations made through the callbacks were not freed";
    EXPECT_EQ(counter.unknown_frees(), 0u);
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
        auto a = HostDepthRenderer::create(*context, narrow, host::depth_desc(host->options));
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
    auto a = HostDepthRenderer::create(*context, narrow, host::depth_desc(host->options));
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
    // The host's entry points (here the loader's own): every function vksonar calls resolves, accepted.
    VulkanFunctions functions;
    functions.vkGetInstanceProcAddr = vkGetInstanceProcAddr;
    functions.vkGetDeviceProcAddr = vkGetDeviceProcAddr;
    HostVulkan with_functions = host::host_vulkan(*host->engine);
    with_functions.functions = &functions;
    auto checked = Context::adopt(with_functions);
    ASSERT_TRUE(checked.ok()) << checked.error().message;

    auto context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(context.ok());
    const SonarConfig config = host::demo_config();
    // A host camera narrower than the sonar's beams.
    HostDepthDesc narrow = host::depth_desc(host->options);
    narrow.fx_px *= 3.0;
    narrow.fy_px *= 3.0; // also too short vertically, but the horizontal check comes first
    auto uncovered = HostDepthRenderer::create(*context, config, narrow);
    ASSERT_FALSE(uncovered.ok());
    EXPECT_EQ(uncovered.error().code, ErrorCode::unsupported);
    EXPECT_NE(uncovered.error().message.find("beams reach"), std::string::npos) << uncovered.error().message;
    // An off-centre principal point.
    HostDepthDesc shifted = host::depth_desc(host->options);
    shifted.cx_px += 3.0;
    auto off_centre = HostDepthRenderer::create(*context, config, shifted);
    ASSERT_FALSE(off_centre.ok());
    EXPECT_NE(off_centre.error().message.find("principal point"), std::string::npos);
    // A NaN principal point (it passed the centre test, which a NaN fails no comparison of).
    HostDepthDesc nan_centre = host::depth_desc(host->options);
    nan_centre.cy_px = std::numeric_limits<double>::quiet_NaN();
    auto no_centre = HostDepthRenderer::create(*context, config, nan_centre);
    ASSERT_FALSE(no_centre.ok());
    EXPECT_NE(no_centre.error().message.find("principal point"), std::string::npos) << no_centre.error().message;
    // An encoding cast from a number no encoding has (every pixel read as no hit, in silence).
    HostDepthDesc unknown = host::depth_desc(host->options);
    unknown.encoding = static_cast<DepthEncoding>(9);
    auto no_encoding = HostDepthRenderer::create(*context, config, unknown);
    ASSERT_FALSE(no_encoding.ok());
    EXPECT_NE(no_encoding.error().message.find("encoding = 9"), std::string::npos) << no_encoding.error().message;
    // A format that is no depth.
    HostDepthDesc colour = host::depth_desc(host->options);
    colour.format = VK_FORMAT_R8G8B8A8_UNORM;
    auto not_depth = HostDepthRenderer::create(*context, config, colour);
    ASSERT_FALSE(not_depth.ok());
    EXPECT_EQ(not_depth.error().code, ErrorCode::unsupported);
    // An image in a layout that cannot be sampled.
    auto sonar = HostDepthRenderer::create(*context, config, host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame frame = sonar->make_frame();
    HostDepthImage attachment = host::depth_image(*host->engine);
    attachment.layout = VK_IMAGE_LAYOUT_DEPTH_STENCIL_ATTACHMENT_OPTIMAL;
    auto unreadable = sonar->process(attachment, 0, frame);
    ASSERT_FALSE(unreadable.ok());
    EXPECT_NE(unreadable.error().message.find("cannot be sampled"), std::string::npos);
    // The scene-renderer entry points on a depth renderer and vice versa do not compile (api_test.cpp).
    EXPECT_EQ(host->messages.load(), 0u);
    EXPECT_EQ(old_host->messages.load(), 0u);
}

// The host's entry points as a host with its own loader, layers or volk would pass them: getters that
// record every name vksonar resolves, return null for one name on request, and hand out vkQueueSubmit
// and vkCmdDispatch as wrappers that count their calls before forwarding to the loader's functions.
// Static because a PFN carries no user data; each test resets it (tests in one binary run one at a time).
struct HostGetters {
    static inline std::mutex mutex;
    static inline std::set<std::string> asked;
    static inline std::string refused; // a name the device getter returns null for ("": none)
    static inline std::atomic<int> submits{0}, dispatches{0};
    static inline PFN_vkQueueSubmit real_submit = nullptr;
    static inline PFN_vkCmdDispatch real_dispatch = nullptr;

    static void reset(std::string refuse = {}) {
        std::lock_guard<std::mutex> lock(mutex);
        asked.clear();
        refused = std::move(refuse);
        submits = 0;
        dispatches = 0;
    }
    static bool was_asked(const std::string& name) {
        std::lock_guard<std::mutex> lock(mutex);
        return asked.count(name) != 0;
    }
    static void record(const char* name) {
        std::lock_guard<std::mutex> lock(mutex);
        asked.insert(name);
    }

    static VKAPI_ATTR VkResult VKAPI_CALL counting_submit(VkQueue queue, std::uint32_t count,
                                                          const VkSubmitInfo* submits_, VkFence fence) {
        ++submits;
        return real_submit(queue, count, submits_, fence);
    }
    static VKAPI_ATTR void VKAPI_CALL counting_dispatch(VkCommandBuffer commands, std::uint32_t x, std::uint32_t y,
                                                        std::uint32_t z) {
        ++dispatches;
        real_dispatch(commands, x, y, z);
    }
    static VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL get_instance_proc_addr(VkInstance instance, const char* name) {
        record(name);
        return vkGetInstanceProcAddr(instance, name);
    }
    static VKAPI_ATTR PFN_vkVoidFunction VKAPI_CALL get_device_proc_addr(VkDevice device, const char* name) {
        record(name);
        if (refused == name) return nullptr;
        const PFN_vkVoidFunction real = vkGetDeviceProcAddr(device, name);
        if (std::strcmp(name, "vkQueueSubmit") == 0) {
            real_submit = reinterpret_cast<PFN_vkQueueSubmit>(real);
            return reinterpret_cast<PFN_vkVoidFunction>(&counting_submit);
        }
        if (std::strcmp(name, "vkCmdDispatch") == 0) {
            real_dispatch = reinterpret_cast<PFN_vkCmdDispatch>(real);
            return reinterpret_cast<PFN_vkVoidFunction>(&counting_dispatch);
        }
        return real;
    }
    static VulkanFunctions functions() {
        VulkanFunctions table;
        table.vkGetInstanceProcAddr = get_instance_proc_addr;
        table.vkGetDeviceProcAddr = get_device_proc_addr;
        return table;
    }
};

TEST_F(EmbedTest, CallsGoThroughTheHostsFunctionPointers) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    HostGetters::reset();
    const VulkanFunctions functions = HostGetters::functions();
    HostVulkan through_host = host::host_vulkan(*host->engine);
    through_host.functions = &functions;
    auto context = Context::adopt(through_host);
    ASSERT_TRUE(context.ok()) << context.error().message;
    // Resolved once, by adopt, through the host's getters: instance and device functions.
    EXPECT_TRUE(HostGetters::was_asked("vkGetPhysicalDeviceProperties"));
    EXPECT_TRUE(HostGetters::was_asked("vkCmdDispatch"));
    EXPECT_TRUE(HostGetters::was_asked("vkQueueSubmit"));
    EXPECT_TRUE(HostGetters::was_asked("vkCmdDrawIndexed"));
    EXPECT_FALSE(HostGetters::was_asked("vkCreateDevice")) << "an adopted context resolves only what it calls";
    EXPECT_EQ(HostGetters::submits.load(), 0) << "adopt submits nothing";

    // The host-depth path: the host's depth image, processed through the wrappers.
    const SonarConfig config = host::demo_config();
    auto sonar = HostDepthRenderer::create(*context, config, host::depth_desc(host->options));
    ASSERT_TRUE(sonar.ok()) << sonar.error().message;
    Frame frame = sonar->make_frame();
    ASSERT_TRUE(sonar->process(host::depth_image(*host->engine), 0, frame).ok());
    EXPECT_GT(sum(frame.clean), 0.0);
    EXPECT_GT(HostGetters::submits.load(), 0);
    EXPECT_GT(HostGetters::dispatches.load(), 0);

    // The same image through a context without the host's functions (the loader's): the same scan.
    auto plain_context = Context::adopt(host::host_vulkan(*host->engine));
    ASSERT_TRUE(plain_context.ok()) << plain_context.error().message;
    auto plain = HostDepthRenderer::create(*plain_context, config, host::depth_desc(host->options));
    ASSERT_TRUE(plain.ok()) << plain.error().message;
    Frame plain_frame = plain->make_frame();
    const int dispatches_before = HostGetters::dispatches.load();
    ASSERT_TRUE(plain->process(host::depth_image(*host->engine), 0, plain_frame).ok());
    EXPECT_EQ(HostGetters::dispatches.load(), dispatches_before) << "the plain context must not use the wrappers";
    EXPECT_EQ(frame.clean, plain_frame.clean);

    // A scene render (depth pass, graphics pipeline) through the host's functions too.
    auto scene = host::to_scene(host::demo_scene(), config.default_backscatter_db);
    ASSERT_TRUE(scene.ok());
    auto renderer = Renderer::create(*context, config, *scene);
    ASSERT_TRUE(renderer.ok()) << renderer.error().message;
    Frame rendered = renderer->make_frame();
    const int submits_before = HostGetters::submits.load();
    ASSERT_TRUE(renderer->render(host::to_pose(demo_camera()), 0, rendered).ok());
    EXPECT_GT(sum(rendered.clean), 0.0);
    EXPECT_GT(HostGetters::submits.load(), submits_before);
    EXPECT_EQ(host->messages.load(), 0u);
}

TEST_F(EmbedTest, AdoptNamesTheFunctionTheHostsGetterDoesNotResolve) {
    auto host = make_host(demo_engine_options());
    ASSERT_TRUE(host);
    HostGetters::reset("vkCmdDispatch");
    const VulkanFunctions functions = HostGetters::functions();
    HostVulkan through_host = host::host_vulkan(*host->engine);
    through_host.functions = &functions;
    auto refused = Context::adopt(through_host);
    HostGetters::reset();
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::unsupported);
    EXPECT_EQ(refused.error().message,
              "Context::adopt: HostVulkan.functions->vkGetDeviceProcAddr returns null for vkCmdDispatch");
    EXPECT_EQ(host->messages.load(), 0u);
}

} // namespace
} // namespace vksonar::testing
#endif
