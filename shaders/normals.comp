// Stage 2, normals (docs/pipeline.md §2). geometric: the depth pass's face normals, mapped to the
// sonar frame and oriented. Otherwise Sobel 3x3 (or 5x5 with normal_method = sobel5, where the
// whole 5x5 window is one surface) on reconstructed sonar-frame positions, with one-sided
// differences near depth edges and a facing-the-sonar fallback. Output
// normals4[p] = (n.x, n.y, n.z, cos incidence). Each invocation slides a 3x3 (5x5) window along a
// run of kRun pixels of one row, so every position is reconstructed once per run instead of 9 (25)
// times. The method is a specialization constant: each pipeline holds only its own loop.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"
#include "sonar_kernels.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = kSpecPerInvocation) const uint kRun = 8u; // pixels per invocation, set by the host
// params.normal_method, set by the host as a specialization constant rather than read from the
// uniform: a uniform branch left the sobel5 code in the sobel3 pipeline and made it 1.6x slower on
// llvmpipe (masked execution); a constant compiles the unused path out.
layout(constant_id = kSpecNormalMethod) const uint kNormalMethod = kNormalsSobel3;

layout(std140, binding = kBindingParams) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = kBindingDepth) readonly buffer DepthBuffer { float depth[]; };
// Written by every method; read too by geometric, where the depth pass copied its face normals here.
layout(std430, binding = kBindingNormals) buffer NormalsBuffer { vec4 normals4[]; };
// A uniform block: every lane of a row run reads the same slice (one scalar load on lavapipe).
layout(std140, binding = kBindingSliceInfo) uniform SliceBlock { SliceInfo slice_info[kMaxViews]; };

// The view of pixel column c's slice or tier view: a slice from two table reads (level_slice_view),
// a tier view whole (lavapipe runs every uniform read at a lane-varying index as a gather).
// With no tier views (a constant: lavapipe would run both sides of a branch) only the slices' code.
layout(constant_id = kSpecTierViews) const uint kTierViews = 0u;

PixelView pixel_view(uint view) {
    if (kTierViews == 0u || view < params.slices) {
        return level_slice_view(slice_info[view].forward_x, slice_info[view].forward_y, params.tan_half_h,
                                params.tan_half_v, params.elevation_gate_sin);
    }
    return view_of_slice(slice_info[view]);
}

uint view_of_column(uint c) { // no integer divide per pixel
    if (kTierViews == 0u) {
        return slice_of_column(c, 1.0 / float(params.slice_columns));
    }
    return view_of_pixel_column(c, params.slices, params.slice_columns, 1.0 / float(params.slice_columns),
                                1.0 / float(max(params.tier_columns, 1u)));
}

// Whether the pixel columns a and b (a neighbour, in the image) see one surface side by side: the same
// view, or two slices of the main band (their seams join). A tier view's edges are the image's edges.
bool joined(int a, int b) {
    if (kTierViews == 0u) {
        return true; // the slices all join
    }
    if (a < 0 || b < 0 || a >= int(params.columns) || b >= int(params.columns)) {
        return true; // load() gives no sample outside the image anyway
    }
    uint va = view_of_column(uint(a));
    uint vb = view_of_column(uint(b));
    return va == vb || (va < params.slices && vb < params.slices);
}

// The pixel's Sample (sonar_kernels.h): invalid outside the image or without a hit.
Sample load(int column, int row) {
    if (column < 0 || row < 0 || column >= int(params.columns) || row >= int(params.rows)) {
        return no_sample();
    }
    uint c = uint(column);
    uint j = uint(row);
    float d = depth[j * params.columns + c];
    if (!(d > 0.0)) {
        return no_sample();
    }
    uint index = view_of_column(c);
    PixelView view = pixel_view(index);
    float u = pixel_coord(c - first_column_of_view(index, params.slices, params.slice_columns, params.tier_columns),
                          columns_of_view(index, params.slices, params.slice_columns, params.tier_columns),
                          view.tan_half_h);
    float v = pixel_coord(j, params.rows, view.tan_half_v);
    float z = view_z_from_depth(d, params.depth_a, params.depth_b);
    return sample_at(z, pixel_ray(u, v, view));
}

