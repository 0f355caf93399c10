// What every output records about the run that wrote it, beside its config and pose (meta.json, the
// .h5 attributes, a shard's identity): the version of vksonar and the scene by its content.
#include <cstdint>
#include <cstdio>
#include <string>

#include "core/access.h"
#include "host/meta_fields.h"
#include "scene/scene_data.h"

namespace vksonar::host {

const char* vksonar_version() {
    return VKSONAR_VERSION; // the project's version (CMakeLists.txt), set for this file only
}

namespace {
// FNV-1a 64 over bytes, a field at a time (never a struct's padding).
struct Fnv {
    std::uint64_t hash = 0xcbf29ce484222325ull;
    void bytes(const void* data, std::size_t n) {
        const auto* p = static_cast<const unsigned char*>(data);
        for (std::size_t i = 0; i < n; ++i) {
            hash ^= p[i];
            hash *= 0x100000001b3ull;
        }
    }
    template <typename T> void value(T v) { bytes(&v, sizeof v); }
    void text(const std::string& s) {
        value<std::uint64_t>(s.size());
        bytes(s.data(), s.size());
    }
};
} // namespace

// The scene's path can name another file later (or the same file by another path): its content cannot.
std::string scene_fnv1a64(const Scene& scene) {
    const SceneData& d = scene_data(scene);
    Fnv h;
    h.value<std::uint64_t>(d.positions.size());
    h.bytes(d.positions.data(), d.positions.size() * sizeof(float));
    h.value<std::uint64_t>(d.indices.size());
    h.bytes(d.indices.data(), d.indices.size() * sizeof(std::uint32_t));
    h.value<std::uint64_t>(d.meshes.size());
    for (const MeshRange& m : d.meshes)
        for (std::uint32_t v : {m.first_index, m.index_count, m.first_vertex, m.vertex_count})
            h.value(v);
    h.value<std::uint64_t>(d.draws.size());
    for (const SceneDraw& draw : d.draws) {
        for (std::uint32_t v : {draw.mesh, draw.material, draw.instance})
            h.value(v);
        for (double v : draw.world_from_local)
            h.value(v);
    }
    h.value<std::uint64_t>(d.materials.size());
    for (const AcousticMaterial& m : d.materials) {
        h.text(m.name);
        h.value(static_cast<std::uint8_t>(m.model));
        for (double v : {m.backscatter_db, m.rms_slope, m.reflection_db})
            h.value(v);
    }
    h.value<std::uint64_t>(d.instances.size());
    for (const SceneInstance& i : d.instances) {
        h.value(i.id);
        h.value(i.class_id);
        h.text(i.node);
        h.text(i.mesh);
        h.text(i.class_name);
    }
    h.value<std::uint64_t>(d.classes.size());
    for (const std::string& c : d.classes)
        h.text(c);
    h.text(d.effects_json);
    char text[17];
    std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(h.hash));
    return text;
}

} // namespace vksonar::host
