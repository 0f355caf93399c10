"""Sharded trajectories (`vksonar render --shard i/N`, `vksonar merge`), checked with h5py and numpy.

Run by ctest (tests/CMakeLists.txt) with an interpreter that imports numpy and h5py:
    python3 tests/python/check_shards.py path/to/vksonar
Checks, each of which can fail:
  - 3 shards of a trajectory (.h5, compressed and not, and frame folders) merged equal the unsharded
    run: every array bit for bit, frame_index, pose and time in order;
  - the shard is read from a Slurm array's and a Kubernetes Indexed Job's environment;
  - a shard killed half way and run again renders only the frames it lacks (.h5, folders and a ROS 2
    bag), and the result still merges into the unsharded run (the bag byte for byte);
  - merge refuses a gap, an overlap, a shard of another run and an incomplete shard with one line.
"""
import glob
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time

import h5py
import numpy as np

CLI = sys.argv[1]
SMALL = ["--backend", "cpu", "--set", "bins=64", "--set", "beams=32", "--set", "horizontal_beamwidth=4.5", "--set", "range_min=6", "--seed", "7"]
failures = []


def check(condition, what):
    if not condition:
        failures.append(what)
        print("FAIL:", what)


def vksonar(args, expect=0, env=None):
    run = subprocess.run([CLI] + args, capture_output=True, text=True, env=env)
    check(run.returncode == expect, f"exit {run.returncode} (expected {expect}) for {args}: {run.stderr}")
    return run


def same_h5(a_path, b_path, what):
    with h5py.File(a_path, "r") as a, h5py.File(b_path, "r") as b:
        check(set(a.keys()) == set(b.keys()), f"{what}: datasets {set(a.keys())} vs {set(b.keys())}")
        for name in a.keys():
            if h5py.check_string_dtype(a[name].dtype) is not None:  # /boxes: the texts, not the heap references
                check(b[name].dtype == a[name].dtype and list(a[name].asstr()[:]) == list(b[name].asstr()[:]),
                      f"{what}: /{name} differs")
                continue
            x, y = a[name][:], b[name][:]
            check(x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(),
                  f"{what}: /{name} differs ({x.shape} vs {y.shape})")
        check(b.attrs["complete"] == 1 and b.attrs["frames_written"] == a.attrs["frames_written"],
              f"{what}: complete / frames_written")
        check("shard_index" not in b.attrs, f"{what}: the merged file still has shard attributes")


def same_folders(a_dir, b_dir, what):
    frames_a = sorted(os.path.basename(p) for p in glob.glob(os.path.join(a_dir, "frame_*")))
    frames_b = sorted(os.path.basename(p) for p in glob.glob(os.path.join(b_dir, "frame_*")))
    check(frames_a == frames_b and frames_a, f"{what}: frame folders {frames_a} vs {frames_b}")
    for frame in frames_a:
        files = sorted(f for f in os.listdir(os.path.join(a_dir, frame)) if f != "meta.json")
        check(files == sorted(f for f in os.listdir(os.path.join(b_dir, frame)) if f != "meta.json"),
              f"{what}: files of {frame}")
        for name in files:
            with open(os.path.join(a_dir, frame, name), "rb") as f, open(os.path.join(b_dir, frame, name), "rb") as g:
                check(f.read() == g.read(), f"{what}: {frame}/{name} differs")


def kill_when(process, ready, what):
    deadline = time.time() + 60
    while time.time() < deadline and process.poll() is None and not ready():
        time.sleep(0.01)
    running = process.poll() is None
    process.send_signal(signal.SIGKILL)
    process.wait()
    check(running, f"{what}: the run ended before it could be killed (make the trajectory longer)")


