// The labels stage's flow (LabelsStage::flow, docs/labels.md): where each labelled cell's point lands in
// the polar grid of another pose, and whether that frame's depth image sees it there.
#pragma once

#include <array>
#include <cstddef>

#include "core/plan.h"
#include "stages/labels.h"
#include "vksonar/frame.h"

namespace vksonar::cpu {

// LabelsStage::flow's work: the two frames, their poses as sonar_from_world, and the tables it reads.
struct FlowJob {
    const Plan* plan;
    const Frame* from;
    const Frame* to;
    std::array<double, 16> a, b; // sonar_from_world of the two poses
    bool same_pose;              // a == b: each point maps onto itself, exactly
    float* flow;
    const double* slant_factor; // LabelsStage::Pixels::slant_factor
    const BeamBuckets* buckets;
};

// The flow of cells [begin, end): each cell a function of the two frames alone, so any split gives the
// same flow (and so do the AVX2 path and the plain one).
void flow_cells(const FlowJob& job, std::size_t begin, std::size_t end);

// Cells in a block of the flow's work.
constexpr std::size_t kFlowBlock = 4096;

} // namespace vksonar::cpu
