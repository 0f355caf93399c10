// Stage 3, echo (docs/pipeline.md §3): per pixel, slant range and the combined sonar equation.
// Each invocation handles a run of kPixelsPerInvocation consecutive pixels of one row. Output echo2[p] = (energy relative to SL, slant range m).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = kSpecEffectFlags) const uint kEffectFlags = 0u;
layout(constant_id = kSpecPerInvocation) const uint kPixelsPerInvocation = 4u; // set by the host
const bool kIncidence = (kEffectFlags & kEffectIncidence) != 0u;
const bool kVerticalPattern = (kEffectFlags & kEffectVerticalPattern) != 0u;
const bool kSpreading = (kEffectFlags & kEffectSpreading) != 0u;
const bool kAbsorption = (kEffectFlags & kEffectAbsorption) != 0u;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingDepth) readonly buffer DepthBuffer { float depth[]; };
layout(std430, binding = kBindingMaterialId) readonly buffer MaterialIdBuffer { uint material_id[]; };
layout(std430, binding = kBindingNormals) readonly buffer NormalsBuffer { vec4 normals4[]; };
layout(std430, binding = kBindingEcho) writeonly buffer EchoBuffer { vec2 echo2[]; };
// The same buffer with accuracy.intermediates = fp16: (energy * echo_scale, range) as two halves.
layout(std430, binding = kBindingEcho) writeonly buffer EchoHalfBuffer { uint echo_half2[]; };

layout(constant_id = kSpecTierViews) const uint kTierViews = 0u; // Plan::views > slices, as a constant
layout(constant_id = kSpecEchoHalf) const uint kEchoHalf = 0u; // params.echo_half, as a constant (src/vk/pipelines.h)

void store_echo(uint p, vec2 energy_range) {
    if (kEchoHalf != 0u) {
        echo_half2[p] = packHalf2x16(vec2(energy_range.x * params.echo_scale, energy_range.y));
    } else {
        echo2[p] = energy_range;
    }
}
layout(std430, binding = kBindingMaterials) readonly buffer MaterialBuffer { MaterialGpu materials[]; };
// The same table as a uniform block where it fits one (src/vk/pipelines.h): a divergent uniform load
// is a vector gather on lavapipe, a storage load a loop over the lanes.
layout(constant_id = kSpecUniformTables) const uint kUniformTables = 0u;
layout(constant_id = kSpecTableVec4s0) const uint kMaterialCount = 1u; // entries of the uniform block
layout(std140, binding = kBindingMaterialsUniform) uniform MaterialBlock { MaterialGpu materials_u[kMaterialCount]; };

uint material_count() {
    return kUniformTables != 0u ? kMaterialCount : uint(materials.length());
}
// Set by the host: 1 when a material of the scene has the rough model; only then does the pipeline
// carry the facet term's exponential and the two extra table reads.
layout(constant_id = kSpecRoughMaterials) const uint kRoughMaterials = 0u;
// params.vpattern_shape, so that the pattern code keeps only that shape's branch (a uniform branch
// runs every shape's code on lavapipe: the chebyshev branch made echo ~10 % slower for a sinc pattern).
layout(constant_id = kSpecVerticalShape) const uint kVerticalShape = kPatternSinc;

// The table entry, member by member: a struct copied whole between the std140 and std430 blocks is
// an OpStore of mismatched types before SPIR-V 1.4.
MaterialGpu material(uint m) {
    MaterialGpu g;
    if (kUniformTables != 0u) {
        g.backscatter_linear = materials_u[m].backscatter_linear;
        g.model = materials_u[m].model;
        g.specular_ratio = kRoughMaterials != 0u ? materials_u[m].specular_ratio : 0.0;
        g.inv_two_slope_sq = kRoughMaterials != 0u ? materials_u[m].inv_two_slope_sq : 0.0;
    } else {
        g.backscatter_linear = materials[m].backscatter_linear;
        g.model = materials[m].model;
        g.specular_ratio = kRoughMaterials != 0u ? materials[m].specular_ratio : 0.0;
        g.inv_two_slope_sq = kRoughMaterials != 0u ? materials[m].inv_two_slope_sq : 0.0;
    }
    return g;
}

