// Stage 4c, far side lobes (docs/pipeline.md, "Side lobes"): the horizontal pattern beyond the
// side-lobe kernel's reach, on a coarse grid of cells uniform in the beams' separation variable
// (Plan::far_cells). Two passes of this shader run before sidelobe.comp, which adds each beam's
// share of its two cells:
//   kFarPass 0 (deposit):  far_energy[m][c] = sum over the profile columns [first, end) of cell c, in
//                          increasing order, of far_deposit_weight(column i, c, m) * profile(i), each
//                          column at its own direction (Plan::far_column_cell);
//   kFarPass 1 (convolve): far_cells[m][a] = sum over b in increasing order of weight(a - b) * far_energy[m][b],
// for each channel m < far_channels (sonar_kernels.h, Plan::far_channels); kFarPass 2 the same sums, a
// workgroup row per output cell (stage_table far_cell_groups: a GPU, where one row per channel left
// a few hundred lanes busy, each summing cells^2 terms: 0.10 ms on an H100; and any device past 176
// cells, where kFarPass 1 would loop more often than lavapipe lets an invocation loop).
// An invocation owns four consecutive range bins (one vec4 of the bin-fastest profiles that
// profile.comp writes); a deposit workgroup one (channel, cell) (y = m * cells + c), a convolve
// workgroup one channel (y = m). Every table load is the same for the whole workgroup: one scalar
// load from the uniform view on lavapipe (src/vk/pipelines.h says why).
// The CPU backend (src/stages/cpu_beamform.cpp) makes the same sums in the same order.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = kSpecFarPass) const uint kFarPass = 0u;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingProfiles) readonly buffer ProfileBuffer { vec4 profiles4[]; };
// Plan::far_beam_cell (8 per beam), Plan::far_column_cell (8 per profile column), then
// Plan::far_cell_columns as floats (2 per cell, exact below 2^24), then Plan::far_weight (2 cells - 1);
// and the same as a uniform block where it fits.
layout(std430, binding = kBindingFarTable) readonly buffer FarTableBuffer { float far_table[]; };
layout(constant_id = kSpecUniformTables) const uint kUniformTables = 0u;
layout(constant_id = kSpecTableVec4s0) const uint kFarTableVec4s = 1u;
layout(std140, binding = kBindingFarTableUniform) uniform FarTableBlock { vec4 far_table4[kFarTableVec4s]; };
layout(std430, binding = kBindingFarEnergy) buffer FarEnergyBuffer { vec4 far_energy4[]; };
layout(std430, binding = kBindingFarCells) writeonly buffer FarCellsBuffer { vec4 far_cells4[]; };

float table(uint i) {
    return kUniformTables != 0u ? far_table4[i >> 2u][i & 3u] : far_table[i];
}

void main() {
    uint quads = params.bins_padded / 4u;
    uint q = gl_GlobalInvocationID.x;
    uint cells = params.far_cells;
    uint m = kFarPass != 1u ? gl_WorkGroupID.y / cells : gl_WorkGroupID.y;
    uint c = kFarPass != 1u ? gl_WorkGroupID.y - m * cells : 0u;
    if (q >= quads || m >= params.far_channels) {
        return;
    }
    uint column_cells = 8u * params.beams;
    uint spans = column_cells + 8u * params.profile_columns;
    uint channel_base = m * cells;
    precise vec4 sum = vec4(0.0); // no fused multiply-add: the CPU rounds each product
    if (kFarPass == 0u) {
        uint end = uint(table(spans + 2u * c + 1u));
        for (uint column = uint(table(spans + 2u * c)); column < end; ++column) {
            uint i = column_cells + 8u * column;
            vec4 cell = vec4(table(i), table(i + 1u), table(i + 2u), table(i + 3u));
            vec4 phase = vec4(table(i + 4u), table(i + 5u), table(i + 6u), table(i + 7u));
            // a column that feeds no beam has no cell here: its weight is 0 and adds exactly +0
            sum += far_deposit_weight(cell, phase, c, m) * profiles4[column * quads + q];
        }
        far_energy4[(channel_base + c) * quads + q] = sum;
        return;
    }
    uint weights = spans + 2u * cells;
    if (kFarPass == 2u) {
        // Convolve, a GPU's way: a workgroup row per output cell a = c (y = m * cells + c), the same sum
        // in the same order as below, each energy loaded from memory (coalesced over the lanes' quads).
        precise vec4 level = vec4(0.0); // no fused multiply-add: the CPU rounds each product
        for (uint b = 0u; b < cells; ++b) {
            level += table(weights + cells - 1u + c - b) * far_energy4[(channel_base + b) * quads + q];
        }
        far_cells4[(channel_base + c) * quads + q] = level;
        return;
    }
    // Convolve: a workgroup per channel (y = m, c unused), each lane every cell of its quad, its
    // energies loaded once into registers (lavapipe runs each storage load as a loop over the lanes;
    // cells^2 of them per quad made this pass the far side lobes' main cost there).
    vec4 energy[kMaxFarCells];
    for (uint b = 0u; b < cells; ++b) {
        energy[b] = far_energy4[(channel_base + b) * quads + q];
    }
    for (uint a = 0u; a < cells; ++a) {
        precise vec4 level = vec4(0.0);
        for (uint b = 0u; b < cells; ++b) {
            level += table(weights + cells - 1u + a - b) * energy[b];
        }
        far_cells4[(channel_base + a) * quads + q] = level;
    }
}
