// `vksonar presets`: list the embedded presets, show one resolved, or print the config reference.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#include "config/config_keys.h"
#include "vksonar/config.h"

namespace vksonar::cli {

int run_presets(const std::vector<std::string>& argv) {
    const Args args =
        parse_args(argv, {{"--show", true, false}, {"--keys", false, false}, {"--help", false, false}}, "presets");
    if (args.has("--help")) {
        std::printf("usage: vksonar presets [--show NAME | --keys]\n"
                    "  (no option)   list the presets with a one-line description\n"
                    "  --show NAME   print the fully resolved config of preset NAME as JSON\n"
                    "  --keys        print the config reference table (Markdown; docs/config.md)\n");
        return 0;
    }
    if (!args.positional.empty()) throw BadInput("presets: unexpected argument '" + args.positional[0] + "'");
    if (args.has("--keys") && args.has("--show"))
        throw BadInput("presets: --show and --keys print different things: give one (--keys ignored --show)");
    if (args.has("--keys")) {
        std::fputs(config_keys::reference_markdown().c_str(), stdout);
        return 0;
    }
    if (args.has("--show")) {
        auto preset = load_preset(args.value("--show"));
        if (!preset) throw BadInput(preset.error().message);
        std::printf("%s\n", config_to_json(*preset).c_str());
        return 0;
    }
    const auto names = preset_names();
    std::size_t width = 0;
    for (const auto& name : names)
        width = std::max(width, name.size());
    for (const auto& name : names) {
        auto preset = load_preset(name);
        if (!preset) throw Failure(preset.error().message);
        std::printf("%-*s  %s\n", static_cast<int>(width), name.c_str(), preset->description.c_str());
    }
    return 0;
}

} // namespace vksonar::cli
