// `vksonar info`: which Vulkan device and driver vksonar would run on; `vksonar info SCENE`: what a
// scene holds, for pointing the sonar at it.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/inputs.h"
#include "host/meta_fields.h"
#include "vksonar/context.h"
#include "vksonar/scene.h"

namespace vksonar::cli {

namespace {

int scene_info(const std::string& path, const std::string& asset_root) {
    require_input_file("", path);
    auto scene = Scene::load_gltf(path, SceneLoadOptions{asset_root});
    if (!scene) throw BadInput(scene.error().message);
    for (const std::string& warning : scene->stats().warnings)
        std::fprintf(stderr, "warning: %s\n", warning.c_str());
    const SceneStats& s = scene->stats();
    const SceneBounds b = scene->bounds();
    std::printf("scene: %s\n", path.c_str());
    if (b.empty) {
        std::printf("bounds: empty (nothing to draw)\n");
    } else {
        std::printf("bounds (m, world: x forward, y left, z up): x %.3f .. %.3f, y %.3f .. %.3f, z %.3f .. %.3f\n",
                    b.min_m[0], b.max_m[0], b.min_m[1], b.max_m[1], b.min_m[2], b.max_m[2]);
        std::printf("size: %.3f x %.3f x %.3f m (diagonal %.3f m)\n", b.max_m[0] - b.min_m[0], b.max_m[1] - b.min_m[1],
                    b.max_m[2] - b.min_m[2], b.diagonal_m());
    }
    std::printf("triangles: %llu drawn, %u meshes, %u draws, %llu instances, %u primitives skipped\n",
                static_cast<unsigned long long>(s.triangles), s.meshes, s.draws,
                static_cast<unsigned long long>(s.instances), s.skipped_primitives);
    std::printf("materials: %zu\n", scene->materials().size());
    static const char* const models[] = {"lambert", "constant", "rough"};
    for (const AcousticMaterial& m : scene->materials())
        std::printf("  %s: %s, backscatter %.1f dB\n", m.name.c_str(), models[static_cast<int>(m.model)],
                    m.backscatter_db);
    // The objects ground-truth labels name (SceneInstance), counted per class.
    std::string classes;
    for (std::size_t c = 0; c < scene->classes().size(); ++c) {
        std::size_t objects = 0;
        for (const SceneInstance& i : scene->instances())
            objects += i.class_id == c + 1;
        classes += (classes.empty() ? "" : ", ") + scene->classes()[c] + " (" + std::to_string(objects) + ")";
    }
    std::printf("objects: %zu in %zu classes%s%s\n", scene->instances().size(), scene->classes().size(),
                classes.empty() ? "" : ": ", classes.c_str());
    std::string extensions;
    for (const std::string& e : s.extensions)
        extensions += (extensions.empty() ? "" : ", ") + e;
    std::printf("extensions: %s\n", extensions.empty() ? "none" : extensions.c_str());
    return 0;
}

} // namespace

int run_info(const std::vector<std::string>& argv) {
    const Args args = parse_args(
        argv, {{"--validation", false, false}, {"--asset-root", true, false}, {"--help", false, false}}, "info");
    if (args.has("--help")) {
        std::printf("usage: vksonar info [--validation]\n"
                    "       vksonar info SCENE.gltf|.glb [--asset-root DIR]\n"
                    "  prints the Vulkan device and driver in use (VKSONAR_DEVICE=N picks a device) and the backend\n"
                    "  render --backend auto runs on it,\n"
                    "  or a scene's bounds, triangles, instances, materials and glTF extensions\n"
                    "  --validation   also enable VK_LAYER_KHRONOS_validation\n");
        return 0;
    }
    if (args.positional.size() == 1) return scene_info(args.positional[0], args.value("--asset-root"));
    if (!args.positional.empty()) throw BadInput("info: unexpected argument '" + args.positional[1] + "'");
    if (args.has("--asset-root"))
        throw BadInput("info: --asset-root " + args.value("--asset-root") +
                       " is for a scene's files: give the scene (vksonar info SCENE.gltf --asset-root DIR)");
    std::printf("vksonar %s\n", host::vksonar_version());
    ContextOptions options;
    options.enable_validation = args.has("--validation");
    auto from_env = context_options_from_env(options);
    if (!from_env) throw BadInput(from_env.error().message);
    auto context = Context::create(from_env.value());
    if (!context) {
        std::printf("Vulkan: none usable (%s)\nThe CPU backend still works: vksonar render --backend cpu ...\n",
                    context.error().message.c_str());
        return 1;
    }
    std::printf("Vulkan: %s\n", context->device_description().c_str());
    // what `render` runs on by default (meta.json's backend and backend_reason say the same per run)
    Backend backend = Backend::vulkan;
    std::string why;
    choose_backend(backend, why);
    std::printf("render --backend auto: %s (%s)\n", backend == Backend::cpu ? "cpu" : "vulkan", why.c_str());
    return 0;
}

} // namespace vksonar::cli
