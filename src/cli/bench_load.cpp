// `vksonar bench load`: how long a big scene takes to load in each glTF form: plain floats, gltfpack's
// quantized output (KHR_mesh_quantization), its meshopt-compressed output (EXT_meshopt_compression) and
// Draco (KHR_draco_mesh_compression, written with draco's encoder at 14-bit positions, Blender's default),
// for a generated terrain of about a million triangles (--grid N: N x N vertices). The plain .glb is
// written here, and the Draco one when this build has libdraco; the quantized and meshopt ones are made
// with Debian's gltfpack when it is installed (else skipped, saying so). After one untimed load, each form is loaded
// three times (median). Memory is the peak resident-set growth during a load (the largest of the three), beside the
// bytes of the arrays the scene keeps: before each load the allocator returns its free memory to the system
// (malloc_trim) and the kernel's high-water mark is reset (/proc/self/clear_refs), so what an earlier load left
// mapped does not hide a temporary.
#include <unistd.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/bench_common.h"
#include "cli/commands.h"
#include "scene/draco_pack.h"
#include "scene/gltf_draco.h"
#include "scene/scene_data.h"
#include "vksonar/scene.h"

namespace vksonar::cli {
namespace {

namespace fs = std::filesystem;

// A field of /proc/self/status in MiB ("VmRSS:" now, "VmHWM:" the peak since the last reset), -1 if absent.
double status_mib(const char* field) {
    std::ifstream status("/proc/self/status");
    std::string line;
    const std::size_t length = std::strlen(field);
    while (std::getline(status, line))
        if (line.compare(0, length, field) == 0) return std::atof(line.c_str() + length) / 1024.0;
    return -1.0;
}

// Gives the allocator's free memory back to the system and sets the resident-set high-water mark
// (VmHWM) to the current resident set. False where the kernel does not allow the reset.
bool reset_peak_resident() {
#if defined(__GLIBC__)
    ::malloc_trim(0);
#endif
    std::ofstream clear("/proc/self/clear_refs");
    clear << "5";
    clear.flush();
    return bool(clear) && status_mib("VmHWM:") >= 0.0;
}

// An N x N grid of a rolling seabed, 1 m spacing, as one indexed mesh in a .glb.
void write_terrain_glb(const fs::path& path, std::uint32_t n) {
    std::vector<float> positions;
    positions.reserve(std::size_t(n) * n * 3);
    for (std::uint32_t i = 0; i < n; ++i)
        for (std::uint32_t j = 0; j < n; ++j) {
            const double x = i, z = j;
            positions.insert(positions.end(),
                             {float(x), float(-5.0 + 0.8 * std::sin(0.11 * x) * std::cos(0.07 * z)), float(z)});
        }
    std::vector<std::uint32_t> indices;
    indices.reserve(std::size_t(n - 1) * (n - 1) * 6);
    for (std::uint32_t i = 0; i + 1 < n; ++i)
        for (std::uint32_t j = 0; j + 1 < n; ++j) {
            const std::uint32_t a = i * n + j, b = a + 1, c = a + n, d = c + 1;
            indices.insert(indices.end(), {a, b, c, b, d, c});
        }
    const std::size_t pos_bytes = positions.size() * 4, idx_bytes = indices.size() * 4;
    char json[1024];
    std::snprintf(json, sizeof json,
                  R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
                  R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
                  R"("accessors":[{"bufferView":0,"componentType":5126,"count":%zu,"type":"VEC3",)"
                  R"("min":[0,-5.8,0],"max":[%u,-4.2,%u]},{"bufferView":1,"componentType":5125,"count":%zu,)"
                  R"("type":"SCALAR"}],"bufferViews":[{"buffer":0,"byteLength":%zu},)"
                  R"({"buffer":0,"byteOffset":%zu,"byteLength":%zu}],"buffers":[{"byteLength":%zu}]})",
                  positions.size() / 3, n - 1, n - 1, indices.size(), pos_bytes, pos_bytes, idx_bytes,
                  pos_bytes + idx_bytes);
    std::string text = json;
    while (text.size() % 4)
        text += ' ';
    const std::uint32_t bin = static_cast<std::uint32_t>(pos_bytes + idx_bytes);
    const std::uint32_t total = static_cast<std::uint32_t>(12 + 8 + text.size() + 8 + bin);
    std::ofstream out(path, std::ios::binary);
    auto u32 = [&](std::uint32_t v) { out.write(reinterpret_cast<const char*>(&v), 4); };
    out.write("glTF", 4);
    u32(2);
    u32(total);
    u32(static_cast<std::uint32_t>(text.size()));
    u32(0x4E4F534Au);
    out.write(text.data(), std::streamsize(text.size()));
    u32(bin);
    u32(0x004E4942u);
    out.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(pos_bytes));
    out.write(reinterpret_cast<const char*>(indices.data()), std::streamsize(idx_bytes));
    if (!out) throw Failure("bench load: cannot write " + path.string());
}

} // namespace

