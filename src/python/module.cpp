// The Python module `vksonar` (pybind11): scenes, configs and renderers as Python objects, frames as
// numpy arrays. docs/python.md is the user's guide; tests/python/test_module.py checks it against the
// CLI's files.
//
// Ownership: a Frame owns its vksonar::Frame; its arrays are numpy views of that memory (no copy) that
// keep the Frame alive, so they stay valid after the next render(), which renders into a new Frame
// unless `out=` hands one back to reuse. A Renderer keeps its Context and Scene alive. Errors are
// exceptions with the CLI's one-line messages: bad input (a file, a key, a value) is ValueError,
// anything else RuntimeError; nothing aborts the interpreter. render() releases the GIL.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "config/config_keys.h"
#include "config/layers.h"
#include "core/plan.h"
#include "core/renderer_access.h"
#include "core/renderer_workers.h"
#include "host/backend_choice.h"
#include "host/boxes.h"
#include "host/host_stages.h"
#include "host/meta_fields.h"
#include "host/scene_framing.h"
#include "scene/scene_data.h"
#include "vksonar/vksonar.h"

namespace py = pybind11;
using namespace vksonar;

namespace {

[[noreturn]] void raise(const Error& e) {
    switch (e.code) {
    case ErrorCode::invalid_argument:
    case ErrorCode::parse:
    case ErrorCode::unsupported:
    case ErrorCode::io:
        throw py::value_error(e.message);
    default:
        throw std::runtime_error(e.message);
    }
}

template <class T> T take(Result<T>&& r) {
    if (!r) raise(r.error());
    return std::move(r.value());
}

void check(const Result<void>& r) {
    if (!r) raise(r.error());
}

// A Python UserWarning (warnings.warn) for what the CLI prints as a `warning:` line.
void warn(const std::string& text) {
    if (PyErr_WarnEx(PyExc_UserWarning, text.c_str(), 1) < 0) throw py::error_already_set();
}

// ---- Config ----------------------------------------------------------------------------------------

// A Python value as JSON text: numpy scalars (np.int64(64), np.float32(0.5)) and arrays as the Python
// numbers and lists they hold, which json.dumps alone refuses.
std::string json_text(const py::object& value) {
    const py::object json = py::module_::import("json");
    const py::cpp_function plain([](const py::object& o) -> py::object {
        if (py::hasattr(o, "tolist")) return o.attr("tolist")(); // numpy scalars and arrays
        throw py::type_error("Object of type " + py::str(py::type::of(o).attr("__name__")).cast<std::string>() +
                             " is not JSON serializable");
    });
    return json.attr("dumps")(value, py::arg("default") = plain).cast<std::string>();
}

struct ConfigObject {
    SonarConfig config;
    // How it was made, kept so that the layers apply in the CLI's order whatever the order of the calls,
    // and so that a Renderer can put a scene's effect requests between the base and the user's keys:
    // base (preset or --sonar FILE) < scene effects < from_dict (--config) < quality (--quality) < set
    // (--set).
    enum class Layer { json, quality, key };
    SonarConfig base;
    std::vector<std::pair<Layer, std::string>> layers;

    static ConfigObject preset(const std::string& name) { return over(take(load_preset(name))); }
    // A sonar config file, as `--sonar FILE.json` reads it: its keys over the built-in defaults, named
    // by the file's stem unless it names itself.
    static ConfigObject from_file(const std::string& path) {
        ConfigObject o = over(take(load_sonar_file(path)));
        require_ranges(o.config);
        return o;
    }
    // Keys as in a config file (nested dicts for groups, "effects": {...}), over a preset.
    static ConfigObject from_dict(const py::dict& keys, const std::string& base) {
        ConfigObject c = preset(base);
        c.add(Layer::json, json_text(keys));
        return c;
    }
    // One key as --set takes it ("effects.speckle", "off"). The key's own range is checked here; how keys
    // agree with each other (range_min below range_max, ...) when a Renderer takes the config, as the
    // CLI checks after all its layers.
    void set(const std::string& key, const py::object& value) {
        add(Layer::key, key + "=" + (py::isinstance<py::str>(value) ? value.cast<std::string>() : json_text(value)));
    }
    void quality(const std::string& name) { add(Layer::quality, name); }
    py::dict to_dict() const {
        return py::module_::import("json").attr("loads")(config_to_json(config)).cast<py::dict>();
    }
    // The config a Renderer of `scene` runs: with the scene's effect requests (its glTF
    // scenes[N].extras.vksonar.effects) over the base and under this config's own keys, as the CLI does.
    SonarConfig for_scene(const Scene& scene) const {
        const std::string effects = scene_effects_layer(scene);
        if (effects.empty()) return config;
        return replay(take(apply_config_json(base, effects, "the scene's extras vksonar.effects")), layers);
    }

private:
    // Each key within its own range (config_keys::check_ranges); how keys agree is the Renderer's check.
    static void require_ranges(const SonarConfig& c) {
        if (const std::string problem = config_keys::check_ranges(c); !problem.empty())
            throw py::value_error("invalid config: " + problem);
    }
    static ConfigObject over(const SonarConfig& base) {
        ConfigObject c;
        c.config = c.base = base;
        return c;
    }
    // Adds a layer; a refused one (a parse error, a value outside its key's range) leaves the config as it was.
    void add(Layer layer, const std::string& text) {
        std::vector<std::pair<Layer, std::string>> more = layers;
        more.emplace_back(layer, text);
        SonarConfig changed = replay(base, more);
        require_ranges(changed);
        config = std::move(changed);
        layers = std::move(more);
    }
    // `from` with the layers in the CLI's order (json, then quality, then keys), each kind in call order.
    static SonarConfig replay(SonarConfig from, const std::vector<std::pair<Layer, std::string>>& layers) {
        for (const Layer kind : {Layer::json, Layer::quality, Layer::key})
            for (const auto& [layer, text] : layers)
                if (layer == kind) from = take(apply(from, layer, text));
        return from;
    }
    static Result<SonarConfig> apply(const SonarConfig& c, Layer layer, const std::string& text) {
        switch (layer) {
        case Layer::json:
            return apply_config_json(c, text, "dict");
        case Layer::quality:
            return apply_quality(c, text);
        case Layer::key:
            return apply_config_override(c, text);
        }
        return c;
    }
};

// ---- Scene -----------------------------------------------------------------------------------------

struct SceneObject {
    // Shared with the Renderers made from it, which render it with the GIL released: add() changes a
    // copy once a Renderer holds it (copy on write), so a Renderer's scene never changes under it and
    // later add()s do not reach it (as documented).
    std::shared_ptr<Scene> scene = std::make_shared<Scene>();
    std::optional<std::string> path; // the glTF file it was loaded from (meta.json "scene"); none for arrays
    SceneLoadOptions loaded;         // the asset root and scale it was loaded with (the config's scene.* keys)

