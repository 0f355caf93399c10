// Scene::load_gltf: .gltf / .glb -> SceneData. gltf_file.cpp reads and checks the file and has
// tinygltf parse it; this file converts the model: node hierarchy, meshes and primitives, acoustic
// materials. tinygltf does not bounds-check accessors or buffer views, so everything that reads
// buffer memory is checked here first. Errors travel as gltf::LoadFailure and are turned into a
// Result at the boundary, so nothing throws across the API.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/mat4.h"
#include "scene/gltf_accessors.h"
#include "scene/gltf_draco.h"
#include "scene/gltf_file.h"
#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace vksonar {
namespace {

using gltf::component_bytes;
using gltf::fail;
using gltf::LoadFailure;
using gltf::one_line;
using nlohmann::json;

// glTF +Y up -> world +Z up: world = (x, -z, y), a +90 deg rotation about x.
const Mat4& world_from_gltf() {
    static const Mat4 m{1, 0, 0, 0, /**/ 0, 0, 1, 0, /**/ 0, -1, 0, 0, /**/ 0, 0, 0, 1};
    return m;
}

// The world transform times a uniform scale (SceneLoadOptions::scale).
Mat4 scaled(Mat4 m, double scale) {
    for (int i = 0; i < 12; ++i)
        m[std::size_t(i)] *= scale;
    return m;
}

// ---- conversion ---------------------------------------------------------------------------------

struct PrimitiveOut {
    std::uint32_t mesh = 0; // SceneData mesh index
    int gltf_material = -1;
};

class Converter {
public:
    Converter(const tinygltf::Model& model, SceneData& out, double scale) : model_(model), out_(out), scale_(scale) {}

    void run() {
        convert_materials();
        select_scene();
        out_.stats.meshes = static_cast<std::uint32_t>(out_.meshes.size());
        out_.stats.draws = static_cast<std::uint32_t>(out_.draws.size());
        if (out_.draws.empty()) out_.stats.warnings.push_back("scene has no triangles to draw");
    }

private:
    void warn(std::string text) { out_.stats.warnings.push_back(std::move(text)); }
    // Once per text: a mesh's extras are read for every node that draws it.
    void warn_once(std::string text) {
        std::vector<std::string>& w = out_.stats.warnings;
        if (std::find(w.begin(), w.end(), text) == w.end()) w.push_back(std::move(text));
    }

    // A material's acoustics: its extras.vksonar when it has them, else its name looked up in
    // acoustic_material_by_name (scene.h), else the default (Lambert, -30 dB). The names that fell to
    // the default are listed in one warning, so a scene from elsewhere is never mapped in silence.
    void convert_materials() {
        std::string unmapped;
        for (std::size_t i = 0; i < model_.materials.size(); ++i) {
            const tinygltf::Material& src = model_.materials[i];
            AcousticMaterial m;
            m.name = src.name.empty() ? "material " + std::to_string(i) : src.name;
            const std::string where = "material " + std::to_string(i) + " '" + m.name + "'";
            const json extras = src.extras_json_string.empty() ? json() : json::parse(src.extras_json_string);
            if (extras.is_object() && extras.contains("vksonar")) {
                apply_acoustic_extras(extras, m, where);
            } else if (const std::optional<AcousticMaterial> known = acoustic_material_by_name(m.name)) {
                const std::string name = m.name;
                m = *known;
                m.name = name;
            } else {
                unmapped += (unmapped.empty() ? "" : ", ") + ("'" + m.name + "'");
            }
            if (const auto valid = m.validate(); !valid)
                fail(ErrorCode::parse, where + ": extras.vksonar." + valid.error().message);
            out_.materials.push_back(m);
        }
        if (!unmapped.empty())
            warn("materials without extras.vksonar whose names match no acoustic material use the default "
                 "(lambert, -30 dB): " +
                 unmapped);
    }

    void apply_acoustic_extras(const json& extras, AcousticMaterial& m, const std::string& where) {
        if (!extras.is_object()) return;
        const auto it = extras.find("vksonar");
        if (it == extras.end()) return;
        if (!it->is_object()) fail(ErrorCode::parse, where + ": extras.vksonar is not an object");
        const auto finite_number = [&](const json& value, const std::string& key) {
            if (!value.is_number() || !std::isfinite(value.get<double>()))
                fail(ErrorCode::parse,
                     where + ": extras.vksonar." + key + " = " + value.dump() + " is not a finite number");
            return value.get<double>();
        };
        std::vector<std::string> facet_keys; // rough-model parameters, checked against the model below
        for (const auto& [key, value] : it->items()) {
            if (key == "backscatter_db") {
                m.backscatter_db = finite_number(value, key);
            } else if (key == "rms_slope" || key == "reflection_db") {
                (key == "rms_slope" ? m.rms_slope : m.reflection_db) = finite_number(value, key);
                facet_keys.push_back(key);
            } else if (key == "model") {
                const std::string model = value.is_string() ? value.get<std::string>() : value.dump();
                if (model == "lambert")
                    m.model = AcousticMaterial::Model::lambert;
                else if (model == "constant" || model == "lommel_seeliger")
                    m.model = AcousticMaterial::Model::constant;
                else if (model == "rough")
                    m.model = AcousticMaterial::Model::rough;
                else
                    fail(ErrorCode::parse,
                         where + ": extras.vksonar.model = " + value.dump() +
                             " (expected \"lambert\", \"constant\", \"lommel_seeliger\" or \"rough\")");
            } else {
                warn(where + ": unknown key extras.vksonar." + key + " ignored");
            }
        }
        if (m.model != AcousticMaterial::Model::rough)
            for (const std::string& key : facet_keys)
                warn(where + ": extras.vksonar." + key + " ignored (only the \"rough\" model uses it)");
    }

