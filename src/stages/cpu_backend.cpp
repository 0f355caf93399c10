// The CPU StageBackend: walks kStageTable and runs each stage's CPU function (run_*, defined here
// next to the buffers they share, allocated once at construction). Arithmetic precision follows
// plan.config.cpu_precision (f64 -> double, else float).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "host/workers.h"
#include "stages/cpu_stages.h"
#include "stages/stage_table.h"

namespace vksonar::cpu {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// [0, n) in blocks of `block`, taken by the workers' threads as they come (Workers::run_blocks): the
// rows of a sonar image are not equally loaded (above the seabed most rows have no hit), nor are its
// bins (the side-lobe pass skips empty ones), and a thread that the system runs late (on a busy
// machine) leaves its share to the others. part(begin, end, thread) runs once per block; thread picks
// the per-thread scratch. On one thread, part runs once over the whole range.
template <class Part>
void split_blocks(host::Workers* workers, std::uint32_t n, std::uint32_t block, const Part& part) {
    if (workers == nullptr || workers->count() == 1 || n <= block) {
        part(0u, n, 0u);
        return;
    }
    struct Context {
        const Part* part;
        std::uint32_t n, block;
    } context{&part, n, block};
    workers->run_blocks(
        [](void* c, std::uint32_t index, std::uint32_t thread) {
            const auto& t = *static_cast<const Context*>(c);
            const std::uint32_t begin = index * t.block;
            (*t.part)(begin, std::min(begin + t.block, t.n), thread);
        },
        &context, (n + block - 1) / block);
}
constexpr std::uint32_t kRowBlock = 16, kBinBlock = 32;
// Below this many cluster-views (a few tens of microseconds of culling) waking the threads costs more
// than it saves.
constexpr std::size_t kParallelCullClusterViews = 1024;

// The profile stage's blocks of profile columns, as split_blocks hands them out: on several threads about
// four blocks per thread, 32 to 128 columns each (a block also spreads the pixels that straddle its first
// column, the previous block's too, so fewer, wider blocks repeat less: 64 -> 128 on two threads,
// beamform -1.5 %); on one thread all of them at once.
std::uint32_t profile_column_block(const Plan& plan, std::uint32_t threads) {
    if (threads <= 1) return std::max(plan.profile_columns, 1u);
    return static_cast<std::uint32_t>(std::clamp<std::uint64_t>(ceil_div(plan.profile_columns, 4 * threads), 32, 128));
}

// A saved image: the stage's buffer when it ran, none when it did not (normals with incidence off).
template <class T> void save(std::vector<T>& dst, const std::vector<T>& src, bool ran) {
    if (ran) {
        dst.assign(src.begin(), src.end()); // reuses the capacity make_frame() reserved
    } else {
        dst.clear();
    }
}

} // namespace

