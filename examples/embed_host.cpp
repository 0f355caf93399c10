// embed_host: a tiny "host engine" (embed_host_engine.h) that owns its Vulkan device, renders its own
// depth image with its own pipeline, and hands that image to vksonar on the engine's own device:
//   1. process(): vksonar submits the compute stages on the engine's queue and returns the frame;
//   2. record():  vksonar records into the engine's command buffer, right after the engine's depth
//                 pass, and the engine submits it as part of its frame (no CPU wait inside vksonar);
//   3. the standalone Renderer::render of the same scene and pose, for comparison.
// Exit status 0 if record() == process() exactly, process() agrees with the standalone render within
// the GPU-vs-CPU whole-frame tolerance (tests/tolerances.h), and the validation layer stayed silent.
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "embed_glue.h"
#include "embed_host_engine.h"
#include "vksonar/vksonar.h"

namespace {

// tests/tolerances.h kFrameDbTol / kFrameCellBudget: triangle-edge pixels that the two rasterizations
// (different clip matrices, same pixel grid) cover differently move energy between neighbouring cells.
constexpr double kFrameDbTol = 1.0;
constexpr double kFrameCellBudget = 0.02;

int fail(const std::string& what) {
    std::fprintf(stderr, "embed_host: %s\n", what.c_str());
    return 1;
}

} // namespace

int main() {
    const vksonar::SonarConfig config = host::demo_config();
    const std::vector<host::Mesh> meshes = host::demo_scene();
    auto scene = host::to_scene(meshes, config.default_backscatter_db);
    if (!scene) return fail(scene.error().message);

    // The engine's camera reproduces the standalone render's pixel grid; a CPU renderer tells its size.
    vksonar::Context cpu = vksonar::Context::cpu_only();
    vksonar::RendererOptions cpu_options;
    cpu_options.backend = vksonar::Backend::cpu;
    auto grid = vksonar::Renderer::create(cpu, config, *scene, cpu_options);
    if (!grid) return fail(grid.error().message);
    host::EngineOptions engine_options = host::engine_options_for(config, grid->make_frame());
    const char* validation = std::getenv("VKSONAR_VALIDATION");
    engine_options.validation = validation && std::strcmp(validation, "1") == 0;

    host::Engine engine; // declared first: outlives everything vksonar made on its device
    if (std::string e = engine.create(engine_options); !e.empty()) return fail(e);
    if (std::string e = engine.upload(meshes); !e.empty()) return fail(e);
    host::CameraPose camera;
    camera.pitch_deg = 10.0; // nose down: the seabed is in view
    if (std::string e = engine.render_depth(camera); !e.empty()) return fail(e);

    // --- What an engine writes (docs/embedding.md) ---
    auto context = vksonar::Context::adopt(host::host_vulkan(engine));
    if (!context) return fail(context.error().message);
    auto sonar = vksonar::HostDepthRenderer::create(*context, config, host::depth_desc(engine_options));
    if (!sonar) return fail(sonar.error().message);
    vksonar::Frame frame = sonar->make_frame();
    if (auto r = sonar->process(host::depth_image(engine), 0, frame); !r) return fail(r.error().message);
    // ---

    // The same ping recorded into the engine's own frame, then read back.
    vksonar::Frame recorded = sonar->make_frame();
    std::string e = engine.render_depth(camera, [&](VkCommandBuffer commands) {
        auto r = sonar->record(commands, host::depth_image(engine));
        return r ? std::string() : r.error().message;
    });
    if (!e.empty()) return fail(e);
    if (auto r = sonar->read_back(0, recorded); !r) return fail(r.error().message);
    const bool record_matches = recorded.clean == frame.clean;

    // The standalone render of the same scene from the same pose, on the same (adopted) device.
    auto standalone = vksonar::Renderer::create(*context, config, *scene);
    if (!standalone) return fail(standalone.error().message);
    vksonar::Frame reference = standalone->make_frame();
    if (auto r = standalone->render(host::to_pose(camera), 0, reference); !r) return fail(r.error().message);
    const host::Comparison c = host::compare_clean(frame, reference, config, kFrameDbTol);
    const bool agrees = c.above > 0 && double(c.over) <= kFrameCellBudget * double(c.above);

    std::printf("embed_host: %s, host depth %u x %u\n", context->device_description().c_str(), engine_options.width,
                engine_options.height);
    std::printf("  record() == process(): %s\n", record_matches ? "yes (bit-identical)" : "NO");
    std::printf("  process() vs standalone render: %zu cells above the noise floor, %zu differ by > %.1f dB "
                "(budget %.0f%%), max %.2f dB\n",
                c.above, c.over, kFrameDbTol, 100.0 * kFrameCellBudget, c.max_db);
    std::printf("  validation messages: %u\n", engine.validation_messages());
    return record_matches && agrees && engine.validation_messages() == 0 ? 0 : 1;
}
