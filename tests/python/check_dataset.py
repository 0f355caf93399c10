"""The HDF5 dataset file (`vksonar render --out run.h5`), read back with h5py the way a user does.

Run by ctest (tests/CMakeLists.txt) with an interpreter that imports numpy and h5py:
    python3 tests/python/check_dataset.py path/to/vksonar
Checks, each of which can fail:
  - every frame of the file equals polar.npy / polar_u16.npy of the per-frame folders of the same
    trajectory and seed, bit for bit; compressed equals uncompressed;
  - pose, frame_index, time, the tables and the attributes say what was rendered;
  - with --save labels,flow, the six label arrays and /flow equal the folders' instance.npy ... point.npy, one chunk a
    frame, compressed with --compress; without it there are none;
  - with --save labels, /boxes holds each frame's boxes.json text, character for character, with and
    without --compress; without labels there is no /boxes;
  - a run killed half way leaves a readable file under its temporary name (.~NAME.writing-PID) and
    no file at OUT: frames_written whole frames, equal to the same frames of an uninterrupted run,
    and complete = 0;
  - what a dataset cannot hold is refused with one line (exit 2) and no file is left;
  - a write that fails (a file size limit, as a full disk fails it) ends the run with one line, exit 1 and
    no crash (HDF5's exit handler used to crash on the file it could not close): no file at OUT and no
    temporary; a frame-folder run keeps only its whole frames and says which;
  - a FIFO (or a link to one) at OUT is refused, exit 2, and stays a FIFO.
"""
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time

import json

import h5py
import numpy as np

CLI = sys.argv[1]
SMALL = ["--backend", "cpu", "--set", "bins=64", "--set", "beams=32", "--set", "range_min=6", "--seed", "5"]
failures = []


def check(condition, what):
    if not condition:
        failures.append(what)
        print("FAIL:", what)


def render(args, expect=0):
    run = subprocess.run([CLI, "render"] + args, capture_output=True, text=True)
    check(run.returncode == expect, f"exit {run.returncode} (expected {expect}) for {args}: {run.stderr}")
    return run


