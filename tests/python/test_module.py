"""The Python module against the CLI's files for the same inputs, its errors and its numpy layouts.

Run by ctest (`python_module`, tests/CMakeLists.txt) with PYTHONPATH at the built module and
VKSONAR_CLI at the built executable.
"""
import json
import os
import re
import struct
import subprocess
import threading
import time

import numpy as np
import pytest

import vksonar

CLI = os.environ["VKSONAR_CLI"]
ASSETS = os.environ["VKSONAR_ASSET_DIR"]
SCENE = os.path.join(ASSETS, "scenes", "default.gltf")
KEYS = {"bins": 64, "beams": 48, "range_min": 6, "display.fan_width": 256}
POSE = (0.5, -0.2, 0.1, 0.0, 10.0, 3.0)


def small_config():
    config = vksonar.Config.preset("default")
    for key, value in KEYS.items():
        config.set(key, value)
    return config


def cli(tmp_path, *extra):
    args = [CLI, "render", "--scene", SCENE, "--backend", "cpu", "--seed", "9", "--out", str(tmp_path)]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    run = subprocess.run(args + ["--pose", ",".join(str(v) for v in POSE)] + list(extra),
                         capture_output=True, text=True)
    return run


@pytest.fixture(scope="module")
def renderer():
    return vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", seed=9,
                            outputs=["depth", "normals", "echo"])


def test_arrays_equal_the_cli_files(tmp_path, renderer):
    assert cli(tmp_path, "--save", "default,depth,normals,echo").returncode == 0
    frame = renderer.render(POSE, frame=0)
    assert np.array_equal(frame.polar, np.load(tmp_path / "polar.npy"))
    assert np.array_equal(frame.polar_u16, np.load(tmp_path / "polar_u16.npy"))
    assert np.array_equal(frame.depth, np.load(tmp_path / "depth.npy"))
    assert np.array_equal(frame.normals, np.load(tmp_path / "normals.npy"))
    assert np.array_equal(frame.echo, np.load(tmp_path / "echo.npy"))
    width, height = struct.unpack(">II", (tmp_path / "fan.png").read_bytes()[16:24])  # the PNG's IHDR
    assert frame.fan.shape == (height, width, 3)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert frame.meta["ranges_m"] == meta["ranges_m"]
    assert frame.meta["beam_angles_rad"] == meta["beam_angles_rad"]
    assert frame.meta["config"] == meta["config"]
    assert frame.meta["seed"] == 9 and frame.meta["pose"]["yaw_deg"] == 3.0
    # every key of the CLI's meta.json, the same values but for why the backend was chosen
    # (but `files`: the files the CLI wrote before meta.json, its commit record; Python writes none)
    assert list(frame.meta) == [key for key in meta if key != "files"]
    for key in ("vksonar_version", "scene", "scene_fnv1a64", "objects", "backend", "device"):
        assert frame.meta[key] == meta[key], key
    assert meta["backend_reason"] == "--backend cpu" and frame.meta["backend_reason"] == "Renderer(backend='cpu')"


def test_the_default_backend_is_the_clis_auto(tmp_path):
    # Renderer() without backend= runs what `vksonar render` runs without --backend (its auto rule:
    # a GPU runs Vulkan, lavapipe or no device the CPU backend), and says why in the same words;
    # the frame is then the CLI's, bit for bit.
    args = [CLI, "render", "--scene", SCENE, "--seed", "9", "--out", str(tmp_path),
            "--pose", ",".join(str(v) for v in POSE)]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    assert subprocess.run(args, capture_output=True, text=True).returncode == 0
    meta = json.loads((tmp_path / "meta.json").read_text())
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), seed=9)
    frame = renderer.render(POSE, frame=0)
    assert meta["backend_reason"].startswith("auto: ")
    assert renderer.backend == meta["backend"] and frame.meta["backend"] == meta["backend"]
    assert frame.meta["backend_reason"] == meta["backend_reason"] and frame.meta["device"] == meta["device"]
    assert np.array_equal(frame.polar, np.load(tmp_path / "polar.npy"))
    explicit = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="auto", seed=9)
    assert explicit.backend == renderer.backend