// The CPU backend's working buffers, allocated once at construction, and the frame being rendered:
// what the table's run_* functions work on.
template <class Real> struct StageContext {
    StageContext(const Plan& plan_in, const SceneData& scene_in, host::Workers* workers_in, bool pass_timing_in)
        : plan(plan_in), scene(scene_in), workers(workers_in), pass_timing(pass_timing_in) {
        const std::uint32_t parts = workers != nullptr ? workers->count() : 1;
        const std::size_t pixels = static_cast<std::size_t>(plan.rows) * plan.columns;
        depth.assign(pixels, 0.0f);
        material.assign(pixels, shared::kNoMaterial);
        if (plan.effects.incidence) normals.assign(pixels * 4, 0.0f);
        if (plan.face_normals) face.assign(pixels * 4, 0.0f);
        echo.assign(pixels * 2, 0.0f);
        echo_table.assign(echo_table_count(plan), Real(0));
        cpu::echo_table<Real>(plan, echo_table.data());
        profiles.assign(static_cast<std::size_t>(plan.bins) * plan.profile_columns, 0.0f);
        beam_profiles.assign(static_cast<std::size_t>(plan.bins) * plan.beams, 0.0f);
        scratch.assign(std::max<std::size_t>(beamform_accumulator_count(plan), 1), Real(0));
        resample_w.assign(std::max<std::size_t>(resample_weight_count(plan), 1), Real(0));
        resample_weights<Real>(plan, resample_w.data());
        if (plan.effects.incidence && !plan.face_normals)
            normals_scratch.assign(std::max<std::size_t>(normals_scratch_count(plan), 1) * parts, Real(0));
        draws.resize(static_cast<std::size_t>(plan.views) * scene.draws.size());
        build_depth_clusters(scene, clusters);
        clusters_drawn.resize(std::size_t(plan.views) * clusters.size());
        view_drawn.assign(plan.views, 1);
        subpixel.prepare(plan);
        // Each profile block's cone spans, where they take fewer words than the depth image has pixels
        // (else each frame searches for them): searching took 4-8 % of the beamform stage.
        const std::uint32_t block = profile_column_block(plan, parts);
        const std::size_t blocks = ceil_div(plan.profile_columns, block);
        if (cone_span_count(plan) * blocks <= pixels) {
            cone_spans.resize(cone_span_count(plan) * blocks); // none for planar (cone_span_count 0)
            for (std::size_t b = 0; b < blocks && !cone_spans.empty(); ++b) {
                const auto begin = static_cast<std::uint32_t>(b * block);
                cone_column_spans(plan, begin, std::min(begin + block, plan.profile_columns),
                                  cone_spans.data() + b * cone_span_count(plan));
            }
        }
    }

    Plan plan;              // copied: the backend may outlive the caller's Plan object
    const SceneData& scene; // the scene must outlive the renderer (renderer.h)
    host::Workers* workers; // the Renderer's threads, borrowed (null: all on the caller)
    // StageTiming::passes: a whole stage's passes add their host times here (cleared per stage; a
    // stage's row is followed by its passes' rows in Frame::times)
    bool pass_timing = false;
    std::array<std::pair<const char*, double>, 4> passes{};
    std::size_t pass_count = 0;
    // this frame's
    Pose pose{};
    SaveFlags save_mask = SaveFlags::none;
    float* polar = nullptr; // the side-lobe pass writes the polar scan straight into the frame

    std::vector<shared::DepthPush> draws;
    std::vector<DepthCluster> clusters;
    std::vector<std::uint8_t> clusters_drawn; // views * clusters, 0 = the cluster cannot reach that view
    std::vector<std::uint8_t> view_drawn;     // views: 0 = no cluster reaches it this frame (all its pixels empty)
    SubpixelReturns subpixel;                 // the frame's sub-pixel returns (core/subpixel.h)
    std::vector<float> depth;
    std::vector<std::uint32_t> material;
    std::vector<float> face; // face normals of the depth pass (normal_method = geometric only)
    std::vector<float> normals, echo, profiles, beam_profiles;
    std::vector<Real> scratch, normals_scratch; // scratch: the profile accumulators (beamform_accumulator_count)
    std::vector<Real> echo_table;               // echo_table, filled once
    std::vector<Real> resample_w;               // resample_weights, filled once
    std::vector<std::uint32_t> cone_spans;      // cone_column_spans of each profile block, or empty
};

