// `vksonar bench speed|effects|accuracy`: argument dispatch. The benchmark bodies are not built yet.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"

namespace vksonar::cli {

int run_bench(const std::vector<std::string>& argv) {
    static const std::vector<std::string> modes = {"speed", "effects", "accuracy"};
    if (argv.empty() || argv[0] == "--help") {
        std::fprintf(argv.empty() ? stderr : stdout, "usage: vksonar bench: speed|effects|accuracy\n");
        return argv.empty() ? 2 : 0;
    }
    const std::string& mode = argv[0];
    bool known = false;
    for (const auto& m : modes) known = known || m == mode;
    if (!known)
        throw BadInput("bench: unknown mode '" + mode + "' (did you mean '" + closest_word(mode, modes) +
                       "'?); usage: vksonar bench: speed|effects|accuracy");
    throw Failure("bench mode " + mode + " not built yet");
}

} // namespace vksonar::cli