def test_a_scenes_effect_requests_layer_as_in_the_cli(tmp_path):
    # A glTF scene's extras.vksonar.effects sit between the preset and the user's keys (CLI: preset <
    # scene effects < --config < --quality < --set); a Renderer applies them the same way, so its frame
    # is the CLI's for the same scene, and a key the user set still wins over the scene's request.
    with open(SCENE) as f:
        doc = json.load(f)
    doc["scenes"][0]["extras"] = {"vksonar": {"effects": {"speckle": "off", "vertical_sidelobes": "off"}}}
    scene_path = tmp_path / "quiet.gltf"
    scene_path.write_text(json.dumps(doc))
    args = [CLI, "render", "--scene", str(scene_path), "--backend", "cpu", "--seed", "9", "--out",
            str(tmp_path / "cli"), "--pose", ",".join(str(v) for v in POSE), "--set", "effects.vertical_sidelobes=on"]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    assert subprocess.run(args, capture_output=True, text=True).returncode == 0
    meta = json.loads((tmp_path / "cli" / "meta.json").read_text())
    config = small_config()
    config.set("effects.vertical_sidelobes", "on")
    frame = vksonar.Renderer(vksonar.Scene.load(str(scene_path)), config, backend="cpu", seed=9).render(POSE, frame=0)
    assert meta["effects"]["speckle"]["on"] is False and meta["effects"]["vertical_sidelobes"]["on"] is True
    # meta says which the scene decided: speckle (no later layer touched it), not the side lobes (--set did)
    assert meta["effects"]["speckle"]["why"] == "off: the scene requests it (scenes[N].extras.vksonar.effects)"
    assert meta["effects"]["vertical_sidelobes"]["why"].startswith("on in config")
    assert meta["effects"]["ambient_noise"]["why"].startswith("auto: ")
    assert frame.meta["effects"] == meta["effects"] and frame.meta["config"] == meta["config"]
    assert np.array_equal(frame.polar, np.load(tmp_path / "cli" / "polar.npy"))
    assert config.to_dict()["effects"]["speckle"] == "auto"  # the Config itself is left as the user made it


def test_config_layers_apply_in_the_clis_order(tmp_path):
    # The CLI checks how keys agree once, after every layer, and applies --quality under --set whatever
    # their order on the command line; Config does the same, whatever the order of the calls.
    config = small_config()
    config.set("range_min", 50)  # past the preset's range_max (40) until the next call
    config.set("range_max", 100)
    config.set("accuracy.pixels_per_beam", 3)
    config.quality("fast")  # after the set, as on the CLI: the set still wins
    assert config.to_dict()["accuracy"]["pixels_per_beam"] == 3
    config.set("range_max", np.float64(90.0))  # numpy scalars as the numbers they hold
    config.set("range_min", np.int64(45))
    assert (config.to_dict()["range_min"], config.to_dict()["range_max"]) == (45, 90)
    run = cli(tmp_path, "--set", "range_min=50", "--set", "range_max=100", "--set", "accuracy.pixels_per_beam=3",
              "--quality", "fast", "--set", "range_max=90", "--set", "range_min=45")
    assert run.returncode == 0, run.stderr
    frame = vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend="cpu", seed=9).render(POSE, frame=0)
    assert np.array_equal(frame.polar, np.load(tmp_path / "polar.npy"))
    assert frame.meta["config"] == json.loads((tmp_path / "meta.json").read_text())["config"]
    crossed = small_config()
    crossed.set("range_min", 50)  # the keys disagree: refused when a Renderer takes the config
    with pytest.raises(ValueError, match="range_max"):
        vksonar.Renderer(vksonar.Scene.load(SCENE), crossed, backend="cpu")
    sonar_file = tmp_path / "mysonar.json"
    sonar_file.write_text(json.dumps({"beams": 48, "bins": 64, "range_min": 6}))
    from_file = vksonar.Config.from_file(str(sonar_file))  # as --sonar FILE.json reads it
    assert from_file.to_dict()["name"] == "mysonar" and from_file.to_dict()["beams"] == 48