    static std::shared_ptr<SceneObject> load(const std::string& path, const std::string& asset_root, double scale) {
        auto s = std::make_shared<SceneObject>();
        s->loaded = SceneLoadOptions{asset_root, scale};
        s->scene = std::make_shared<Scene>(take(Scene::load_gltf(path, s->loaded)));
        s->path = path;
        // What the loader skipped or ignored, as the CLI's warning lines (also in scene.warnings).
        for (const std::string& w : s->scene->stats().warnings)
            warn(w);
        return s;
    }

    // One mesh from numpy arrays: vertices [n, 3] (metres, sonar world frame: x forward, y port, z up),
    // triangle indices [m, 3] (or flat), one material, drawn once with a 4x4 row-major transform;
    // `instance`: the object id its labels carry (0: none; a scene built here has no class table).
    static std::shared_ptr<SceneObject>
    from_arrays(const py::object& vertices, const py::object& indices, double backscatter_db,
                const std::optional<py::array_t<double, py::array::c_style | py::array::forcecast>>& transform,
                std::int64_t instance) {
        auto s = std::make_shared<SceneObject>();
        s->add(vertices, indices, backscatter_db, transform, instance);
        return s;
    }

    std::uint32_t add(const py::object& vertex_input, const py::object& index_input, double backscatter_db,
                      const std::optional<py::array_t<double, py::array::c_style | py::array::forcecast>>& transform,
                      std::int64_t instance) {
        // Everything is checked before the scene changes: a refused add leaves no mesh or material behind.
        // Arrays or anything numpy takes (nested lists), as np.asarray reads them.
        const py::array vertex_array = py::array::ensure(vertex_input);
        const py::array indices = py::array::ensure(index_input);
        if (!vertex_array) throw py::value_error("vertices: not an array of numbers");
        if (!indices) throw py::value_error("indices: not an array of integers");
        const char kind = vertex_array.dtype().kind();
        if (kind != 'f' && kind != 'i' && kind != 'u')
            throw py::value_error("vertices: dtype " + py::str(vertex_array.dtype()).cast<std::string>() +
                                  " is not a real number type");
        const auto vertices = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(vertex_array);
        if (!vertices) throw py::value_error("vertices: not convertible to float32");
        if (vertices.ndim() != 2 || vertices.shape(1) != 3)
            throw py::value_error("vertices: expected shape (n, 3), got " + shape_text(vertices));
        const std::vector<std::uint32_t> index_values = checked_indices(indices);
        if (instance < 0 || instance > 0xffff)
            throw py::value_error("instance: " + std::to_string(instance) + " is not an object id in [0, 65535]");
        AcousticMaterial material;
        material.name = "from_arrays";
        material.backscatter_db = backscatter_db;
        // NaN: the config's default_backscatter (as a glTF material without extras); inf is no level.
        if (std::isinf(backscatter_db))
            throw py::value_error("backscatter_db: " + std::to_string(backscatter_db) +
                                  " (expected -100 to 0 dB, or nan for the config's default_backscatter)");
        if (const auto valid = material.validate(); !valid)
            throw py::value_error("backscatter_db: " + valid.error().message);
        SceneDraw draw;
        draw.instance = static_cast<std::uint32_t>(instance);
        if (transform) {
            if (transform->ndim() != 2 || transform->shape(0) != 4 || transform->shape(1) != 4)
                throw py::value_error("transform: expected shape (4, 4), got " + shape_text(*transform));
            for (int r = 0; r < 4; ++r)
                for (int c = 0; c < 4; ++c) {
                    const double v = transform->at(r, c);
                    if (!std::isfinite(v) || !std::isfinite(static_cast<float>(v)))
                        throw py::value_error("transform: entry [" + std::to_string(r) + ", " + std::to_string(c) +
                                              "] = " + std::to_string(v) + " is not finite (in float)");
                    draw.world_from_local[std::size_t(c * 4 + r)] = v; // column-major
                }
        }
        if (scene.use_count() > 1) scene = std::make_shared<Scene>(detail::Access::copy(*scene)); // a Renderer holds it
        const auto mesh = take(scene->add_mesh(vertices.data(), static_cast<std::uint32_t>(vertices.shape(0)),
                                               index_values.data(), static_cast<std::uint32_t>(index_values.size())));
        draw.mesh = mesh;
        draw.material = take(scene->add_material(material));
        check(scene->add_draw(draw));
        return mesh;
    }

