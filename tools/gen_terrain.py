#!/usr/bin/env python3
"""Writes a bathymetry heightfield as one .glb, for benchmarks of big scenes (docs/benchmarks.md).

    python3 tools/gen_terrain.py N SIZE_M OUT.glb [--seed S] [--relief M]

N x N quads (2 N^2 triangles, (N + 1)^2 vertices) over a SIZE_M square centred on the world origin,
at world z = 0 give or take the relief: a sum of a few seeded sine ridges of RELIEF_M metres (default
0.5), deterministic for a seed. Rows of quads are written in order, as terrain exporters write them,
so consecutive triangles form long thin strips across the whole terrain. One Lambert material of
-30 dB (sand). glTF's frame is +Y up: world (x fwd, y left, z up) = (x_gltf, -z_gltf, y_gltf).
Pure Python (no numpy); 1000 x 1000 takes a few seconds.
"""
import argparse
import json
import math
import random
import struct


def heights(n, size, relief, seed):
    rng = random.Random(seed)
    ridges = [(rng.uniform(0.02, 0.2), rng.uniform(0, 2 * math.pi), rng.uniform(0, 2 * math.pi)) for _ in range(4)]
    step = size / n
    for j in range(n + 1):
        y = -size / 2 + j * step
        for i in range(n + 1):
            x = -size / 2 + i * step
            z = 0.0
            for k, (f, a, p) in enumerate(ridges):
                z += relief / len(ridges) * math.sin(f * (x * math.cos(a) + y * math.sin(a)) + p)
            yield x, y, z


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n", type=int)
    ap.add_argument("size_m", type=float)
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--relief", type=float, default=0.5)
    a = ap.parse_args()
    n = a.n
    if n < 1 or n > 4000:
        raise SystemExit("gen_terrain: N = %d: must be 1 .. 4000" % n)
    positions = bytearray()
    lo = [math.inf] * 3
    hi = [-math.inf] * 3
    for x, y, z in heights(n, a.size_m, a.relief, a.seed):
        g = (x, z, -y)  # world -> glTF
        positions += struct.pack("<3f", *g)
        for k in range(3):
            v = struct.unpack("<f", struct.pack("<f", g[k]))[0]
            lo[k] = min(lo[k], v)
            hi[k] = max(hi[k], v)
    indices = bytearray()
    row = n + 1
    for j in range(n):
        for i in range(n):
            v0 = j * row + i
            # counter-clockwise seen from above (+Y in glTF)
            indices += struct.pack("<6I", v0, v0 + row, v0 + 1, v0 + 1, v0 + row, v0 + row + 1)
    binary = bytes(positions) + bytes(indices)
    vertex_count = row * row
    gltf = {
        "asset": {"version": "2.0", "generator": "vksonar tools/gen_terrain.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "terrain"}],
        "meshes": [{"name": "terrain", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"name": "sand", "extras": {"vksonar": {"backscatter_db": -30, "model": "lambert"}}}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(positions), "target": 34962},
            {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices), "target": 34963},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": vertex_count, "type": "VEC3", "min": lo, "max": hi},
            {"bufferView": 1, "componentType": 5125, "count": 6 * n * n, "type": "SCALAR"},
        ],
    }
    text = json.dumps(gltf, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    with open(a.out, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    print("gen_terrain: %s: %d x %d quads, %d triangles, %.0f m square" % (a.out, n, n, 2 * n * n, a.size_m))


if __name__ == "__main__":
    main()