Column3 load_column(int column, int row) {
    Column3 col;
    col.up = load(column, row - 1);
    col.mid = load(column, row);
    col.down = load(column, row + 1);
    return col;
}

Column3 no_column3() {
    Column3 col;
    col.up = no_sample();
    col.mid = no_sample();
    col.down = no_sample();
    return col;
}

// The window column `col` of pixel column `column` as the centre pixel `centre` sees it: nothing across
// a seam that does not join (joined).
Column3 seen3(Column3 col, int column, uint centre) {
    return joined(column, int(centre)) ? col : no_column3();
}

Column5 load_column5(int column, int row) {
    Column5 col;
    col.up2 = load(column, row - 2);
    col.up = load(column, row - 1);
    col.mid = load(column, row);
    col.down = load(column, row + 1);
    col.down2 = load(column, row + 2);
    return col;
}

Column5 seen5(Column5 col, int column, uint centre) {
    if (joined(column, int(centre))) {
        return col;
    }
    Column5 none;
    none.up2 = no_sample();
    none.up = no_sample();
    none.mid = no_sample();
    none.down = no_sample();
    none.down2 = no_sample();
    return none;
}

void run_sobel5(uint row, uint first, uint last) {
    Column5 l2 = load_column5(int(first) - 2, int(row));
    Column5 l1 = load_column5(int(first) - 1, int(row));
    Column5 c = load_column5(int(first), int(row));
    Column5 r1 = load_column5(int(first) + 1, int(row));
    for (uint column = first; column < last; ++column) {
        Column5 r2 = load_column5(int(column) + 2, int(row));
        int x = int(column);
        normals4[row * params.columns + column] =
            c.mid.valid ? sobel5_normal(seen5(l2, x - 2, column), seen5(l1, x - 1, column), c, seen5(r1, x + 1, column),
                                        seen5(r2, x + 2, column), params.edge_relative_jump)
                        : vec4(0.0);
        l2 = l1;
        l1 = c;
        c = r1;
        r1 = r2;
    }
}

void run_sobel3(uint row, uint first, uint last) {
    Column3 l = load_column(int(first) - 1, int(row));
    Column3 c = load_column(int(first), int(row));
    for (uint column = first; column < last; ++column) {
        Column3 r = load_column(int(column) + 1, int(row));
        int x = int(column);
        normals4[row * params.columns + column] =
            c.mid.valid ? sobel3_normal(seen3(l, x - 1, column), c, seen3(r, x + 1, column), params.edge_relative_jump)
                        : vec4(0.0);
        l = c;
        c = r;
    }
}

// geometric: normals4 holds the depth pass's face normal q (clip-linear coordinates, sonar_math.h);
// map it to the sonar frame of the pixel's slice and orient it in place.
void run_geometric(uint row, uint first, uint last) {
    for (uint column = first; column < last; ++column) {
        uint i = row * params.columns + column;
        Sample p = load(int(column), int(row));
        if (!p.valid) {
            normals4[i] = vec4(0.0);
            continue;
        }
        normals4[i] = geometric_normal(p, normals4[i].xyz, pixel_view(view_of_column(column)));
    }
}

void main() {
    uint runs_per_row = (params.columns + kRun - 1u) / kRun;
    uint row = gl_GlobalInvocationID.x / runs_per_row;
    if (row >= params.rows) {
        return;
    }
    uint first = (gl_GlobalInvocationID.x - row * runs_per_row) * kRun;
    uint last = min(first + kRun, params.columns);
    if (kNormalMethod == kNormalsGeometric) {
        run_geometric(row, first, last);
    } else if (kNormalMethod == kNormalsSobel5) {
        run_sobel5(row, first, last);
    } else {
        run_sobel3(row, first, last);
    }
}
