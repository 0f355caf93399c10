// The labels stage (SaveFlags::labels, docs/labels.md): per polar cell, the object that put the most
// energy into it, its share, its class, the energy-weighted elevation and its spread, and the 3-D point
// of the object's strongest return there. It runs on the host after either backend, on that backend's material/instance
// image and echo, and follows each pixel's energy along the main lobe exactly as the beamform stage spreads it
// (pixel_spread's range shares in the backend's precision, the cone or pixel columns, the beam table;
// the sums in double), and the returns
// of objects below the pixel grid's size (core/subpixel.h) as the profile stage adds them. Side lobes,
// speckle and noise are left out: a label says what the beam looks at, not what leaks into it.
//
// Made only when labels are asked for (effects on demand): its scratch is allocated here, once.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/plan.h"
#include "vksonar/frame.h"
#include "vksonar/scene.h"

namespace vksonar::host {
class Workers;
}

namespace vksonar {
struct SceneData;
class SubpixelReturns;
} // namespace vksonar

namespace vksonar::cpu {

// Contributions of more than kLabelSlots distinct instances to one cell: the first kLabelSlots (in the
// order the beam's pixels are visited) are told apart, the rest count only in the cell's total energy
// (so a cell that mixed that many objects has a small instance_fraction, as it should).
inline constexpr std::uint32_t kLabelSlots = 4;

// The beam table's steering angles (strictly decreasing) in 4 buckets per beam, each with the first
// beam below its upper edge: LabelsStage::flow finds the first beam below an angle in a step or two from there
// instead of a binary search (the same beam).
struct BeamBuckets {
    BeamBuckets() = default;
    explicit BeamBuckets(const std::vector<double>& beam_angles); // empty with fewer than two beams
    // the first j with beam_angles[j] < a, for beam_angles[n - 1] < a < beam_angles[0] (inline: the flow
    // asks it twice per labelled cell)
    std::size_t first_below(const std::vector<double>& beam_angles, double a) const;
    double low = 0.0, per_rad = 0.0;
    std::vector<std::uint32_t> first;
};

inline std::size_t BeamBuckets::first_below(const std::vector<double>& t, double a) const {
    // From the bucket above a's (a rounding of a's bucket by one is covered): every j before that bucket's
    // first has t[j] >= its upper edge > a, so the answer is there or after it. No buckets, or a NaN or
    // huge quotient: from the first beam.
    const double u = (a - low) * per_rad;
    std::size_t j = 0;
    if (u >= 0.0 && u + 1.0 < double(first.size())) j = first[static_cast<std::size_t>(u) + 1];
    while (j < t.size() && !(t[j] < a))
        ++j;
    return j;
}

class LabelsStage {
public:
    // class_of_instance[id] = the class id of instance id (0 for 0 and any id past the table).
    // workers: the Renderer's threads, borrowed (null: all on the caller). scene: borrowed, for
    // Frame::visibility (null: a host depth image, no visibility). float_spreads: each pixel's range
    // spread and shares as the float profile loop makes them (the GPU's profile pass, the CPU backend in
    // float), else in double (the CPU backend with cpu.precision = double).
    LabelsStage(const Plan& plan, std::vector<std::uint16_t> class_of_instance, host::Workers* workers,
                const SceneData* scene, bool float_spreads = true);
    ~LabelsStage();
    LabelsStage(const LabelsStage&) = delete;
    LabelsStage& operator=(const LabelsStage&) = delete;

    // Reads frame.material (material | instance << 16, as the depth pass wrote it with plan.labels) and
    // frame.echo, fills frame.instance ... frame.point, then leaves frame.material as material ids
    // (kNoMaterial where nothing was hit), as without labels. The result does not depend on the threads.
    // pose: the frame's, for Frame::visibility (each labelled object drawn alone on the CPU rasterizer).
    // subpixel: the backend's sub-pixel returns of this frame (null: none): objects too small or thin for
    // the pixel grid (a cable) label the cells their returns reach, as their echo does.
    void run(Frame& frame, const Pose& pose, const SubpixelReturns* subpixel = nullptr);
    // StageTiming::passes: run() also adds its parts' host times to frame.times ("labels:pixels": the
    // label arrays cleared and each hit pixel's spread; "labels:beams"; "labels:visible": the objects
    // drawn alone; names with a ':' are not stages).
    void set_part_timing(bool on) { part_timing_ = on; }
    // Flow between two labelled frames of this plan (docs/labels.md): for each cell of `from` with a label,
    // where its point moves in the polar grid when the sonar goes from from_pose to to_pose in a static
    // scene: flow[2 i] = d_bin, flow[2 i + 1] = d_beam (fractional; the point's coordinates in `to` minus
    // those in `from`), NaN where the cell has no label, where the point leaves the window (range, fan or
    // the depth pass's vertical coverage) or where `to`'s depth image has something nearer in front of it
    // (occluded; with the footprint kernel, only where the point also lies beyond the far end of those
    // pixels' range footprints, from `to`'s echo).
    // `to` needs its depth and echo (labels keep both). flow: bins * beams * 2. The cells are split in
    // blocks between the threads; the flow does not depend on them (stages/labels_flow.cpp).
    void flow(const Frame& from, const Pose& from_pose, const Frame& to, const Pose& to_pose, float* flow) const;

    struct Scratch; // per thread: one beam's bins
    struct Pixels;  // per pixel: what the beams read of it
    struct Alone;   // each labelled object drawn alone (Frame::visibility)

private:
    void visibility(Frame& frame, const Pose& pose, const SubpixelReturns* subpixel);

    const Plan& plan_; // the Renderer's, which owns this stage
    std::vector<std::uint16_t> class_of_instance_;
    host::Workers* workers_;
    std::vector<std::unique_ptr<Scratch>> scratch_; // one per worker thread
    std::unique_ptr<Pixels> pixels_;
    std::unique_ptr<Alone> alone_; // null without a scene
    bool part_timing_ = false;
    BeamBuckets beam_buckets_; // flow()
};

} // namespace vksonar::cpu