def test_scene_scale_and_asset_root_are_the_clis(tmp_path):
    # The CLI applies scene.scale as it loads the scene; Scene.load(scale=) does here, and a config that
    # says another scale than the scene was loaded with is refused, naming the fix.
    run = cli(tmp_path, "--set", "scene.scale=0.5")
    assert run.returncode == 0, run.stderr
    config = small_config()
    config.set("scene.scale", 0.5)
    with pytest.raises(ValueError, match=r"scene.scale = 0.5 in the config, but the scene was loaded at scale 1.0"):
        vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend="cpu")
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE, scale=0.5), config, backend="cpu", seed=9)
    frame = renderer.render(POSE, frame=0)
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert np.array_equal(frame.polar, np.load(tmp_path / "polar.npy"))
    assert frame.meta["config"] == meta["config"] and frame.meta["scene_fnv1a64"] == meta["scene_fnv1a64"]
    plain = vksonar.Renderer(vksonar.Scene.load(SCENE, scale=0.5), small_config(), backend="cpu", seed=9)
    assert plain.render(POSE, frame=0).meta["config"]["scene"]["scale"] == 0.5  # what was applied


def test_a_trajectorys_time_column_is_time_s(tmp_path, renderer):
    # A trajectory with a time column gives meta.json a time_s; render(time_s=) gives frame.meta the
    # same key at the same place.
    poses = tmp_path / "timed.csv"
    poses.write_text("t,x,y,z,roll,pitch,yaw\n100.5," + ",".join(str(v) for v in POSE) + "\n")
    args = [CLI, "render", "--scene", SCENE, "--backend", "cpu", "--seed", "9", "--trajectory", str(poses),
            "--save", "polar", "--out", str(tmp_path / "run")]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    assert subprocess.run(args, capture_output=True, text=True).returncode == 0
    folder = next((tmp_path / "run").glob("frame_*"))
    meta = json.loads((folder / "meta.json").read_text())
    frame = renderer.render(POSE, frame=meta["frame_index"], time_s=100.5)
    assert meta["time_s"] == 100.5 and frame.meta["time_s"] == 100.5
    assert list(frame.meta) == [key for key in meta if key != "files"]
    assert np.array_equal(frame.polar, np.load(folder / "polar.npy"))
    assert "time_s" not in renderer.render(POSE, frame=0).meta


