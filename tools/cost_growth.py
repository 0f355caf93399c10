#!/usr/bin/env python3
"""How frame time grows with the scene and the sonar: sweeps `vksonar bench speed` over triangles,
beams, bins and rows per vertical beamwidth, on both backends, and writes a CSV and an SVG plot.

    python3 tools/cost_growth.py BUILD/vksonar OUT_DIR [--frames N]

Triangles: heightfields from tools/gen_terrain.py (120 m square, sonar 3 m above, pitched 10 degrees
down) of 10k to 2M triangles; beams 128-1024, bins 256-4096 and rows_per_vfov 16-128 on the bundled
default scene at the default pose, one knob at a time around the default preset. Each point is the
median full frame of N timed frames (default 40) in one run; the machine and its load are printed
with the results. Pure Python, no third-party packages.
"""
import argparse
import csv
import math
import os
import re
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

SWEEPS = [
    ("triangles", [10_000, 50_000, 200_000, 500_000, 2_000_000]),
    ("beams", [128, 256, 512, 1024]),
    ("bins", [256, 512, 1024, 2048, 4096]),
    ("rows_per_vfov", [16, 32, 64, 128]),
]


def bench(binary, backend, frames, extra):
    cmd = [binary, "bench", "speed", "--backend", backend, "--frames", str(frames), "--memory-frames",
           str(frames + 10)] + extra
    out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    full = re.search(r"\*\*full frame\*\*[^|]*\|\s*\*\*([0-9.]+)\*\*", out)
    depth = re.search(r"^\| depth \| ([0-9.]+)", out, re.M)
    if full is None or depth is None:
        raise SystemExit("cost_growth: could not read the frame time from:\n" + out)
    return float(full.group(1)), float(depth.group(1))


def svg(rows, path):
    """Four panels (one per knob), frame ms against the knob on log2 axes, a line per backend."""
    width, height, pad = 960, 300, 48
    panel_w = (width - pad) / len(SWEEPS)
    colors = {"vulkan": "#1f77b4", "cpu": "#d62728"}
    parts = ['<svg xmlns="http://www.w3.org/2000/svg" width="%d" height="%d" font-family="sans-serif" '
             'font-size="11">' % (width, height)]
    for i, (knob, _) in enumerate(SWEEPS):
        pts = [r for r in rows if r["knob"] == knob]
        if not pts:
            continue
        x0 = pad + i * panel_w
        xs = [math.log2(r["value"]) for r in pts]
        ys = [r["frame_ms"] for r in pts]
        xmin, xmax = min(xs), max(xs)
        ymax = max(ys) * 1.1
        def px(x):
            return x0 + 10 + (x - xmin) / (xmax - xmin or 1) * (panel_w - 30)
        def py(y):
            return height - pad - y / ymax * (height - 2 * pad)
        parts.append('<rect x="%.1f" y="%d" width="%.1f" height="%d" fill="none" stroke="#999"/>' %
                     (x0, pad, panel_w - 10, height - 2 * pad))
        parts.append('<text x="%.1f" y="%d" text-anchor="middle">%s (log scale)</text>' %
                     (x0 + panel_w / 2, height - pad + 28, knob))
        parts.append('<text x="%.1f" y="%d">%.0f ms</text>' % (x0 + 2, pad - 4, ymax))
        for value in sorted({r["value"] for r in pts}):
            parts.append('<text x="%.1f" y="%d" text-anchor="middle" fill="#555">%s</text>' %
                         (px(math.log2(value)), height - pad + 14,
                          ("%gk" % (value / 1000)) if value >= 10000 else value))
        for backend, color in colors.items():
            line = [r for r in pts if r["backend"] == backend]
            if not line:
                continue
            coords = " ".join("%.1f,%.1f" % (px(math.log2(r["value"])), py(r["frame_ms"])) for r in line)
            parts.append('<polyline points="%s" fill="none" stroke="%s" stroke-width="2"/>' % (coords, color))
    parts.append('<text x="%d" y="16">full frame ms: <tspan fill="%s">Vulkan (lavapipe)</tspan>, '
                 '<tspan fill="%s">CPU backend</tspan></text>' % (pad, colors["vulkan"], colors["cpu"]))
    parts.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(parts) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("binary")
    ap.add_argument("out_dir")
    ap.add_argument("--frames", type=int, default=40)
    a = ap.parse_args()
    os.makedirs(a.out_dir, exist_ok=True)
    rows = []
    for knob, values in SWEEPS:
        for value in values:
            if knob == "triangles":
                n = max(1, round((value / 2) ** 0.5))
                scene = os.path.join(a.out_dir, "terrain_%d.glb" % value)
                if not os.path.exists(scene):
                    subprocess.run([sys.executable, os.path.join(HERE, "gen_terrain.py"), str(n), "120", scene],
                                   check=True, capture_output=True)
                extra = ["--scene", scene, "--pose", "0,0,3,0,10,0"]
            else:
                extra = ["--set", "%s=%d" % ("accuracy.rows_per_vfov" if knob == "rows_per_vfov" else knob, value)]
            for backend in ("vulkan", "cpu"):
                frame_ms, depth_ms = bench(a.binary, backend, a.frames, extra)
                rows.append({"knob": knob, "value": value, "backend": backend, "frame_ms": frame_ms,
                             "depth_ms": depth_ms})
                print("%-14s %8d %-7s frame %7.2f ms  depth %7.2f ms" % (knob, value, backend, frame_ms, depth_ms),
                      flush=True)
    with open(os.path.join(a.out_dir, "cost_growth.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["knob", "value", "backend", "frame_ms", "depth_ms"])
        w.writeheader()
        w.writerows(rows)
    svg(rows, os.path.join(a.out_dir, "cost_growth.svg"))
    with open("/proc/loadavg") as f:
        print("load average:", f.read().split()[:3])


if __name__ == "__main__":
    main()