    // Triangle indices as uint32: an integer array (any width) of whole triangles, none negative or past
    // uint32 (numpy's own cast would wrap -1 to 4294967295 and truncate floats without a word).
    static std::vector<std::uint32_t> checked_indices(const py::array& indices) {
        const char kind = indices.dtype().kind();
        if (kind != 'i' && kind != 'u')
            throw py::value_error("indices: dtype " + py::str(indices.dtype()).cast<std::string>() +
                                  " is not an integer type");
        const bool flat = indices.ndim() == 1, rows = indices.ndim() == 2 && indices.shape(1) == 3;
        if (!flat && !rows)
            throw py::value_error("indices: expected shape (m, 3) or (3 m,), got " + shape_text(indices));
        if (indices.size() % 3 != 0)
            throw py::value_error("indices: " + std::to_string(indices.size()) + " values, not whole triangles");
        const auto wide = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(indices);
        if (!wide) throw py::value_error("indices: not convertible to 64-bit integers");
        std::vector<std::uint32_t> out(static_cast<std::size_t>(wide.size()));
        const std::int64_t* v = wide.data();
        for (std::size_t i = 0; i < out.size(); ++i) {
            if (v[i] < 0 || v[i] > 0xffffffffLL)
                throw py::value_error("indices: index " + std::to_string(i) + " = " + std::to_string(v[i]) +
                                      " is not a vertex index");
            out[i] = static_cast<std::uint32_t>(v[i]);
        }
        return out;
    }

