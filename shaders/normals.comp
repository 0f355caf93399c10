// Stage 2, normals (docs/pipeline.md §2): Sobel 3x3 on reconstructed sonar-frame positions, with
// one-sided differences near depth edges and a facing-the-sonar fallback. Output
// normals4[p] = (n.x, n.y, n.z, cos incidence). Each invocation slides a 3x3 window along a run of
// kRun pixels of one row, so every position is reconstructed once per run instead of 9 times.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "sonar_shared.h"
#define REAL float
#define VKS_ATAN2 atan
#include "sonar_math.h"

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 1) const uint kRun = 8u; // pixels per invocation, set by the host

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 1) readonly buffer DepthBuffer { float depth[]; };
layout(std430, binding = 3) writeonly buffer NormalsBuffer { vec4 normals4[]; };
layout(std430, binding = 8) readonly buffer SliceBuffer { SliceInfo slice_info[]; };

// Sonar-frame position, slant range and validity of a pixel; invalid outside the image or without a hit.
struct Sample {
    vec3 pos;
    float range;
    bool valid;
};

// A window column: rows j-1, j, j+1 of one pixel column.
struct Column {
    Sample up;
    Sample mid;
    Sample down;
};

Sample load(int column, int row) {
    Sample s;
    s.pos = vec3(0.0);
    s.range = 0.0;
    s.valid = false;
    if (column < 0 || row < 0 || column >= int(params.columns) || row >= int(params.rows)) {
        return s;
    }
    uint c = uint(column);
    uint j = uint(row);
    float d = depth[j * params.columns + c];
    if (!(d > 0.0)) {
        return s;
    }
    uint slice = c / params.slice_columns;
    float u = pixel_coord(c - slice * params.slice_columns, params.slice_columns, params.tan_half_h);
    float v = pixel_coord(j, params.rows, params.tan_half_v);
    float z = view_z_from_depth(d, params.depth_a, params.depth_b);
    float cs = slice_info[slice].cos_center;
    float sn = slice_info[slice].sin_center;
    // P = z (f_s + u r_s + v d), f_s = (cos, sin, 0), r_s = (sin, -cos, 0), d = (0, 0, -1)
    s.pos = z * vec3(cs + u * sn, sn - u * cs, -v);
    s.range = length(s.pos);
    s.valid = true;
    return s;
}

Column load_column(int column, int row) {
    Column col;
    col.up = load(column, row - 1);
    col.mid = load(column, row);
    col.down = load(column, row + 1);
    return col;
}

bool same_surface(Sample q, float range_p, float jump) {
    return q.valid && abs(q.range - range_p) <= jump;
}

vec4 facing(Sample p) {
    return vec4(-p.pos / p.range, 1.0);
}

// One-sided difference along an axis towards the valid neighbour whose range is closer (ties: +1 side).
// Returns false when neither neighbour is valid.
bool one_sided(Sample minus, Sample centre, Sample plus, out vec3 t) {
    if (plus.valid && (!minus.valid || abs(plus.range - centre.range) <= abs(minus.range - centre.range))) {
        t = plus.pos - centre.pos;
        return true;
    }
    if (minus.valid) {
        t = centre.pos - minus.pos;
        return true;
    }
    t = vec3(0.0);
    return false;
}

vec4 normal_at(Column l, Column c, Column r) {
    Sample p = c.mid;
    float jump = params.edge_relative_jump * p.range;
    bool smooth_region = same_surface(l.up, p.range, jump) && same_surface(l.mid, p.range, jump) &&
                         same_surface(l.down, p.range, jump) && same_surface(c.up, p.range, jump) &&
                         same_surface(c.down, p.range, jump) && same_surface(r.up, p.range, jump) &&
                         same_surface(r.mid, p.range, jump) && same_surface(r.down, p.range, jump);
    vec3 tx;
    vec3 ty;
    if (smooth_region) {
        tx = (r.up.pos - l.up.pos) + 2.0 * (r.mid.pos - l.mid.pos) + (r.down.pos - l.down.pos);
        ty = (l.down.pos - l.up.pos) + 2.0 * (c.down.pos - c.up.pos) + (r.down.pos - r.up.pos);
    } else {
        if (!one_sided(l.mid, p, r.mid, tx) || !one_sided(c.up, p, c.down, ty)) {
            return facing(p);
        }
    }
    vec3 n = cross(tx, ty);
    float len = length(n);
    if (!(len > 0.0)) {
        return facing(p);
    }
    n = n / len;
    if (dot(n, p.pos) > 0.0) {
        n = -n;
    }
    return vec4(n, clamp(-dot(n, p.pos) / p.range, 0.0, 1.0));
}

void main() {
    uint runs_per_row = (params.columns + kRun - 1u) / kRun;
    uint row = gl_GlobalInvocationID.x / runs_per_row;
    if (row >= params.rows) {
        return;
    }
    uint first = (gl_GlobalInvocationID.x - row * runs_per_row) * kRun;
    uint last = min(first + kRun, params.columns);
    Column l = load_column(int(first) - 1, int(row));
    Column c = load_column(int(first), int(row));
    for (uint column = first; column < last; ++column) {
        Column r = load_column(int(column) + 1, int(row));
        normals4[row * params.columns + column] = c.mid.valid ? normal_at(l, c, r) : vec4(0.0);
        l = c;
        c = r;
    }
}