template <class Real> void run_depth(StageContext<Real>& s) {
    compose_depth_draws(s.plan, s.scene, s.pose, s.draws);
    // Culling tests every cluster in every view: on one thread, the 4k clusters of a 2M-triangle
    // terrain took a tenth of its depth pass. With many clusters the threads take the views (the same
    // flags: each is a function of its cluster and view).
    // (clusters_drawn is sized views * clusters at creation; split_blocks without workers runs every view
    // on this thread.)
    const bool many = s.clusters.size() * s.plan.views >= kParallelCullClusterViews;
    split_blocks(many ? s.workers : nullptr, s.plan.views, 1,
                 [&](std::uint32_t view, std::uint32_t view_end, std::uint32_t) {
                     for (; view < view_end; ++view)
                         cull_depth_clusters_in_slice(s.clusters, s.scene.draws.size(), s.draws, view,
                                                      s.clusters_drawn.data() + std::size_t(view) * s.clusters.size());
                 });
    // the objects a few pixels across or less: their returns (added by the profile step) instead of their
    // pixels' echo
    s.subpixel.build(s.plan, s.scene, s.pose, s.clusters, s.draws, s.clusters_drawn);
    // A view no cluster reaches (a tier view above a scene with nothing overhead) is empty: the stages
    // after the depth pass only zero its pixels.
    const std::size_t count = s.clusters.size();
    for (std::uint32_t v = 0; v < s.plan.views; ++v) {
        const auto first = s.clusters_drawn.begin() + std::ptrdiff_t(v * count);
        s.view_drawn[v] =
            std::find(first, first + std::ptrdiff_t(count), std::uint8_t(1)) != first + std::ptrdiff_t(count);
    }
    const DepthClusters clusters{s.clusters, s.clusters_drawn};
    // Blocks of one view's rows, about two per thread: a view's triangles are set up for its blocks only
    // (splitting rows instead set up every view's triangles once per band: most of the pass's time
    // went there, as the default scene's triangles cover a few pixels each). A view is cut into bands of
    // rows only where there are fewer views than blocks wanted: the seabed's rows hold most of the
    // pixels, so one block per thread would leave a thread waiting. The larger views (the slices) come
    // first, and the threads take blocks as they come.
    const std::uint32_t threads = s.workers ? s.workers->count() : 1u;
    const std::uint32_t views = s.plan.views;
    const std::uint32_t bands = static_cast<std::uint32_t>(ceil_div(2 * threads, views));
    const std::uint32_t band_rows = static_cast<std::uint32_t>(ceil_div(s.plan.rows, bands));
    split_blocks(s.workers, views * bands, 1, [&](std::uint32_t block, std::uint32_t block_end, std::uint32_t) {
        for (; block < block_end; ++block) {
            const std::uint32_t view = block / bands, band = block % bands;
            depth_pass(s.plan, s.scene, s.draws, s.depth.data(), s.material.data(),
                       s.plan.face_normals ? s.face.data() : nullptr, &clusters,
                       {band * band_rows, (band + 1) * band_rows, view, view + 1});
        }
    });
}

template <class Real>
void rows_normals(StageContext<Real>& s, std::uint32_t begin, std::uint32_t end, std::uint32_t thread) {
    if (s.plan.face_normals) {
        geometric_normals_rows<Real>(s.plan, s.depth.data(), s.face.data(), s.normals.data(), begin, end);
        return;
    }
    // each thread slides its own ring of rows: thread i's scratch starts at i * per_thread
    const std::size_t per_thread = std::max<std::size_t>(normals_scratch_count(s.plan), 1);
    normals_rows<Real>(s.plan, s.depth.data(), s.normals.data(), s.normals_scratch.data() + thread * per_thread, begin,
                       end, s.view_drawn.data());
}

template <class Real> void rows_echo(StageContext<Real>& s, std::uint32_t begin, std::uint32_t end, std::uint32_t) {
    // normals only where the normals stage ran (incidence on): a pixel reads its own
    const float* normals = s.plan.effects.incidence ? s.normals.data() : nullptr;
    echo_rows<Real>(s.plan, s.depth.data(), s.material.data(), normals, s.echo.data(), s.echo_table.data(), begin, end,
                    s.view_drawn.data());
}