with tempfile.TemporaryDirectory() as tmp:
    poses = os.path.join(tmp, "poses.csv")
    lines = ["x,y,z,roll,pitch,yaw"] + [f"{0.2 * i},0,{-0.1 * i},0,10,{3 * i}" for i in range(6)]
    with open(poses, "w") as f:
        f.write("\n".join(lines) + "\n")
    folder = os.path.join(tmp, "frames")
    render(["--trajectory", poses, "--out", folder, "--save", "polar,polar_u16"] + SMALL)
    plain = os.path.join(tmp, "run.h5")
    render(["--trajectory", poses, "--out", plain, "--save", "polar,polar_u16"] + SMALL)
    # The same command twice writes the same bytes: HDF5's object timestamps are off (with them, 14
    # header bytes differed and a checksum of the file said two equal datasets were not).
    again = os.path.join(tmp, "again.h5")
    time.sleep(1.1)  # HDF5's timestamps count whole seconds: with them on, this run's would differ
    render(["--trajectory", poses, "--out", again, "--save", "polar,polar_u16"] + SMALL)
    with open(plain, "rb") as a, open(again, "rb") as b:
        check(a.read() == b.read(), "two runs of one command wrote different .h5 bytes")
    packed = os.path.join(tmp, "packed.h5")
    render(["--trajectory", poses, "--out", packed, "--save", "polar,polar_u16", "--compress"] + SMALL)

    with h5py.File(plain, "r") as f, h5py.File(packed, "r") as g:
        check(f["polar"].shape == (6, 64, 32) and f["polar"].dtype == np.float32, f"polar {f['polar'].shape}")
        check(f["polar_u16"].dtype == np.uint16, "polar_u16 dtype")
        check(f.attrs["frames_written"] == 6 and f.attrs["complete"] == 1, "frames_written / complete")
        check(f.attrs["format"] == "vksonar-dataset-1", "format")
        check(len(f.attrs["vksonar_version"]) > 0, "vksonar_version")
        check(len(f.attrs["scene_fnv1a64"]) == 16, "scene_fnv1a64 of an unsharded run")
        check(f.attrs["seed"] == 5 and f.attrs["bins"] == 64 and f.attrs["beams"] == 32, "seed / bins / beams")
        check(f["ranges_m"].shape == (64,) and f["beam_angles_rad"].shape == (32,), "tables")
        check(list(f["frame_index"][:]) == [2, 3, 4, 5, 6, 7], f"frame_index {f['frame_index'][:]}")
        check(np.array_equal(f["time"][:], np.arange(6.0)), "time is the ordinal without a time column")
        for i in range(6):
            line = i + 2
            expected_pose = [0.2 * i, 0, -0.1 * i, 0, 10, 3 * i]
            check(np.allclose(f["pose"][i], expected_pose, rtol=0, atol=1e-12), f"pose {i}: {f['pose'][i]}")
            frame = os.path.join(folder, f"frame_{line:06d}")
            check(np.array_equal(f["polar"][i], np.load(os.path.join(frame, "polar.npy"))), f"polar {i}")
            check(np.array_equal(f["polar_u16"][i], np.load(os.path.join(frame, "polar_u16.npy"))), f"u16 {i}")
            check(np.array_equal(g["polar"][i], f["polar"][i]), f"compressed polar {i}")
        check(g["polar"].compression == "gzip" and f["polar"].compression is None, "compression")
        check(f["polar"].chunks == (1, 64, 32), f"one chunk per frame: {f['polar'].chunks}")
        config = json.loads(f.attrs["config"])
        check(config["bins"] == 64 and config["range_min"] == 6, "config attribute")
        meta = json.load(open(os.path.join(folder, "frame_000002", "meta.json")))
        check(f.attrs["beam_geometry"] == meta["beam_geometry"]["used"] == "line_array"
              and f.attrs["beam_geometry_why"] == meta["beam_geometry"]["why"], "beam_geometry as meta.json")
        noise = json.loads(f.attrs["noise"])
        check(noise == meta["noise"] and len(noise["floor_db_by_beam"]) == 32, "noise as meta.json")
        objects = json.loads(f.attrs["objects"])
        check(objects == meta["objects"] and [c["name"] for c in objects["classes"]][:2] == ["seabed", "piling"],
              "objects as meta.json")

    # --save labels: the label arrays beside polar, as the per-frame folders' files.
    LABELS = {"instance": ("instance.npy", np.uint16, ()), "class": ("class.npy", np.uint16, ()),
              "instance_fraction": ("instance_fraction.npy", np.float32, ()),
              "elevation": ("elevation.npy", np.float32, ()),
              "elevation_spread": ("elevation_spread.npy", np.float32, ()), "point": ("point.npy", np.float32, (3,)),
              "flow": ("flow.npy", np.float32, (2,))}
    labelled = os.path.join(tmp, "labelled")
    render(["--trajectory", poses, "--out", labelled, "--save", "polar,labels,flow"] + SMALL)
    for name, compress in (("labels.h5", []), ("labels_packed.h5", ["--compress"])):
        render(["--trajectory", poses, "--out", os.path.join(tmp, name), "--save", "polar,labels,flow"] + compress +
               SMALL)
    with h5py.File(os.path.join(tmp, "labels.h5"), "r") as f, h5py.File(os.path.join(tmp, "labels_packed.h5")) as g:
        check("polar_u16" not in f, "labels without polar_u16")
        labelled_cells = 0
        for name, (npy, dtype, tail) in LABELS.items():
            d = f[name]
            check(d.dtype == dtype and d.shape == (6, 64, 32) + tail, f"/{name}: {d.dtype} {d.shape}")
            check(d.chunks == (1, 64, 32) + tail, f"/{name}: one chunk per frame: {d.chunks}")
            check(d.compression is None and g[name].compression == "gzip", f"/{name} compression")
            for i in range(6):
                expected = np.load(os.path.join(labelled, f"frame_{i + 2:06d}", npy))
                check(np.array_equal(d[i], expected, equal_nan=True), f"/{name} frame {i} differs from {npy}")
                check(np.array_equal(g[name][i], expected, equal_nan=True), f"compressed /{name} frame {i}")
            check(g[name].shuffle and g[name].compression_opts == 4, f"/{name}: shuffle + deflate 4")
            # vksonar deflates the rows itself on several threads and writes the chunks as they are; they
            # are the bytes HDF5's own shuffle and deflate filters store for the same row (h5py writing
            # it into a file in memory), so any HDF5 reader decodes them as before.
            with h5py.File(os.path.join(tmp, f"filtered_{name}.h5"), "w", driver="core", backing_store=False) as m:
                ref = m.create_dataset("row", shape=g[name].shape, dtype=g[name].dtype, chunks=g[name].chunks,
                                       shuffle=True, compression="gzip", compression_opts=4)
                for i in range(6):
                    ref[i] = g[name][i]
                    origin = (i,) + (0,) * (len(g[name].shape) - 1)
                    ours, theirs = g[name].id.read_direct_chunk(origin), ref.id.read_direct_chunk(origin)
                    check(ours == theirs, f"/{name} frame {i}: the stored chunk is not HDF5's shuffle + deflate "
                                          f"of the row ({len(ours[1])} vs {len(theirs[1])} bytes)")
        labelled_cells = int((f["instance"][:] > 0).sum())
        flow = f["flow"][:]
        check(np.isfinite(flow[:-1]).any() and not np.isfinite(flow[-1]).any(),
              "flow: finite before the last frame, all NaN in it (no next frame)")
        check(labelled_cells > 100, f"the labels label something: {labelled_cells} cells")
        ids = {o["id"]: o["class_id"] for o in json.loads(f.attrs["objects"])["instances"]}
        instance, classes = f["instance"][:], f["class"][:]
        check(set(np.unique(instance[instance > 0]).tolist()) <= set(ids), "instance ids are the objects' ids")
        check(all(ids.get(int(i), 0) == c for i, c in zip(instance.ravel(), classes.ravel())),
              "class is the class of the instance in the objects table")
        for i in range(6):
            polar = np.load(os.path.join(labelled, f"frame_{i + 2:06d}", "polar.npy"))
            check(np.array_equal(f["polar"][i], polar), f"polar {i} with labels")
        # /boxes: one UTF-8 string per frame, the frame folder's boxes.json as it is.
        for h in (f, g):
            d = h["boxes"]
            check(d.shape == (6,) and h5py.check_string_dtype(d.dtype) is not None
                  and h5py.check_string_dtype(d.dtype).encoding == "utf-8" and h5py.check_string_dtype(d.dtype).length
                  is None, f"/boxes: {d.dtype} {d.shape}")
            check(d.chunks is not None and d.maxshape == (None,), f"/boxes grows per frame: {d.chunks} {d.maxshape}")
            texts = d.asstr()[:]
            boxed = 0
            for i in range(6):
                with open(os.path.join(labelled, f"frame_{i + 2:06d}", "boxes.json"), encoding="utf-8") as src:
                    expected = src.read()
                check(texts[i] == expected, f"{h.filename}: /boxes[{i}] is not boxes.json's text")
                parsed = json.loads(texts[i])
                check(parsed == json.loads(expected) and parsed["frame_index"] == i + 2,
                      f"{h.filename}: /boxes[{i}] parses to another object than boxes.json")
                boxed += len(parsed["boxes"])
            check(boxed > 0, "/boxes: some frame has a box")
    with h5py.File(plain, "r") as f:
        check(not any(name in f for name in LABELS), f"no label arrays without --save labels: {list(f.keys())}")
        check("boxes" not in f, "no /boxes without --save labels")

    # A time column (header t / time / time_s) fills /time and each folder's meta.json time_s.
    timed = os.path.join(tmp, "timed.csv")
    with open(timed, "w") as f:
        f.write("time,x,y,z,roll,pitch,yaw\n0.0,0,0,0,0,10,0\n0.1,0.5,0,0,0,10,5\n0.25,1,0,0,0,10,10\n")
    render(["--trajectory", timed, "--out", os.path.join(tmp, "timed.h5")] + SMALL)
    render(["--trajectory", timed, "--out", os.path.join(tmp, "timed"), "--save", "polar"] + SMALL)
    with h5py.File(os.path.join(tmp, "timed.h5"), "r") as f:
        check(np.array_equal(f["time"][:], [0.0, 0.1, 0.25]), f"time column: {f['time'][:]}")
        check(f.attrs["time_unit"].startswith("s "), "time_unit")
    with open(os.path.join(tmp, "timed", "frame_000003", "meta.json")) as f:
        check(json.load(f)["time_s"] == 0.1, "meta.json time_s")
    with open(timed, "a") as f:
        f.write("0.2,0,0,0,0,10,0\n")
    run = render(["--trajectory", timed, "--out", os.path.join(tmp, "backwards.h5")] + SMALL, expect=2)
    check("timed.csv:5: time 0.2 is before" in run.stderr, f"time going backwards: {run.stderr}")

    # Killed half way: the frames written before the kill are whole and readable.
    long_poses = os.path.join(tmp, "long.csv")
    with open(long_poses, "w") as f:
        f.write("\n".join(f"{0.001 * i},0,0,0,10,{0.01 * i}" for i in range(3000)) + "\n")
    out = os.path.join(tmp, "killed.h5")
    process = subprocess.Popen([CLI, "render", "--trajectory", long_poses, "--out", out] + SMALL,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # An unsharded run writes a temporary beside OUT and renames it onto OUT only when it is complete.
    killed = os.path.join(tmp, f".~killed.h5.writing-{process.pid}")
    deadline = time.time() + 60
    while time.time() < deadline and process.poll() is None:
        if os.path.exists(killed) and os.path.getsize(killed) > 200_000:
            break
        time.sleep(0.02)
    still_running = process.poll() is None
    process.send_signal(signal.SIGKILL)
    process.wait()
    check(still_running, "the long run ended before it could be killed (make the trajectory longer)")
    check(not os.path.exists(out), "a killed unsharded run leaves nothing at OUT")
    with h5py.File(killed, "r") as f:
        written = int(f.attrs["frames_written"])
        check(f.attrs["complete"] == 0, "a killed run is not complete")
        check(0 < written < 3000, f"frames_written {written}")
        check(f["polar"].shape[0] >= written, "polar holds frames_written frames")
        first = list(f["frame_index"][:written])
        check(first == list(range(1, written + 1)), "frame_index of the whole frames")
        whole = f["polar"][:written]
    # The same frames of an uninterrupted run.
    head = os.path.join(tmp, "head.csv")
    with open(long_poses) as src, open(head, "w") as dst:
        dst.writelines(src.readlines()[:written])
    reference = os.path.join(tmp, "head.h5")
    render(["--trajectory", head, "--out", reference] + SMALL)
    with h5py.File(reference, "r") as f:
        check(np.array_equal(f["polar"][:], whole), f"the {written} frames before the kill equal a whole run's")
    print(f"killed run: {written} whole frames readable")

    # Refused: one line, exit 2, no file.
    bad = os.path.join(tmp, "bad.h5")
    run = render(["--out", bad, "--save", "fan"] + SMALL, expect=2)
    check(run.stderr.count("\n") == 1 and "--save fan" in run.stderr, f"one line naming --save fan: {run.stderr}")
    check(not os.path.exists(bad), "no file left after a refusal")
    run = render(["--out", bad, "--save", "labels"] + SMALL, expect=2)
    check(run.stderr.count("\n") == 1 and "nothing for the dataset" in run.stderr, f"labels alone: {run.stderr}")
    check(not os.path.exists(bad), "no file left after a refusal")
    run = render(["--out", os.path.join(tmp, "dir_out"), "--compress"] + SMALL, expect=2)
    check("--compress" in run.stderr, f"--compress without .h5: {run.stderr}")
    run = render(["--out", os.path.join(tmp, "no_such_folder", "x.h5")] + SMALL, expect=2)
    check("no_such_folder" in run.stderr, f"missing folder named: {run.stderr}")



def limited_to(size):
    """A preexec_fn: writes past `size` bytes fail with EFBIG instead of killing the process (SIGXFSZ)."""
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))
    return apply


