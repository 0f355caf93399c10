#!/usr/bin/env python3
"""Writes vksonar's bundled scenes (assets/scenes/) and the glTF test data (tests/data/).

    python3 tools/gen_scenes.py            # from the repository root; deterministic output

Frames: meshes are authored in glTF's frame (+Y up). vksonar's world frame is x forward, y left,
z up, with world = (x_gltf, -z_gltf, y_gltf); the helpers `w2g` and `quat_world` let placements be
written in world coordinates. Units are metres. The sonar typically sits near the world origin
looking along +x (the same direction as glTF +x), so "ahead of the sonar" is +x in both frames.

Acoustic materials live in material extras: {"vksonar": {"backscatter_db": -15, "model": "lambert"}}.
"""
import base64
import json
import math
import os
import random
import struct
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

FLOAT, U8, U16, U32 = 5126, 5121, 5123, 5125
POINTS, LINES, TRIANGLES, STRIP, FAN = 0, 1, 4, 5, 6


# ---- frames -----------------------------------------------------------------------------------

def w2g(x, y, z):
    """World (x fwd, y left, z up) -> glTF (x, y up, z)."""
    return [x, z, -y]


def quat_world(axis, deg):
    """Quaternion (x, y, z, w) in glTF's frame for a rotation of `deg` about the world axis `axis`."""
    ax = w2g(*axis)
    n = math.sqrt(sum(a * a for a in ax))
    s = math.sin(math.radians(deg) / 2) / n
    return [round(ax[0] * s, 12), round(ax[1] * s, 12), round(ax[2] * s, 12), round(math.cos(math.radians(deg) / 2), 12)]


# ---- meshes (glTF frame, +Y up, counter-clockwise = outward) ----------------------------------

def grid(size_x, size_z, nx, nz, height=lambda x, z: 0.0):
    verts, tris = [], []
    for j in range(nz + 1):
        for i in range(nx + 1):
            x = -size_x / 2 + size_x * i / nx
            z = -size_z / 2 + size_z * j / nz
            verts.append((x, height(x, z), z))
    for j in range(nz):
        for i in range(nx):
            a = j * (nx + 1) + i
            b, c, d = a + 1, a + nx + 1, a + nx + 2
            tris += [(a, c, b), (b, c, d)]  # normal +Y
    return verts, tris


def cylinder(radius, height, segments, y0=0.0):
    """Along +Y from y0 to y0 + height, closed."""
    verts, tris = [], []
    for k in range(segments):
        a = 2 * math.pi * k / segments
        verts.append((radius * math.cos(a), y0, radius * math.sin(a)))
        verts.append((radius * math.cos(a), y0 + height, radius * math.sin(a)))
    bottom, top = len(verts), len(verts) + 1
    verts += [(0.0, y0, 0.0), (0.0, y0 + height, 0.0)]
    for k in range(segments):
        b0, t0 = 2 * k, 2 * k + 1
        b1, t1 = 2 * ((k + 1) % segments), 2 * ((k + 1) % segments) + 1
        tris += [(b0, t0, b1), (b1, t0, t1), (top, t1, t0), (bottom, b0, b1)]
    return verts, tris


def uv_sphere(radius, stacks, slices):
    verts, tris = [(0.0, radius, 0.0)], []
    for s in range(1, stacks):
        phi = math.pi * s / stacks
        for k in range(slices):
            th = 2 * math.pi * k / slices
            verts.append((radius * math.sin(phi) * math.cos(th), radius * math.cos(phi), radius * math.sin(phi) * math.sin(th)))
    verts.append((0.0, -radius, 0.0))
    south = len(verts) - 1

    def ring(s, k):
        return 1 + (s - 1) * slices + k % slices

    for k in range(slices):
        tris.append((0, ring(1, k + 1), ring(1, k)))
        tris.append((south, ring(stacks - 1, k), ring(stacks - 1, k + 1)))
    for s in range(1, stacks - 1):
        for k in range(slices):
            a, b = ring(s, k), ring(s, k + 1)
            c, d = ring(s + 1, k), ring(s + 1, k + 1)
            tris += [(a, b, c), (b, d, c)]
    return verts, tris


