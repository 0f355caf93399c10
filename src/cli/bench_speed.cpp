// `vksonar bench speed`: per-stage and full-frame times of the default scene, frames/s, the ratio
// full frame / depth pass, and RSS and live-heap growth over 1000 frames.
#ifdef VKSONAR_HAVE_BENCHMARK

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <benchmark/benchmark.h>

#include "cli/bench_cmd.h"
#include "cli/bench_common.h"
#include "core/angles.h"

namespace vksonar::cli::bench {
namespace {

constexpr const char* kUsage =
    "usage: vksonar bench speed [--backend vulkan|cpu] [--frames N] [--scene FILE] [--sonar PRESET|FILE]\n"
    "                           [--set key=value ...] [--pose x,y,z,roll,pitch,yaw] [--memory-frames M]\n"
    "                           [--labels] [--flow]\n"
    "\n"
    "Renders N timed frames (default 300) of the scene (default: the bundled scene, pose 0,0,0,0,10,0)\n"
    "and prints the median time of each stage (Frame.times; the CPU backend runs normals and echo fused,\n"
    "a block of rows through both, and shares that pass's time by their summed block times), the median\n"
    "full frame (wall clock around Renderer::render: all stages, readback and the host noise stage),\n"
    "frames/s and the ratio full frame / depth pass, paired frame by frame. RSS and the live heap\n"
    "(malloc'd, not freed) are read after 10 frames and after M frames (default 1000, counting the timed\n"
    "ones).\n"
    "Targets (README \"Speed\"): >= 150 frames/s (goal 200) and the post-depth stages (full frame - depth)\n"
    "<= 1.5x the depth pass, on the faster backend of a machine without a GPU; RSS growth <= 1 MiB,\n"
    "0 allocations per frame. full frame / depth is printed too (the retired target, for comparison).\n"
    "--labels: every frame also runs the labels stage (as `render --save labels` does; Frame.times\n"
    "'labels', part of the full frame): what a dataset run with ground truth pays per frame.\n"
    "--flow (implies --labels): then N calls of Renderer::label_flow from a frame to one 5 cm ahead and\n"
    "0.1 deg of yaw (a trajectory's step; `render --save flow`), timed apart from the frame: the\n"
    "median ms per call, and its allocations after the first.\n";

struct SpeedSamples {
    std::vector<double> full_ms, depth_ms, ratio, stage_sum_ms;
    std::map<std::string, std::vector<double>> stages;
    std::vector<std::string> stage_order;
    std::string depth_source;
};

// --flow: Renderer::label_flow from `frame` (rendered at pose) to a frame one trajectory step ahead,
// `calls` times (each call the same work: the flow of two fixed frames).
void run_flow_timing(Renderer& renderer, const Pose& pose, std::uint64_t frame_index, std::uint32_t calls,
                     Frame& frame) {
    Pose ahead = pose;
    const double yaw = pose.yaw_deg * kDegToRad;
    ahead.x_m += 0.05 * std::cos(yaw);
    ahead.y_m += 0.05 * std::sin(yaw);
    ahead.yaw_deg += 0.1;
    Frame next = renderer.make_frame();
    timed_render(renderer, pose, frame_index, frame);
    timed_render(renderer, ahead, frame_index + 1, next);
    std::vector<float> flow;
    std::vector<double> ms;
    ms.reserve(calls);
    std::uint64_t allocations = 0;
    for (std::uint32_t i = 0; i <= calls; ++i) {
        const std::uint64_t before = heap_allocations();
        const auto t0 = std::chrono::steady_clock::now();
        auto flowed = renderer.label_flow(frame, pose, next, ahead, flow);
        const auto t1 = std::chrono::steady_clock::now();
        if (!flowed) throw Failure("label_flow: " + flowed.error().message);
        if (i == 0) continue; // the first call sizes `flow`
        allocations += heap_allocations() - before;
        ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
    }
    std::size_t labelled = 0, moved = 0;
    for (std::size_t c = 0; c + 1 < flow.size(); c += 2) {
        labelled += frame.instance[c / 2] != 0;
        moved += flow[c] == flow[c];
    }
    std::printf("flow (Renderer::label_flow to a frame 5 cm ahead and 0.1 deg of yaw, %u calls; %zu labelled "
                "cells, %zu with a flow): median %s ms, p10 %s, p90 %s; allocations after the first call %llu\n",
                calls, labelled, moved, fmt(median(ms), 3).c_str(), fmt(percentile(ms, 0.1), 3).c_str(),
                fmt(percentile(ms, 0.9), 3).c_str(), static_cast<unsigned long long>(allocations));
}

} // namespace

int run_bench_speed(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv,
                                 {{"--backend", true, false},
                                  {"--frames", true, false},
                                  {"--memory-frames", true, false},
                                  {"--scene", true, false},
                                  {"--sonar", true, false},
                                  {"--set", true, true},
                                  {"--pose", true, false},
                                  {"--labels", false, false},
                                  {"--flow", false, false},
                                  {"--help", false, false}},
                                 "bench speed");
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (!args.positional.empty()) throw BadInput("bench speed: unexpected argument '" + args.positional[0] + "'");
    const Backend backend = parse_backend(args.value("--backend", "vulkan"));
    const std::uint32_t frames = frames_option(args, 300);
    std::uint64_t memory_frames = 1000;
    if (args.has("--memory-frames")) memory_frames = parse_u64(args.value("--memory-frames"), "--memory-frames");
    constexpr std::uint32_t kWarmup = 10;
    // RSS is read after the warm-up and again after M frames in all (at least those the bench renders
    // anyway): an M within the warm-up asks for growth over no frames, and was raised in silence
    if (memory_frames <= kWarmup)
        throw BadInput("--memory-frames " + args.value("--memory-frames") + ": more than the " +
                       std::to_string(kWarmup) + " warm-up frames, after which RSS is first read");

