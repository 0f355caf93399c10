// Shared pieces of `vksonar bench` (see bench_common.h).
#ifdef VKSONAR_HAVE_BENCHMARK

#include "cli/bench_common.h"
#include "cli/inputs.h"

#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <new>
#include <system_error>

#include <benchmark/benchmark.h>

namespace fs = std::filesystem;

namespace {
std::atomic<std::uint64_t> g_heap_allocations{0};

void* counted_allocation(std::size_t size) {
    g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
    throw std::bad_alloc();
}
} // namespace

// Counting replacements of the global allocation functions (the aligned forms keep their library
// definitions, which allocate through their own paths and are not counted). The nothrow forms are
// replaced too: their memory is released by the operator delete below (free), so it must come from
// malloc; the library's nothrow new need not use malloc (under ASan it does not: alloc-dealloc
// mismatch, found by scripts/sanitize.sh in the validation layer's nothrow allocations).
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
    g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return std::malloc(size == 0 ? 1 : size);
}
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept {
    g_heap_allocations.fetch_add(1, std::memory_order_relaxed);
    return std::malloc(size == 0 ? 1 : size);
}
void operator delete(void* p, const std::nothrow_t&) noexcept {
    std::free(p);
}
void operator delete[](void* p, const std::nothrow_t&) noexcept {
    std::free(p);
}
void* operator new(std::size_t size) {
    return counted_allocation(size);
}
void* operator new[](std::size_t size) {
    return counted_allocation(size);
}
void operator delete(void* p) noexcept {
    std::free(p);
}
void operator delete[](void* p) noexcept {
    std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
    std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
    std::free(p);
}

