// vksonar: the command-line tool. Dispatches subcommands and turns errors into one stderr line and an
// exit code: 0 success, 2 bad input, 1 any other failure.
#include <cstdio>
#include <exception>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/dataset_h5.h"
#include "host/meta_fields.h"
#include "vksonar/result.h"

namespace {

// One line of the usage text per source line.
// clang-format off
constexpr const char* kUsage =
    "usage: vksonar <command> [options]\n"
    "\n"
    "commands:\n"
    "  render    render a scene (or a trajectory) to PNG/NPY/PLY/JSON files\n"
    "  presets   list the sonar presets; --show NAME prints one as JSON\n"
    "  info      print the Vulkan device and driver, and the backend render picks (or: info SCENE)\n"
    "  merge     merge the shards of a trajectory (render --shard i/N) into one output\n"
    "  compare   compare two .npy scans (max abs, RMSE, max dB difference, PSNR)\n"
    "  export    export a run's boxes (render --save fan,labels) as COCO: export coco RUN OUT.json\n"
    "  bench     benchmarks: speed | effects | accuracy | load\n"
    "\n"
    "Run 'vksonar <command> --help' for the options of a command.\n";
// clang-format on

int dispatch(const std::vector<std::string>& argv) {
    using namespace vksonar::cli;
    if (argv.empty()) {
        std::fputs(kUsage, stderr);
        return 2;
    }
    const std::string& command = argv[0];
    const std::vector<std::string> rest(argv.begin() + 1, argv.end());
    if (command == "--help" || command == "-h" || command == "help") {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (command == "--version") {
        std::printf("vksonar %s\n", vksonar::host::vksonar_version());
        return 0;
    }
    if (command == "render") return run_render(rest);
    if (command == "presets") return run_presets(rest);
    if (command == "info") return run_info(rest);
    if (command == "compare") return run_compare(rest);
    if (command == "merge") return run_merge(rest);
    if (command == "bench") return run_bench(rest);
    if (command == "export") return run_export(rest);
    throw BadInput("unknown command '" + command + "' (did you mean '" +
                   closest_word(command, {"render", "presets", "info", "compare", "merge", "bench", "export"}) +
                   "'?); run 'vksonar --help'");
}

// Messages go out as exactly one line, control characters escaped as in every vksonar::Error.
std::string one_line(std::string text) {
    return vksonar::detail::escape_control_chars(std::move(text));
}

} // namespace

int main(int argc, char** argv) {
    using namespace vksonar::cli;
    skip_hdf5_exit_cleanup(); // before any HDF5 call (dataset_h5.h)
    try {
        return dispatch(std::vector<std::string>(argv + 1, argv + argc));
    } catch (const BadInput& e) {
        std::fprintf(stderr, "error: %s\n", one_line(e.what()).c_str());
        return 2;
    } catch (const Failure& e) {
        std::fprintf(stderr, "error: %s\n", one_line(e.what()).c_str());
        return 1;
    } catch (const std::bad_alloc&) {
        // (a config validate() accepts can still need more memory than the machine or its limit gives)
        std::fprintf(stderr, "error: out of memory: this config's buffers do not fit (fewer bins, beams or "
                             "accuracy.rows_per_vfov / pixels_per_beam need less)\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "error: internal: %s\n", one_line(e.what()).c_str());
        return 1;
    } catch (...) {
        std::fprintf(stderr, "error: internal: unknown exception\n");
        return 1;
    }
}