def box(sx, sy, sz, y0=None):
    """Centred box; with y0 the bottom sits at y = y0."""
    cy = 0.0 if y0 is None else y0 + sy / 2
    hx, hy, hz = sx / 2, sy / 2, sz / 2
    verts = [(x, cy + y, z) for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)]
    # vertex index = 4*ix + 2*iy + iz
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [(a, b, c), (a, c, d)]
    return verts, tris


def rock(radius, rng, jitter=0.25):
    """Once-subdivided icosahedron with radial jitter: 80 triangles."""
    t = (1 + math.sqrt(5)) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
         (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
         (8, 6, 7), (9, 8, 1)]
    v = [tuple(c / math.sqrt(1 + t * t) for c in p) for p in v]
    mid = {}

    def midpoint(a, b):
        key = (min(a, b), max(a, b))
        if key not in mid:
            p = [(v[a][i] + v[b][i]) / 2 for i in range(3)]
            n = math.sqrt(sum(c * c for c in p))
            v.append(tuple(c / n for c in p))
            mid[key] = len(v) - 1
        return mid[key]

    tris = []
    for a, b, c in f:
        ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
        tris += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    scale = [1.0, 0.6, 0.9]  # flattened, as boulders are
    verts = []
    for p in v:
        r = radius * (1 + jitter * (rng.random() * 2 - 1))
        verts.append((p[0] * r * scale[0], p[1] * r * scale[1], p[2] * r * scale[2]))
    return verts, tris


def signed_volume(verts, tris):
    vol = 0.0
    for a, b, c in tris:
        pa, pb, pc = verts[a], verts[b], verts[c]
        vol += (pa[0] * (pb[1] * pc[2] - pb[2] * pc[1]) - pa[1] * (pb[0] * pc[2] - pb[2] * pc[0]) +
                pa[2] * (pb[0] * pc[1] - pb[1] * pc[0])) / 6
    return vol


def closed(mesh):
    assert signed_volume(*mesh) > 0, "closed mesh must wind outward"
    return mesh


def seabed_relief(seed, amplitude):
    """Smooth deterministic ripples plus a little roughness, so the seabed has texture in the image."""
    rng = random.Random(seed)
    waves = [(rng.uniform(0.15, 0.6), rng.uniform(0, 2 * math.pi), rng.uniform(0, 2 * math.pi)) for _ in range(4)]
    cache = {}

    def h(x, z):
        key = (round(x, 6), round(z, 6))
        if key not in cache:
            s = sum(math.sin(k * (x * math.cos(d) + z * math.sin(d)) + p) for k, d, p in waves) / len(waves)
            cache[key] = amplitude * (s + 0.3 * rng.uniform(-1, 1))
        return cache[key]

    return h


# ---- glTF writer --------------------------------------------------------------------------------