namespace vksonar::cli::bench {

Setup load_setup(const Args& args) {
    Setup setup;
    setup.default_scene = !args.has("--scene");
    setup.scene_path = setup.default_scene ? find_default_scene().string() : args.value("--scene");
    if (!setup.default_scene) require_input_file("--scene", setup.scene_path);
    setup.sonar_name = args.value("--sonar", "default");
    setup.preset = sonar_base_config(setup.sonar_name);
    auto scene = Scene::load_gltf(setup.scene_path);
    if (!scene) {
        if (setup.default_scene) throw Failure(scene.error().message);
        throw BadInput(scene.error().message);
    }
    setup.scene = std::move(scene.value());
    const std::string& effects = setup.scene.effects_json();
    if (!effects.empty() && effects != "{}" && effects != "null") setup.scene_effects = effects;
    setup.config = layered_config(setup, args.values("--set"));
    if (args.has("--pose")) {
        setup.pose = parse_pose(args.value("--pose"), "--pose");
    } else if (setup.default_scene) {
        setup.pose.pitch_deg = 10.0; // the default pose of `vksonar render` for the bundled scene
    }
    return setup;
}

SonarConfig layered_config(const Setup& setup, const std::vector<std::string>& overrides) {
    SonarConfig config = setup.preset;
    ProblemOrigin problem(config, "--sonar " + setup.sonar_name);
    if (!setup.scene_effects.empty()) {
        const std::string scene_origin = setup.scene_path + " (scene extras vksonar.effects)";
        auto layered = apply_config_json(config, "{\"effects\": " + setup.scene_effects + "}", scene_origin);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
        problem.after(config, scene_origin);
    }
    for (const auto& item : overrides) {
        auto layered = apply_config_override(config, item);
        if (!layered) throw BadInput(layered.error().message);
        config = layered.value();
        problem.after(config, "--set " + item);
    }
    problem.throw_if_invalid();
    return config;
}

Backend parse_backend(const std::string& name) {
    if (name == "vulkan") return Backend::vulkan;
    if (name == "cpu") return Backend::cpu;
    throw BadInput("--backend: '" + name + "' is not a backend (vulkan or cpu)");
}

const char* backend_name(Backend backend) {
    return backend == Backend::vulkan ? "vulkan" : "cpu";
}

Renderer make_renderer(Context& context, const SonarConfig& config, const Scene& scene, Backend backend,
                       std::uint64_t seed, SaveFlags save_mask) {
    RendererOptions options = renderer_options_from_env();
    options.backend = backend;
    options.seed = seed;
    options.save_mask = save_mask;
    auto renderer = Renderer::create(context, config, scene, options);
    if (!renderer) throw Failure(std::string(backend_name(backend)) + " renderer: " + renderer.error().message);
    return std::move(renderer.value());
}

double timed_render(Renderer& renderer, const Pose& pose, std::uint64_t frame_index, Frame& frame) {
    const auto start = std::chrono::steady_clock::now();
    auto rendered = renderer.render(pose, frame_index, frame);
    const auto stop = std::chrono::steady_clock::now();
    if (!rendered) throw Failure("render: " + rendered.error().message);
    return std::chrono::duration<double, std::milli>(stop - start).count();
}

double stage_ms(const Frame& frame, const std::string& stage) {
    double total = 0;
    for (const auto& t : frame.times)
        if (t.stage == stage) total += t.ms;
    return total;
}

double median(std::vector<double> values) {
    return percentile(std::move(values), 0.5);
}

double percentile(std::vector<double> values, double p) {
    if (values.empty()) return 0.0;
    std::sort(values.begin(), values.end());
    const double position = std::clamp(p, 0.0, 1.0) * static_cast<double>(values.size() - 1);
    const auto below = static_cast<std::size_t>(std::floor(position));
    const std::size_t above = std::min(below + 1, values.size() - 1);
    const double t = position - static_cast<double>(below);
    return values[below] * (1.0 - t) + values[above] * t;
}

double rss_mib() {
    std::FILE* f = std::fopen("/proc/self/statm", "r");
    if (!f) return 0.0;
    unsigned long long size = 0, resident = 0;
    const int n = std::fscanf(f, "%llu %llu", &size, &resident);
    std::fclose(f);
    if (n != 2) return 0.0;
    return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

double live_heap_mib() {
    const struct mallinfo2 info = mallinfo2();
    return static_cast<double>(info.uordblks + info.hblkhd) / (1024.0 * 1024.0);
}

std::uint64_t heap_allocations() {
    return g_heap_allocations.load(std::memory_order_relaxed);
}

std::string fmt(double value, int decimals) {
    char text[64];
    std::snprintf(text, sizeof text, "%.*f", decimals, value);
    return text;
}

const char* verdict(bool ok) {
    return ok ? "PASS" : "MISS";
}

std::uint32_t frames_option(const Args& args, std::uint32_t fallback) {
    if (!args.has("--frames")) return fallback;
    const std::uint64_t n = parse_u64(args.value("--frames"), "--frames");
    if (n < 1 || n > 1000000) throw BadInput("--frames: expected 1..1000000, got " + args.value("--frames"));
    return static_cast<std::uint32_t>(n);
}

void record_failure(Setup& setup, const std::string& message) {
    setup.failures.push_back(message);
}

void run_registered_benchmarks(Setup& setup) {
    if (!setup.benchmark_initialized) {
        // Google Benchmark reads its own flags from argv; ours are parsed already. Static storage:
        // it keeps argv[0] as the executable's name for its report (never written here).
        static char arg0[] = "vksonar-bench";
        static char arg1[] = "--benchmark_counters_tabular=true";
        static char* argv[] = {arg0, arg1, nullptr};
        int argc = 2;
        benchmark::Initialize(&argc, argv);
        setup.benchmark_initialized = true;
    }
    std::fflush(stdout);
    benchmark::RunSpecifiedBenchmarks();
    benchmark::ClearRegisteredBenchmarks();
    std::fflush(stdout);
    if (!setup.failures.empty()) {
        const std::string first = setup.failures.front();
        setup.failures.clear();
        throw Failure(first);
    }
}

} // namespace vksonar::cli::bench

#endif // VKSONAR_HAVE_BENCHMARK
