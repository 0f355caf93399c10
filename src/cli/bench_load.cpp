// `vksonar bench load`: how long a big scene takes to load in each glTF form: plain floats, gltfpack's
// quantized output (KHR_mesh_quantization), its meshopt-compressed output (EXT_meshopt_compression) and
// Draco (KHR_draco_mesh_compression, written with draco's encoder at 14-bit positions, Blender's default),
// for a generated terrain of about a million triangles (--grid N: N x N vertices). The plain .glb is
// written here, and the Draco one when this build has libdraco; the quantized and meshopt ones are made
// with Debian's gltfpack when it is installed (else skipped, saying so). After one untimed load, each form is loaded
// three times in this process (median time). Memory is the peak resident-set growth during a load beside the bytes
// of the arrays the scene keeps, measured in three fresh processes (this executable with --measure; the largest of
// the three): in this process the allocator keeps, and places new arrays around, what earlier loads freed, which
// moves the peak by several MiB either way. Before the load the allocator returns its free memory to the system
// (malloc_trim) and the kernel's high-water mark is reset (/proc/self/clear_refs).
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

struct Measured {
    double ms = 0;
    double peak_mib = -1; // resident-set growth during the load; -1: unknown
    double arrays_mib = 0;
    std::uint64_t triangles = 0;
};

// One load of `file` in this process.
Measured measure_load(const std::string& file) {
    Measured m;
    const bool reset = reset_peak_resident();
    const double before = status_mib("VmRSS:");
    const auto start = std::chrono::steady_clock::now();
    auto scene = Scene::load_gltf(file);
    const auto end = std::chrono::steady_clock::now();
    const double high = status_mib("VmHWM:");
    if (!scene) throw Failure("bench load: " + scene.error().message);
    m.ms = std::chrono::duration<double, std::milli>(end - start).count();
    if (reset && before >= 0) m.peak_mib = high - before;
    m.triangles = scene->stats().triangles;
    m.arrays_mib =
        double(scene_data(*scene).positions.size() + scene_data(*scene).indices.size()) * 4.0 / (1024 * 1024);
    return m;
}

// The same in a fresh process: `exe bench load --measure FILE`, which prints its figures on one line.
Measured measure_in_fresh_process(const fs::path& exe, const fs::path& file) {
    const std::string command = "'" + exe.string() + "' bench load --measure '" + file.string() + "' 2>/dev/null";
    std::FILE* pipe = ::popen(command.c_str(), "r");
    if (!pipe) throw Failure("bench load: cannot run " + command);
    Measured m;
    unsigned long long triangles = 0;
    const int fields = std::fscanf(pipe, "%lf %lf %lf %llu", &m.ms, &m.peak_mib, &m.arrays_mib, &triangles);
    if (::pclose(pipe) != 0 || fields != 4) throw Failure("bench load: " + command + " failed");
    m.triangles = triangles;
    return m;
}

std::string figure(double value, int decimals) {
    char text[32];
    std::snprintf(text, sizeof text, "%.*f", decimals, value);
    return text;
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
    const Args args =
        parse_args(argv, {{"--grid", true, false}, {"--measure", true, false}, {"--help", false, false}}, "bench load");
    if (args.has("--help")) {
        std::printf("usage: vksonar bench load [--grid N]\n"
                    "  load time, peak resident-set growth and scene arrays of a generated N x N terrain (default\n"
                    "  709: 1,002,528 triangles) as plain, quantized, meshopt- and Draco-compressed glTF (quantized\n"
                    "  and meshopt made with gltfpack if installed, Draco with libdraco if this build has it)\n"
                    "       vksonar bench load --measure FILE\n"
                    "  loads FILE once and prints: ms, peak resident-set growth MiB (-1: unknown), scene arrays MiB,\n"
                    "  triangles (what each fresh process of the table's memory column runs)\n");
        return 0;
    }
    if (args.has("--measure")) {
        const Measured m = measure_load(args.value("--measure"));
        std::printf("%.3f %.3f %.3f %llu\n", m.ms, m.peak_mib, m.arrays_mib,
                    static_cast<unsigned long long>(m.triangles));
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
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (ec) throw Failure("bench load: cannot find this executable (/proc/self/exe): " + ec.message());
    // (one untimed load first: the file cache and the allocator are warm for every form alike)
    if (!Scene::load_gltf((dir / "plain.glb").string())) throw Failure("bench load: the generated scene does not load");
    std::printf("| form | file MB | load ms (median of 3) | Mtriangles/s | scene arrays MiB | peak RSS growth MiB | "
                "peak / arrays |\n"
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
        Measured m;
        for (int run = 0; run < 3; ++run) {
            m = measure_load(file.string());
            ms.push_back(m.ms);
        }
        std::sort(ms.begin(), ms.end());
        double peak = 0;
        bool known = true;
        for (int run = 0; run < 3; ++run) {
            const Measured fresh = measure_in_fresh_process(exe, file);
            known = known && fresh.peak_mib >= 0;
            peak = std::max(peak, fresh.peak_mib);
        }
        peak_known = peak_known && known;
        std::printf("| %s | %.1f | %.0f | %.1f | %.1f | %s | %s |\n", form.name, double(fs::file_size(file)) / 1e6,
                    ms[1], double(m.triangles) / ms[1] / 1e3, m.arrays_mib, known ? figure(peak, 1).c_str() : "n/a",
                    known && m.arrays_mib > 0 ? figure(peak / m.arrays_mib, 2).c_str() : "n/a");
    }
    std::printf("(%u x %u grid; one run: compare rows, not machines. Peak RSS growth: the largest of three loads, each "
                "in a fresh process.%s)\n",
                n, n, peak_known ? "" : " n/a: this kernel does not let /proc/self/clear_refs reset the peak.");
    return 0;
}

} // namespace vksonar::cli