    template <class A> static std::string shape_text(const A& a) {
        std::string t = "(";
        for (py::ssize_t i = 0; i < a.ndim(); ++i)
            t += (i ? ", " : "") + std::to_string(a.shape(i));
        return t + ")";
    }
};

// ---- Frame and Renderer ----------------------------------------------------------------------------

struct FrameObject {
    Frame frame;
    const Plan* plan = nullptr;
    py::object renderer; // keeps the plan (and the fan lookup) alive while this frame exists
    std::vector<std::uint16_t> u16;
    std::vector<float> range;
    host::Image fan_image;
    std::vector<std::uint16_t> instance_fan, class_fan; // labels on the fan image (instance_fan.npy, class_fan.npy)
    bool u16_ready = false, range_ready = false, fan_ready = false, instance_fan_ready = false, class_fan_ready = false;
    Pose pose;
    std::optional<double> time_s; // render(time_s=): meta's time_s, as a trajectory's time column gives it
};

// The CLI applies the config's scene.scale and scene.asset_root as it loads the scene; here the Scene
// is loaded first (Scene.load(path, asset_root, scale)), so the config must agree with how it was, and
// meta.json's config then says what was applied, as the CLI's does.
void resolve_scene_keys(SonarConfig& config, const SceneObject& scene) {
    const SceneLoadOptions& loaded = scene.loaded;
    const SonarConfig defaults;
    const auto fmt = [](double x) { return py::str(py::float_(x)).cast<std::string>(); };
    if (config.scene_scale != defaults.scene_scale && config.scene_scale != loaded.scale)
        throw py::value_error("scene.scale = " + fmt(config.scene_scale) + " in the config, but the scene was " +
                              (scene.path ? "loaded at scale " + fmt(loaded.scale) +
                                                ": Scene.load(path, scale=" + fmt(config.scene_scale) + ")"
                                          : "built from arrays (scene.scale applies as a glTF file loads)"));
    if (!config.scene_asset_root.empty() && config.scene_asset_root != loaded.asset_root)
        throw py::value_error("scene.asset_root = '" + config.scene_asset_root + "' in the config, but the scene was " +
                              (scene.path ? "loaded with asset_root '" + loaded.asset_root +
                                                "': Scene.load(path, asset_root='" + config.scene_asset_root + "')"
                                          : "built from arrays (scene.asset_root applies as a glTF file loads)"));
    config.scene_scale = loaded.scale;
    config.scene_asset_root = loaded.asset_root;
}

struct RendererObject {
    std::shared_ptr<Context> context;
    std::shared_ptr<SceneObject> scene;      // its path and load options (meta.json)
    std::shared_ptr<const Scene> scene_data; // the scene as this renderer took it (SceneObject::scene)
    // One call at a time: render() releases the GIL, and two threads on one Renderer would share its
    // frame slots and worker pool. The second waits (without the GIL) for the first.
    std::mutex busy;
    Renderer renderer;
    std::unique_ptr<host::FanRenderer> fan;
    std::string backend;        // vulkan or cpu ("auto" resolved)
    std::string backend_reason; // meta.json "backend_reason": Renderer(backend='cpu'), or what auto saw
    std::string device;         // the Vulkan device, or "cpu" (meta.json "device")
    std::string scene_hash;     // meta.json "scene_fnv1a64" of the scene as the renderer took it
    std::string effects_json;   // meta.json "effects": the plan's, the scene's requests named (as the CLI's)
    // Frame.boxes: the CLI's boxes.json (host/boxes.h), its scratch kept across frames.
    host::BoxFinder box_finder;
    std::vector<host::Box> boxes;
    std::vector<std::string> class_names; // Scene::classes() as the renderer took the scene
};

// The Renderer's lock, waited for without the GIL: the thread that holds it may be waiting for the GIL.
std::unique_lock<std::mutex> one_call_at_a_time(RendererObject& r) {
    std::unique_lock<std::mutex> lock(r.busy, std::try_to_lock);
    if (!lock.owns_lock()) {
        py::gil_scoped_release unlocked;
        lock.lock();
    }
    return lock;
}

// A numpy view of `data` (shape `shape`) owned by the Python Frame `owner`; None where the frame has no
// such array (an output not asked for). A py::object, not a py::array: None cast to an array would be
// a 0-d object array that is not None.
template <class T> py::object view(std::vector<T>& data, std::vector<py::ssize_t> shape, const py::object& owner) {
    if (data.empty()) return py::none();
    return py::array_t<T>(shape, data.data(), owner);
}

// A label image on the fan (nearest cell: ids stay ids), as the CLI's instance_fan.npy / class_fan.npy;
// None without labels. Made on first use, once per render.
py::object fan_labels(py::object self, bool instance) {
    auto& f = self.cast<FrameObject&>();
    if (f.frame.instance.empty()) return py::none();
    const host::FanRenderer& fan = *f.renderer.cast<RendererObject&>().fan;
    std::vector<std::uint16_t>& out = instance ? f.instance_fan : f.class_fan;
    bool& ready = instance ? f.instance_fan_ready : f.class_fan_ready;
    if (!ready) fan.nearest_cell(instance ? f.frame.instance : f.frame.object_class, out);
    ready = true;
    return view(out, {fan.height(), fan.width()}, self);
}

// render(out=frame): the arrays made on first read (polar_u16, depth, fan, instance_fan, class_fan) that
// were read before are made again from the new frame, into their own buffers (the same size: no new
// memory), so a numpy view taken from an earlier render of this Frame shows this one, as the frame's own
// arrays' views do. Those not read yet stay unmade until they are.
void rebuild_read_arrays(FrameObject& f, const host::FanRenderer& fan) {
    f.u16_ready = !f.u16.empty();
    if (f.u16_ready) host::quantize_display(f.frame, f.u16);
    f.range_ready = !f.range.empty() && !f.frame.depth.empty();
    if (f.range_ready) host::depth_to_view_range(*f.plan, f.frame, f.range);
    f.fan_ready = !f.fan_image.rgb.empty();
    if (f.fan_ready) fan.render(f.frame, f.fan_image);
    f.instance_fan_ready = !f.instance_fan.empty() && !f.frame.instance.empty();
    if (f.instance_fan_ready) fan.nearest_cell(f.frame.instance, f.instance_fan);
    f.class_fan_ready = !f.class_fan.empty() && !f.frame.object_class.empty();
    if (f.class_fan_ready) fan.nearest_cell(f.frame.object_class, f.class_fan);
}

py::object frame_meta(FrameObject& f) {
    const py::module_ json = py::module_::import("json");
    py::dict extra;
    const RendererObject& r = f.renderer.cast<RendererObject&>();
    // the CLI's keys in the CLI's order (render_frame.cpp), but `legacy`, which describes the legacy
    // outputs only the CLI writes, and `files`, the files the CLI wrote before meta.json
    const py::dict config = json.attr("loads")(config_to_json(f.plan->config));
    extra["effects"] = json.attr("loads")(r.effects_json); // in place of the plan's, as the CLI's
    extra["vksonar_version"] = host::vksonar_version();
    extra["config"] = config;
    extra["scene"] = r.scene->path ? py::object(py::str(*r.scene->path)) : py::object(py::none());
    extra["scene_fnv1a64"] = r.scene_hash;
    if (f.time_s) extra["time_s"] = *f.time_s; // render(time_s=): a trajectory's time column
    extra["pose"] = py::dict(py::arg("x_m") = f.pose.x_m, py::arg("y_m") = f.pose.y_m, py::arg("z_m") = f.pose.z_m,
                             py::arg("roll_deg") = f.pose.roll_deg, py::arg("pitch_deg") = f.pose.pitch_deg,
                             py::arg("yaw_deg") = f.pose.yaw_deg);
    extra["objects"] = json.attr("loads")(host::objects_json(*r.scene_data).dump());
    extra["backend"] = r.backend;
    extra["backend_reason"] = r.backend_reason;
    extra["device"] = r.device;
    extra["mode"] = config["mode"]; // the config's own name for it, as the CLI writes it
    const std::string text = host::meta_json_text(*f.plan, f.frame, json.attr("dumps")(extra).cast<std::string>());
    return json.attr("loads")(text);
}

} // namespace