    std::uint32_t material_index(int gltf_material) {
        if (gltf_material >= 0) return static_cast<std::uint32_t>(gltf_material);
        if (!default_material_) {
            AcousticMaterial m;
            m.name = "default";
            out_.materials.push_back(m);
            default_material_ = static_cast<std::uint32_t>(out_.materials.size() - 1);
        }
        return *default_material_;
    }

    void select_scene() {
        // extras.vksonar at the file's top level reads as the scene's to a person, but the effects
        // belong to a scene (a file can hold several): say where they go rather than drop them silently.
        if (!model_.extras_json_string.empty()) {
            const json top = json::parse(model_.extras_json_string, nullptr, /*allow_exceptions=*/false);
            if (top.is_object() && top.contains("vksonar"))
                warn("extras.vksonar at the file's top level ignored: a scene's effects go in "
                     "scenes[N].extras.vksonar.effects");
        }
        std::vector<int> roots;
        if (model_.scenes.empty()) {
            // No scene: draw every node that is nobody's child, as most viewers do.
            std::vector<char> is_child(model_.nodes.size(), 0);
            for (const tinygltf::Node& n : model_.nodes)
                for (int c : n.children)
                    if (c >= 0 && std::size_t(c) < is_child.size()) is_child[std::size_t(c)] = 1;
            for (std::size_t i = 0; i < model_.nodes.size(); ++i)
                if (!is_child[i]) roots.push_back(static_cast<int>(i));
            if (!roots.empty()) warn("file has no scenes; drawing all root nodes");
        } else {
            const int scene_index = model_.defaultScene >= 0 ? model_.defaultScene : 0;
            if (std::size_t(scene_index) >= model_.scenes.size())
                fail(ErrorCode::parse, "scene " + std::to_string(scene_index) + " does not exist (" +
                                           std::to_string(model_.scenes.size()) + " scenes)");
            const tinygltf::Scene& scene = model_.scenes[std::size_t(scene_index)];
            roots = scene.nodes;
            if (!scene.extras_json_string.empty())
                read_scene_extras(json::parse(scene.extras_json_string), scene_index);
        }
        traverse(roots);
        // a sonar frame is one instant: the file's nodes as they are written, no animation played
        if (!model_.animations.empty())
            warn(std::to_string(model_.animations.size()) +
                 " animation(s) ignored: the scene is drawn as the file places its nodes (a vksonar scene is static)");
    }

    void read_scene_extras(const json& extras, int scene_index) {
        if (!extras.is_object()) return;
        const auto vk = extras.find("vksonar");
        if (vk == extras.end()) return;
        const std::string where = "scene " + std::to_string(scene_index) + ": extras.vksonar";
        if (!vk->is_object()) fail(ErrorCode::parse, where + " is not an object");
        for (const auto& [key, value] : vk->items())
            if (key != "effects")
                warn(where + "." + key +
                     " ignored: a scene's extras.vksonar holds effects only (sonar keys go in "
                     "--config or --set)");
        const auto effects = vk->find("effects");
        if (effects == vk->end()) return;
        if (!effects->is_object()) fail(ErrorCode::parse, where + ".effects is not an object");
        out_.effects_json = effects->dump();
    }

    static void check_finite(const std::vector<double>& v, const std::string& where) {
        for (double x : v)
            if (!std::isfinite(x)) fail(ErrorCode::parse, where + " has a NaN or Inf value");
    }

    // A node's world transform (column-major): every entry within kMaxWorldEntry (a translation of 1e39
    // rendered as float infinities in silence, 1e300 failed later naming no file), and a warning where it
    // flattens its meshes (a zero matrix or scale: nothing of them is drawn).
    static constexpr double kMaxWorldEntry = 1e12; // m (or m per unit): far past any scene, far inside float
    void check_world(const Mat4& world, const std::string& where, bool has_mesh) {
        for (double v : world) {
            if (std::abs(v) <= kMaxWorldEntry) continue;
            char text[32];
            std::snprintf(text, sizeof text, "%g", v);
            fail(ErrorCode::parse, where + ": its world transform reaches " + text +
                                       " (more than 1e12: no scene is that large; a unit or export mistake?)");
        }
        if (!has_mesh) return;
        if (determinant3(world) == 0.0 && !flat_warned_) {
            flat_warned_ = true;
            warn(where + ": its transform flattens its meshes (a zero scale or matrix): they are drawn as nothing");
        }
    }
    bool flat_warned_ = false;

