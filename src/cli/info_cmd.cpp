// `vksonar info`: which Vulkan device and driver vksonar would run on.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#include "vksonar/context.h"

namespace vksonar::cli {

int run_info(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv, {{"--validation", false, false}, {"--help", false, false}}, "info");
    if (args.has("--help")) {
        std::printf("usage: vksonar info [--validation]\n"
                    "  prints the Vulkan device and driver in use (VKSONAR_DEVICE=N picks a device)\n"
                    "  --validation   also enable VK_LAYER_KHRONOS_validation\n");
        return 0;
    }
    if (!args.positional.empty()) throw BadInput("info: unexpected argument '" + args.positional[0] + "'");
    std::printf("vksonar 0.1.0\n");
    ContextOptions options;
    options.enable_validation = args.has("--validation");
    auto context = Context::create(options);
    if (!context) {
        std::printf("Vulkan: none usable (%s)\nThe CPU backend still works: vksonar render --backend cpu ...\n",
                    context.error().message.c_str());
        return 1;
    }
    std::printf("Vulkan: %s\n", context->device_description().c_str());
    return 0;
}

} // namespace vksonar::cli