PYBIND11_MODULE(vksonar, m) {
    m.doc() = "vksonar: a physically based imaging-sonar simulator (docs/python.md)";

    py::class_<ConfigObject>(m, "Config", "A sonar config: a preset plus keys, validated as the CLI does.")
        .def(py::init([] { return ConfigObject::preset("default"); }))
        .def_static("preset", &ConfigObject::preset, py::arg("name") = "default", "A bundled preset by name.")
        .def_static("from_dict", &ConfigObject::from_dict, py::arg("keys"), py::arg("base") = "default",
                    "Keys as in a config file (nested dicts for groups) over the preset `base`.")
        .def_static("from_file", &ConfigObject::from_file, py::arg("path"),
                    "A sonar config file, as `vksonar render --sonar FILE.json` reads it.")
        .def_static("presets", &preset_names, "The bundled presets' names.")
        .def("set", &ConfigObject::set, py::arg("key"), py::arg("value"), "One key as --set takes it.")
        .def("quality", &ConfigObject::quality, py::arg("name"), "fast | balanced | accurate (the accuracy keys).")
        .def("to_dict", &ConfigObject::to_dict, "The resolved config, as meta.json's `config`.")
        .def("__repr__", [](const ConfigObject& c) { return "vksonar.Config('" + c.config.name + "')"; });

    py::class_<SceneObject, std::shared_ptr<SceneObject>>(m, "Scene", "A scene: a glTF file or meshes from arrays.")
        .def(py::init([] { return std::make_shared<SceneObject>(); }))
        .def_static("load", &SceneObject::load, py::arg("path"), py::arg("asset_root") = "", py::arg("scale") = 1.0,
                    "Loads .gltf / .glb; files it names must lie inside asset_root (default: its folder); scale "
                    "multiplies its coordinates (the config's scene.asset_root and scene.scale, which the CLI "
                    "applies as it loads the scene).")
        .def_static("from_arrays", &SceneObject::from_arrays, py::arg("vertices"), py::arg("indices"),
                    py::arg("backscatter_db") = -30.0, py::arg("transform") = py::none(), py::arg("instance") = 0,
                    "One mesh: vertices (n, 3) float, indices (m, 3) integers, a Lambert material, a 4x4 transform, "
                    "the object id its labels carry (0: none).")
        .def("add", &SceneObject::add, py::arg("vertices"), py::arg("indices"), py::arg("backscatter_db") = -30.0,
             py::arg("transform") = py::none(), py::arg("instance") = 0,
             "Adds one more mesh, material and draw (object id `instance`); returns the mesh index.")
        .def_property_readonly("triangles", [](const SceneObject& s) { return s.scene->stats().triangles; })
        .def_property_readonly("warnings", [](const SceneObject& s) { return s.scene->stats().warnings; })
        .def_property_readonly(
            "objects",
            [](const SceneObject& s) {
                py::list out;
                for (const SceneInstance& i : s.scene->instances())
                    out.append(py::dict(py::arg("id") = i.id, py::arg("node") = i.node, py::arg("mesh") = i.mesh,
                                        py::arg("class") = i.class_name, py::arg("class_id") = i.class_id));
                return out;
            },
            "The glTF nodes with a mesh (meta.json 'objects'): id = node index + 1, class and class_id.")
        .def_property_readonly(
            "classes", [](const SceneObject& s) { return s.scene->classes(); },
            "Class names; class_id k is classes[k - 1] (0: no class).");

    py::class_<FrameObject, std::shared_ptr<FrameObject>>(m, "Frame", "One rendered ping. Arrays are views, no copy.")
        .def_property_readonly(
            "polar",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.intensity, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: received intensity, uPa^2 (polar.npy)")
        .def_property_readonly(
            "clean",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.clean, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: the echo before noise, relative to the source level")
        .def_property_readonly(
            "display",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.display, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: the display value in [0, 1]")
        .def_property_readonly(
            "polar_u16",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                if (!f.u16_ready) host::quantize_display(f.frame, f.u16);
                f.u16_ready = true;
                return view(f.u16, {f.frame.bins, f.frame.beams}, self);
            },
            "uint16 [bins, beams]: display x 65535 (polar_u16.npy)")
        .def_property_readonly(
            "depth",
            [](py::object self) -> py::object {
                auto& f = self.cast<FrameObject&>();
                if (f.frame.depth.empty()) return py::none();
                if (!f.range_ready) host::depth_to_view_range(*f.plan, f.frame, f.range);
                f.range_ready = true;
                return view(f.range, {f.frame.rows, f.frame.columns}, self);
            },
            "float32 [rows, columns]: slant range (m), 0 = no hit (depth.npy; outputs=['depth'])")
        .def_property_readonly(
            "normals",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.normals, {f.frame.rows, f.frame.columns, 4}, self);
            },
            "float32 [rows, columns, 4]: normal and cos incidence (outputs=['normals'])")
        .def_property_readonly(
            "echo",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.echo, {f.frame.rows, f.frame.columns, 2}, self);
            },
            "float32 [rows, columns, 2]: energy, slant range (outputs=['echo'])")
        // Ground truth per polar cell (outputs=['labels'], docs/labels.md), None without it.
        .def_property_readonly(
            "instance",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.instance, {f.frame.bins, f.frame.beams}, self);
            },
            "uint16 [bins, beams]: the id (Scene.objects' id) of the object with the most energy in the cell, "
            "0: none (instance.npy; outputs=['labels'])")
        .def_property_readonly(
            "instance_fraction",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.instance_fraction, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: that object's share of the cell's energy, 0: no energy (outputs=['labels'])")
        .def_property_readonly(
            "object_class",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.object_class, {f.frame.bins, f.frame.beams}, self);
            },
            "uint16 [bins, beams]: the class_id of `instance` (Scene.classes[class_id - 1]), 0: none "
            "(class.npy; outputs=['labels'])")
        .def_property_readonly(
            "elevation",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.elevation, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: energy-weighted mean elevation, rad, up positive; NaN: no energy "
            "(outputs=['labels'])")
        .def_property_readonly(
            "elevation_spread",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.elevation_spread, {f.frame.bins, f.frame.beams}, self);
            },
            "float32 [bins, beams]: the elevation's energy-weighted standard deviation, rad; NaN: no energy "
            "(outputs=['labels'])")
        .def_property_readonly(
            "point",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                return view(f.frame.point, {f.frame.bins, f.frame.beams, 3}, self);
            },
            "float32 [bins, beams, 3]: the point of the instance's strongest return in the cell, sonar frame, m; "
            "NaN: none (outputs=['labels'])")
        .def_property_readonly(
            "visibility",
            [](const FrameObject& f) -> py::object {
                if (f.frame.instance.empty()) return py::none();
                py::list out;
                for (const ObjectVisibility& v : f.frame.visibility)
                    out.append(py::dict(py::arg("instance") = v.instance, py::arg("pixels") = v.pixels,
                                        py::arg("hidden") = v.hidden, py::arg("outside") = v.outside));
                return out;
            },
            "Per object with a labelled cell (increasing id): its pixels in the depth pass's view drawn alone, "
            "how many a nearer object hides and how many unhidden ones lie outside the range window, as dicts "
            "(outputs=['labels'], docs/labels.md)")
        .def_property_readonly(
            "instance_fan", [](py::object self) { return fan_labels(self, true); },
            "uint16 [height, width]: instance on the fan image, each pixel its nearest cell's (instance_fan.npy); "
            "None without outputs=['labels']")
        .def_property_readonly(
            "class_fan", [](py::object self) { return fan_labels(self, false); },
            "uint16 [height, width]: object_class on the fan image (class_fan.npy); None without labels")
        .def_property_readonly(
            "boxes",
            [](py::object self) -> py::object {
                auto& f = self.cast<FrameObject&>();
                if (f.frame.instance.empty()) return py::none();
                auto& r = f.renderer.cast<RendererObject&>();
                fan_labels(self, true); // f.instance_fan, which the fan extents are read off
                r.box_finder.find(f.frame, f.instance_fan, r.fan->width(), r.fan->height(), r.boxes);
                return py::module_::import("json").attr("loads")(
                    host::boxes_json_text(f.frame, r.fan->width(), r.fan->height(), r.boxes, r.class_names));
            },
            "The frame's boxes.json as a dict: each labelled object's polar and fan extent, cells and energy "
            "(docs/datasets.md, 'Boxes and COCO export'); None without labels")
        .def_property_readonly(
            "fan",
            [](py::object self) {
                auto& f = self.cast<FrameObject&>();
                if (!f.fan_ready) f.renderer.cast<RendererObject&>().fan->render(f.frame, f.fan_image);
                f.fan_ready = true;
                return view(f.fan_image.rgb, {f.fan_image.height, f.fan_image.width, 3}, self);
            },
            "uint8 [height, width, 3]: the fan image (fan.png)")
        .def_property_readonly("beam_angles_rad",
                               [](py::object self) {
                                   auto& f = self.cast<FrameObject&>();
                                   return view(f.frame.beam_angles_rad, {f.frame.beams}, self);
                               })
        .def_property_readonly("ranges_m",
                               [](py::object self) {
                                   auto& f = self.cast<FrameObject&>();
                                   return view(f.frame.bin_ranges_m, {f.frame.bins}, self);
                               })
        .def_property_readonly("frame_index", [](const FrameObject& f) { return f.frame.frame_index; })
        .def_property_readonly("seed", [](const FrameObject& f) { return f.frame.seed; })
        .def_property_readonly(
            "meta", [](FrameObject& f) { return frame_meta(f); }, "meta.json's fields as a dict");

    py::class_<RendererObject, std::shared_ptr<RendererObject>>(m, "Renderer", "One simulated sonar over one scene.")
        .def(py::init([](std::shared_ptr<SceneObject> scene, const ConfigObject& config, const std::string& backend,
                         std::uint64_t seed, const std::vector<std::string>& outputs) {
                 if (!scene) throw py::value_error("scene: None");
                 // The config as the CLI resolves it for this scene, checked before any device is made.
                 SonarConfig resolved = config.for_scene(*scene->scene);
                 if (const auto valid = resolved.validate(); !valid)
                     throw py::value_error("invalid config: " + valid.error().message);
                 resolve_scene_keys(resolved, *scene);
                 RendererOptions options = renderer_options_from_env();
                 if (backend == "cpu")
                     options.backend = Backend::cpu;
                 else if (backend != "vulkan" && backend != "auto")
                     throw py::value_error("backend: '" + backend + "' is not a backend (auto, vulkan or cpu)");
                 options.seed = seed;
                 for (const std::string& o : outputs) {
                     if (o == "depth")
                         options.save_mask |= SaveFlags::depth;
                     else if (o == "normals")
                         options.save_mask |= SaveFlags::normals;
                     else if (o == "echo")
                         options.save_mask |= SaveFlags::echo;
                     else if (o == "labels")
                         options.save_mask |= SaveFlags::labels;
                     else
                         throw py::value_error("outputs: unknown '" + o + "' (depth, normals, echo, labels)");
                 }
                 auto r = std::make_shared<RendererObject>();
                 r->scene_data = scene->scene;
                 r->scene = std::move(scene);
                 if (backend == "auto") { // the CLI's rule (host/backend_choice.h)
                     auto vulkan_options = context_options_from_env();
                     const char* device = std::getenv("VKSONAR_DEVICE");
                     r->context = std::make_shared<Context>(
                         take(host::choose_backend(vulkan_options ? Context::create(vulkan_options.value())
                                                                  : Result<Context>(vulkan_options.error()),
                                                   device && *device, options.backend, r->backend_reason)));
                 } else {
                     r->backend_reason = "Renderer(backend='" + backend + "')";
                     r->context = std::make_shared<Context>(
                         options.backend == Backend::cpu ? Context::cpu_only()
                                                         : take(Context::create(take(context_options_from_env()))));
                 }
                 r->backend = options.backend == Backend::cpu ? "cpu" : "vulkan";
                 r->device = options.backend == Backend::cpu ? "cpu" : r->context->device_description();
                 r->renderer = take(Renderer::create(*r->context, resolved, *r->scene_data, options));
                 for (const ModelValidity& v : r->renderer.validity())
                     if (!v.ok) warn(v.warning()); // the CLI's warning lines (also renderer.validity())
                 const std::string unit_mistake = host::unit_mistake_warning(
                     *r->scene_data, resolved, r->scene->path.value_or("the scene"), "Scene.load(path, scale=", ")");
                 if (!unit_mistake.empty()) warn(unit_mistake);
                 r->scene_hash = host::scene_fnv1a64(*r->scene_data); // later add()s do not reach the renderer
                 r->class_names = r->scene_data->classes();
                 r->effects_json = host::effects_json(credit_scene_requests(renderer_plan(r->renderer).effects.states,
                                                                            config.config.effects, resolved.effects))
                                       .dump();
                 r->fan =
                     std::make_unique<host::FanRenderer>(renderer_plan(r->renderer), renderer_workers(r->renderer));
                 return r;
             }),
             py::arg("scene"), py::arg("config") = ConfigObject::preset("default"), py::arg("backend") = "auto",
             py::arg("seed") = 1, py::arg("outputs") = std::vector<std::string>{})
        .def(
            "render",
            [](py::object self, const std::vector<double>& pose, std::uint64_t frame_index,
               std::optional<std::uint64_t> seed, std::shared_ptr<FrameObject> out,
               std::optional<std::vector<double>> next_pose, std::optional<std::uint64_t> next_frame,
               std::optional<double> time_s) {
                auto& r = self.cast<RendererObject&>();
                if (pose.size() != 6)
                    throw py::value_error("pose: needs 6 numbers x,y,z,roll,pitch,yaw (metres, degrees), got " +
                                          std::to_string(pose.size()));
                if (next_pose && next_pose->size() != 6)
                    throw py::value_error("next_pose: needs 6 numbers x,y,z,roll,pitch,yaw (metres, degrees), got " +
                                          std::to_string(next_pose->size()));
                if (next_frame && !next_pose) throw py::value_error("next_frame: given without next_pose");
                if (time_s && !std::isfinite(*time_s))
                    throw py::value_error("time_s: " + py::str(py::float_(*time_s)).cast<std::string>() +
                                          " is not a finite time");
                if (out && out->renderer.ptr() != self.ptr()) throw py::value_error("out: a Frame of another Renderer");
                const std::unique_lock<std::mutex> lock = one_call_at_a_time(r);
                // seed= is this render's: the Renderer's own seed comes back after it.
                const std::uint64_t own_seed = r.renderer.seed();
                if (seed) r.renderer.set_seed(*seed);
                if (!out) {
                    out = std::make_shared<FrameObject>();
                    out->frame = r.renderer.make_frame();
                }
                out->plan = &renderer_plan(r.renderer);
                out->renderer = self;
                out->pose = Pose{pose[0], pose[1], pose[2], pose[3], pose[4], pose[5]};
                out->time_s = time_s;
                // (a failed render leaves every derived array to be made again on its next read)
                out->u16_ready = out->range_ready = out->fan_ready = false;
                out->instance_fan_ready = out->class_fan_ready = false;
                Result<void> rendered;
                {
                    py::gil_scoped_release unlocked; // other Python threads run while the sonar renders
                    if (next_pose) {
                        const std::vector<double>& n = *next_pose;
                        const NextFrame next{Pose{n[0], n[1], n[2], n[3], n[4], n[5]},
                                             next_frame ? *next_frame : frame_index + 1};
                        rendered = r.renderer.render(out->pose, frame_index, out->frame, next);
                    } else {
                        rendered = r.renderer.render(out->pose, frame_index, out->frame);
                    }
                    if (rendered) rebuild_read_arrays(*out, *r.fan);
                }
                if (seed) r.renderer.set_seed(own_seed);
                check(rendered);
                return out;
            },
            py::arg("pose"), py::arg("frame") = 0, py::arg("seed") = py::none(), py::arg("out") = nullptr,
            py::arg("next_pose") = py::none(), py::arg("next_frame") = py::none(), py::arg("time_s") = py::none(),
            "Renders one ping from pose (x, y, z, roll, pitch, yaw); frame keys the noise with the seed. "
            "Returns a new Frame, or fills `out` (a Frame of this renderer) to reuse its memory. "
            "next_pose (and next_frame, default frame + 1): the ping rendered next, which a GPU then renders "
            "while this one's host stages run (the same bytes; faster for a sequence of poses). time_s: the "
            "ping's time, meta's time_s (as a trajectory's time column gives it to the CLI).")
        .def(
            "flow",
            [](py::object self, std::shared_ptr<FrameObject> from, std::shared_ptr<FrameObject> to) {
                auto& r = self.cast<RendererObject&>();
                if (!from || !to) throw py::value_error("flow: frames must not be None");
                if (from->renderer.ptr() != self.ptr() || to->renderer.ptr() != self.ptr())
                    throw py::value_error("flow: frames of another Renderer");
                if (!renderer_plan(r.renderer).labels)
                    throw py::value_error("flow: this Renderer was made without outputs=['labels']");
                const std::unique_lock<std::mutex> lock = one_call_at_a_time(r);
                std::vector<float> flow;
                check(r.renderer.label_flow(from->frame, from->pose, to->frame, to->pose, flow));
                const std::size_t bins = from->frame.bins, beams = from->frame.beams;
                py::array_t<float> out(
                    {static_cast<py::ssize_t>(bins), static_cast<py::ssize_t>(beams), static_cast<py::ssize_t>(2)});
                std::copy(flow.begin(), flow.end(), out.mutable_data());
                return out;
            },
            py::arg("frame_from"), py::arg("frame_to"),
            "Where each labelled cell of frame_from moves by frame_to (both rendered by this Renderer with "
            "outputs=['labels'], from their own poses; a static scene): float32 [bins, beams, 2] of d_bin, d_beam, "
            "NaN where the cell has no label, leaves the window or is hidden (docs/labels.md).")
        .def_property_readonly("bins", [](const RendererObject& r) { return renderer_plan(r.renderer).bins; })
        .def_property_readonly("beams", [](const RendererObject& r) { return renderer_plan(r.renderer).beams; })
        .def_property_readonly("seed",
                               [](RendererObject& r) {
                                   const std::unique_lock<std::mutex> lock = one_call_at_a_time(r);
                                   return r.renderer.seed(); // not a render's seed= while it runs
                               })
        .def_property_readonly("backend", [](const RendererObject& r) { return r.backend; })
        .def_property_readonly(
            "beam_geometry",
            [](const RendererObject& r) {
                return std::string(renderer_plan(r.renderer).line_array ? "line_array" : "planar");
            },
            "The beam geometry as resolved (meta.json beam_geometry.used): 'line_array' or 'planar'.")
        .def(
            "frame_pose",
            [](const RendererObject& r) {
                Pose p;
                bool whole = false;
                if (!host::frame_pose(*r.scene_data, r.renderer.config(), p, whole))
                    throw py::value_error("frame_pose: the scene has nothing to frame");
                return py::make_tuple(p.x_m, p.y_m, p.z_m, p.roll_deg, p.pitch_deg, p.yaw_deg);
            },
            "The CLI's --pose frame: a pose (x, y, z, roll, pitch, yaw) looking along +x at the scene's "
            "bounding box, its width filling the fan, pitched down by half the vertical beamwidth.")
        .def("validity", [](const RendererObject& r) {
            py::list out;
            for (const ModelValidity& v : r.renderer.validity())
                out.append(py::dict(py::arg("model") = v.model, py::arg("ok") = v.ok, py::arg("key") = v.key,
                                    py::arg("value") = v.value, py::arg("domain") = v.domain,
                                    py::arg("action") = v.action));
            return out;
        });
}