def test_frame_pose_is_the_clis_pose_frame(tmp_path):
    args = [CLI, "render", "--scene", SCENE, "--backend", "cpu", "--seed", "9", "--pose", "frame", "--save", "polar",
            "--out", str(tmp_path)]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    run = subprocess.run(args, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    pose = json.loads((tmp_path / "meta.json").read_text())["pose"]
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", seed=9)
    framed = renderer.frame_pose()
    assert framed == (pose["x_m"], pose["y_m"], pose["z_m"], pose["roll_deg"], pose["pitch_deg"], pose["yaw_deg"])
    assert np.array_equal(renderer.render(framed, frame=0).polar, np.load(tmp_path / "polar.npy"))


def test_a_scene_in_other_units_gets_the_clis_warning(tmp_path):
    # The CLI warns about a scene thousands of times the range window ("--set scene.scale=0.001 ...");
    # Python says the same, with the Scene.load argument that fixes it.
    run = subprocess.run([CLI, "render", "--scene", SCENE, "--backend", "cpu", "--set", "scene.scale=1000",
                          "--set", "bins=64", "--set", "beams=48", "--save", "polar", "--out", str(tmp_path)],
                         capture_output=True, text=True)
    cli_lines = [line for line in run.stderr.splitlines() if "times range_max" in line]
    assert run.returncode == 0 and len(cli_lines) == 1 and "--set scene.scale=0.001 (0.01)" in cli_lines[0]
    with pytest.warns(UserWarning) as caught:
        vksonar.Renderer(vksonar.Scene.load(SCENE, scale=1000), small_config(), backend="cpu")
    mine = [str(w.message) for w in caught if "times range_max" in str(w.message)]
    assert mine == [cli_lines[0][len("warning: "):].replace("--set scene.scale=0.001", "Scene.load(path, scale=0.001)")]


def test_render_seed_is_that_renders_only(renderer):
    a = renderer.render(POSE, frame=3).polar
    renderer.render(POSE, frame=3, seed=10)
    assert renderer.seed == 9 and np.array_equal(renderer.render(POSE, frame=3).polar, a)


def test_warnings_are_the_clis_lines(tmp_path):
    # The CLI prints a model used outside its domain as a `warning:` line; Python warns with the same text.
    args = [CLI, "render", "--backend", "cpu", "--out", str(tmp_path)]
    run = subprocess.run(args, capture_output=True, text=True)
    lines = [line[len("warning: "):] for line in run.stderr.splitlines() if line.startswith("warning: ")]
    assert run.returncode == 0 and lines
    with pytest.warns(UserWarning) as caught:
        vksonar.Renderer(vksonar.Scene.load(SCENE), backend="cpu")
    assert [str(w.message) for w in caught] == lines


def test_numpy_layouts_are_views_that_outlive_the_next_render(renderer):
    frame = renderer.render(POSE, frame=0)
    polar = frame.polar
    assert polar.dtype == np.float32 and polar.shape == (64, 48) and polar.flags["C_CONTIGUOUS"]
    assert frame.polar_u16.dtype == np.uint16 and frame.fan.dtype == np.uint8
    assert frame.depth.shape == frame.normals.shape[:2] and frame.normals.shape[2] == 4
    assert frame.echo.shape[2] == 2
    assert frame.ranges_m.shape == (64,) and frame.beam_angles_rad.shape == (48,)
    assert np.shares_memory(polar, frame.polar)  # a view of the frame, not a copy
    kept = polar.copy()
    del frame
    other = renderer.render((0, 0, 0, 0, 10, 20), frame=1)  # a new frame: the old arrays stay
    assert np.array_equal(polar, kept) and not np.array_equal(other.polar, kept)
    reused = renderer.render(POSE, frame=0, out=other)  # out= reuses a frame's memory
    assert reused is other and np.array_equal(other.polar, kept)


def test_out_overwrites_every_array_already_read(renderer):
    # The arrays made on first read (polar_u16, depth, fan, instance_fan, class_fan) were left showing the
    # earlier render of a reused Frame while polar and the labels moved on: a dataset loop holding both
    # wrote one ping's labels beside another's image.
    labels = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", seed=9,
                              outputs=["labels", "depth"])
    other_pose = (3.0, 1.0, 0.0, 0.0, 10.0, 30.0)
    names = ("polar", "polar_u16", "depth", "fan", "instance", "instance_fan", "class_fan")
    frame = labels.render(POSE, frame=0)
    held = {name: getattr(frame, name) for name in names}
    before = {name: array.copy() for name, array in held.items()}
    fresh = labels.render(other_pose, frame=5)
    assert labels.render(other_pose, frame=5, out=frame) is frame
    for name in names:
        assert not np.array_equal(before[name], getattr(fresh, name)), name  # the poses' arrays differ
        assert np.array_equal(held[name], getattr(fresh, name)), name  # the view held shows the new render
        assert np.shares_memory(held[name], getattr(frame, name)), name  # in the same memory
    unread = labels.render(other_pose, frame=5)  # a reused Frame's arrays not read yet: made on their read
    labels.render(POSE, frame=0, out=unread)
    assert np.array_equal(unread.fan, before["fan"]) and np.array_equal(unread.polar_u16, before["polar_u16"])


def test_seed_and_frame_index_key_the_noise(renderer):
    a = renderer.render(POSE, frame=3).polar
    b = renderer.render(POSE, frame=3, seed=9).polar
    c = renderer.render(POSE, frame=4).polar
    d = renderer.render(POSE, frame=3, seed=10).polar
    renderer.render(POSE, frame=0, seed=9)
    assert np.array_equal(a, b) and not np.array_equal(a, c) and not np.array_equal(a, d)


@pytest.mark.parametrize("backend", ["cpu", "vulkan"])
def test_rendering_ahead_gives_the_plain_frames(backend):
    # next_pose starts the next ping on the device before this one's host stages: the same bytes,
    # also when the next call asks for another pose than announced
    config = small_config()
    config.set("effects.speckle", "on")
    ahead = vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend=backend, seed=9)
    plain = vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend=backend, seed=9)
    poses = [(0, 0, 0, 0, 10 + 3 * i, 4 * i) for i in range(4)]
    order = [(0, 1), (1, 2), (3, 0), (0, None)]  # (pose, announced pose): the third breaks the announcement
    for frame, (i, j) in enumerate(order):
        if j is None:
            got = ahead.render(poses[i], frame=frame).polar
        else:
            got = ahead.render(poses[i], frame=frame, next_pose=poses[j]).polar
        assert np.array_equal(got, plain.render(poses[i], frame=frame).polar), (frame, i, j)
    with pytest.raises(ValueError, match="next_pose"):
        ahead.render(POSE, next_pose=(0, 0, 0))