    static Mat4 local_matrix(const tinygltf::Node& node, const std::string& where) {
        if (!node.matrix.empty()) {
            if (node.matrix.size() != 16)
                fail(ErrorCode::parse,
                     where + ": matrix has " + std::to_string(node.matrix.size()) + " values (expected 16)");
            check_finite(node.matrix, where + ": matrix");
            // an affine transform (glTF's matrices decompose into translation, rotation and scale): its last
            // row 0 0 0 1; a projective one would divide every vertex by a w the depth pass never sees
            for (int k = 0; k < 4; ++k) {
                if (std::abs(node.matrix[std::size_t(4 * k + 3)] - (k == 3 ? 1.0 : 0.0)) <= 1e-6) continue;
                char row[128];
                std::snprintf(row, sizeof row, "%g %g %g %g", node.matrix[3], node.matrix[7], node.matrix[11],
                              node.matrix[15]);
                fail(ErrorCode::parse, where + ": matrix is not affine: its last row is " + row + ", not 0 0 0 1");
            }
            Mat4 m;
            std::copy(node.matrix.begin(), node.matrix.end(), m.begin());
            return m;
        }
        const auto check_size = [&](const std::vector<double>& v, std::size_t n, const char* name) {
            if (!v.empty() && v.size() != n)
                fail(ErrorCode::parse, where + ": " + name + " has " + std::to_string(v.size()) + " values (expected " +
                                           std::to_string(n) + ")");
            check_finite(v, where + ": " + name);
        };
        check_size(node.translation, 3, "translation");
        check_size(node.rotation, 4, "rotation");
        check_size(node.scale, 3, "scale");
        double t[3] = {0, 0, 0}, s[3] = {1, 1, 1}, q[4] = {0, 0, 0, 1}; // q = x, y, z, w
        if (!node.translation.empty()) std::copy(node.translation.begin(), node.translation.end(), t);
        if (!node.scale.empty()) std::copy(node.scale.begin(), node.scale.end(), s);
        if (!node.rotation.empty()) {
            const double norm = std::sqrt(node.rotation[0] * node.rotation[0] + node.rotation[1] * node.rotation[1] +
                                          node.rotation[2] * node.rotation[2] + node.rotation[3] * node.rotation[3]);
            if (!(norm > 1e-12)) fail(ErrorCode::parse, where + ": rotation quaternion has zero length");
            for (int k = 0; k < 4; ++k)
                q[k] = node.rotation[std::size_t(k)] / norm; // exporters round; renormalize
        }
        const double x = q[0], y = q[1], z = q[2], w = q[3];
        const double r[9] = {// column-major 3x3
                             1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),
                             2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                             2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y)};
        Mat4 m = identity4();
        for (int col = 0; col < 3; ++col)
            for (int row = 0; row < 3; ++row)
                m[col * 4 + row] = r[col * 3 + row] * s[col];
        for (int row = 0; row < 3; ++row)
            m[12 + row] = t[row];
        return m;
    }

    void traverse(const std::vector<int>& roots) {
        // glTF nodes form a forest: a node reached twice is a cycle or a second parent. Rejecting it
        // keeps traversal finite (a node DAG could otherwise expand into exponentially many draws).
        std::vector<char> seen(model_.nodes.size(), 0);
        struct Item {
            int node;
            Mat4 parent;            // world_from_parent, including the y-up -> z-up rotation
            std::string class_name; // the nearest mesh-less ancestor's extras.vksonar.class, if any
        };
        std::vector<Item> stack;
        for (auto it = roots.rbegin(); it != roots.rend(); ++it)
            stack.push_back({*it, scaled(world_from_gltf(), scale_), {}});
        // Every node's world, for the joints of skinned meshes (drawn after the walk: a joint may come later).
        std::vector<Mat4> world_of(model_.nodes.size(), identity4());
        struct Skinned {
            int node;
            std::uint32_t id;
            std::string where;
        };
        std::vector<Skinned> skinned;
        while (!stack.empty()) {
            const Item item = stack.back();
            stack.pop_back();
            const std::string where = "node " + std::to_string(item.node);
            if (item.node < 0 || std::size_t(item.node) >= model_.nodes.size())
                fail(ErrorCode::parse, where + " does not exist (" + std::to_string(model_.nodes.size()) + " nodes)");
            if (seen[std::size_t(item.node)])
                fail(ErrorCode::parse, where + " is reached twice (node cycle or more than one parent)");
            seen[std::size_t(item.node)] = 1;
            const tinygltf::Node& node = model_.nodes[std::size_t(item.node)];
            const Mat4 world = multiply(item.parent, local_matrix(node, where));
            world_of[std::size_t(item.node)] = world;
            // a class set on a node without a mesh holds for the meshes below it (an exporter's empty parent:
            // Blender's custom property on the object that groups a diver's parts) unless one of them sets its
            // own; a mesh node's class is its own object's (a seabed's, not the rocks' placed below it)
            std::string own_class = class_of(node.extras_json_string, where);
            const std::string& class_name = own_class.empty() ? item.class_name : own_class;
            const std::string& passed_down = node.mesh >= 0 ? item.class_name : class_name;
            // (a skinned node's own transform is ignored: its joints place it)
            check_world(world, where, node.mesh >= 0 && node.skin < 0);
            if (node.skin >= 0 && node.mesh < 0) warn(where + ": skin on a node without a mesh ignored");
            if (node.mesh >= 0 && !node.weights.empty())
                warn(where + ": morph weights of the node ignored (the mesh's default weights are drawn)");
            if (node.mesh >= 0 && node.skin >= 0) {
                skinned.push_back({item.node, add_instance(item.node, class_name), where});
            } else if (node.mesh >= 0) {
                add_node_draws(node, world, add_instance(item.node, class_name), where);
            } else if (node.mesh < -1)
                fail(ErrorCode::parse, where + ": mesh index " + std::to_string(node.mesh) + " is invalid");
            for (auto c = node.children.rbegin(); c != node.children.rend(); ++c)
                stack.push_back({*c, world, passed_down});
        }
        for (const Skinned& s : skinned) {
            const tinygltf::Node& node = model_.nodes[std::size_t(s.node)];
            add_node_draws(node, skinned_placement(node.skin, world_of, seen, s.where), s.id, s.where);
        }
    }

    // A mesh node's draws: its mesh through `placement`, or once per EXT_mesh_gpu_instancing instance.
    void add_node_draws(const tinygltf::Node& node, const Mat4& placement, std::uint32_t id, const std::string& where) {
        const std::vector<Mat4> instances = instance_matrices(node, where);
        if (instances.empty()) add_draws(node.mesh, placement, id, where);
        for (const Mat4& instance : instances)
            add_draws(node.mesh, multiply(placement, instance), id, where);
    }

    // A skinned mesh's placement (glTF "Skins": the node's own transform is ignored; a vertex goes through
    // sum_i w_i J_i IBM_i, J_i its joints' worlds). vksonar draws meshes rigidly, through one matrix: the
    // first joint's J IBM. In the bind pose every joint's J IBM is the same matrix (the mesh's placement
    // when it was bound), so this is exact there; a posed skeleton is drawn in that placement, not
    // deformed, with a warning.
    Mat4 skinned_placement(int skin_index, const std::vector<Mat4>& world_of, const std::vector<char>& seen,
                           const std::string& where) {
        const std::string skin_where = where + ": skin " + std::to_string(skin_index);
        if (skin_index < 0 || std::size_t(skin_index) >= model_.skins.size())
            fail(ErrorCode::parse, skin_where + " does not exist (" + std::to_string(model_.skins.size()) + " skins)");
        const tinygltf::Skin& skin = model_.skins[std::size_t(skin_index)];
        if (skin.joints.empty()) fail(ErrorCode::parse, skin_where + " has no joints");
        std::vector<double> inverse_bind;
        if (skin.inverseBindMatrices >= 0) {
            if (std::size_t(skin.inverseBindMatrices) < model_.accessors.size() &&
                model_.accessors[std::size_t(skin.inverseBindMatrices)].type != TINYGLTF_TYPE_MAT4)
                fail(ErrorCode::parse, skin_where + " inverseBindMatrices accessor " +
                                           std::to_string(skin.inverseBindMatrices) + " is not MAT4");
            inverse_bind = gltf::read_accessor(model_, skin.inverseBindMatrices, skin_where + " inverseBindMatrices");
            check_finite(inverse_bind, skin_where + " inverseBindMatrices");
            if (inverse_bind.size() < 16 * skin.joints.size()) // glTF: at least one per joint
                fail(ErrorCode::parse, skin_where + " inverseBindMatrices holds " +
                                           std::to_string(inverse_bind.size() / 16) + " matrices for " +
                                           std::to_string(skin.joints.size()) + " joints");
        }
        const auto joint_matrix = [&](std::size_t j) {
            const int joint = skin.joints[j];
            if (joint < 0 || std::size_t(joint) >= model_.nodes.size() || !seen[std::size_t(joint)])
                fail(ErrorCode::parse, skin_where + ": joint " + std::to_string(joint) + " is not a node of the scene");
            Mat4 ibm = identity4();
            if (!inverse_bind.empty()) std::copy_n(inverse_bind.begin() + std::ptrdiff_t(16 * j), 16, ibm.begin());
            return multiply(world_of[std::size_t(joint)], ibm);
        };
        const Mat4 placement = joint_matrix(0);
        double scale = 0.0, off = 0.0;
        for (double v : placement)
            scale = std::max(scale, std::abs(v));
        for (std::size_t j = 1; j < skin.joints.size(); ++j) {
            const Mat4 other = joint_matrix(j);
            for (int k = 0; k < 16; ++k)
                off = std::max(off, std::abs(other[k] - placement[k]));
        }
        // (float matrices: a long chain of joints in its bind pose rounds to a few 1e-5 of the largest entry)
        warn(where + (off <= 1e-4 * std::max(scale, 1.0)
                          ? ": skin drawn in its bind pose (where its joints hold it; not animated)"
                          : ": skin drawn rigidly where its first joint holds it: its joints are posed, and vksonar "
                            "does not deform meshes"));
        check_world(placement, where, true);
        return placement;
    }

    // EXT_mesh_gpu_instancing: one matrix per instance from its TRANSLATION, ROTATION (a unit
    // quaternion, float or normalized integers) and SCALE accessors; empty without the extension.
    // Each instance becomes a draw of the same mesh: the mesh is stored once.
    std::vector<Mat4> instance_matrices(const tinygltf::Node& node, const std::string& where) {
        const auto ext = node.extensions.find("EXT_mesh_gpu_instancing");
        if (ext == node.extensions.end()) return {};
        const std::string ext_where = where + ": EXT_mesh_gpu_instancing";
        const tinygltf::Value& attributes = ext->second.Get("attributes");
        if (!attributes.IsObject()) fail(ErrorCode::parse, ext_where + " has no attributes object");
        std::vector<double> t, r, s;
        std::size_t count = 0;
        bool any = false;
        auto read = [&](const char* name, int components, std::vector<double>& out) {
            if (!attributes.Has(name)) return;
            const tinygltf::Value& index = attributes.Get(name);
            if (!index.IsInt() && !index.IsNumber())
                fail(ErrorCode::parse, ext_where + "." + name + " is not an index");
            const int accessor = index.GetNumberAsInt();
            const std::string attr_where = ext_where + "." + name + " accessor " + std::to_string(accessor);
            out = gltf::read_accessor(model_, accessor, attr_where);
            const tinygltf::Accessor& acc = model_.accessors[std::size_t(accessor)];
            if (gltf::type_components(acc.type) != components)
                fail(ErrorCode::parse, attr_where + " is not VEC" + std::to_string(components));
            check_finite(out, attr_where);
            const std::size_t n = out.size() / std::size_t(components);
            if (any && n != count)
                fail(ErrorCode::parse,
                     attr_where + " has " + std::to_string(n) + " instances, the others " + std::to_string(count));
            count = n;
            any = true;
        };
        read("TRANSLATION", 3, t);
        read("ROTATION", 4, r);
        read("SCALE", 3, s);
        if (!any) fail(ErrorCode::parse, ext_where + " has no TRANSLATION, ROTATION or SCALE");
        std::vector<Mat4> matrices(count);
        for (std::size_t i = 0; i < count; ++i) {
            tinygltf::Node trs;
            if (!t.empty())
                trs.translation.assign(t.begin() + std::ptrdiff_t(3 * i), t.begin() + std::ptrdiff_t(3 * i + 3));
            if (!r.empty())
                trs.rotation.assign(r.begin() + std::ptrdiff_t(4 * i), r.begin() + std::ptrdiff_t(4 * i + 4));
            if (!s.empty()) trs.scale.assign(s.begin() + std::ptrdiff_t(3 * i), s.begin() + std::ptrdiff_t(3 * i + 3));
            matrices[i] = local_matrix(trs, ext_where + " instance " + std::to_string(i));
        }
        out_.stats.instances += count;
        return matrices;
    }

    // extras.vksonar.class of a node or mesh ("" if not given); anything but a string is an error.
    std::string class_of(const std::string& extras_json, const std::string& where) {
        if (extras_json.empty()) return {};
        const json extras = json::parse(extras_json, nullptr, /*allow_exceptions=*/false);
        if (!extras.is_object() || !extras.contains("vksonar") || !extras["vksonar"].is_object()) return {};
        const json& vk = extras["vksonar"];
        for (const auto& [key, value] : vk.items())
            if (key != "class")
                warn_once(where + ": unknown key extras.vksonar." + key +
                          " ignored (a node's or mesh's extras.vksonar holds class only)");
        if (!vk.contains("class")) return {};
        if (!vk["class"].is_string() || vk["class"].get<std::string>().empty())
            fail(ErrorCode::parse, where + ": extras.vksonar.class = " + vk["class"].dump() + " is not a name");
        return vk["class"].get<std::string>();
    }

    // The object a node with a mesh is (SceneInstance): its id, name and class (node_class: its own
    // extras.vksonar.class or its nearest mesh-less ancestor's, else the mesh's, else the mesh's name).
    std::uint32_t add_instance(int node_index, const std::string& node_class) {
        const tinygltf::Node& node = model_.nodes[std::size_t(node_index)];
        SceneInstance instance;
        instance.id = static_cast<std::uint32_t>(node_index) + 1;
        instance.node = node.name;
        std::string mesh_class;
        if (std::size_t(node.mesh) < model_.meshes.size()) {
            const tinygltf::Mesh& mesh = model_.meshes[std::size_t(node.mesh)];
            instance.mesh = mesh.name;
            mesh_class = class_of(mesh.extras_json_string, "mesh " + std::to_string(node.mesh));
        }
        instance.class_name = node_class;
        if (instance.class_name.empty()) instance.class_name = mesh_class;
        if (instance.class_name.empty()) instance.class_name = instance.mesh;
        if (instance.class_name.empty()) instance.class_name = "mesh " + std::to_string(node.mesh);
        std::vector<std::string>& classes = out_.classes;
        const auto known = std::find(classes.begin(), classes.end(), instance.class_name);
        instance.class_id = static_cast<std::uint32_t>(known - classes.begin()) + 1;
        if (known == classes.end()) classes.push_back(instance.class_name);
        out_.instances.push_back(instance);
        return instance.id;
    }

    void add_draws(int mesh_index, const Mat4& world, std::uint32_t instance, const std::string& where) {
        if (std::size_t(mesh_index) >= model_.meshes.size())
            fail(ErrorCode::parse, where + ": mesh " + std::to_string(mesh_index) + " does not exist (" +
                                       std::to_string(model_.meshes.size()) + " meshes)");
        if (mesh_cache_.empty()) mesh_cache_.resize(model_.meshes.size());
        auto& cached = mesh_cache_[std::size_t(mesh_index)];
        if (!cached) cached = convert_mesh(mesh_index);
        for (const PrimitiveOut& p : *cached) {
            SceneDraw draw;
            draw.mesh = p.mesh;
            draw.material = material_index(p.gltf_material);
            draw.instance = instance;
            draw.world_from_local = world;
            out_.draws.push_back(draw);
            out_.stats.triangles += out_.meshes[p.mesh].index_count / 3;
        }
    }

    std::vector<PrimitiveOut> convert_mesh(int mesh_index) {
        std::vector<PrimitiveOut> prims;
        const tinygltf::Mesh& mesh = model_.meshes[std::size_t(mesh_index)];
        current_mesh_weights_ = mesh.weights;
        for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
            const std::string where = "mesh " + std::to_string(mesh_index) + " primitive " + std::to_string(p);
            if (std::optional<PrimitiveOut> out = convert_primitive(mesh.primitives[p], where)) prims.push_back(*out);
        }
        return prims;
    }

    void skip(const std::string& where, const std::string& why) {
        ++out_.stats.skipped_primitives;
        warn(where + ": skipped (" + why + ")");
    }

    std::optional<PrimitiveOut> convert_primitive(const tinygltf::Primitive& prim, const std::string& where) {
        static const char* const mode_names[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
        if (prim.mode >= 0 && prim.mode <= 3) {
            skip(where, std::string("mode ") + mode_names[prim.mode] + " has no surface");
            return std::nullopt;
        }
        if (prim.mode < 0 || prim.mode > 6)
            fail(ErrorCode::parse, where + ": unknown mode " + std::to_string(prim.mode));
        if (prim.material < -1 || (prim.material >= 0 && std::size_t(prim.material) >= model_.materials.size()))
            fail(ErrorCode::parse, where + ": material " + std::to_string(prim.material) + " does not exist (" +
                                       std::to_string(model_.materials.size()) + " materials)");

        const auto position = prim.attributes.find("POSITION");
        if (position == prim.attributes.end()) fail(ErrorCode::parse, where + ": missing POSITION attribute");
        const std::string pos_where = where + ": POSITION accessor " + std::to_string(position->second);
        // The primitive's vertices and triangles are appended to the scene's arrays as they are read,
        // with no copy in between, and taken back if the primitive is skipped.
        const std::size_t first_position = out_.positions.size(), first_index = out_.indices.size();
        const auto skip_primitive = [&](const std::string& why) {
            out_.positions.resize(first_position);
            out_.indices.resize(first_index);
            skip(where, why);
            return std::nullopt;
        };
        // KHR_draco_mesh_compression: positions and triangles from the stream (gltf_draco.h), in
        // place of the accessors' data (absent, or an uncompressed fallback).
        const auto draco = prim.extensions.find("KHR_draco_mesh_compression");
        if (draco != prim.extensions.end())
            gltf::decode_draco(model_, prim, draco->second, where, out_.positions, out_.indices);
        else
            append_positions(position->second, pos_where, out_.positions);
        const std::size_t position_values = out_.positions.size() - first_position;
        if (position_values == 0) return skip_primitive("no vertices");
        if (position_values / 3 > std::numeric_limits<std::uint32_t>::max())
            fail(ErrorCode::unsupported, pos_where + ": more than 2^32 vertices");
        const auto vertex_count = static_cast<std::uint32_t>(position_values / 3);
        apply_morph_targets(prim, out_.positions.data() + first_position, position_values, where);

        if (draco == prim.extensions.end()) append_triangles(prim, vertex_count, where);
        const std::size_t index_count = out_.indices.size() - first_index;
        if (index_count % 3 != 0) // a Draco stream's faces are whole triangles
            fail(ErrorCode::parse,
                 where + ": " + std::to_string(index_count) + " triangle indices is not a multiple of 3");
        if (index_count == 0) return skip_primitive("no triangles");
        if (all_degenerate(out_.positions.data() + first_position, out_.indices.data() + first_index, index_count))
            return skip_primitive("all " + std::to_string(index_count / 3) + " triangles are degenerate");

        constexpr std::uint64_t max_u32 = std::numeric_limits<std::uint32_t>::max();
        if (first_position / 3 + vertex_count > max_u32 || first_index + index_count > max_u32)
            fail(ErrorCode::unsupported, where + ": scene exceeds 2^32 vertices or indices");
        MeshRange range;
        range.first_index = static_cast<std::uint32_t>(first_index);
        range.index_count = static_cast<std::uint32_t>(index_count);
        range.first_vertex = static_cast<std::uint32_t>(first_position / 3);
        range.vertex_count = vertex_count;
        out_.meshes.push_back(range); // put in spatial order once every mesh is read (load_gltf)
        return PrimitiveOut{static_cast<std::uint32_t>(out_.meshes.size() - 1), prim.material};
    }

    // The primitive's triangles as a list appended to out_.indices: its indices accessor (or 0 ..
    // vertex_count - 1 without one), a strip or fan unrolled. The caller checks the count.
    void append_triangles(const tinygltf::Primitive& prim, std::uint32_t vertex_count, const std::string& where) {
        if (prim.mode == TINYGLTF_MODE_TRIANGLES) {
            append_indices(prim, vertex_count, where, out_.indices);
            return;
        }
        std::vector<std::uint32_t> in;
        append_indices(prim, vertex_count, where, in);
        if (in.size() < 3) return;
        out_.indices.reserve(out_.indices.size() + (in.size() - 2) * 3);
        for (std::size_t i = 0; i + 2 < in.size(); ++i) {
            if (prim.mode == TINYGLTF_MODE_TRIANGLE_FAN)
                out_.indices.insert(out_.indices.end(), {in[0], in[i + 1], in[i + 2]});
            else if (i % 2 == 0)
                out_.indices.insert(out_.indices.end(), {in[i], in[i + 1], in[i + 2]}); // strip keeps winding
            else
                out_.indices.insert(out_.indices.end(), {in[i + 1], in[i], in[i + 2]});
        }
    }

    void append_indices(const tinygltf::Primitive& prim, std::uint32_t vertex_count, const std::string& where,
                        std::vector<std::uint32_t>& out) {
        const std::size_t first = out.size();
        if (prim.indices == -1) {
            out.resize(first + vertex_count);
            for (std::uint32_t i = 0; i < vertex_count; ++i)
                out[first + i] = i;
            return;
        }
        const std::string idx_where = where + ": indices accessor " + std::to_string(prim.indices);
        if (prim.indices < 0 || std::size_t(prim.indices) >= model_.accessors.size())
            fail(ErrorCode::parse,
                 idx_where + " does not exist (" + std::to_string(model_.accessors.size()) + " accessors)");
        const tinygltf::Accessor& acc = model_.accessors[std::size_t(prim.indices)];
        if (acc.type != TINYGLTF_TYPE_SCALAR || (acc.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                                                 acc.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                                                 acc.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
            fail(ErrorCode::parse, idx_where + " is not an unsigned byte/short/int SCALAR");
        // Whole numbers below 2^32 (or, normalized, in [0, 1]): as uint32 they compare with vertex_count
        // as their values do.
        gltf::append_accessor(model_, prim.indices, idx_where, out);
        for (std::size_t i = first; i < out.size(); ++i) {
            if (out[i] >= vertex_count)
                fail(ErrorCode::parse, idx_where + ": index " + std::to_string(i - first) + " = " +
                                           std::to_string(out[i]) + " is out of range (" +
                                           std::to_string(vertex_count) + " vertices)");
        }
    }

    // POSITION (or a morph target's displacement): float VEC3, or an integer type of
    // KHR_mesh_quantization (byte, short, unsigned or not, normalized or not; the node transform
    // gltfpack writes dequantizes them). Sparse accessors and accessors without data are read too.
    void append_positions(int accessor, const std::string& where, std::vector<float>& out) {
        if (accessor < 0 || std::size_t(accessor) >= model_.accessors.size())
            fail(ErrorCode::parse,
                 where + " does not exist (" + std::to_string(model_.accessors.size()) + " accessors)");
        const tinygltf::Accessor& acc = model_.accessors[std::size_t(accessor)];
        const bool quantized = acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT;
        const bool declared = std::find(model_.extensionsUsed.begin(), model_.extensionsUsed.end(),
                                        "KHR_mesh_quantization") != model_.extensionsUsed.end();
        if (acc.type != TINYGLTF_TYPE_VEC3 || component_bytes(acc.componentType) == 0 ||
            acc.componentType == TINYGLTF_COMPONENT_TYPE_INT ||
            acc.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT || (quantized && !declared))
            fail(ErrorCode::unsupported, where + " is not float VEC3 (byte and short positions need "
                                                 "KHR_mesh_quantization in extensionsUsed)");
        // A float component converts to float and back exactly, an integer one is finite: the float is
        // finite exactly when the value read is.
        const std::size_t first = out.size();
        gltf::append_accessor(model_, accessor, where, out);
        for (std::size_t i = first; i < out.size(); ++i) {
            if (!std::isfinite(out[i]))
                fail(ErrorCode::parse, where + " has " + (std::isnan(out[i]) ? "NaN" : "Inf") + " at vertex " +
                                           std::to_string((i - first) / 3));
        }
    }

    // Morph targets at the mesh's default weights (glTF: mesh.weights, 0 when absent): each target's
    // POSITION displacement times its weight. Animation is not read: the default pose is drawn.
    void apply_morph_targets(const tinygltf::Primitive& prim, float* positions, std::size_t values,
                             const std::string& where) {
        if (prim.targets.empty()) return;
        const std::vector<double>& weights = current_mesh_weights_;
        for (std::size_t t = 0; t < prim.targets.size(); ++t) {
            const double weight = t < weights.size() ? weights[t] : 0.0;
            const auto it = prim.targets[t].find("POSITION");
            if (it == prim.targets[t].end() || weight == 0.0) continue;
            const std::string target_where = where + ": morph target " + std::to_string(t) + " POSITION";
            std::vector<float> delta;
            append_positions(it->second, target_where, delta);
            if (delta.size() != values)
                fail(ErrorCode::parse, target_where + " has " + std::to_string(delta.size() / 3) +
                                           " vertices, POSITION " + std::to_string(values / 3));
            for (std::size_t i = 0; i < values; ++i)
                positions[i] = static_cast<float>(positions[i] + weight * delta[i]);
        }
    }

    static bool all_degenerate(const float* pos, const std::uint32_t* idx, std::size_t index_count) {
        for (std::size_t t = 0; t < index_count; t += 3) {
            const float* a = &pos[std::size_t(idx[t]) * 3];
            const float* b = &pos[std::size_t(idx[t + 1]) * 3];
            const float* c = &pos[std::size_t(idx[t + 2]) * 3];
            const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
            const double v[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
            const double n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
            if (n[0] != 0 || n[1] != 0 || n[2] != 0) return false;
        }
        return true;
    }

    const tinygltf::Model& model_;
    SceneData& out_;
    std::optional<std::uint32_t> default_material_;
    std::vector<std::optional<std::vector<PrimitiveOut>>> mesh_cache_;
    std::vector<double> current_mesh_weights_; // the morph weights of the mesh being converted
    double scale_ = 1.0;                       // SceneLoadOptions::scale
};

} // namespace

Result<Scene> Scene::load_gltf(const std::string& path, const SceneLoadOptions& options) {
    try {
        Scene scene;
        SceneData& data = *scene.data_;
        data.source_path = path;
        // A path with a NUL byte (from Python or C++; argv cannot hold one) would be opened cut short there.
        if (path.find('\0') != std::string::npos)
            return make_error(ErrorCode::invalid_argument,
                              "scene path '" + path.substr(0, path.find('\0')) + "\\0...': holds a NUL byte");
        // The config's scene.scale range (config_keys.cpp): a unit mistake is at most km for mm.
        if (!(options.scale >= 1e-6 && options.scale <= 1e6)) {
            char scale[32];
            std::snprintf(scale, sizeof scale, "%g", options.scale);
            return make_error(ErrorCode::invalid_argument, path + ": scale " + scale + " is not in [1e-06, 1e+06]");
        }
        {
            const tinygltf::Model model = gltf::read_model(path, options.asset_root, data.stats.warnings);
            Converter(model, data, options.scale).run();
            data.stats.extensions = model.extensionsUsed;
        } // the file's buffers are freed before the spatial order allocates its scratch
        order_triangles_spatially(data);
        data.positions.shrink_to_fit(); // no-ops when the arrays grew by exactly one primitive
        data.indices.shrink_to_fit();
        for (std::string& w : data.stats.warnings) // one line each, like errors (names may hold newlines)
            w = detail::escape_control_chars(path + ": " + w);
        return Result<Scene>(std::move(scene));
    } catch (const LoadFailure& e) {
        return make_error(e.code, path + ": " + e.what);
    } catch (const json::exception& e) {
        return make_error(ErrorCode::parse, path + ": invalid JSON: " + one_line(e.what()));
    } catch (const std::bad_alloc&) {
        return make_error(ErrorCode::io, path + ": out of memory while loading");
    } catch (const std::exception& e) {
        return make_error(ErrorCode::internal, path + ": " + one_line(e.what()));
    }
}

} // namespace vksonar
