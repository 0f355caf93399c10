// Sub-pixel objects (docs/pipeline.md "Sub-pixel objects", issue 17): the pixel grid gives a small object
// the energy of the pixel centres it happens to cover: none for a 2 cm sphere at 15 m, a whole pixel's for
// one that covers a centre. So an object (a draw) whose bounding sphere subtends a few pixels or less,
// and each depth cluster (plan.h) whose extent across its length is under a pixel (a cable), has its echo
// computed here instead, per triangle, from the triangle's area, orientation and material (sonar_kernels.h
// facet_echo), a triangle longer than a pixel split into pieces that are not. Each piece goes to the
// range profile of its direction's column at its range, unless the depth image holds a nearer surface in
// its direction (subpixel_visible, tested on the device by profile.comp and in the CPU's profile loop).
//   - under two pixels across (the smaller pixel side), and thin clusters: not rasterized at all (their
//     depth clusters are culled): what they hide is sub-pixel too;
//   - up to four pixels across (the larger pixel side, the coarser sampling): rasterized for the depth
//     image, so that they still hide what lies behind them (a sphere's shadow on the seabed), but with the
//     plan's silent material (Plan::subpixel_silent_material, no backscatter): their echo is the returns'.
//
// The list is made on the host for both backends, by the same code from the same pose: they add the
// same returns. Nothing is allocated per frame: the buffers are sized once (Plan::subpixel_capacity);
// a frame whose objects would overflow them leaves the rest to the depth pass as before.
#pragma once

#include <cstdint>
#include <vector>

#include "sonar_shared.h"
#include "vksonar/scene.h"

namespace vksonar {

struct Plan;
struct SceneData;
struct DepthCluster;

// make_plan's step: the candidates (Plan::subpixel_candidates) and the most returns a frame can list
// (Plan::subpixel_capacity; 0: nothing of the scene can be sub-pixel inside the range gate): the
// returns of every candidate at its finest split, capped at kMaxSubpixelReturns.
void plan_subpixel(Plan& plan, const SceneData& scene);
constexpr std::uint32_t kMaxSubpixelReturns = 1u << 18; // 4 MiB of returns

// What the labels stage (stages/labels.h) needs of a return beside its echo: its centroid (sonar frame)
// and the instance id of its object (SceneDraw::instance).
struct SubpixelLabel {
    float x, y, z;
    std::uint32_t instance;
};

class SubpixelReturns {
public:
    // Sizes everything once for the plan (plan.subpixel_capacity).
    void prepare(const Plan& plan);

    // One frame: the candidate clusters that are sub-pixel at this pose are taken out of the depth pass
    // (drawn = 0 in every slice; drawn: cull_depth_clusters's flags) and their returns listed, sorted by
    // profile column (each column's in the order the clusters and triangles come).
    // pushes: compose_depth_draws's (the objects drawn silent get the silent material there).
    void build(const Plan& plan, const SceneData& scene, const Pose& pose, const std::vector<DepthCluster>& clusters,
               std::vector<shared::DepthPush>& pushes, std::vector<std::uint8_t>& drawn);

    std::uint32_t count() const { return count_; }
    std::uint32_t clusters_taken() const { return clusters_taken_; } // culled from the depth pass
    std::uint32_t draws_silent() const { return draws_silent_; }     // drawn with the silent material
    // column c's returns: returns()[column_begin()[c] .. column_begin()[c + 1])
    const std::uint32_t* column_begin() const { return column_begin_.data(); }
    const shared::SubpixelReturn* returns() const { return returns_.data(); }
    const SubpixelLabel* labels() const { return labels_.data(); } // returns()[i]'s centroid and instance

    // The device buffer (binding kBindingSubpixel): column_begin, the silent material, then the returns
    // from the next multiple of 4 uints (sonar_shared.h). buffer_bytes: its size for the plan (>= 16).
    static std::size_t buffer_bytes(const Plan& plan);
    // The first buffer_bytes of this frame's list (only the returns listed are copied).
    void write_buffer(const Plan& plan, void* destination) const;
    // How many bytes of the buffer write_buffer wrote (the header and this frame's returns: what the
    // device needs copied of it).
    std::size_t written_bytes(const Plan& plan) const;

private:
    std::vector<std::uint32_t> column_begin_;
    std::vector<shared::SubpixelReturn> returns_, unsorted_;
    std::vector<SubpixelLabel> labels_, unsorted_labels_;
    std::vector<std::uint32_t> unsorted_column_;
    std::uint32_t capacity_ = 0, count_ = 0, clusters_taken_ = 0, draws_silent_ = 0;
};

} // namespace vksonar