def test_errors_are_the_cli_messages(tmp_path):
    run = cli(tmp_path, "--set", "source_level=400")
    assert run.returncode == 2
    with pytest.raises(ValueError) as error:
        small_config().set("source_level", 400)
    # the CLI also names the option that gave the value; the rest of the line is the same
    prefix = "invalid config: "
    assert str(error.value).startswith(prefix)
    assert run.stderr.strip() == "error: " + prefix + "--set source_level=400: " + str(error.value)[len(prefix):]
    config = small_config()
    with pytest.raises(ValueError):
        config.set("source_level", 400)
    assert config.to_dict()["source_level"] != 400  # a refused value leaves the config as it was
    with pytest.raises(ValueError, match="did you mean"):
        config.set("sorce_level", 200)
    with pytest.raises(ValueError, match="unknown preset 'nope'"):
        vksonar.Config.preset("nope")
    with pytest.raises(ValueError, match="missing.gltf: file not found"):
        vksonar.Scene.load(str(tmp_path / "missing.gltf"))
    with pytest.raises(ValueError, match="not a backend"):
        vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend="gpu")
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), config, backend="cpu")
    with pytest.raises(ValueError, match="needs 6 numbers"):
        renderer.render((0, 0, 0))
    with pytest.raises(ValueError, match=r"vertices: expected shape \(n, 3\)"):
        vksonar.Scene.from_arrays(np.zeros((4, 2)), np.zeros((1, 3), np.uint32))
    with pytest.raises(ValueError):
        vksonar.Scene.from_arrays(np.zeros((3, 3)), np.array([[0, 1, 7]], np.uint32))  # index out of range
    # numpy's cast to uint32 would wrap -1 and truncate 1.5 without a word
    with pytest.raises(ValueError, match="index 2 = -1 is not a vertex index"):
        vksonar.Scene.from_arrays(np.zeros((3, 3)), np.array([[0, 1, -1]]))
    with pytest.raises(ValueError, match="dtype float64 is not an integer type"):
        vksonar.Scene.from_arrays(np.zeros((3, 3)), np.array([[0.0, 1.0, 2.0]]))
    with pytest.raises(ValueError, match=r"instance: 65536 is not an object id in \[0, 65535\]"):
        vksonar.Scene.from_arrays(np.zeros((3, 3)), np.array([[0, 1, 2]]), instance=65536)
    # arguments of the wrong type are pybind11's TypeError (docs/python.md)
    with pytest.raises(TypeError):
        renderer.render("0,0,0,0,10,0")
    plain = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu")
    frame = plain.render((0, 0, 0, 0, 10, 0))
    with pytest.raises(ValueError, match=r"flow: this Renderer was made without outputs=\['labels'\]"):
        plain.flow(frame, frame)


def test_a_scene_from_arrays_echoes_at_its_range():
    # A 4 m x 4 m plate facing the sonar 12 m ahead (sonar frame: x forward, y port, z up).
    vertices = np.array([[12, -2, -2], [12, 2, -2], [12, 2, 2], [12, -2, 2]], np.float32)
    indices = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    config = vksonar.Config.from_dict({"bins": 128, "range_min": 1, "range_max": 20,
                                       "effects": {"speckle": "off", "ambient_noise": "off"}})
    frame = vksonar.Renderer(vksonar.Scene.from_arrays(vertices, indices), config, backend="cpu").render(
        (0, 0, 0, 0, 0, 0))
    peak_bin = int(np.argmax(frame.polar.max(axis=1)))
    assert abs(frame.ranges_m[peak_bin] - 12.0) <= 20.0 / 128  # the plate's range, within a bin
    # the config's scene.* keys apply as a glTF file loads: for arrays the message says so
    for key, value in (("scene.scale", 2.0), ("scene.asset_root", "/tmp")):
        keyed = vksonar.Config.from_dict({"bins": 128, "range_min": 1, "range_max": 20})
        keyed.set(key, value)
        with pytest.raises(ValueError, match=re.escape(key) + r".*built from arrays"):
            vksonar.Renderer(vksonar.Scene.from_arrays(vertices, indices), keyed, backend="cpu")
    moved = np.eye(4)
    moved[0, 3] = 4.0  # the same plate 4 m further through the transform
    frame = vksonar.Renderer(vksonar.Scene.from_arrays(vertices, indices, transform=moved), config,
                             backend="cpu").render((0, 0, 0, 0, 0, 0))
    assert abs(frame.ranges_m[int(np.argmax(frame.polar.max(axis=1)))] - 16.0) <= 20.0 / 128
    # with an object id its cells carry it in the labels (int64 indices, numpy's default, taken as they are)
    scene = vksonar.Scene.from_arrays(vertices, indices.astype(np.int64), instance=7)
    frame = vksonar.Renderer(scene, config, backend="cpu", outputs=["labels"]).render((0, 0, 0, 0, 0, 0))
    assert set(np.unique(frame.instance).tolist()) == {0, 7}
    assert frame.instance[peak_bin].max() == 7
    assert [v["instance"] for v in frame.visibility] == [7]


