// Stage 4c, far side lobes (docs/pipeline.md, "Side lobes"): the horizontal pattern beyond the
// side-lobe kernel's reach, on a coarse grid of cells uniform in the beams' separation variable
// (Plan::far_cells). Runs before sidelobe.comp, which adds each beam's share of its two cells.
//
// A workgroup owns four consecutive range bins (one vec4 of the beam-major B[j * bins_padded + k]
// that resample.comp writes). Its lanes first put each beam's energy into its two cells (cell c sums
// the beams [first, end) of its span in increasing order, each times far_cell_share), then convolve
// the cells: far_cells[a] = sum over b in increasing order of weight(a - b) * cell_energy[b].
// The CPU backend (src/stages/cpu_beamform.cpp) makes the same sums in the same order.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingBeamProfiles) readonly buffer BeamProfileBuffer { vec4 beam_profiles4[]; };
// Plan::far_beam_cell (4 per beam), then Plan::far_cell_beams as floats (2 per cell, exact below
// 2^24), then Plan::far_weight (2 cells - 1).
layout(std430, binding = kBindingFarTable) readonly buffer FarTableBuffer { float far_table[]; };
layout(std430, binding = kBindingFarCells) writeonly buffer FarCellsBuffer { vec4 far_cells4[]; };

shared vec4 cell_energy[kMaxFarCells];

vec4 beam_cell(uint j) {
    uint i = 4u * j;
    return vec4(far_table[i], far_table[i + 1u], far_table[i + 2u], far_table[i + 3u]);
}

void main() {
    uint quads = params.bins_padded / 4u;
    uint q = gl_WorkGroupID.x;
    uint cells = params.far_cells;
    uint lane = gl_LocalInvocationID.x;
    uint spans = 4u * params.beams;
    uint weights = spans + 2u * cells;
    for (uint c = lane; c < cells; c += kWorkgroupSize) {
        vec4 sum = vec4(0.0);
        uint end = uint(far_table[spans + 2u * c + 1u]);
        for (uint j = uint(far_table[spans + 2u * c]); j < end; ++j) {
            sum += far_cell_share(beam_cell(j), c) * beam_profiles4[j * quads + q];
        }
        cell_energy[c] = sum;
    }
    barrier();
    for (uint a = lane; a < cells; a += kWorkgroupSize) {
        vec4 sum = vec4(0.0);
        for (uint b = 0u; b < cells; ++b) {
            sum += far_table[weights + cells - 1u + a - b] * cell_energy[b];
        }
        far_cells4[a * quads + q] = sum;
    }
}