with tempfile.TemporaryDirectory() as tmp:
    poses = os.path.join(tmp, "poses.csv")
    # A header and a comment: frame indices (trajectory lines) are not the ordinals.
    lines = ["x,y,z,roll,pitch,yaw", "# survey leg"] + [f"{0.2 * i},0,{-0.1 * i},0,10,{3 * i}" for i in range(11)]
    with open(poses, "w") as f:
        f.write("\n".join(lines) + "\n")
    p = lambda name: os.path.join(tmp, name)

    # ---- .h5: 3 shards merged == the unsharded file ----------------------------------------------
    for compress in ([], ["--compress"]):
        tag = "packed" if compress else "plain"
        vksonar(["render", "--trajectory", poses, "--out", p(f"{tag}.h5"), "--save", "polar,polar_u16"] + compress + SMALL)
        for i in range(3):
            run = vksonar(["render", "--trajectory", poses, "--out", p(f"{tag}_{i}.h5"), "--save", "polar,polar_u16",
                           "--shard", f"{i}/3"] + compress + SMALL)
            check(f"shard {i}/3 (--shard {i}/3)" in run.stderr, f"shard line: {run.stderr}")
        with h5py.File(p(f"{tag}_1.h5"), "r") as f:
            # 11 frames in 3 shards: 0..2, 3..6, 7..10; frame 3 is line 6 (header, comment).
            check((f.attrs["shard_index"], f.attrs["shard_count"], f.attrs["shard_first"], f.attrs["shard_end"]) ==
                  (1, 3, 3, 7), "shard attributes of 1/3")
            check(list(f["frame_index"][:]) == [6, 7, 8, 9], f"shard 1/3 frame_index {f['frame_index'][:]}")
            check(list(f["time"][:]) == [3.0, 4.0, 5.0, 6.0], "the time ordinal is global")
        vksonar(["merge", p(f"{tag}_merged.h5"), p(f"{tag}_2.h5"), p(f"{tag}_0.h5"), p(f"{tag}_1.h5")])
        same_h5(p(f"{tag}.h5"), p(f"{tag}_merged.h5"), f"{tag} merged")

    # ---- --save labels: the label arrays merge with the frames; shards with and without are refused -----
    vksonar(["render", "--trajectory", poses, "--out", p("labels.h5"), "--save", "polar,labels"] + SMALL)
    for i in range(3):
        vksonar(["render", "--trajectory", poses, "--out", p(f"labels_{i}.h5"), "--save", "polar,labels",
                 "--shard", f"{i}/3"] + SMALL)
    vksonar(["merge", p("labels_merged.h5"), p("labels_0.h5"), p("labels_1.h5"), p("labels_2.h5")])
    same_h5(p("labels.h5"), p("labels_merged.h5"), "labels merged")
    with h5py.File(p("labels_merged.h5"), "r") as f:
        check(f["instance"].shape == (11, 64, 32) and f["point"].shape == (11, 64, 32, 3), "merged label shapes")
        boxes = [json.loads(t) for t in f["boxes"].asstr()[:]]
        check(len(boxes) == 11 and [b["frame_index"] for b in boxes] == list(f["frame_index"][:])
              and any(b["boxes"] for b in boxes), "merged /boxes: one boxes.json per frame, in order")
    vksonar(["render", "--trajectory", poses, "--out", p("nolabels_1.h5"), "--save", "polar", "--shard", "1/3"]
            + SMALL)
    run = vksonar(["merge", p("mixed.h5"), p("labels_0.h5"), p("nolabels_1.h5"), p("labels_2.h5")], expect=2)
    check(run.stderr.count("\n") == 1 and "another run" in run.stderr and "labels" in run.stderr,
          f"merge of shards with and without labels: {run.stderr}")
    check(not os.path.exists(p("mixed.h5")), "mixed merge left a file")

    # ---- the engines' environment picks the shard ------------------------------------------------
    base = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "JOB_COMPLETION", "VKSONAR_SHARD"))}
    slurm = []
    for task in (1, 2, 3):  # sbatch --array=1-3
        env = dict(base, SLURM_ARRAY_TASK_ID=str(task), SLURM_ARRAY_TASK_MIN="1", SLURM_ARRAY_TASK_MAX="3",
                   SLURM_ARRAY_TASK_COUNT="3")
        out = p(f"slurm_{task}.h5")
        run = vksonar(["render", "--trajectory", poses, "--out", out, "--save", "polar,polar_u16"] + SMALL, env=env)
        check(f"shard {task - 1}/3 (SLURM_ARRAY_TASK_ID={task}" in run.stderr, f"slurm shard: {run.stderr}")
        slurm.append(out)
    vksonar(["merge", p("slurm_merged.h5")] + slurm)
    same_h5(p("plain.h5"), p("slurm_merged.h5"), "slurm merged")
    k8s = []
    for index in range(3):
        env = dict(base, JOB_COMPLETION_INDEX=str(index), VKSONAR_SHARD_COUNT="3")
        out = p(f"k8s_{index}")
        vksonar(["render", "--trajectory", poses, "--out", out, "--save", "polar,polar_u16"] + SMALL, env=env)
        k8s.append(out)
    vksonar(["render", "--trajectory", poses, "--out", p("frames"), "--save", "polar,polar_u16"] + SMALL)
    vksonar(["merge", p("k8s_merged")] + k8s)
    same_folders(p("frames"), p("k8s_merged"), "k8s folders merged")

    # ---- killed half way, run again: only the missing frames are rendered -------------------------
    long_poses = p("long.csv")
    with open(long_poses, "w") as f:
        f.write("\n".join(f"{0.001 * i},0,0,0,10,{0.01 * i}" for i in range(1500)) + "\n")
    # The .h5 shard saves labels too: /boxes (text of variable length) is cut back and goes on like the arrays.
    h5_save = ["--save", "polar,labels"]
    args = ["render", "--trajectory", long_poses, "--save", "polar", "--shard", "1/2"] + SMALL
    h5_args = ["render", "--trajectory", long_poses, "--shard", "1/2"] + h5_save + SMALL
    killed = p("killed.h5")

    def h5_frames():
        try:
            with h5py.File(killed, "r", locking=False) as f:
                return int(f.attrs["frames_written"])
        except Exception:
            return 0

    process = subprocess.Popen([CLI] + h5_args + ["--out", killed], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    kill_when(process, lambda: h5_frames() >= 40, ".h5 shard")
    before = h5_frames()
    check(0 < before < 750, f".h5 shard killed with {before} of 750 frames")
    run = vksonar(h5_args + ["--out", killed])
    check("already on disk" in run.stderr, f"the re-run resumed: {run.stderr}")
    rendered = int(run.stderr.split("frames rendered")[0].split(":")[-1])
    kept = re.search(r"(\d+) already on disk", run.stderr)
    kept = int(kept.group(1)) if kept else -1
    # A frame counts for a resume once its commit record is written, after frames_written is flushed
    # (src/cli/dataset_h5.cpp): a kill between the two leaves frames_written one ahead of what the
    # re-run keeps. (An ASan CI run hit that window: 40 read, 39 kept, 711 rendered.)
    check(before - 1 <= kept <= before, f"the re-run kept {kept} frames, frames_written said {before}")
    check(rendered == 750 - kept, f"the re-run rendered {rendered} frames, {kept} were kept")
    vksonar(["render", "--trajectory", long_poses, "--shard", "0/2", "--out", p("first.h5")] + h5_save + SMALL)
    vksonar(["render", "--trajectory", long_poses, "--out", p("long.h5")] + h5_save + SMALL)
    vksonar(["merge", p("long_merged.h5"), p("first.h5"), killed])
    same_h5(p("long.h5"), p("long_merged.h5"), "killed and resumed .h5 merged")
    print(f"killed .h5 shard: {before} frames on disk, {rendered} rendered by the re-run")

    folder = p("killed")
    done = lambda: len(glob.glob(os.path.join(folder, "frame_*", "meta.json")))
    process = subprocess.Popen([CLI] + args + ["--out", folder], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    kill_when(process, lambda: done() >= 40, "folder shard")
    before = done()
    check(0 < before < 750, f"folder shard killed with {before} of 750 frames")
    vksonar(["render", "--trajectory", long_poses, "--save", "polar", "--shard", "0/2", "--out", p("first_f")] + SMALL)
    run = vksonar(["merge", p("early"), p("first_f"), folder], expect=2)
    check("incomplete" in run.stderr and run.stderr.count("\n") == 1, f"merge of an incomplete shard: {run.stderr}")
    run = vksonar(args + ["--out", folder])
    check(f"{before} already on disk" in run.stderr, f"the folder re-run resumed: {run.stderr}")
    vksonar(["render", "--trajectory", long_poses, "--save", "polar", "--out", p("long_f")] + SMALL)
    vksonar(["merge", p("long_f_merged"), p("first_f"), folder])
    same_folders(p("long_f"), p("long_f_merged"), "killed and resumed folders merged")
    print(f"killed folder shard: {before} frames on disk before the re-run")

    # A ROS 2 bag shard killed half way keeps the frames of its whole chunks (~1 MiB each); the re-run
    # writes them into a new bag and renders only the rest, and the bags merge into the unsharded one.
    bag = p("killed.mcap")
    bag_args = ["render", "--trajectory", long_poses, "--save", "polar", "--shard", "1/2"] + SMALL
    process = subprocess.Popen([CLI] + bag_args + ["--out", bag], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    kill_when(process, lambda: os.path.exists(bag) and os.path.getsize(bag) > (3 << 20), "bag shard")
    killed_size = os.path.getsize(bag)
    vksonar(["render", "--trajectory", long_poses, "--save", "polar", "--shard", "0/2", "--out", p("first.mcap")]
            + SMALL)
    run = vksonar(["merge", p("early.mcap"), p("first.mcap"), bag], expect=2)
    check("is incomplete" in run.stderr and "not closed" in run.stderr and run.stderr.count("\n") == 1,
          f"merge of a killed bag shard: {run.stderr}")
    run = vksonar(bag_args + ["--out", bag])
    before = int(run.stderr.split(" already on disk")[0].split(",")[-1]) if "already on disk" in run.stderr else 0
    rendered = int(run.stderr.split("frames rendered")[0].split(":")[-1])
    check(0 < before < 750 and rendered == 750 - before,
          f"the bag re-run kept {before} frames of a {killed_size}-byte bag and rendered {rendered}: {run.stderr}")
    os.makedirs(p("bag_whole"))
    os.makedirs(p("bag_merged"))
    vksonar(["render", "--trajectory", long_poses, "--save", "polar", "--out", p("bag_whole/long.mcap")] + SMALL)
    vksonar(["merge", p("bag_merged/long.mcap"), p("first.mcap"), bag])
    with open(p("bag_whole/long.mcap"), "rb") as f, open(p("bag_merged/long.mcap"), "rb") as g:
        check(f.read() == g.read(), "killed and resumed bag shard merged differs from the unsharded bag")
    print(f"killed bag shard: {before} frames in whole chunks of a {killed_size}-byte bag, {rendered} rendered by "
          "the re-run")

    # ---- merge refuses, one line each -------------------------------------------------------------
    def refused(args, *expected):
        run = vksonar(["merge"] + args, expect=2)
        check(run.stderr.count("\n") == 1 and all(e in run.stderr for e in expected),
              f"merge {args}: expected one line with {expected}: {run.stderr}")
        check(not os.path.exists(args[0]), f"merge {args}: output left behind")

    refused([p("m1.h5"), p("plain_0.h5"), p("plain_2.h5")], "shard 1/3 is missing", "frames 3..6")
    refused([p("m2.h5"), p("plain_0.h5"), p("plain_1.h5"), p("plain_1.h5"), p("plain_2.h5")], "given twice")
    vksonar(["render", "--trajectory", poses, "--out", p("other_1.h5"), "--save", "polar,polar_u16", "--shard", "1/3",
             "--seed", "8"] + SMALL[:-2])
    refused([p("m3.h5"), p("plain_0.h5"), p("other_1.h5"), p("plain_2.h5")], "another run", "seed: 7 vs 8")
    vksonar(["render", "--trajectory", poses, "--out", p("four_1.h5"), "--save", "polar,polar_u16", "--shard", "1/4"]
            + SMALL)
    refused([p("m4.h5"), p("plain_0.h5"), p("four_1.h5"), p("plain_2.h5")], "different splits")
    refused([p("m5.h5"), p("plain.h5")], "not a shard")

    # ---- a re-run into an .h5 of another shard or run is refused, the file kept --------------------
    shard_1 = ["render", "--trajectory", poses, "--out", p("plain_1.h5"), "--save", "polar,polar_u16"]
    with open(p("plain_1.h5"), "rb") as f:
        before = f.read()
    run = vksonar(shard_1 + ["--shard", "1/3", "--seed", "8"] + SMALL[:-2], expect=2)
    check(run.stderr.count("\n") == 1 and "holds another run (seed: 7 vs 8)" in run.stderr, f"seed clash: {run.stderr}")
    run = vksonar(shard_1 + ["--shard", "2/3"] + SMALL, expect=2)
    check("holds shard 1/3, not shard 2/3" in run.stderr, f"shard clash: {run.stderr}")
    # Refused after the output was opened (the seed clash is found reading the file): the file stays.
    with open(p("plain_1.h5"), "rb") as f:
        check(f.read() == before, "refused re-runs left the shard file as it was")
    run = vksonar(shard_1 + ["--shard", "1/3"] + SMALL)
    check("4 already on disk" in run.stderr and ": 0 frames rendered" in run.stderr, f"complete re-run: {run.stderr}")
    with h5py.File(p("plain_1.h5"), "r") as f:
        check(f.attrs["complete"] == 1 and f.attrs["frames_written"] == 4, "a complete shard stays complete")
    vksonar(["merge", p("again.h5"), p("plain_0.h5"), p("plain_1.h5"), p("plain_2.h5")])
    same_h5(p("plain.h5"), p("again.h5"), "merged after a no-op re-run")

if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("shards: all checks passed")