def test_render_releases_the_gil():
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), vksonar.Config.preset("default"), backend="cpu")
    renderer.render((0, 0, 0, 0, 10, 0))
    span = {}
    done = threading.Event()

    def work():
        span["start"] = time.perf_counter()
        renderer.render((0, 0, 0, 0, 10, 1), frame=1)
        span["end"] = time.perf_counter()
        done.set()

    stamps = []
    thread = threading.Thread(target=work)
    thread.start()
    while not done.is_set():
        stamps.append(time.perf_counter())
        time.sleep(0.001)
    thread.join()
    # Holding the GIL, render() would keep this thread from running any Python until it returned: no
    # stamp could fall inside the render. Released, the loop stamps about once a millisecond all the
    # while (under load, fewer; one is enough). The middle 80 % of the render leaves its edges out.
    start, end = span["start"], span["end"]
    margin = 0.1 * (end - start)
    inside = [t for t in stamps if start + margin < t < end - margin]
    assert inside, f"no stamp during a {end - start:.4f} s render ({len(stamps)} stamps in all)"


def test_scene_objects_and_beam_geometry_as_meta_json(tmp_path, renderer):
    run = cli(tmp_path)
    assert run.returncode == 0, run.stderr
    meta = json.load(open(tmp_path / "meta.json"))
    scene = vksonar.Scene.load(SCENE)
    assert scene.objects == meta["objects"]["instances"]
    assert scene.classes == [c["name"] for c in meta["objects"]["classes"]]
    assert scene.classes[:2] == ["seabed", "piling"]
    assert renderer.beam_geometry == meta["beam_geometry"]["used"] == "line_array"


@pytest.fixture(scope="module")
def labelled():
    scene = vksonar.Scene.load(SCENE)
    renderer = vksonar.Renderer(scene, small_config(), backend="cpu", seed=9, outputs=["labels"])
    return scene, renderer.render(POSE, frame=0)


def test_labels_layout_and_consistency_with_the_scene_table(labelled):
    scene, frame = labelled
    cells = (64, 48)
    for name, dtype in (("instance", np.uint16), ("object_class", np.uint16), ("instance_fraction", np.float32),
                        ("elevation", np.float32), ("elevation_spread", np.float32)):
        array = getattr(frame, name)
        assert array.dtype == dtype and array.shape == cells, (name, array.dtype, array.shape)
    assert frame.point.dtype == np.float32 and frame.point.shape == cells + (3,)
    instance, fraction = frame.instance, frame.instance_fraction
    hit = instance > 0
    assert hit.sum() > 100, "the bundled scene fills many cells"
    class_of = {o["id"]: o["class_id"] for o in scene.objects}
    assert set(np.unique(instance[hit]).tolist()) <= set(class_of)
    expected_class = np.vectorize(lambda i: class_of.get(int(i), 0), otypes=[np.uint16])(instance)
    assert np.array_equal(frame.object_class, expected_class)
    assert len(np.unique(frame.object_class[hit])) >= 2  # more than one class in view (seabed and another)
    assert np.all((fraction[hit] > 0) & (fraction[hit] <= 1))
    assert np.all(fraction[~hit] == 0)
    energy = fraction > 0
    assert np.array_equal(np.isfinite(frame.elevation), energy)
    assert np.array_equal(np.isfinite(frame.elevation_spread), energy)
    assert np.all(frame.elevation_spread[energy] >= 0)
    assert np.all(np.isfinite(frame.point[hit]))
    # A labelled cell's point lies in it: its range within about a bin of the cell's range.
    bins, beams = np.nonzero(hit)
    ranges = np.linalg.norm(frame.point[bins, beams], axis=1)
    width = frame.ranges_m[1] - frame.ranges_m[0]
    assert np.median(np.abs(ranges - frame.ranges_m[bins])) <= width