    Setup setup = load_setup(args);
    Context context = make_context(backend);
    const bool flow = args.has("--flow");
    Renderer renderer = make_renderer(context, setup.config, setup.scene, backend, 1,
                                      flow || args.has("--labels") ? SaveFlags::labels : SaveFlags::none);
    Frame frame = renderer.make_frame();
    const std::string device = backend == Backend::vulkan ? context.device_description() : "CPU backend";
    const SceneStats& stats = setup.scene.stats();

    std::printf("vksonar bench speed: backend %s (%s)\n", backend_name(backend), device.c_str());
    std::printf("scene %s (%llu triangles, %u draws), sonar %s, pose %g,%g,%g,%g,%g,%g\n", setup.scene_path.c_str(),
                static_cast<unsigned long long>(stats.triangles), stats.draws, setup.sonar_name.c_str(), setup.pose.x_m,
                setup.pose.y_m, setup.pose.z_m, setup.pose.roll_deg, setup.pose.pitch_deg, setup.pose.yaw_deg);
    std::printf("grid %u x %u pixels, %u beams x %u bins, %llu timed frames after %u warm-up frames\n\n", frame.columns,
                frame.rows, frame.beams, frame.bins, static_cast<unsigned long long>(frames), kWarmup);

    // The live heap is read after every frame and reported as the least of the last three readings:
    // now and then a single reading catches about 1 MiB of the driver's per-frame blocks not yet
    // freed (lavapipe's threads free them after the frame's fence); memory kept per frame raises all three.
    std::array<double, 3> live_readings{};
    std::uint64_t live_count = 0;
    auto read_live_heap = [&]() { live_readings[live_count++ % live_readings.size()] = live_heap_mib(); };
    auto live_heap_now = [&]() {
        const std::size_t n = std::min<std::size_t>(live_count, live_readings.size());
        return n ? *std::min_element(live_readings.begin(), live_readings.begin() + std::ptrdiff_t(n)) : 0.0;
    };

    std::uint64_t frame_index = 0;
    for (std::uint32_t i = 0; i < kWarmup; ++i) {
        timed_render(renderer, setup.pose, frame_index++, frame);
        read_live_heap();
    }
    const double rss_10 = rss_mib();
    const double live_10 = live_heap_now();

    // After the warm-up: operator new calls inside Renderer::render, and RSS at a few frame counts (a
    // leak grows linearly; driver warm-up flattens out).
    std::uint64_t allocations = 0, counted_frames = 0;
    struct MemoryCheckpoint {
        std::uint64_t frame;
        double rss_mib, live_heap_mib;
    };
    std::vector<MemoryCheckpoint> rss_checkpoints;
    rss_checkpoints.reserve(16);
    rss_checkpoints.push_back({frame_index, rss_10, live_10});
    std::uint64_t next_checkpoint = 100;
    auto render_counted = [&]() {
        const std::uint64_t before = heap_allocations();
        const double ms = timed_render(renderer, setup.pose, frame_index++, frame);
        allocations += heap_allocations() - before;
        ++counted_frames;
        read_live_heap();
        if (frame_index == next_checkpoint) {
            rss_checkpoints.push_back({frame_index, rss_mib(), live_heap_now()});
            next_checkpoint = next_checkpoint == 100 ? 250 : 2 * next_checkpoint; // 100, 250, 500, 1000, 2000...
        }
        return ms;
    };