// The views of the depth pass (sonar_shared.h): each pixel's half extents, ray and cell.
layout(std140, binding = kBindingSliceInfo) uniform SliceBlock { SliceInfo slice_info[kMaxViews]; };

// The echo constants of a view `width` columns wide: its half extents and pixel size.
EchoConstants echo_constants(PixelView view, uint width) {
    EchoConstants k;
    k.tan_half_h = view.tan_half_h;
    k.tan_half_v = view.tan_half_v;
    k.pixel_du = 2.0 * view.tan_half_h / float(width);
    k.pixel_dv = 2.0 * view.tan_half_v / float(params.rows);
    k.depth_a = params.depth_a;
    k.depth_b = params.depth_b;
    k.gate_min_m = params.gate_min_m;
    k.gate_max_m = params.gate_max_m;
    k.alpha_db_per_m = params.alpha_db_per_m;
    k.vpattern_k = params.vpattern_k;
    k.vpattern_halfwidth_rad = params.vpattern_halfwidth_rad;
    k.vpattern_chebyshev_a = params.vpattern_chebyshev_a;
    k.element_k = params.element_k;
    return k;
}

EchoTerms echo_terms() {
    EchoTerms t;
    t.incidence = kIncidence;
    t.rough_materials = kRoughMaterials != 0u;
    t.vertical_pattern = kVerticalPattern;
    t.vertical_shape = kVerticalShape;
    t.spreading = kSpreading;
    t.absorption = kAbsorption;
    return t;
}

// (energy relative to SL, slant range) of a pixel (sonar_kernels.h), (0, 0) without a hit. One store
// at the end, not one per way out: lavapipe runs every branch under a lane mask, and each store is a
// loop over the lanes.
vec2 echo_pixel(uint row, uint column) {
    uint p = row * params.columns + column;
    float d = depth[p];
    if (!(d > 0.0)) {
        return vec2(0.0);
    }
    // no integer divide per pixel
    uint slice = kTierViews == 0u ? slice_of_column(column, 1.0 / float(params.slice_columns))
                                  : view_of_pixel_column(column, params.slices, params.slice_columns,
                                                         1.0 / float(params.slice_columns),
                                                         1.0 / float(max(params.tier_columns, 1u)));
    // a slice from two table reads (level_slice_view), a tier view whole
    PixelView view = kTierViews == 0u || slice < params.slices
                         ? level_slice_view(slice_info[slice].forward_x, slice_info[slice].forward_y, params.tan_half_h,
                                            params.tan_half_v, params.elevation_gate_sin)
                         : view_of_slice(slice_info[slice]);
    uint width = columns_of_view(slice, params.slices, params.slice_columns, params.tier_columns);
    uint first = first_column_of_view(slice, params.slices, params.slice_columns, params.tier_columns);
    float u = pixel_coord(column - first, width, view.tan_half_h);
    float v = pixel_coord(row, params.rows, view.tan_half_v);
    MaterialGpu mat = material(material_index(material_id[p], material_count()));
    float cos_incidence = kIncidence ? normals4[p].w : 0.0;
    return echo_of_pixel(echo_constants(view, width), echo_terms(), d, u, v, view, mat, cos_incidence);
}

// x: runs of kPixelsPerInvocation columns of one row, y: the row (a 2-D grid: no divide by columns).
void main() {
    uint row = gl_GlobalInvocationID.y;
    uint first = gl_GlobalInvocationID.x * kPixelsPerInvocation;
    uint last = min(first + kPixelsPerInvocation, params.columns);
    for (uint column = first; column < last; ++column) {
        store_echo(row * params.columns + column, echo_pixel(row, column));
    }
}