class Gltf:
    def __init__(self):
        self.buf = bytearray()
        self.accessors, self.views, self.meshes, self.nodes, self.materials = [], [], [], [], []
        self.triangles = 0

    def _view(self, data, target=None, stride=None):
        while len(self.buf) % 4:
            self.buf.append(0)
        view = {"buffer": 0, "byteOffset": len(self.buf), "byteLength": len(data)}
        if target:
            view["target"] = target
        if stride:
            view["byteStride"] = stride
        self.buf += data
        self.views.append(view)
        return len(self.views) - 1

    def material(self, name, backscatter_db=None, model=None, extras=None):
        m = {"name": name}
        vk = {}
        if backscatter_db is not None:
            vk["backscatter_db"] = backscatter_db
        if model is not None:
            vk["model"] = model
        if vk:
            m["extras"] = {"vksonar": vk}
        if extras is not None:
            m["extras"] = extras
        self.materials.append(m)
        return len(self.materials) - 1

    def positions(self, verts):
        data = b"".join(struct.pack("<3f", *p) for p in verts)
        f32 = [struct.unpack("<3f", struct.pack("<3f", *p)) for p in verts]
        lo = [min(p[i] for p in f32) for i in range(3)]
        hi = [max(p[i] for p in f32) for i in range(3)]
        self.accessors.append({"bufferView": self._view(data, 34962), "componentType": FLOAT, "count": len(verts),
                               "type": "VEC3", "min": lo, "max": hi})
        return len(self.accessors) - 1

    def indices(self, idx, component=None):
        if component is None:
            component = U16 if max(idx) < 65536 else U32
        fmt = {U8: "B", U16: "H", U32: "I"}[component]
        data = struct.pack("<%d%s" % (len(idx), fmt), *idx)
        self.accessors.append({"bufferView": self._view(data, 34963), "componentType": component, "count": len(idx),
                               "type": "SCALAR"})
        return len(self.accessors) - 1

    def primitive(self, verts, tris=None, material=None, mode=None, component=None, flat=None):
        prim = {"attributes": {"POSITION": self.positions(verts)}}
        if tris is not None or flat is not None:
            prim["indices"] = self.indices(flat if flat is not None else [i for t in tris for i in t], component)
        if material is not None:
            prim["material"] = material
        if mode is not None:
            prim["mode"] = mode
        return prim

    def mesh(self, name, mesh, material):
        verts, tris = mesh
        self.meshes.append({"name": name, "primitives": [self.primitive(verts, tris, material)]})
        return len(self.meshes) - 1

    def node(self, name, mesh=None, children=None, t=None, r=None, s=None, matrix=None, object_class=None):
        n = {"name": name}
        if object_class is not None:  # the label class of this object (README "Scene objects")
            n["extras"] = {"vksonar": {"class": object_class}}
        if mesh is not None:
            n["mesh"] = mesh
        if children:
            n["children"] = children
        if matrix is not None:
            n["matrix"] = matrix
        if t is not None:
            n["translation"] = t
        if r is not None:
            n["rotation"] = r
        if s is not None:
            n["scale"] = s
        self.nodes.append(n)
        return len(self.nodes) - 1

    def document(self, roots, uri, scene_extras=None, extra_top=None):
        doc = {"asset": {"version": "2.0", "generator": "vksonar tools/gen_scenes.py"}, "scene": 0,
               "scenes": [{"name": "scene", "nodes": roots}], "nodes": self.nodes, "meshes": self.meshes,
               "accessors": self.accessors, "bufferViews": self.views,
               "buffers": [{"byteLength": len(self.buf)}]}
        if uri is not None:
            doc["buffers"][0]["uri"] = uri
        if self.materials:
            doc["materials"] = self.materials
        if scene_extras is not None:
            doc["scenes"][0]["extras"] = scene_extras
        if extra_top:
            doc.update(extra_top)
        return doc

    def write_gltf(self, path, roots, external_bin=False, **kw):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        if external_bin:
            bin_name = os.path.splitext(os.path.basename(path))[0] + ".bin"
            with open(os.path.join(os.path.dirname(path), bin_name), "wb") as f:
                f.write(self.buf)
            uri = bin_name
        else:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.buf)).decode("ascii")
        write_json(path, self.document(roots, uri, **kw))

    def glb_bytes(self, roots, **kw):
        text = json.dumps(self.document(roots, None, **kw), separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        binary = bytes(self.buf) + b"\0" * (-len(self.buf) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
        return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def write_json(path, doc):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


def count_triangles(g, roots):
    """Triangles drawn (instances counted), for the summary line."""
    total = 0

    def visit(n):
        nonlocal total
        node = g.nodes[n]
        if "mesh" in node:
            for p in g.meshes[node["mesh"]]["primitives"]:
                total += g.accessors[p["indices"]]["count"] // 3
        for c in node.get("children", []):
            visit(c)

    for r in roots:
        visit(r)
    return total


def report(path, g, roots):
    print("%-45s %6d triangles  %4d KiB" % (os.path.relpath(path, ROOT), count_triangles(g, roots),
                                           os.path.getsize(path) // 1024))


# ---- bundled scenes -----------------------------------------------------------------------------

def default_scene(seabed_quads=48, path=None):
    """Seabed at z = -5 m with concrete pilings, a steel pipe, a crate and a sphere 8-30 m ahead."""
    g = Gltf()
    sand = g.material("seabed_sand", -30, "lambert")
    steel = g.material("steel", -10, "lambert")
    concrete = g.material("concrete", -15, "lambert")

    seabed = g.mesh("seabed", grid(60, 60, seabed_quads, seabed_quads, seabed_relief(1, 0.06)), sand)
    piling = g.mesh("piling", closed(cylinder(0.4, 10.0, 32)), concrete)  # base at its origin
    pipe = g.mesh("pipe", closed(cylinder(0.5, 6.0, 32, y0=-3.0)), steel)  # centred on its origin
    crate = g.mesh("crate", closed(box(2.0, 1.5, 1.2, y0=0.0)), steel)
    sphere = g.mesh("sphere", closed(uv_sphere(1.0, 16, 24)), steel)

    nodes = [g.node("seabed", seabed, t=w2g(25, 0, -5))]
    # Pilings are children of one group node placed on the seabed (hierarchy + instancing).
    piles = [g.node("piling_%d" % i, piling, t=w2g(x, y, 0)) for i, (x, y) in enumerate([(12, -4), (18, 5), (26, -8)])]
    nodes.append(g.node("pilings", children=piles, t=w2g(0, 0, -5)))
    # A pipe lying on the seabed, its axis (glTF +Y) turned horizontal then yawed 30 deg.
    pipe_node = g.node("pipe", pipe, t=w2g(20, 2, -4.5),
                       r=quat_mul(quat_world((0, 0, 1), 30), quat_world((1, 0, 0), 90)))
    nodes.append(pipe_node)
    nodes.append(g.node("crate", crate, t=w2g(15, 6, -5), r=quat_world((0, 0, 1), 20)))
    nodes.append(g.node("sphere", sphere, t=w2g(10, -3, -4)))
    path = path or os.path.join(ROOT, "assets/scenes/default.gltf")
    g.write_gltf(path, nodes)
    report(path, g, nodes)


def harbour_scene():
    """A quay wall across the view at x = 18-20 m, a pier with piles reaching towards the sonar, seabed at -8 m."""
    g = Gltf()
    sand = g.material("seabed_silt", -32, "lambert")
    # Cast concrete and a steel crate: smooth enough for a near-specular lobe (the rough model's facet
    # term) where the sonar sees them face-on.
    concrete = g.material("concrete", extras={"vksonar": {"backscatter_db": -15, "model": "rough", "rms_slope": 0.08,
                                                          "reflection_db": -3}})
    timber = g.material("timber", -20, "lambert")
    steel = g.material("steel", extras={"vksonar": {"backscatter_db": -10, "model": "rough", "rms_slope": 0.1,
                                                    "reflection_db": -1}})

    seabed = g.mesh("seabed", grid(80, 80, 40, 40, seabed_relief(2, 0.05)), sand)
    # Wall: 2 m thick (x), 80 m long (y), 10 m high (z).
    wall = g.mesh("quay_wall", closed(box(2.0, 10.0, 80.0, y0=0.0)), concrete)
    deck = g.mesh("pier_deck", closed(box(12.0, 0.5, 4.0, y0=0.0)), timber)
    pile = g.mesh("pier_pile", closed(cylinder(0.3, 10.0, 24)), timber)
    crate = g.mesh("sunken_crate", closed(box(1.5, 1.0, 1.0, y0=0.0)), steel)

    nodes = [g.node("seabed", seabed, t=w2g(20, 0, -8)), g.node("quay_wall", wall, t=w2g(19, 0, -8), object_class="wall")]
    # Pier from the wall back to x = 6 m at y = +10 m; deck at z = +1.5, piles down to the seabed.
    children = [g.node("deck", deck, t=w2g(0, 0, 1.5), object_class="pier")]
    for i, x in enumerate([-5.0, -1.5, 2.0, 5.0]):
        for j, y in enumerate([-1.5, 1.5]):
            children.append(g.node("pile_%d_%d" % (i, j), pile, t=w2g(x, y, -8), object_class="piling"))
    nodes.append(g.node("pier", children=children, t=w2g(12, 10, 0)))
    nodes.append(g.node("sunken_crate", crate, t=w2g(10, -5, -8), r=quat_world((0, 0, 1), -35), object_class="crate"))
    path = os.path.join(ROOT, "assets/scenes/harbour.gltf")
    g.write_gltf(path, nodes)
    report(path, g, nodes)


def tilted_seafloor_scene():
    """A seabed sloping up away from the sonar (10 deg) with boulders resting on it."""
    g = Gltf()
    mud = g.material("seabed_mud", -28, "lambert")
    stone = g.material("rock", -18, "lambert")
    rng = random.Random(3)

    seabed = g.mesh("seabed", grid(60, 60, 48, 48, seabed_relief(4, 0.1)), mud)
    radii = [0.8, 1.2, 0.6, 1.5]
    rocks = [g.mesh("rock_%d" % i, closed(rock(r, rng)), stone) for i, r in enumerate(radii)]
    block = g.mesh("block", closed(box(1.6, 1.2, 2.4, y0=0.0)), stone)

    # Rocks are children of the tilted seabed node, placed in its (sloped) frame.
    kids = []
    for i, ((x, y), r) in enumerate(zip([(-12, -3), (-6, 5), (-2, -6), (6, 2)], radii)):
        # Partly buried: the centre sits at 0.4 of the (flattened) radius above the slope.
        kids.append(g.node("rock_%d" % i, rocks[i], t=w2g(x, y, 0.4 * 0.6 * r), r=quat_world((0, 0, 1), 40 * i),
                          object_class="rock"))
    kids.append(g.node("block", block, t=w2g(-9, 7, 0), r=quat_world((0, 0, 1), 15)))
    # Rotating by -10 deg about world y lifts +x: z = -8 + tan(10 deg) * (x - 25).
    nodes = [g.node("seabed", seabed, children=kids, t=w2g(25, 0, -8), r=quat_world((0, 1, 0), -10))]
    path = os.path.join(ROOT, "assets/scenes/tilted_seafloor.gltf")
    g.write_gltf(path, nodes)
    report(path, g, nodes)


def quat_mul(a, b):
    """a * b for (x, y, z, w) quaternions: apply b first."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return [round(v, 12) for v in (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                                   aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)]


# ---- test scenes --------------------------------------------------------------------------------

def plane_10m():
    """4 m x 4 m plane facing world -x, centred at world (10, 0, 0); mesh-local = glTF coordinates."""
    g = Gltf()
    # World corners (10, y, z) for y, z in {-2, 2}; front face (CCW) towards -x.
    corners = [w2g(10, y, z) for (y, z) in [(-2, -2), (2, -2), (2, 2), (-2, 2)]]
    # (b - a) x (c - a) for world a=(10,-2,-2), b=(10,2,-2), c=(10,2,2) is +x; reverse for -x.
    g.meshes.append({"name": "plane", "primitives": [g.primitive(corners, [(0, 2, 1), (0, 3, 2)], None)]})
    roots = [g.node("plane", 0)]
    d = os.path.join(ROOT, "tests/data/scenes")
    g.write_gltf(os.path.join(d, "plane_10m.gltf"), roots, external_bin=True)
    with open(os.path.join(d, "plane_10m.glb"), "wb") as f:
        f.write(g.glb_bytes(roots))
    return g, roots


def node_transform():
    """One triangle placed by parent translation + child TRS, and again by a root `matrix` node."""
    g = Gltf()
    g.meshes.append({"name": "tri", "primitives": [g.primitive([(1, 0, 0), (0, 1, 0), (0, 0, 1)], [(0, 1, 2)], None)]})
    child = g.node("child", 0, t=[0.5, 0, 0], r=[0, math.sin(math.pi / 4), 0, math.cos(math.pi / 4)], s=[2, 2, 2])
    parent = g.node("parent", children=[child], t=[1, 2, 3])
    # Column-major matrix: rotate 90 deg about glTF Z, then translate (10, 0, 0).
    m = [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 10, 0, 0, 1]
    other = g.node("by_matrix", 0, matrix=m)
    write = os.path.join(ROOT, "tests/data/scenes/node_transform.gltf")
    g.write_gltf(write, [parent, other])


def primitives():
    """Materials, index types, strips/fans, points/lines/degenerate skipping and scene effects."""
    g = Gltf()
    mud = g.material("mud", -27, "lambert")
    steel = g.material("steel", -12, "constant")
    plain = g.material("plain")
    odd = g.material("odd_keys", extras={"vksonar": {"backscatter_db": -20, "roughness": 0.3}, "other": 1})
    quad = [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)]
    prims = [
        g.primitive(quad, [(0, 2, 1), (0, 3, 2)], mud, component=U8),  # 2 triangles, u8
        g.primitive(quad[:3], [(0, 2, 1)], steel, component=U32),  # 1 triangle, u32
        g.primitive([(0, 1, 0), (0, 1, 1), (1, 1, 0)], None, plain),  # non-indexed, 1 triangle
        g.primitive(quad, None, None, mode=STRIP, flat=[0, 1, 3, 2]),  # strip, 2 triangles, no material
        g.primitive([(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1), (-1, 0, 1)], None, odd, mode=FAN),  # 3 triangles
        g.primitive(quad, None, mud, mode=POINTS),  # skipped
        g.primitive(quad, [(0, 1), (2, 3)], mud, mode=LINES),  # skipped
        g.primitive([(2, 2, 2), (2, 2, 2), (2, 2, 2)], [(0, 1, 2)], mud),  # degenerate only: skipped
    ]
    g.meshes.append({"name": "mixed", "primitives": prims})
    roots = [g.node("mixed", 0)]
    g.write_gltf(os.path.join(ROOT, "tests/data/scenes/primitives.gltf"), roots,
                 scene_extras={"vksonar": {"effects": {"speckle": "off", "tvg": "on"}}})


def rough_materials():
    """The scattering models' glTF spelling: rough with and without its parameters, the Lommel-Seeliger
    name, and a facet parameter on a model that ignores it (a warning)."""
    g = Gltf()
    sand = g.material("sand", extras={"vksonar": {"backscatter_db": -31, "model": "rough", "rms_slope": 0.15,
                                                  "reflection_db": -9}})
    rock = g.material("rock", -18, "lommel_seeliger")
    mud = g.material("mud", extras={"vksonar": {"backscatter_db": -27, "model": "lambert", "rms_slope": 0.2}})
    pipe = g.material("pipe", -12, "rough")
    tri = [(0, 0, 0), (1, 0, 0), (1, 0, 1)]
    prims = [g.primitive(tri, [(0, 2, 1)], m) for m in (sand, rock, mud, pipe)]
    g.meshes.append({"name": "four", "primitives": prims})
    g.write_gltf(os.path.join(ROOT, "tests/data/scenes/rough_materials.gltf"), [g.node("four", 0)])


# ---- malformed corpus ---------------------------------------------------------------------------

def triangle_gltf():
    g = Gltf()
    g.meshes.append({"name": "tri", "primitives": [g.primitive([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1, 2)], None)]})
    roots = [g.node("tri", 0)]
    return g, roots


def bad_corpus():
    d = os.path.join(ROOT, "tests/data/bad_gltf")
    os.makedirs(d, exist_ok=True)
    for name in os.listdir(d):
        os.remove(os.path.join(d, name))

    def data_uri(buf):
        return "data:application/octet-stream;base64," + base64.b64encode(bytes(buf)).decode()

    def base():
        g, roots = triangle_gltf()
        return g, g.document(roots, data_uri(g.buf))

    def put(name, doc):
        write_json(os.path.join(d, name), doc)

    def put_bytes(name, data):
        with open(os.path.join(d, name), "wb") as f:
            f.write(data)

    g, doc = base()
    text = json.dumps(doc, indent=1)
    put_bytes("truncated_json.gltf", text[: len(text) // 2].encode())
    put_bytes("not_json.gltf", b"this is not a glTF file\n")
    put_bytes("empty.gltf", b"")
    put_bytes("top_level_array.gltf", b"[1, 2, 3]\n")
    put_bytes("deep_nesting.gltf", (text[:-2] + ', "extras": ' + "[" * 5000 + "]" * 5000 + "}\n").encode())
    # a second "nodes" member (JSON would keep the last in silence)
    put_bytes("duplicate_key.gltf", (text[:-2] + ', "nodes": [{"mesh": 0, "translation": [1000, 0, 0]}]}\n').encode())

    g, roots = triangle_gltf()
    glb = g.glb_bytes(roots)
    put_bytes("bad_magic.glb", b"gLTF" + glb[4:])
    put_bytes("json_named_glb.glb", text.encode())
    put_bytes("truncated.glb", glb[: len(glb) - 16])
    over = bytearray(glb)
    json_len = struct.unpack_from("<I", glb, 12)[0]
    struct.pack_into("<I", over, 20 + json_len, len(glb))  # BIN chunk claims more than the file
    put_bytes("bin_chunk_overrun.glb", bytes(over))
    put_bytes("glb_version1.glb", glb[:4] + struct.pack("<I", 1) + glb[8:])
    short_json = bytearray(glb)
    struct.pack_into("<I", short_json, 12, 4)  # the JSON chunk's length cut to 4: JSON text follows it
    put_bytes("glb_json_length_short.glb", bytes(short_json))

    g, doc = base()
    doc["accessors"][0]["count"] = 4  # 3 vertices in the buffer
    put("short_buffer.gltf", doc)

    g, doc = base()
    doc["bufferViews"][0]["byteLength"] = 4096
    put("view_past_buffer.gltf", doc)

    g, doc = base()
    doc["accessors"][0]["count"] = 4294967295
    put("huge_count.gltf", doc)

    g, doc = base()
    doc["accessors"][1]["count"] = -3
    put("negative_count.gltf", doc)

    # node transforms glTF does not allow, or no scene has: a matrix beside translation (tinygltf kept the
    # matrix), a projective matrix (last row not 0 0 0 1), a translation past float range
    g, doc = base()
    doc["nodes"][0]["matrix"] = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    doc["nodes"][0]["translation"] = [1, 0, 0]
    put("matrix_and_translation.gltf", doc)
    g, doc = base()
    doc["nodes"][0]["matrix"] = [1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    put("projective_matrix.gltf", doc)
    g, doc = base()
    doc["nodes"][0]["translation"] = [1e39, 0, 0]
    put("translation_past_float.gltf", doc)

    g, doc = base()
    doc["buffers"][0]["uri"] = "tri%zz.bin"  # not an escape: it used to read as a NUL byte
    put("uri_bad_percent.gltf", doc)

    g, doc = base()
    doc["buffers"][0]["uri"] = ""  # tinygltf's own words were "'uri' is missing ... File not found :"
    put("uri_empty.gltf", doc)

    g, _ = triangle_gltf()
    g.accessors.clear(), g.views.clear(), g.buf.clear()
    g.meshes[0]["primitives"] = [g.primitive([(0, 0, 0), (1, 0, 0), (0, 1, 0)], None, None, flat=[0, 1, 7])]
    put("index_out_of_range.gltf", g.document([0], data_uri(g.buf)))

    g, doc = base()
    doc["meshes"][0]["primitives"][0]["attributes"] = {"NORMAL": 0}
    put("missing_position.gltf", doc)

    for name, value in [("nan_position.gltf", float("nan")), ("inf_position.gltf", float("inf"))]:
        g, _ = triangle_gltf()
        g.accessors.clear(), g.views.clear(), g.buf.clear()
        g.meshes[0]["primitives"] = [g.primitive([(0, 0, 0), (1, value, 0), (0, 1, 0)], [(0, 1, 2)], None)]
        doc = g.document([0], data_uri(g.buf))
        doc["accessors"][0].pop("min"), doc["accessors"][0].pop("max")  # json cannot write NaN/Inf
        put(name, doc)

    g, doc = base()
    doc["buffers"][0]["uri"] = "missing.bin"
    put("missing_bin.gltf", doc)

    g, doc = base()
    doc["buffers"][0]["uri"] = "wrong_size.bin"
    put("wrong_size_bin.gltf", doc)
    put_bytes("wrong_size.bin", bytes(g.buf[:10]))

    g, doc = base()
    doc["buffers"][0]["byteLength"] = len(g.buf) + 4
    put("bad_data_uri.gltf", doc)

    g, doc = base()
    doc["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    # The primitive's "stream" is its float positions: refused as unsupported without libdraco, as not
    # a Draco mesh with it.
    doc["meshes"][0]["primitives"][0]["extensions"] = {
        "KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    put("draco_required.gltf", doc)

    # EXT_meshopt_compression whose compressed stream is not one: the positions' view is decoded from
    # the first 12 bytes of the data buffer into a fallback buffer, and those bytes are no meshopt stream.
    g, doc = base()
    doc["extensionsUsed"] = ["EXT_meshopt_compression"]
    doc["extensionsRequired"] = ["EXT_meshopt_compression"]
    view = doc["bufferViews"][0]
    doc["buffers"].append({"byteLength": view["byteLength"], "extensions": {"EXT_meshopt_compression": {"fallback": True}}})
    view["extensions"] = {"EXT_meshopt_compression": {"buffer": 0, "byteOffset": 0, "byteLength": 12,
                                                      "byteStride": 12, "count": 3, "mode": "ATTRIBUTES"}}
    view["buffer"] = len(doc["buffers"]) - 1
    view["byteOffset"] = 0
    put("meshopt_bad_stream.gltf", doc)

    g, doc = base()
    doc["nodes"] = [{"name": "a", "children": [1]}, {"name": "b", "mesh": 0, "children": [0]}]
    put("node_cycle.gltf", doc)

    g, doc = base()
    doc["nodes"][0]["mesh"] = 5
    put("bad_mesh_index.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "loud", "extras": {"vksonar": {"backscatter_db": "loud"}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    put("bad_backscatter.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "mirror", "extras": {"vksonar": {"backscatter_db": 6}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    put("backscatter_above_0db.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "shiny", "extras": {"vksonar": {"model": "phong"}}}]
    put("bad_model.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "glass", "extras": {"vksonar": {"model": "rough", "rms_slope": 0}}}]
    put("bad_rms_slope.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "louder", "extras": {"vksonar": {"model": "rough", "reflection_db": 3}}}]
    put("bad_reflection.gltf", doc)

    g, doc = base()
    doc["materials"] = [{"name": "vague", "extras": {"vksonar": {"model": "rough", "rms_slope": "smooth"}}}]
    put("bad_rms_slope_type.gltf", doc)

    g, doc = base()
    doc.pop("asset")
    put("missing_asset.gltf", doc)

    g, _ = triangle_gltf()
    g.accessors.clear(), g.views.clear(), g.buf.clear()
    g.meshes[0]["primitives"] = [g.primitive([(0, 0, 0), (1, 0, 0), (0, 1, 0)], None, None, flat=[0, 1, 2, 0])]
    put("index_count_not_multiple.gltf", g.document([0], data_uri(g.buf)))

    g, doc = base()
    doc["accessors"][0]["componentType"] = U16
    put("position_not_float.gltf", doc)

    g, doc = base()
    doc["scene"] = 3
    put("bad_default_scene.gltf", doc)

    # Names from the file with control characters: the error must still be one line.
    g, doc = base()
    doc["materials"] = [{"name": "quay\nwall\x01", "extras": {"vksonar": {"backscatter_db": "loud"}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    put("newline_in_name.gltf", doc)

    g, doc = base()
    doc["extensionsRequired"] = ["KHR_\nmade_up\r"]
    put("newline_in_extension.gltf", doc)
    print("%-45s %6d files" % (os.path.relpath(d, ROOT), len(os.listdir(d))))


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--heavy":
        # Not bundled (1.6 MB): the default scene with a 220 x 220-quad seabed, 98k triangles in all, the
        # load the early prototype was timed at (docs/benchmarks.md, depth-pass culling).
        default_scene(220, os.path.join(sys.argv[2], "default_98k.gltf"))
        return
    default_scene()
    harbour_scene()
    tilted_seafloor_scene()
    plane_10m()
    node_transform()
    primitives()
    rough_materials()
    bad_corpus()


if __name__ == "__main__":
    main()
