// libFuzzer target for the glTF/GLB loader (Scene::load_gltf). The loader reads from a path, so each
// input is written to a per-process temporary file, named .glb when it starts with the GLB magic
// and .gltf otherwise (the loader itself decides by content).
// Build: scripts/fuzz.sh (clang, -DVKSONAR_FUZZ=ON). Seeds: tests/data/bad_gltf, tests/data/scenes.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace {

// Messages are printed one per line: no newline, carriage return or other control character.
bool one_printable_line(const std::string& text) {
    return std::none_of(text.begin(), text.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; });
}

// A fresh directory per process whose path has the same length in every run (mkdtemp's six random
// characters, not a PID): the path is part of every message, and a message of another length would
// change loop counts, coverage and so the inputs a seeded run goes on to try (scripts/fuzz.sh).
std::string temp_dir() {
    static const std::string dir = [] {
        const char* base = std::getenv("TMPDIR");
        std::string pattern = std::string(base && *base ? base : "/tmp") + "/vksonar_fuzz_gltf_XXXXXX";
        if (!::mkdtemp(pattern.data())) std::abort();
        return pattern;
    }();
    return dir;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size == 0) return 0;
    const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
    const std::string path = temp_dir() + (binary ? "/input.glb" : "/input.gltf");
    std::FILE* f = std::fopen(path.c_str(), "wb");
    if (!f) return 0;
    std::fwrite(data, 1, size, f);
    std::fclose(f);

    const vksonar::Result<vksonar::Scene> scene = vksonar::Scene::load_gltf(path);
    if (scene.ok()) {
        // A loaded scene is consistent: every index inside its mesh, every position finite.
        const vksonar::SceneData& d = scene_data(scene.value());
        for (const auto& mesh : d.meshes) {
            if (std::size_t(mesh.first_index) + mesh.index_count > d.indices.size()) std::abort();
            for (std::uint32_t i = 0; i < mesh.index_count; ++i)
                if (d.indices[mesh.first_index + i] >= mesh.vertex_count) std::abort();
        }
        for (float x : d.positions)
            if (!std::isfinite(x)) std::abort();
        for (const auto& draw : d.draws)
            if (draw.mesh >= d.meshes.size() || draw.material >= d.materials.size()) std::abort();
        for (const std::string& warning : scene.value().stats().warnings)
            if (!one_printable_line(warning) || warning.find(path) == std::string::npos) std::abort();
    } else {
        // Errors are one line that names the file.
        const std::string& message = scene.error().message;
        if (!one_printable_line(message) || message.find(path) == std::string::npos) std::abort();
    }
    return 0;
}