template <class Real> void run_beamform(StageContext<Real>& s) {
    // StageTiming::passes: the profile pass, then the beams pass (the resample, the far and the near side
    // lobes, fused per block of bins)
    auto pass_done = [&](const char* name, Clock::time_point& start) {
        if (!s.pass_timing) return;
        const auto now = Clock::now();
        s.passes[s.pass_count++] = {name, std::chrono::duration<double, std::milli>(now - start).count()};
        start = now;
    };
    Clock::time_point start;
    if (s.pass_timing) start = Clock::now();
    // the float profiles only when saved: the resample reads the accumulators
    float* profiles = any(s.save_mask & SaveFlags::profiles) ? s.profiles.data() : nullptr;
    const SubpixelInput subpixel{s.subpixel, s.depth.data(), s.material.data()};
    const SubpixelInput* with_subpixel = s.plan.subpixel_capacity > 0 ? &subpixel : nullptr;
    const std::uint32_t column_block = profile_column_block(s.plan, s.workers ? s.workers->count() : 1u);
    split_blocks(
        s.workers, s.plan.profile_columns, column_block, [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
            // [begin, end) is block begin / column_block (profile_column_block)
            const std::uint32_t* spans =
                s.cone_spans.empty() ? nullptr : s.cone_spans.data() + begin / column_block * cone_span_count(s.plan);
            beamform_profiles<Real>(s.plan, s.echo.data(), profiles, s.scratch.data(), begin, end, with_subpixel,
                                    s.view_drawn.data(), spans);
        });
    pass_done("bf:profile", start);
    split_blocks(s.workers, s.plan.bins, kBinBlock, [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
        beamform_beams<Real>(s.plan, s.scratch.data(), s.resample_w.data(), s.beam_profiles.data(), s.polar, begin,
                             end);
    });
    pass_done("bf:beams", start);
}

// The table's pointers name these; they are defined here, next to the buffers they touch.
template void run_depth<float>(StageContext<float>&);
template void run_depth<double>(StageContext<double>&);
template void rows_normals<float>(StageContext<float>&, std::uint32_t, std::uint32_t, std::uint32_t);
template void rows_normals<double>(StageContext<double>&, std::uint32_t, std::uint32_t, std::uint32_t);
template void rows_echo<float>(StageContext<float>&, std::uint32_t, std::uint32_t, std::uint32_t);
template void rows_echo<double>(StageContext<double>&, std::uint32_t, std::uint32_t, std::uint32_t);
template void run_beamform<float>(StageContext<float>&);
template void run_beamform<double>(StageContext<double>&);

