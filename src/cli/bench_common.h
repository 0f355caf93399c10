// Shared pieces of `vksonar bench speed|effects|accuracy`: scene/config/pose setup (the same defaults
// as `vksonar render`), renderer creation with CLI-style errors, timing, medians, RSS and the Google
// Benchmark driver. The timing loops themselves run inside Google Benchmark (manual time); each bench
// keeps its own samples and prints its summary tables after the Google Benchmark report.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/inputs.h"
#include "vksonar/vksonar.h"

namespace vksonar::cli::bench {

// Scene + layered config + pose, resolved like `vksonar render`:
// preset < scene effects < --set.
struct Setup {
    std::string scene_path;
    bool default_scene = false;
    std::string sonar_name;
    Scene scene;
    SonarConfig preset;        // the preset alone (before the scene's effects)
    std::string scene_effects; // the scene's "effects" JSON ("" if none)
    SonarConfig config;        // preset < scene effects < --set
    Pose pose;
    // What the benchmark bodies reported (record_failure), for run_registered_benchmarks to rethrow,
    // and whether it has initialized Google Benchmark: carried here, not in globals.
    std::vector<std::string> failures;
    bool benchmark_initialized = false;
};

// Reads --scene, --sonar, --set (repeatable) and --pose from `args` (any of them may be absent).
Setup load_setup(const Args& args);
// `base` with the scene's effects and then `overrides` (key=value) applied; validated.
SonarConfig layered_config(const Setup& setup, const std::vector<std::string>& overrides);

Backend parse_backend(const std::string& name);
const char* backend_name(Backend backend);

// Throws Failure with the renderer's message.
// save_mask: the outputs the renderer fills (SaveFlags::labels for the labels row of bench effects).
Renderer make_renderer(Context& context, const SonarConfig& config, const Scene& scene, Backend backend,
                       std::uint64_t seed = 1, SaveFlags save_mask = SaveFlags::none);

// Renders one frame and returns the wall-clock milliseconds around Renderer::render. Throws Failure.
double timed_render(Renderer& renderer, const Pose& pose, std::uint64_t frame_index, Frame& frame);

double stage_ms(const Frame& frame, const std::string& stage); // 0 if the stage did not run
double median(std::vector<double> values);
double percentile(std::vector<double> values, double p); // p in [0, 1]
double rss_mib();                                        // resident set size from /proc/self/statm
// Bytes malloc'd and not yet freed, all threads and arenas (glibc mallinfo2: in arenas + mmapped), in
// MiB. Unlike RSS it does not move when the allocator's free space fragments or is trimmed, so the
// difference over many frames is what somebody (vksonar or the driver) keeps per frame.
double live_heap_mib();
// Calls of the global operator new / new[] in this process so far (the CLI replaces them with counting
// versions): the difference around Renderer::render is what vksonar allocates per frame. Allocations
// of the Vulkan driver (malloc inside libvulkan / lavapipe) are not counted; RSS covers those.
std::uint64_t heap_allocations();

std::string fmt(double value, int decimals = 2);
// "PASS" or "MISS".
const char* verdict(bool ok);

std::uint32_t frames_option(const Args& args, std::uint32_t fallback);

// Runs every benchmark registered so far through Google Benchmark's console reporter (manual time,
// fixed iteration counts). Errors a benchmark body reported (SkipWithError) are rethrown as Failure.
void run_registered_benchmarks(Setup& setup);
// Call from inside a benchmark body: records `message` in `setup` so run_registered_benchmarks() fails.
void record_failure(Setup& setup, const std::string& message);

} // namespace vksonar::cli::bench