int run_bench_load(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv, {{"--grid", true, false}, {"--help", false, false}}, "bench load");
    if (args.has("--help")) {
        std::printf("usage: vksonar bench load [--grid N]\n"
                    "  load time, peak resident-set growth and scene arrays of a generated N x N terrain (default\n"
                    "  709: 1,002,528 triangles) as plain, quantized, meshopt- and Draco-compressed glTF (quantized\n"
                    "  and meshopt made with gltfpack if installed, Draco with libdraco if this build has it)\n");
        return 0;
    }
    const auto n = static_cast<std::uint32_t>(parse_u64(args.value("--grid", "709"), "--grid"));
    if (n < 2 || n > 8192) throw BadInput("--grid " + std::to_string(n) + ": must be in [2, 8192]");
    char pattern[] = "/tmp/vksonar_bench_load_XXXXXX";
    if (!::mkdtemp(pattern)) throw Failure("bench load: cannot create a temporary folder");
    const fs::path dir = pattern;
    struct Cleanup {
        fs::path dir;
        ~Cleanup() {
            std::error_code ec;
            fs::remove_all(dir, ec);
        }
    } cleanup{dir};
    write_terrain_glb(dir / "plain.glb", n);
    struct Form {
        const char* name;
        const char* file;
        const char* gltfpack_flags; // null: written here
    };
    const Form forms[] = {{"plain (float)", "plain.glb", nullptr},
                          {"quantized (KHR_mesh_quantization)", "quantized.glb", ""},
                          {"meshopt (EXT_meshopt_compression)", "meshopt.glb", "-c"},
                          {"Draco (KHR_draco_mesh_compression)", "draco.glb", nullptr}};
    const bool have_gltfpack = std::system("command -v gltfpack >/dev/null 2>&1") == 0;
    if (!Scene::load_gltf((dir / "plain.glb").string())) throw Failure("bench load: the generated scene does not load");
    // (one untimed load first: the file cache and the allocator are warm for every form alike)
    std::printf("| form | file MB | load ms (median of 3) | Mtriangles/s | scene arrays MiB | peak RSS growth MiB | "
                "peak / arrays "
                "|\n"
                "|---|---:|---:|---:|---:|---:|---:|\n");
    bool peak_known = true;
    for (const Form& form : forms) {
        const fs::path file = dir / form.file;
        if (std::string(form.file) == "draco.glb") {
            if (!gltf::draco_available()) {
                std::printf("| %s | skipped: this build has no libdraco | | | | | |\n", form.name);
                continue;
            }
            const std::string error = gltf::write_draco_gltf((dir / "plain.glb").string(), file.string(), 14);
            if (!error.empty()) throw Failure("bench load: writing the Draco scene: " + error);
        }
        if (form.gltfpack_flags) {
            if (!have_gltfpack) {
                std::printf("| %s | skipped: gltfpack is not installed | | | | | |\n", form.name);
                continue;
            }
            const std::string command = std::string("gltfpack ") + form.gltfpack_flags + " -i '" +
                                        (dir / "plain.glb").string() + "' -o '" + file.string() + "' >/dev/null 2>&1";
            if (std::system(command.c_str()) != 0) throw Failure("bench load: " + command + " failed");
        }
        std::vector<double> ms;
        double peak = 0, arrays = 0;
        std::uint64_t triangles = 0;
        for (int run = 0; run < 3; ++run) {
            peak_known = reset_peak_resident() && peak_known;
            const double before = status_mib("VmRSS:");
            const auto start = std::chrono::steady_clock::now();
            auto scene = Scene::load_gltf(file.string());
            const auto end = std::chrono::steady_clock::now();
            const double high = status_mib("VmHWM:");
            if (!scene) throw Failure("bench load: " + scene.error().message);
            ms.push_back(std::chrono::duration<double, std::milli>(end - start).count());
            peak = std::max(peak, high - before);
            triangles = scene->stats().triangles;
            arrays = (scene_data(*scene).positions.size() * 4.0 + scene_data(*scene).indices.size() * 4.0) /
                     (1024.0 * 1024.0);
        }
        std::sort(ms.begin(), ms.end());
        std::printf("| %s | %.1f | %.0f | %.1f | %.1f | %s | %s |\n", form.name, double(fs::file_size(file)) / 1e6,
                    ms[1], double(triangles) / ms[1] / 1e3, arrays, peak_known ? bench::fmt(peak, 1).c_str() : "n/a",
                    peak_known && arrays > 0 ? bench::fmt(peak / arrays, 2).c_str() : "n/a");
    }
    std::printf("(%u x %u grid; one run: compare rows, not machines.%s)\n", n, n,
                peak_known ? "" : " Peak RSS n/a: this kernel does not let /proc/self/clear_refs reset the peak.");
    return 0;
}

} // namespace vksonar::cli
