// The CPU StageBackend: runs the four reference stages on buffers allocated once at construction.
// Arithmetic precision follows plan.config.cpu_precision (f64 -> double, else float).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
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
constexpr std::uint32_t kRowBlock = 16, kBinBlock = 32, kColumnBlock = 64;

// Copies into a preallocated frame vector; assign() reuses the capacity make_frame() reserved.
template <class T> void store(std::vector<T>& dst, const std::vector<T>& src) {
    dst.assign(src.begin(), src.end());
}

template <class Real> class CpuBackend final : public StageBackend {
public:
    CpuBackend(const Plan& plan, const SceneData& scene, host::Workers* workers)
        : plan_(plan), scene_(scene), workers_(workers) {
        const std::uint32_t parts = workers_ != nullptr ? workers_->count() : 1;
        const std::size_t pixels = static_cast<std::size_t>(plan_.rows) * plan_.columns;
        depth_.assign(pixels, 0.0f);
        material_.assign(pixels, shared::kNoMaterial);
        if (plan_.effects.incidence) normals_.assign(pixels * 4, 0.0f);
        if (plan_.face_normals) face_.assign(pixels * 4, 0.0f);
        echo_.assign(pixels * 2, 0.0f);
        echo_table_.assign(echo_table_count(plan_), Real(0));
        echo_table<Real>(plan_, echo_table_.data());
        profiles_.assign(static_cast<std::size_t>(plan_.bins) * plan_.profile_columns, 0.0f);
        beam_profiles_.assign(static_cast<std::size_t>(plan_.bins) * plan_.beams, 0.0f);
        scratch_.assign(std::max<std::size_t>(beamform_accumulator_count(plan_), 1), Real(0));
        resample_w_.assign(std::max<std::size_t>(resample_weight_count(plan_), 1), Real(0));
        resample_weights<Real>(plan_, resample_w_.data());
        if (plan_.effects.incidence && !plan_.face_normals)
            normals_scratch_.assign(std::max<std::size_t>(normals_scratch_count(plan_), 1) * parts, Real(0));
        draws_.resize(static_cast<std::size_t>(plan_.slices) * scene_.draws.size());
        build_depth_clusters(scene_, clusters_);
        clusters_drawn_.resize(std::size_t(plan_.slices) * clusters_.size());
    }

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
        // The side-lobe pass writes the polar scan straight into the frame (make_frame sized it).
        frame.clean.resize(static_cast<std::size_t>(plan_.bins) * plan_.beams);
        for (const StageInfo& stage : kStageTable) {
            if (!stage.runs(plan_)) continue;
            const auto start = Clock::now();
            run(stage.id, pose, save_mask, frame.clean.data());
            frame.times.push_back({stage.name, ms_since(start)});
            frame.stages_run.emplace_back(stage.name);
        }

        if (any(save_mask & SaveFlags::depth)) {
            store(frame.depth, depth_);
            store(frame.material, material_);
        }
        if (any(save_mask & SaveFlags::normals)) {
            if (plan_.effects.incidence) {
                store(frame.normals, normals_);
            } else {
                frame.normals.clear(); // the normals stage did not run (incidence off)
            }
        }
        if (any(save_mask & SaveFlags::echo)) store(frame.echo, echo_);
        if (any(save_mask & SaveFlags::profiles)) {
            store(frame.profiles, profiles_);
            store(frame.beam_profiles, beam_profiles_);
        }
        return {};
    }

    const char* name() const override { return "cpu"; }

private:
    // One stage of kStageTable on this backend's buffers.
    void run(StageId stage, const Pose& pose, SaveFlags save_mask, float* polar) {
        switch (stage) {
        case StageId::depth: {
            compose_depth_draws(plan_, scene_, pose, draws_);
            cull_depth_clusters(clusters_, scene_.draws.size(), draws_, clusters_drawn_);
            const DepthClusters clusters{clusters_, clusters_drawn_};
            depth_pass(plan_, scene_, draws_, depth_.data(), material_.data(),
                       plan_.face_normals ? face_.data() : nullptr, &clusters);
            break;
        }
        case StageId::normals:
            if (plan_.face_normals) {
                split_blocks(workers_, plan_.rows, kRowBlock,
                             [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
                                 cpu::geometric_normals_rows<Real>(plan_, depth_.data(), face_.data(), normals_.data(),
                                                                   begin, end);
                             });
            } else { // each part slides its own ring of rows: part i's scratch starts at i * per_part
                const std::size_t per_part = std::max<std::size_t>(normals_scratch_count(plan_), 1);
                split_blocks(workers_, plan_.rows, kRowBlock,
                             [&](std::uint32_t begin, std::uint32_t end, std::uint32_t part) {
                                 cpu::normals_rows<Real>(plan_, depth_.data(), normals_.data(),
                                                         normals_scratch_.data() + part * per_part, begin, end);
                             });
            }
            break;
        case StageId::echo: // normals only where the normals stage ran (incidence on)
            split_blocks(workers_, plan_.rows, kRowBlock, [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
                cpu::echo_rows<Real>(plan_, depth_.data(), material_.data(),
                                     plan_.effects.incidence ? normals_.data() : nullptr, echo_.data(),
                                     echo_table_.data(), begin, end);
            });
            break;
        case StageId::beamform: { // every column's profile before any beam reads it
            // the float profiles only when saved: the resample reads the accumulators
            float* profiles = any(save_mask & SaveFlags::profiles) ? profiles_.data() : nullptr;
            split_blocks(workers_, plan_.profile_columns, kColumnBlock,
                         [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
                             cpu::beamform_profiles<Real>(plan_, echo_.data(), profiles, scratch_.data(), begin, end);
                         });
            split_blocks(workers_, plan_.bins, kBinBlock, [&](std::uint32_t begin, std::uint32_t end, std::uint32_t) {
                cpu::beamform_beams<Real>(plan_, scratch_.data(), resample_w_.data(), beam_profiles_.data(), polar,
                                          begin, end);
            });
            break;
        }
        }
    }

    Plan plan_;              // copied: the backend may outlive the caller's Plan object
    const SceneData& scene_; // the scene must outlive the renderer (renderer.h)
    host::Workers* workers_; // the Renderer's threads, borrowed (null: all on the caller)
    std::vector<shared::DepthPush> draws_;
    std::vector<DepthCluster> clusters_;
    std::vector<std::uint8_t> clusters_drawn_; // slices * clusters, 0 = the cluster cannot reach that slice
    std::vector<float> depth_;
    std::vector<std::uint32_t> material_;
    std::vector<float> face_; // face normals of the depth pass (normal_method = geometric only)
    std::vector<float> normals_, echo_, profiles_, beam_profiles_; // the polar scan: in the frame
    std::vector<Real> scratch_, normals_scratch_; // scratch_: the profile accumulators (beamform_accumulator_count)
    std::vector<Real> echo_table_;                // echo_table, filled once
    std::vector<Real> resample_w_;                // resample_weights, filled once
};

} // namespace

std::unique_ptr<StageBackend> make_backend(const Plan& plan, const SceneData& scene, host::Workers* workers) {
    if (plan.config.cpu_precision == Precision::f64) return std::make_unique<CpuBackend<double>>(plan, scene, workers);
    return std::make_unique<CpuBackend<float>>(plan, scene, workers);
}

} // namespace vksonar::cpu
