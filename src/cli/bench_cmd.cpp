// `vksonar bench speed|effects|accuracy|load`: argument dispatch to the bench_*.cpp bodies.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#ifdef VKSONAR_HAVE_BENCHMARK
#include "cli/bench_cmd.h"
#endif

namespace vksonar::cli {

int run_bench(const std::vector<std::string>& argv) {
    static const std::vector<std::string> modes = {"speed", "effects", "accuracy", "load"};
    if (argv.empty() || argv[0] == "--help") {
        std::fprintf(
            argv.empty() ? stderr : stdout,
            "usage: vksonar bench: speed|effects|accuracy|load\n"
            "  speed     per-stage and full-frame times, frames/s, full/depth ratio, RSS growth\n"
            "  effects   cost of each effect, on vs off, interleaved\n"
            "  accuracy  error vs time over the accuracy knobs against a CPU double reference (CSV + SVG)\n"
            "  load      load time and memory of a million-triangle scene as plain, quantized, meshopt and Draco glTF\n"
            "Run 'vksonar bench MODE --help' for the options of a mode.\n");
        return argv.empty() ? 2 : 0;
    }
    const std::string& mode = argv[0];
    bool known = false;
    for (const auto& m : modes)
        known = known || m == mode;
    if (!known)
        throw BadInput("bench: unknown mode '" + mode + "' (did you mean '" + closest_word(mode, modes) +
                       "'?); usage: vksonar bench: speed|effects|accuracy|load");
    if (mode == "load") return run_bench_load(std::vector<std::string>(argv.begin() + 1, argv.end()));
#ifdef VKSONAR_HAVE_BENCHMARK
    const std::vector<std::string> rest(argv.begin() + 1, argv.end());
    if (mode == "speed") return bench::run_bench_speed(rest);
    if (mode == "effects") return bench::run_bench_effects(rest);
    return bench::run_bench_accuracy(rest);
#else
    throw Failure("bench mode " + mode + " is not available: this vksonar was built with VKSONAR_BUILD_BENCH=OFF");
#endif
}

} // namespace vksonar::cli
