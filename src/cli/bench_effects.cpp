// `vksonar bench effects`: the cost of each effect (README "Effects: only what the scene calls for"), on vs off in the
// same run, interleaved, with an off-vs-off pair of identical renderers as the noise reference.
#ifdef VKSONAR_HAVE_BENCHMARK

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "cli/bench_cmd.h"
#include "cli/bench_common.h"

namespace vksonar::cli::bench {
namespace {

constexpr const char* kUsage =
    "usage: vksonar bench effects [--backend vulkan|cpu] [--frames N] [--scene FILE] [--sonar PRESET|FILE]\n"
    "                             [--set key=value ...] [--pose x,y,z,roll,pitch,yaw] [--only EFFECT,...]\n"
    "\n"
    "For each effect (incidence, vertical_pattern, vertical_sidelobes, horizontal_pattern, spreading,\n"
    "absorption, speckle, ambient_noise, tvg) three renderers of the same scene: effects.X=on, effects.X=off and a "
    "second,\n"
    "identical effects.X=off (the noise reference); 'labels' is the ground-truth labels stage (--save labels)\n"
    "on vs off the same way. Their frames are interleaved (the order rotates every\n"
    "round), N rounds per effect (default 60); the table holds medians of full-frame wall-clock times and\n"
    "medians of the per-round ratios. Target: off'/off within 1.02 (a disabled effect costs nothing\n"
    "measurable).\n";

const std::array<const char*, 10> kEffects = {"incidence",
                                              "vertical_pattern",
                                              "vertical_sidelobes",
                                              "horizontal_pattern",
                                              "spreading",
                                              "absorption",
                                              "speckle",
                                              "ambient_noise",
                                              "tvg",
                                              "labels"};

struct Variant {
    std::vector<double> full_ms;
    std::map<std::string, std::vector<double>> stages;
    std::vector<std::string> stages_run;
};

struct EffectResult {
    std::string effect;
    std::array<Variant, 3> variants; // on, off, off'
    std::vector<double> on_over_off, off2_over_off;
    bool done = false;
};

} // namespace

int run_bench_effects(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv,
                                 {{"--backend", true, false},
                                  {"--frames", true, false},
                                  {"--scene", true, false},
                                  {"--sonar", true, false},
                                  {"--set", true, true},
                                  {"--pose", true, false},
                                  {"--only", true, false},
                                  {"--help", false, false}},
                                 "bench effects");
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (!args.positional.empty()) throw BadInput("bench effects: unexpected argument '" + args.positional[0] + "'");
    const Backend backend = parse_backend(args.value("--backend", "vulkan"));
    const std::uint32_t rounds = frames_option(args, 60);
    std::vector<std::string> effects(kEffects.begin(), kEffects.end());
    if (args.has("--only")) {
        effects.clear();
        for (const auto& item : split(args.value("--only"), ',')) {
            if (std::find(kEffects.begin(), kEffects.end(), item) == kEffects.end())
                throw BadInput("--only: unknown effect '" + item + "' (did you mean '" +
                               closest_word(item, {kEffects.begin(), kEffects.end()}) + "'?)");
            effects.push_back(item);
        }
    }
    constexpr std::uint32_t kWarmup = 3;

    Setup setup = load_setup(args);
    Context context = make_context(backend);
    const std::string device = backend == Backend::vulkan ? context.device_description() : "CPU backend";
    std::printf("vksonar bench effects: backend %s (%s), scene %s, sonar %s, %u interleaved rounds per effect\n\n",
                backend_name(backend), device.c_str(), setup.scene_path.c_str(), setup.sonar_name.c_str(), rounds);