    SpeedSamples samples;
    // Reserved up front so the samples themselves do not show up as RSS growth.
    for (auto* v : {&samples.full_ms, &samples.depth_ms, &samples.ratio, &samples.stage_sum_ms})
        v->reserve(frames);
    samples.depth_source = backend == Backend::vulkan
                               ? "Frame.times 'depth' (lavapipe: the depth command buffer submitted and waited alone, "
                                 "host-timed; real GPUs: timestamps), same frame as the full-frame time"
                               : "Frame.times 'depth' of the CPU backend, same frame as the full-frame time";
    const std::string name = std::string("speed/") + backend_name(backend) + "/full_frame";
    benchmark::RegisterBenchmark(name.c_str(),
                                 [&](benchmark::State& state) {
                                     try {
                                         for (auto _ : state) {
                                             const double full = render_counted();
                                             state.SetIterationTime(full * 1e-3);
                                             double sum = 0;
                                             for (const auto& t : frame.times) {
                                                 if (!samples.stages.count(t.stage)) {
                                                     samples.stage_order.push_back(t.stage);
                                                     samples.stages[t.stage].reserve(frames);
                                                 }
                                                 samples.stages[t.stage].push_back(t.ms);
                                                 // a pass or host step (VKSONAR_STAGE_TIMING=passes) is
                                                 // not a stage: inside or beside one
                                                 if (t.stage.find(':') == std::string::npos) sum += t.ms;
                                             }
                                             const double depth = stage_ms(frame, "depth");
                                             samples.full_ms.push_back(full);
                                             samples.depth_ms.push_back(depth);
                                             samples.stage_sum_ms.push_back(sum);
                                             if (depth > 0) samples.ratio.push_back(full / depth);
                                         }
                                         state.counters["full_med_ms"] = median(samples.full_ms);
                                         state.counters["depth_med_ms"] = median(samples.depth_ms);
                                         state.counters["full/depth"] = median(samples.ratio);
                                         state.counters["fps"] = 1000.0 / std::max(1e-9, median(samples.full_ms));
                                     } catch (const std::exception& e) {
                                         state.SkipWithError(e.what());
                                         record_failure(setup, e.what());
                                     }
                                 })
        ->UseManualTime()
        ->Iterations(frames)
        ->Unit(benchmark::kMillisecond);
    run_registered_benchmarks(setup);

