"""A .h5 shard killed inside HDF5's flush of a frame, then re-run: the result is the uninterrupted shard.

Run by ctest (tests/CMakeLists.txt, `dataset_resume_torn`) with an interpreter that imports numpy and h5py:
    python3 tests/python/check_resume_torn.py path/to/vksonar path/to/libkill_at_write.so
The shim (tests/preload/kill_at_write.cpp) SIGKILLs the render at its Nth write to the .h5, so every
write of one frame's flush (the new chunks, the metadata about in address order, the superblock, the
commit record) is a kill point, deterministically, and each write over a page is also cut in half.
One HDF5 flush writes frames_written before the chunk indexes and the end of the file last, so a resume that
trusted frames_written read an unindexed frame as zeros or allocated the next frame over it (before the
commit record, /polar and the labels differed at 4 of a frame's ~23 writes and the re-run failed at 5
more). Checks, each of which can fail:
  - each killed shard, run again, exits 0 and equals the uninterrupted shard bit for bit, every array;
  - a shard whose recorded frames were changed on disk is started over (one warning line), not resumed.
"""
import concurrent.futures
import os
import subprocess
import sys
import tempfile
import time

import h5py
import numpy as np

CLI, SHIM = sys.argv[1], sys.argv[2]
SMALL = ["--backend", "cpu", "--set", "bins=32", "--set", "beams=16", "--set", "horizontal_beamwidth=9", "--set", "range_min=6", "--seed", "7"]
FRAMES = 8
failures = []


def check(condition, what):
    if not condition:
        failures.append(what)
        print("FAIL:", what)


def differences(a_path, b_path):
    bad = []
    with h5py.File(a_path, "r") as a, h5py.File(b_path, "r") as b:
        for name in a.keys():
            if name not in b:
                bad.append(f"/{name} missing")
            elif h5py.check_string_dtype(a[name].dtype) is not None:
                if list(a[name].asstr()[:]) != list(b[name].asstr()[:]):
                    bad.append(f"/{name}")
            else:
                x, y = a[name][:], b[name][:]
                if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
                    bad.append(f"/{name}")
        for attr in ("frames_written", "complete"):
            if int(b.attrs[attr]) != int(a.attrs[attr]):
                bad.append(f"attribute {attr} {int(b.attrs[attr])}")
    return bad


def shim_env(**extra):
    env = dict(os.environ, LD_PRELOAD=SHIM, **{k: str(v) for k, v in extra.items()})
    # Under AddressSanitizer the shim comes before its runtime in the library list.
    env["ASAN_OPTIONS"] = (env.get("ASAN_OPTIONS", "") + ":verify_asan_link_order=0").lstrip(":")
    return env


start = time.time()
with tempfile.TemporaryDirectory() as tmp:
    poses = os.path.join(tmp, "poses.csv")
    with open(poses, "w") as f:
        f.write("\n".join(f"{0.001 * i},0,0,0,10,{0.01 * i}" for i in range(2 * FRAMES)) + "\n")
    # Labels: many arrays, /boxes text in chunks of many frames; shard 1/2 renders FRAMES frames.
    args = ["render", "--trajectory", poses, "--shard", "1/2", "--save", "polar,labels"] + SMALL
    reference = os.path.join(tmp, "reference.h5")
    run = subprocess.run([CLI] + args + ["--out", reference], capture_output=True, text=True)
    check(run.returncode == 0, f"reference render: {run.stderr}")

    # The writes of an uninterrupted run: the kill points are one frame's worth in the middle.
    logged = os.path.join(tmp, "logged.h5")
    run = subprocess.run([CLI] + args + ["--out", logged], capture_output=True, text=True, env=shim_env(LOG_WRITES=1))
    writes = [line.split() for line in run.stderr.splitlines() if line.startswith("W ")]
    check(run.returncode == 0 and len(writes) > 4 * FRAMES, f"logged render: {len(writes)} writes, {run.stderr[-300:]}")
    per_frame = -(-len(writes) // FRAMES)
    first = len(writes) * 3 // FRAMES
    window = range(first, first + per_frame + 2)
    # Every write whole, and those over a page also cut in half (a kill can land between their pages).
    kill_points = [(n, None) for n in window] + [(n, int(writes[n - 1][3]) // 2) for n in window
                                                 if int(writes[n - 1][3]) > 4096]

    def killed_and_resumed(point):
        n, part = point
        out = os.path.join(tmp, f"killed_{n}_{part}.h5")
        extra = {"KILL_AT_WRITE": n}
        if part is not None:
            extra["KILL_PART"] = part
        run = subprocess.run([CLI] + args + ["--out", out], capture_output=True, text=True, env=shim_env(**extra))
        if run.returncode != -9:
            return f"kill at write {n} ({part}): the render was not killed (exit {run.returncode}): {run.stderr[-300:]}"
        run = subprocess.run([CLI] + args + ["--out", out], capture_output=True, text=True)
        if run.returncode != 0:
            return f"kill at write {n} ({part}): the re-run failed (exit {run.returncode}): {run.stderr.strip()}"
        bad = differences(reference, out)
        if bad:
            return f"kill at write {n} ({part} of {writes[n - 1][3]} bytes at {writes[n - 1][2]}): resumed shard differs: {bad}"
        if "already on disk" in run.stderr:
            return "resumed"
        # Allowed, when it says why: frames that do not match their record are not kept.
        print(f"kill at write {n} ({part} of {writes[n - 1][3]} bytes at {writes[n - 1][2]}):", run.stderr.splitlines()[0])
        return "started over"

    with concurrent.futures.ThreadPoolExecutor(max_workers=4) as pool:
        results = list(pool.map(killed_and_resumed, kill_points))
    for r in results:
        check(r in ("resumed", "started over"), r)
    print(f"{len(kill_points)} kill points (writes {window[0]}..{window[-1]} of {len(writes)}, "
          f"{len(kill_points) - len(window)} of them torn): "
          f"{results.count('resumed')} resumed, {results.count('started over')} started over")

    # Frames on disk that no longer match their commit record (changed after the fact): not resumed.
    changed = os.path.join(tmp, "changed.h5")
    run = subprocess.run([CLI] + args + ["--out", changed], capture_output=True, text=True,
                         env=shim_env(KILL_AT_WRITE=len(writes) * 6 // FRAMES))
    check(run.returncode == -9, f"the render to change was not killed: {run.returncode}")
    with h5py.File(changed, "r+") as f:
        polar = f["polar"][2]
        polar[0, 0] = polar[0, 0] * 2.0 + 1.0  # (+1 alone is lost in the float's rounding above 2^24)
        f["polar"][2] = polar
    run = subprocess.run([CLI] + args + ["--out", changed], capture_output=True, text=True)
    warnings = [line for line in run.stderr.splitlines() if line.startswith("warning:")]
    check(run.returncode == 0 and len(warnings) == 1 and "do not match their commit record (/polar)" in warnings[0]
          and "starting the shard over" in warnings[0], f"a changed frame: {run.stderr}")
    check(not differences(reference, changed), "the shard started over differs from the uninterrupted one")

print(f"resume after a torn write: {time.time() - start:.1f} s")
if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("resume after a torn write: all checks passed")