    std::vector<EffectResult> results(effects.size());
    for (std::size_t e = 0; e < effects.size(); ++e) {
        results[e].effect = effects[e];
        const std::string name = "effects/" + effects[e] + "/on,off,off'";
        benchmark::RegisterBenchmark(
            name.c_str(),
            [&, e](benchmark::State& state) {
                EffectResult& result = results[e];
                try {
                    // labels is an output, not a config effect: the same config, with and without the stage
                    const bool labels = effects[e] == "labels";
                    const std::string key = "effects." + effects[e];
                    std::vector<std::string> sets = args.values("--set");
                    if (!labels) sets.push_back(key + "=on");
                    const SonarConfig on = layered_config(setup, sets);
                    if (!labels) sets.back() = key + "=off";
                    const SonarConfig off = layered_config(setup, sets);
                    std::array<Renderer, 3> renderers{make_renderer(context, on, setup.scene, backend, 1,
                                                                    labels ? SaveFlags::labels : SaveFlags::none),
                                                      make_renderer(context, off, setup.scene, backend),
                                                      make_renderer(context, off, setup.scene, backend)};
                    std::array<Frame, 3> frames{renderers[0].make_frame(), renderers[1].make_frame(),
                                                renderers[2].make_frame()};
                    std::uint64_t index = 0;
                    for (std::uint32_t w = 0; w < kWarmup; ++w)
                        for (int v = 0; v < 3; ++v)
                            timed_render(renderers[v], setup.pose, index, frames[v]);
                    std::uint64_t round = 0;
                    for (auto _ : state) {
                        std::array<double, 3> ms{};
                        for (int k = 0; k < 3; ++k) {
                            const int v = static_cast<int>((round + k) % 3); // rotate the order every round
                            ms[v] = timed_render(renderers[v], setup.pose, kWarmup + round, frames[v]);
                            Variant& variant = result.variants[v];
                            variant.full_ms.push_back(ms[v]);
                            for (const auto& t : frames[v].times)
                                variant.stages[t.stage].push_back(t.ms);
                        }
                        state.SetIterationTime(ms[0] * 1e-3);
                        result.on_over_off.push_back(ms[0] / ms[1]);
                        result.off2_over_off.push_back(ms[2] / ms[1]);
                        ++round;
                    }
                    for (int v = 0; v < 3; ++v)
                        result.variants[v].stages_run = frames[v].stages_run;
                    state.counters["on_ms"] = median(result.variants[0].full_ms);
                    state.counters["off_ms"] = median(result.variants[1].full_ms);
                    state.counters["on/off"] = median(result.on_over_off);
                    state.counters["off'/off"] = median(result.off2_over_off);
                    result.done = true;
                } catch (const std::exception& ex) {
                    state.SkipWithError(ex.what());
                    record_failure(setup, ex.what());
                }
            })
            ->UseManualTime()
            ->Iterations(rounds)
            ->Unit(benchmark::kMillisecond);
    }
    run_registered_benchmarks(setup);

    std::printf("\n## vksonar bench effects (%s, %s; %u interleaved rounds; medians)\n\n", backend_name(backend),
                device.c_str(), rounds);
    std::printf("| effect | on ms | off ms | ratio on/off | off' ms | off'/off (noise ref) | off'/off <= 1.02 | "
                "largest stage change (on - off) | passes skipped when off |\n");
    std::printf("|---|---:|---:|---:|---:|---:|:---:|---|---|\n");
    for (const auto& r : results) {
        if (!r.done) continue;
        const Variant& on = r.variants[0];
        const Variant& off = r.variants[1];
        std::string biggest = "-";
        double biggest_delta = 0;
        for (const auto& [stage, values] : on.stages) {
            const auto it = off.stages.find(stage);
            const double delta = median(values) - (it == off.stages.end() ? 0.0 : median(it->second));
            if (std::fabs(delta) > std::fabs(biggest_delta)) {
                biggest_delta = delta;
                biggest = stage;
            }
        }
        std::string skipped;
        for (const auto& stage : on.stages_run)
            if (std::find(off.stages_run.begin(), off.stages_run.end(), stage) == off.stages_run.end())
                skipped += (skipped.empty() ? "" : ", ") + stage;
        const double noise = median(r.off2_over_off);
        char change[96];
        std::snprintf(change, sizeof change, "%s %+.3f ms", biggest.c_str(), biggest_delta);
        std::printf(
            "| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", r.effect.c_str(), fmt(median(on.full_ms), 3).c_str(),
            fmt(median(off.full_ms), 3).c_str(), fmt(median(r.on_over_off), 3).c_str(),
            fmt(median(r.variants[2].full_ms), 3).c_str(), fmt(noise, 3).c_str(),
            verdict(std::fabs(noise - 1.0) <= 0.02), change,
            skipped.empty()
                ? "none listed (compiled out of a shader, a dispatch skipped inside a stage, or a host-loop flag)"
                : skipped.c_str());
    }
    std::printf("\noff and off' are two renderers with identical configs: their ratio is what \"no cost\" looks "
                "like on this machine.\n(timings vary +-30-50%% between runs on lavapipe; ratios come from "
                "interleaved rounds)\n");
    return 0;
}

} // namespace vksonar::cli::bench

#endif // VKSONAR_HAVE_BENCHMARK
