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

layout(local_size_x = kWorkgroupSize) in;
layout(constant_id = 1) const uint kRun = 8u; // pixels per invocation, set by the host
// params.normal_method, set by the host as a specialization constant rather than read from the
// uniform: a uniform branch left the sobel5 code in the sobel3 pipeline and made it 1.6x slower on
// llvmpipe (masked execution); a constant compiles the unused path out.
layout(constant_id = 2) const uint kNormalMethod = kNormalsSobel3;

layout(std140, binding = 0) uniform ParamsBlock { SonarParams params; };
layout(std430, binding = 1) readonly buffer DepthBuffer { float depth[]; };
// Written by every method; read too by geometric, where the depth pass copied its face normals here.
layout(std430, binding = 3) buffer NormalsBuffer { vec4 normals4[]; };
// A uniform block: every lane of a row run reads the same slice (one scalar load on lavapipe).
layout(std140, binding = 8) uniform SliceBlock { SliceInfo slice_info[kMaxSlices]; };

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
    uint slice = slice_of_column(c, 1.0 / float(params.slice_columns)); // no integer divide per pixel
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

// n normalized, turned to face the sonar; degenerate -> facing fallback.
vec4 orient(Sample p, vec3 n) {
    float len = length(n);
    if (!(len > 0.0)) {
        return facing(p);
    }
    n = n / len;
    if (dot(n, p.pos) > 0.0) {
        n = -n;
    }
    return vec4(n, incidence_cos(dot(n, p.pos), p.range));
}

// n from the two tangents.
vec4 finish(Sample p, vec3 tx, vec3 ty) {
    return orient(p, cross(tx, ty));
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
    return finish(p, tx, ty);
}

// sobel5: a window column of rows j-2 .. j+2.
struct Column5 {
    Sample up2;
    Sample up;
    Sample mid;
    Sample down;
    Sample down2;
};

Column5 load_column5(int column, int row) {
    Column5 col;
    col.up2 = load(column, row - 2);
    col.up = load(column, row - 1);
    col.mid = load(column, row);
    col.down = load(column, row + 1);
    col.down2 = load(column, row + 2);
    return col;
}

Column inner(Column5 k) {
    Column col;
    col.up = k.up;
    col.mid = k.mid;
    col.down = k.down;
    return col;
}

bool column_same_surface(Column5 k, float range_p, float jump) {
    return same_surface(k.up2, range_p, jump) && same_surface(k.up, range_p, jump) &&
           same_surface(k.mid, range_p, jump) && same_surface(k.down, range_p, jump) &&
           same_surface(k.down2, range_p, jump);
}

// Derivative (-1 -2 0 2 1) as differences of symmetric pairs, as cpu_normals.cpp: the large positions
// cancel before the weights multiply.
vec3 derivative5(Sample m2, Sample m1, Sample p1, Sample p2) {
    return 2.0 * (p1.pos - m1.pos) + (p2.pos - m2.pos);
}

// Sobel 5x5 where all 24 neighbours are on the pixel's surface, else exactly the sobel3 path.
// Sums with smoothing (1 4 6 4 1) from the -2 side, the order docs/pipeline.md §2 fixes.
vec4 normal5_at(Column5 l2, Column5 l1, Column5 c, Column5 r1, Column5 r2) {
    Sample p = c.mid;
    float jump = params.edge_relative_jump * p.range;
    bool smooth5 = column_same_surface(l2, p.range, jump) && column_same_surface(l1, p.range, jump) &&
                   same_surface(c.up2, p.range, jump) && same_surface(c.up, p.range, jump) &&
                   same_surface(c.down, p.range, jump) && same_surface(c.down2, p.range, jump) &&
                   column_same_surface(r1, p.range, jump) && column_same_surface(r2, p.range, jump);
    if (!smooth5) {
        return normal_at(inner(l1), inner(c), inner(r1));
    }
    vec3 tx = derivative5(l2.up2, l1.up2, r1.up2, r2.up2);
    tx = tx + 4.0 * derivative5(l2.up, l1.up, r1.up, r2.up);
    tx = tx + 6.0 * derivative5(l2.mid, l1.mid, r1.mid, r2.mid);
    tx = tx + 4.0 * derivative5(l2.down, l1.down, r1.down, r2.down);
    tx = tx + derivative5(l2.down2, l1.down2, r1.down2, r2.down2);
    vec3 ty = derivative5(l2.up2, l2.up, l2.down, l2.down2);
    ty = ty + 4.0 * derivative5(l1.up2, l1.up, l1.down, l1.down2);
    ty = ty + 6.0 * derivative5(c.up2, c.up, c.down, c.down2);
    ty = ty + 4.0 * derivative5(r1.up2, r1.up, r1.down, r1.down2);
    ty = ty + derivative5(r2.up2, r2.up, r2.down, r2.down2);
    return finish(p, tx, ty);
}

void run_sobel5(uint row, uint first, uint last) {
    Column5 l2 = load_column5(int(first) - 2, int(row));
    Column5 l1 = load_column5(int(first) - 1, int(row));
    Column5 c = load_column5(int(first), int(row));
    Column5 r1 = load_column5(int(first) + 1, int(row));
    for (uint column = first; column < last; ++column) {
        Column5 r2 = load_column5(int(column) + 2, int(row));
        normals4[row * params.columns + column] = c.mid.valid ? normal5_at(l2, l1, c, r1, r2) : vec4(0.0);
        l2 = l1;
        l1 = c;
        c = r1;
        r1 = r2;
    }
}

void run_sobel3(uint row, uint first, uint last) {
    Column l = load_column(int(first) - 1, int(row));
    Column c = load_column(int(first), int(row));
    for (uint column = first; column < last; ++column) {
        Column r = load_column(int(column) + 1, int(row));
        normals4[row * params.columns + column] = c.mid.valid ? normal_at(l, c, r) : vec4(0.0);
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
        vec3 q = normals4[i].xyz;
        uint slice = column / params.slice_columns;
        float cs = slice_info[slice].cos_center;
        float sn = slice_info[slice].sin_center;
        vec3 n = vec3(face_normal_sonar_x(q.x, q.z, params.tan_half_h, cs, sn),
                      face_normal_sonar_y(q.x, q.z, params.tan_half_h, cs, sn),
                      face_normal_sonar_z(q.y, params.tan_half_v));
        normals4[i] = orient(p, n);
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