def test_labels_equal_the_cli_files_and_leave_the_intensities_alone(tmp_path, labelled):
    _, frame = labelled
    run = cli(tmp_path, "--save", "polar,labels")
    assert run.returncode == 0, run.stderr
    assert np.array_equal(frame.instance, np.load(tmp_path / "instance.npy"))
    assert np.array_equal(frame.object_class, np.load(tmp_path / "class.npy"))
    for name in ("instance_fraction", "elevation", "elevation_spread", "point"):
        assert np.array_equal(getattr(frame, name), np.load(tmp_path / f"{name}.npy"), equal_nan=True), name
    # Labels are read off the render, not a part of it: the same seed gives the same intensities.
    plain = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", seed=9).render(POSE, frame=0)
    assert np.array_equal(frame.polar, plain.polar) and np.array_equal(frame.clean, plain.clean)
    assert np.array_equal(frame.polar, np.load(tmp_path / "polar.npy"))
    # the labels on the fan image and the boxes, as the CLI's files
    assert frame.instance_fan.dtype == np.uint16 and frame.instance_fan.shape == frame.fan.shape[:2]
    assert np.array_equal(frame.instance_fan, np.load(tmp_path / "instance_fan.npy"))
    assert np.array_equal(frame.class_fan, np.load(tmp_path / "class_fan.npy"))
    boxes = frame.boxes
    assert boxes == json.loads((tmp_path / "boxes.json").read_text()) and len(boxes["boxes"]) >= 2
    for name in ("instance", "instance_fraction", "object_class", "elevation", "elevation_spread", "point",
                 "depth", "normals", "echo", "instance_fan", "class_fan", "boxes"):
        assert getattr(plain, name) is None, name  # not asked for
    with pytest.raises(ValueError, match="labels"):
        vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", outputs=["label"])