with tempfile.TemporaryDirectory() as tmp:
    # A failed write: one line, exit 1, no crash, nothing left at OUT.
    poses = os.path.join(tmp, "poses.csv")
    with open(poses, "w") as f:
        f.write("\n".join(f"{0.1 * i},0,0,0,10,0" for i in range(5)) + "\n")
    whole = os.path.join(tmp, "whole.h5")
    render(["--trajectory", poses, "--out", whole] + SMALL)
    whole_size = os.path.getsize(whole)
    os.remove(whole)
    # at the first write, and half way through the run
    for name, limit in (("full.h5", 1024), ("full_later.h5", whole_size // 2)):
        out = os.path.join(tmp, name)
        run = subprocess.run([CLI, "render", "--trajectory", poses, "--out", out] + SMALL, capture_output=True,
                             text=True, preexec_fn=limited_to(limit))
        errors = [line for line in run.stderr.splitlines() if line.startswith("error:")]
        check(run.returncode == 1, f"{name}: a failed write exits 1, not {run.returncode}: {run.stderr}")
        check(len(errors) == 1 and "cannot write" in errors[0], f"{name}: one error line: {run.stderr}")
        check(not os.path.exists(out), f"{name}: nothing at OUT after a failed write")
        check(not [f for f in os.listdir(tmp) if f.startswith(".~")], f"{name}: no temporary left: {os.listdir(tmp)}")

    # A frame-folder run whose third frame fails: the first two stay whole, the third is gone, and the
    # error says so. Facing away (yaw 180) the fan is dark and its PNG small; facing the scene it is not.
    facing = os.path.join(tmp, "facing.csv")
    with open(facing, "w") as f:
        f.write("0,0,0,0,10,180\n0,0,0,0,10,180\n0,0,0,0,10,0\n0,0,0,0,10,180\n")
    quiet = ["--set", "effects.speckle=off", "--set", "effects.ambient_noise=off", "--save", "fan"]
    sizes = os.path.join(tmp, "sizes")
    render(["--trajectory", facing, "--out", sizes] + quiet + SMALL)
    png = [os.path.getsize(os.path.join(sizes, f"frame_00000{i}", "fan.png")) for i in range(1, 5)]
    check(png[2] > max(png[0], png[1], png[3]) + 4096, f"the lit frame's fan is the largest file: {png}")
    folder = os.path.join(tmp, "cut")
    run = subprocess.run([CLI, "render", "--trajectory", facing, "--out", folder] + quiet + SMALL,
                         capture_output=True, text=True, preexec_fn=limited_to((png[2] + max(png[0], png[1])) // 2))
    check(run.returncode == 1, f"folder: exit {run.returncode}: {run.stderr}")
    check(sorted(os.listdir(folder)) == ["frame_000001", "frame_000002"], f"folder holds: {os.listdir(folder)}")
    for frame in ("frame_000001", "frame_000002"):
        check(sorted(os.listdir(os.path.join(folder, frame))) == ["fan.png", "meta.json"], f"{frame} whole")
    check("holds this run's first 2 frames, each whole (frame_000001 to frame_000002)" in run.stderr,
          f"the error says what OUT holds: {run.stderr}")

    # A FIFO at OUT, or a link to one: refused, and left a FIFO (the rename used to put a file in its place).
    fifo = os.path.join(tmp, "pipe.h5")
    os.mkfifo(fifo)
    link = os.path.join(tmp, "link.h5")
    os.symlink(fifo, link)
    for out in (fifo, link):
        run = render(["--out", out] + SMALL, expect=2)
        check("not a regular file" in run.stderr, f"a FIFO at OUT named: {run.stderr}")
    # export and merge write through the same check: a FIFO at their OUT is refused and left as it was.
    fifo_json = os.path.join(tmp, "pipe.json")
    os.mkfifo(fifo_json)
    run = subprocess.run([CLI, "export", "coco", plain, fifo_json], capture_output=True, text=True)
    check(run.returncode == 2 and "not a regular file" in run.stderr, f"export coco to a FIFO: {run.returncode} {run.stderr}")
    run = subprocess.run([CLI, "merge", fifo, plain], capture_output=True, text=True)
    check(run.returncode == 2 and "exists" in run.stderr, f"merge to a FIFO: {run.returncode} {run.stderr}")
    import stat
    for path in (fifo, fifo_json):
        check(stat.S_ISFIFO(os.stat(path).st_mode), f"{path} is still a FIFO")

if failures:
    print(f"{len(failures)} check(s) failed")
    sys.exit(1)
print("dataset file: all checks passed")