    // Render-ahead (Renderer::render with a NextFrame): each call finishes its frame and starts the
    // next one's device work before its host stages, so a device renders while the host works. The
    // same number of frames, back to back; frames/s from the wall clock over all of them.
    std::vector<double> ahead_ms;
    ahead_ms.reserve(frames);
    std::uint64_t ahead_allocations = 0;
    const auto ahead_start = std::chrono::steady_clock::now();
    for (std::uint32_t i = 0; i < frames; ++i) {
        const std::uint64_t before = heap_allocations();
        const auto t0 = std::chrono::steady_clock::now();
        auto rendered = renderer.render(setup.pose, frame_index, frame, NextFrame{setup.pose, frame_index + 1});
        const auto t1 = std::chrono::steady_clock::now();
        if (!rendered) throw Failure("render: " + rendered.error().message);
        ahead_allocations += heap_allocations() - before;
        ahead_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        ++frame_index;
    }
    const double ahead_wall_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - ahead_start).count();

    // Soak: keep rendering (untimed) up to `memory_frames` frames in all, then read RSS again.
    while (frame_index < memory_frames)
        render_counted();
    const double rss_end = rss_mib();
    const double live_end = live_heap_now();
    if (rss_checkpoints.back().frame != frame_index) rss_checkpoints.push_back({frame_index, rss_end, live_end});

    const double full = median(samples.full_ms);
    const double depth = median(samples.depth_ms);
    const double fps = 1000.0 / full;
    const double ratio = median(samples.ratio);
    const double stage_sum = median(samples.stage_sum_ms);

    std::printf("\n## vksonar bench speed (%s, %s)\n\n", backend_name(backend), device.c_str());
    std::printf("| stage | median ms | p10 ms | p90 ms | share of full frame |\n|---|---:|---:|---:|---:|\n");
    for (const auto& stage : samples.stage_order) {
        const auto& v = samples.stages[stage];
        std::printf("| %s | %s | %s | %s | %s%% |\n", stage.c_str(), fmt(median(v), 3).c_str(),
                    fmt(percentile(v, 0.1), 3).c_str(), fmt(percentile(v, 0.9), 3).c_str(),
                    fmt(100.0 * median(v) / full, 1).c_str());
    }
    std::printf("| (sum of stages) | %s | | | %s%% |\n", fmt(stage_sum, 3).c_str(),
                fmt(100.0 * stage_sum / full, 1).c_str());
    std::printf("| (full frame - sum: submits, readback copy, bookkeeping) | %s | | | %s%% |\n",
                fmt(full - stage_sum, 3).c_str(), fmt(100.0 * (full - stage_sum) / full, 1).c_str());
    std::printf("| **full frame** (wall clock around Renderer::render) | **%s** | %s | %s | 100%% |\n\n",
                fmt(full, 3).c_str(), fmt(percentile(samples.full_ms, 0.1), 3).c_str(),
                fmt(percentile(samples.full_ms, 0.9), 3).c_str());

    std::printf("depth pass alone: %s\n", samples.depth_source.c_str());
    std::printf("  (the config cannot switch off the stages after depth; echo and beamform always run)\n");
    std::printf("frames/s (1000 / median full frame): %s  target >= 150: %s\n", fmt(fps, 1).c_str(),
                verdict(fps >= 150.0));
    // (full - depth) / depth = full / depth - 1 frame by frame, so its median is the ratio's minus 1.
    std::printf("frames/s rendering ahead (render() announcing the next frame, %u frames back to back): %s "
                "(median call %s ms; the last frame's device work is left started)%s; allocations %llu\n",
                frames, fmt(1000.0 * frames / std::max(1e-9, ahead_wall_ms), 1).c_str(),
                fmt(median(ahead_ms), 3).c_str(),
                backend == Backend::cpu ? " (the CPU backend has no device to overlap: plain render())" : "",
                static_cast<unsigned long long>(ahead_allocations));
    std::printf("post-depth stages / depth pass ((full frame - depth) / depth, median of per-frame ratios): %s  "
                "target <= 1.5: %s\n",
                fmt(ratio - 1.0, 2).c_str(), verdict(ratio - 1.0 <= 1.5));
    std::printf("full frame / depth pass (median of per-frame ratios): %s  (ratio of medians %s; the retired "
                "target was <= 1.5)\n",
                fmt(ratio, 2).c_str(), fmt(full / std::max(1e-9, depth), 2).c_str());
    const double growth = rss_end - rss_10;
    std::printf("RSS after %u frames: %s MiB; after %llu frames: %s MiB; difference %+.3f MiB  target <= 1 MiB: %s\n",
                kWarmup, fmt(rss_10, 2).c_str(), static_cast<unsigned long long>(frame_index), fmt(rss_end, 2).c_str(),
                growth, verdict(growth <= 1.0));
    if (rss_checkpoints.size() >= 3) {
        // From frame 100 on: driver and allocator warm-up is over; what grows now grows per frame.
        const double steady = rss_end - rss_checkpoints[1].rss_mib;
        std::printf("RSS steady state (frame %llu to %llu): %+.3f MiB\n",
                    static_cast<unsigned long long>(rss_checkpoints[1].frame),
                    static_cast<unsigned long long>(frame_index), steady);
    }
    std::printf("RSS by frame:");
    for (const auto& point : rss_checkpoints)
        std::printf(" %llu: %s MiB;", static_cast<unsigned long long>(point.frame), fmt(point.rss_mib, 2).c_str());
    std::printf("\n");
    // RSS also moves when the allocator's free space fragments: lavapipe mallocs and frees a few MiB per
    // frame on its own threads (vertex buffers per draw, 64 KiB bin blocks). Live bytes do not.
    std::printf("live heap (malloc'd, not freed, all threads incl. the driver; mallinfo2; least of the last 3 "
                "frames) after %u frames: %s MiB; "
                "after %llu: %s MiB; difference %+.3f MiB\n",
                kWarmup, fmt(live_10, 3).c_str(), static_cast<unsigned long long>(frame_index),
                fmt(live_end, 3).c_str(), live_end - live_10);
    std::printf("live heap by frame:");
    for (const auto& point : rss_checkpoints)
        std::printf(" %llu: %s MiB;", static_cast<unsigned long long>(point.frame),
                    fmt(point.live_heap_mib, 3).c_str());
    std::printf("\n");
    std::printf("heap allocations (operator new) inside Renderer::render after the warm-up: %llu in %llu frames "
                "(%s per frame)  target 0: %s\n",
                static_cast<unsigned long long>(allocations), static_cast<unsigned long long>(counted_frames),
                fmt(counted_frames ? double(allocations) / double(counted_frames) : 0.0, 3).c_str(),
                verdict(allocations == 0));
    if (frame_index < 1000)
        std::printf("  (note: only %llu frames rendered; the target is stated for 1000)\n",
                    static_cast<unsigned long long>(frame_index));
    std::printf("(timings vary +-30-50%% between runs on lavapipe; LP_NUM_THREADS=1 gives steadier numbers)\n");
    if (flow) run_flow_timing(renderer, setup.pose, frame_index, frames, frame);
    return 0;
}

} // namespace vksonar::cli::bench

#endif // VKSONAR_HAVE_BENCHMARK