def test_flow_between_two_frames_matches_the_cli(tmp_path):
    # Renderer.flow is the CLI's --save flow: the same numbers for the same two poses, finite only on
    # labelled cells, and a moved sonar moves the cells (the range shrinks going forward).
    scene = vksonar.Scene.load(SCENE)
    renderer = vksonar.Renderer(scene, small_config(), backend="cpu", seed=1, outputs=["labels"])
    poses = [(0, 0, 0, 0, 10, 0), (0.3, 0, 0, 0, 10, 0)]
    frames = [renderer.render(p, frame=i + 1) for i, p in enumerate(poses)]
    flow = renderer.flow(frames[0], frames[1])
    assert flow.shape == frames[0].instance.shape + (2,) and flow.dtype == np.float32
    finite = np.isfinite(flow[..., 0])
    assert not finite[frames[0].instance == 0].any()
    assert finite.sum() > 0.5 * (frames[0].instance > 0).sum()
    assert np.nanmedian(flow[..., 0]) < 0  # forward: points come nearer
    with pytest.raises(ValueError):
        vksonar.Renderer(scene, small_config(), backend="cpu").flow(frames[0], frames[1])
    (tmp_path / "poses.csv").write_text("".join(",".join(str(v) for v in p) + "\n" for p in poses))
    args = [CLI, "render", "--scene", SCENE, "--backend", "cpu", "--trajectory", str(tmp_path / "poses.csv"),
            "--save", "flow", "--out", str(tmp_path / "run")]
    for key, value in KEYS.items():
        args += ["--set", f"{key}={value}"]
    run = subprocess.run(args, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    np.testing.assert_array_equal(np.load(tmp_path / "run" / "frame_000001" / "flow.npy"), flow)


def test_visibility_lists_the_labelled_objects(labelled):
    scene, frame = labelled
    ids = sorted(set(np.unique(frame.instance).tolist()) - {0})
    vis = frame.visibility
    assert [v["instance"] for v in vis] == ids
    assert all(0 <= v["hidden"] + v["outside"] <= v["pixels"] for v in vis)
    assert any(v["pixels"] > 0 for v in vis)


# An audit's: arrays misread or half-added without a word. Index arrays of another shape than (m, 3) or
# flat were read flat (wrong triangles); a vertex array of complex, bool or object dtype was force-cast;
# a refused add() left its mesh and material behind; inf backscatter became the default.
def test_scene_arrays_are_checked_before_the_scene_changes():
    vertices = np.array([[12, -2, -2], [12, 2, -2], [12, 2, 2], [12, -2, 2]], np.float32)
    indices = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    for shape in ((3, 2), (2, 3, 1)):
        with pytest.raises(ValueError, match=r"indices: expected shape \(m, 3\) or \(3 m,\)"):
            vksonar.Scene.from_arrays(vertices, np.zeros(shape, np.uint32))
    for dtype in (np.complex64, bool, object):
        with pytest.raises(ValueError, match="vertices: dtype .* is not a real number type"):
            vksonar.Scene.from_arrays(vertices.astype(dtype), indices)
    with pytest.raises(ValueError, match="backscatter_db"):
        vksonar.Scene.from_arrays(vertices, indices, backscatter_db=float("inf"))
    huge = np.eye(4)
    huge[0, 3] = 1e39  # finite as a double, inf as the float the depth pass holds
    scene = vksonar.Scene.from_arrays(vertices, indices)
    before = scene.triangles
    for bad in (dict(backscatter_db=5.0), dict(transform=huge), dict(instance=70000)):
        with pytest.raises(ValueError):
            scene.add(vertices, indices, **bad)
    assert scene.triangles == before
    assert scene.add(vertices, indices) == 1  # the second mesh: nothing was left behind
    # nan: the config's default_backscatter; integer vertices are converted, nested lists too
    vksonar.Scene.from_arrays(vertices.astype(np.int32), indices.ravel(), backscatter_db=float("nan"))
    assert vksonar.Scene.from_arrays(vertices.tolist(), indices.tolist()).triangles == 2


def test_a_renderer_keeps_its_scene_while_it_grows_and_renders_on_another_thread():
    vertices = np.array([[12, -2, -2], [12, 2, -2], [12, 2, 2], [12, -2, 2]], np.float32)
    indices = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    config = vksonar.Config.from_dict({"bins": 128, "range_min": 1, "range_max": 20})
    scene = vksonar.Scene.from_arrays(vertices, indices)
    renderer = vksonar.Renderer(scene, config, backend="cpu")
    first = renderer.render((0, 0, 0, 0, 0, 0)).polar.copy()
    hash_before = renderer.render((0, 0, 0, 0, 0, 0)).meta["scene_fnv1a64"]
    stop = threading.Event()

    def grow():  # a segfault before: add() reallocated the arrays the render was reading
        while not stop.is_set():
            scene.add(vertices + np.float32(1.0), indices)

    thread = threading.Thread(target=grow)
    thread.start()
    try:
        for _ in range(40):
            assert np.array_equal(renderer.render((0, 0, 0, 0, 0, 0)).polar, first)
    finally:
        stop.set()
        thread.join()
    assert scene.triangles > 2
    frame = renderer.render((0, 0, 0, 0, 0, 0))
    assert frame.meta["scene_fnv1a64"] == hash_before and np.array_equal(frame.polar, first)


def test_one_renderer_on_two_threads_takes_turns():
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu", seed=9)
    expect = renderer.render(POSE, frame=0).polar.copy()
    errors = []

    def work():
        try:
            for _ in range(15):
                if not np.array_equal(renderer.render(POSE, frame=0).polar, expect):
                    errors.append("a frame differs")
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(repr(e))

    threads = [threading.Thread(target=work) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "a render hung"
    assert errors == []


def test_time_s_must_be_finite():
    renderer = vksonar.Renderer(vksonar.Scene.load(SCENE), small_config(), backend="cpu")
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="time_s"):
            renderer.render(POSE, time_s=bad)
    assert renderer.render(POSE, time_s=1.5).meta["time_s"] == 1.5


def test_a_beam_table_entry_must_be_finite_when_set():
    config = small_config()
    with pytest.raises(ValueError, match="beam_angles.*entry 1 is not a finite number"):
        config.set("beam_angles", [10.0, float("nan"), -10.0])