namespace {

template <class Real> class CpuBackend final : public StageBackend {
public:
    CpuBackend(const Plan& plan, const SceneData& scene, host::Workers* workers, bool pass_timing)
        : stage_(plan, scene, workers, pass_timing) {}

    Result<void> render(const Pose& pose, SaveFlags save_mask, Frame& frame) override {
        const double pose_values[6] = {pose.x_m, pose.y_m, pose.z_m, pose.roll_deg, pose.pitch_deg, pose.yaw_deg};
        const char* pose_names[6] = {"x", "y", "z", "roll", "pitch", "yaw"};
        for (int i = 0; i < 6; ++i) {
            if (!std::isfinite(pose_values[i])) {
                return make_error(ErrorCode::invalid_argument, std::string("pose: ") + pose_names[i] +
                                                                   " is not finite (" + std::to_string(pose_values[i]) +
                                                                   ")");
            }
        }

        // A frame reused across renders reports this render's stages only (capacity is kept).
        frame.times.clear();
        frame.stages_run.clear();
        frame.clean.resize(static_cast<std::size_t>(stage_.plan.bins) * stage_.plan.beams); // make_frame sized it
        stage_.pose = pose;
        stage_.save_mask = save_mask;
        stage_.polar = frame.clean.data();
        for (std::size_t i = 0; i < kStageCount;) {
            const StageInfo& stage = kStageTable[i];
            if (cpu_rows_function<Real>(stage.cpu) != nullptr) {
                i = run_row_stages(i, frame);
                continue;
            }
            ++i;
            if (!stage.runs(stage_.plan)) continue;
            const auto start = Clock::now();
            stage_.pass_count = 0;
            cpu_function<Real>(stage.cpu)(stage_);
            frame.times.push_back({stage.name, ms_since(start)});
            frame.stages_run.emplace_back(stage.name);
            for (std::size_t p = 0; p < stage_.pass_count; ++p)
                frame.times.push_back({stage_.passes[p].first, stage_.passes[p].second});
        }
        for (const StageInfo& stage : kStageTable) {
            if (!any(save_mask & stage.saves)) continue;
            const bool ran = stage.runs(stage_.plan);
            for_each_buffer(stage.saved, [&](StageBuffers buffer) { save_buffer(buffer, ran, frame); });
        }
        return {};
    }

    const char* name() const override { return "cpu"; }
    const SubpixelReturns* subpixel_returns() const override { return &stage_.subpixel; }

private:
    // The row stages from kStageTable[first] on (up to the next whole stage) that run with this plan, fused:
    // blocks of kRowBlock rows, each through all of them in table order, taken by the threads as they
    // come. Each stage's time is the pass's wall time shared by its summed block time. Returns the index
    // of the next whole stage.
    std::size_t run_row_stages(std::size_t first, Frame& frame) {
        std::array<std::size_t, kStageCount> run{};
        std::size_t n = 0, end = first;
        for (; end < kStageCount && cpu_rows_function<Real>(kStageTable[end].cpu) != nullptr; ++end)
            if (kStageTable[end].runs(stage_.plan)) run[n++] = end;
        if (n == 0) return end;
        // busy[thread][k]: ms that thread spent in run[k]'s rows (no allocation: fixed arrays)
        std::array<std::array<double, kStageCount>, host::Workers::kMaxThreads> busy{};
        const auto start = Clock::now();
        split_blocks(stage_.workers, stage_.plan.rows, kRowBlock,
                     [&](std::uint32_t begin, std::uint32_t block_end, std::uint32_t thread) {
                         // on one thread this is every row at once: still a block at a time
                         for (std::uint32_t row = begin; row < block_end; row += kRowBlock) {
                             const std::uint32_t rows_end = std::min(row + kRowBlock, block_end);
                             for (std::size_t k = 0; k < n; ++k) {
                                 const auto stage_start = Clock::now();
                                 cpu_rows_function<Real>(kStageTable[run[k]].cpu)(stage_, row, rows_end, thread);
                                 busy[thread][k] += ms_since(stage_start);
                             }
                         }
                     });
        const double wall = ms_since(start);
        std::array<double, kStageCount> stage_busy{};
        double total = 0.0;
        for (const auto& thread : busy)
            for (std::size_t k = 0; k < n; ++k) {
                stage_busy[k] += thread[k];
                total += thread[k];
            }
        for (std::size_t k = 0; k < n; ++k) {
            const double share = total > 0.0 ? stage_busy[k] / total : 1.0 / static_cast<double>(n);
            frame.times.push_back({kStageTable[run[k]].name, wall * share});
            frame.stages_run.emplace_back(kStageTable[run[k]].name);
        }
        return end;
    }

    void save_buffer(StageBuffers buffer, bool ran, Frame& frame) const {
        switch (buffer) {
        case StageBuffers::depth:
            return save(frame.depth, stage_.depth, ran);
        case StageBuffers::material:
            return save(frame.material, stage_.material, ran);
        case StageBuffers::normals:
            return save(frame.normals, stage_.normals, ran);
        case StageBuffers::echo:
            return save(frame.echo, stage_.echo, ran);
        case StageBuffers::profiles:
            return save(frame.profiles, stage_.profiles, ran);
        case StageBuffers::beam_profiles:
            return save(frame.beam_profiles, stage_.beam_profiles, ran);
        default: // not one of the Frame's images
            return;
        }
    }

    StageContext<Real> stage_;
};

} // namespace

std::unique_ptr<StageBackend> make_backend(const Plan& plan, const SceneData& scene, host::Workers* workers,
                                           bool pass_timing) {
    if (plan.config.cpu_precision == Precision::f64)
        return std::make_unique<CpuBackend<double>>(plan, scene, workers, pass_timing);
    return std::make_unique<CpuBackend<float>>(plan, scene, workers, pass_timing);
}

} // namespace vksonar::cpu
