// The glTF loader's memory: the spatial order of every mesh at once (after the file's buffers are
// freed) gives the same arrays as ordering each mesh as it is added, and a load's peak resident-set
// growth stays near the file's buffer plus the arrays the scene keeps, which are sized exactly.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <system_error>
#include <vector>

#include "core/plan.h"
#include "host/workers.h"
#include "scene/scene_data.h"
#include "test_support.h"
#include "vksonar/scene.h"

#if defined(__SANITIZE_ADDRESS__)
#define VKSONAR_TEST_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VKSONAR_TEST_UNDER_ASAN 1
#endif
#endif

namespace vksonar {
namespace {

namespace fs = std::filesystem;

// Meshes of random triangles over random vertices (the last few of some meshes unused), more and
// fewer than a depth cluster's worth, each added to `one_by_one` and ordered at once, and all added to
// `at_once` and ordered together: the same positions, indices and mesh ranges.
TEST(SceneOrder, EveryMeshAtOnceEqualsOneMeshAtATime) {
    struct Spec {
        std::uint32_t triangles, vertices, unused;
    };
    const Spec specs[] = {
        {200, 150, 0}, {kClusterTriangles + 1, 400, 3},  {2000, 1200, 0}, {kClusterTriangles, 300, 0}, {1500, 900, 40},
        {1, 3, 0},     {3 * kClusterTriangles + 7, 5, 0}};
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> coordinate(-50.0f, 50.0f);
    SceneData one_by_one, at_once;
    for (const Spec& spec : specs) {
        std::vector<float> positions(3 * std::size_t(spec.vertices));
        for (float& x : positions)
            x = coordinate(rng);
        std::uniform_int_distribution<std::uint32_t> vertex(0, spec.vertices - 1 - spec.unused);
        std::vector<std::uint32_t> indices(3 * std::size_t(spec.triangles));
        for (std::uint32_t& i : indices)
            i = vertex(rng);
        for (SceneData* scene : {&one_by_one, &at_once}) {
            MeshRange range;
            range.first_index = static_cast<std::uint32_t>(scene->indices.size());
            range.index_count = static_cast<std::uint32_t>(indices.size());
            range.first_vertex = static_cast<std::uint32_t>(scene->positions.size() / 3);
            range.vertex_count = spec.vertices;
            scene->positions.insert(scene->positions.end(), positions.begin(), positions.end());
            scene->indices.insert(scene->indices.end(), indices.begin(), indices.end());
            scene->meshes.push_back(range);
        }
        order_triangles_spatially(one_by_one, one_by_one.meshes.back());
    }
    const std::vector<std::uint32_t> unordered = at_once.indices;
    order_triangles_spatially(at_once);
    ASSERT_NE(at_once.indices, unordered) << "the order must change";
    EXPECT_EQ(at_once.indices, one_by_one.indices);
    EXPECT_EQ(at_once.positions, one_by_one.positions);
    EXPECT_EQ(at_once.positions.capacity(), at_once.positions.size());
    ASSERT_EQ(at_once.meshes.size(), one_by_one.meshes.size());
    for (std::size_t m = 0; m < at_once.meshes.size(); ++m) {
        EXPECT_EQ(at_once.meshes[m].first_index, one_by_one.meshes[m].first_index) << "mesh " << m;
        EXPECT_EQ(at_once.meshes[m].index_count, one_by_one.meshes[m].index_count) << "mesh " << m;
        EXPECT_EQ(at_once.meshes[m].first_vertex, one_by_one.meshes[m].first_vertex) << "mesh " << m;
        EXPECT_EQ(at_once.meshes[m].vertex_count, one_by_one.meshes[m].vertex_count) << "mesh " << m;
    }
}

// An n x n-quad rolling terrain, 1 m spacing, as one indexed float mesh in a .glb; returns its size.
std::uintmax_t write_terrain_glb(const fs::path& path, std::uint32_t n) {
    const std::uint32_t row = n + 1;
    std::vector<float> positions;
    for (std::uint32_t j = 0; j < row; ++j)
        for (std::uint32_t i = 0; i < row; ++i)
            positions.insert(positions.end(),
                             {float(i), float(0.5 * std::sin(0.1 * i) * std::cos(0.07 * j)), float(j)});
    std::vector<std::uint32_t> indices;
    for (std::uint32_t j = 0; j < n; ++j)
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::uint32_t a = j * row + i;
            indices.insert(indices.end(), {a, a + row, a + 1, a + 1, a + row, a + row + 1});
        }
    const std::size_t pos_bytes = positions.size() * 4, idx_bytes = indices.size() * 4;
    std::string json = R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
                       R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],)"
                       R"("accessors":[{"bufferView":0,"componentType":5126,"type":"VEC3","count":)" +
                       std::to_string(positions.size() / 3) + R"(},{"bufferView":1,"componentType":5125,)" +
                       R"("type":"SCALAR","count":)" + std::to_string(indices.size()) +
                       R"(}],"bufferViews":[{"buffer":0,"byteLength":)" + std::to_string(pos_bytes) +
                       R"(},{"buffer":0,"byteOffset":)" + std::to_string(pos_bytes) + R"(,"byteLength":)" +
                       std::to_string(idx_bytes) + R"(}],"buffers":[{"byteLength":)" +
                       std::to_string(pos_bytes + idx_bytes) + "}]}";
    while (json.size() % 4)
        json += ' ';
    std::ofstream out(path, std::ios::binary);
    const auto u32 = [&](std::size_t v) {
        const auto x = static_cast<std::uint32_t>(v);
        out.write(reinterpret_cast<const char*>(&x), 4);
    };
    out.write("glTF", 4);
    u32(2);
    u32(12 + 8 + json.size() + 8 + pos_bytes + idx_bytes);
    u32(json.size());
    u32(0x4E4F534Au);
    out.write(json.data(), std::streamsize(json.size()));
    u32(pos_bytes + idx_bytes);
    u32(0x004E4942u);
    out.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(pos_bytes));
    out.write(reinterpret_cast<const char*>(indices.data()), std::streamsize(idx_bytes));
    out.close();
    return fs::file_size(path);
}

// The peak resident set, in MiB, of `vksonar info FILE` (which loads the scene and prints what it
// holds) as a fresh process: its allocator starts clean, so no earlier free memory hides a temporary.
// -1 if it could not be run or failed.
double info_peak_mib(const std::string& file) {
    const std::string cli = VKSONAR_CLI;
    std::vector<std::string> args = {cli, "info", file};
    std::vector<char*> argv;
    for (std::string& a : args)
        argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
    pid_t child = -1;
    const int spawned = posix_spawn(&child, cli.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawned != 0) return -1;
    int status = 0;
    struct rusage usage {};
    if (::wait4(child, &status, 0, &usage) != child || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return -1;
    return double(usage.ru_maxrss) / 1024; // KiB on Linux
}

// A 400 x 400-quad terrain (320,000 triangles, a 5.5 MiB file, 5.9 MiB of arrays): the loader holds the
// file's bytes and tinygltf's copy of its buffer, then that copy and the scene's arrays, then the
// arrays and the spatial order's scratch, never much more than the file and the arrays together.
// Before the arrays were read straight from the buffer and ordered after it was freed, the peak was
// 5.4x the arrays (2.8x the file and the arrays).
TEST(SceneLoadMemory, PeakGrowthStaysNearTheFileAndTheArrays) {
#if defined(VKSONAR_TEST_UNDER_ASAN)
    GTEST_SKIP() << "resident-set sizes under AddressSanitizer include its shadow memory and quarantine";
#endif
    const fs::path dir = fs::temp_directory_path() / ("vksonar_scene_memory_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const fs::path tiny = dir / "tiny.glb", terrain = dir / "terrain.glb";
    write_terrain_glb(tiny, 2);
    const double file_mib = double(write_terrain_glb(terrain, 400)) / (1024 * 1024);
    const Result<Scene> scene = Scene::load_gltf(terrain.string());
    ASSERT_TRUE(scene.ok()) << scene.error().message;
    const SceneData& d = scene_data(scene.value());
    EXPECT_EQ(d.positions.capacity(), d.positions.size()) << "the scene's arrays are sized exactly";
    EXPECT_EQ(d.indices.capacity(), d.indices.size());
    const double arrays_mib = double(d.positions.size() + d.indices.size()) * 4 / (1024 * 1024);
    const double baseline = info_peak_mib(tiny.string()), peak = info_peak_mib(terrain.string());
    fs::remove_all(dir);
    ASSERT_GT(baseline, 0.0) << "vksonar info failed";
    ASSERT_GT(peak, 0.0) << "vksonar info failed";
    EXPECT_LE(peak - baseline, 1.15 * (file_mib + arrays_mib))
        << "file " << file_mib << " MiB, arrays " << arrays_mib << " MiB, peak " << peak << " MiB, baseline "
        << baseline << " MiB";
}

// Out of memory and out of threads, for real: a forked child (a death test) caps its own address space
// (RLIMIT_AS) at what it uses now plus `margin`, so the next allocations and thread stacks fail. Each
// test sweeps the margin so that the failure lands at different points of the call; the child exits 0
// when every call came back as a value (an exception reaching the top, or std::terminate, fails it).
// Not under AddressSanitizer, whose shadow memory needs the address space.
std::size_t address_space_in_use() {
    std::FILE* statm = std::fopen("/proc/self/statm", "r");
    unsigned long pages = 0;
    if (statm == nullptr) return 0;
    if (std::fscanf(statm, "%lu", &pages) != 1) pages = 0;
    std::fclose(statm);
    return std::size_t(pages) * std::size_t(::sysconf(_SC_PAGESIZE));
}

void cap_address_space(std::size_t margin) {
    struct rlimit limit {};
    ::getrlimit(RLIMIT_AS, &limit);
    limit.rlim_cur = margin == 0 ? limit.rlim_max : rlim_t(address_space_in_use() + margin);
    ::setrlimit(RLIMIT_AS, &limit);
}

// The children's bodies (a function each: a death test's statement is a macro argument).
[[noreturn]] void workers_child() {
    int threw = 0;
    for (std::size_t mib = 1; mib <= 80; mib += 3) {
        cap_address_space(mib << 20);
        try {
            host::Workers workers(host::Workers::kMaxThreads);
        } catch (const std::system_error&) {
            ++threw;
        } catch (const std::bad_alloc&) {
            ++threw;
        }
        cap_address_space(0);
    }
    std::fprintf(stderr, "threw %d times\n", threw);
    std::_Exit(threw > 0 ? 0 : 2);
}

[[noreturn]] void renderer_child(const SonarConfig& config, const Scene& scene, const RendererOptions& options) {
    int failed = 0;
    for (std::size_t mib = 1; mib <= 200; mib += 7) {
        cap_address_space(mib << 20);
        try {
            auto renderer = Renderer::create(testing::cpu_context(), config, scene, options);
            cap_address_space(0);
            if (!renderer.ok()) {
                if (renderer.error().message.rfind("Renderer::create: ", 0) != 0) std::_Exit(4);
                ++failed;
            }
        } catch (...) {
            std::_Exit(3); // an exception crossed the public API
        }
        cap_address_space(0);
    }
    std::fprintf(stderr, "failed %d times\n", failed);
    std::_Exit(failed > 0 ? 0 : 2);
}

[[noreturn]] void add_mesh_child(const std::vector<float>& positions, const std::vector<std::uint32_t>& indices) {
    const auto vertices = static_cast<std::uint32_t>(positions.size() / 3);
    Scene scene;
    AcousticMaterial material;
    testing::add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0, material);
    const SceneData& d = scene_data(scene);
    int failed = 0;
    for (std::size_t mib = 1; mib <= 120; mib += 2) {
        const std::size_t p = d.positions.size(), i = d.indices.size(), m = d.meshes.size();
        cap_address_space(mib << 20);
        bool ok = false;
        try {
            auto added =
                scene.add_mesh(positions.data(), vertices, indices.data(), static_cast<std::uint32_t>(indices.size()));
            ok = added.ok();
        } catch (...) {
            cap_address_space(0);
            std::_Exit(3); // an exception crossed the public API
        }
        cap_address_space(0);
        if (ok) break; // it fitted: the sweep is done
        ++failed;
        if (d.positions.size() != p || d.indices.size() != i || d.meshes.size() != m) std::_Exit(4);
    }
    std::fprintf(stderr, "failed %d times\n", failed);
    std::_Exit(failed > 0 ? 0 : 2);
}

// A material whose name cannot be copied (64 MiB under a 16 MiB margin).
[[noreturn]] void add_material_child() {
    Scene scene;
    AcousticMaterial material;
    material.name.assign(std::size_t(64) << 20, 'm');
    bool ok = false;
    cap_address_space(std::size_t(16) << 20);
    try {
        auto added = scene.add_material(material);
        ok = added.ok();
        if (!ok && added.error().message.rfind("Scene::add_material: out of memory", 0) != 0) {
            cap_address_space(0);
            std::_Exit(4);
        }
    } catch (...) {
        cap_address_space(0);
        std::_Exit(3); // an exception crossed the public API
    }
    cap_address_space(0);
    if (ok) std::_Exit(2); // it fitted: nothing was tested
    if (!scene.materials().empty()) std::_Exit(5);
    auto again = scene.add_material(material); // with memory back, the scene takes it as its first
    if (!again.ok() || again.value() != 0) std::_Exit(6);
    std::fprintf(stderr, "failed as expected\n");
    std::_Exit(0);
}

// host::Workers: if the k-th thread cannot start, the threads already started are stopped and joined
// and the std::system_error comes out of the constructor (before, they were destroyed joinable:
// std::terminate).
TEST(OutOfResources, WorkersThatCannotStartEveryThreadThrowInsteadOfTerminating) {
#if defined(VKSONAR_TEST_UNDER_ASAN)
    GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer's shadow memory do not mix";
#endif
    EXPECT_EXIT(workers_child(), ::testing::ExitedWithCode(0), "threw");
}

// Renderer::create out of memory or threads returns an Error naming it; no exception crosses the API.
TEST(OutOfResources, RendererCreateReturnsAnError) {
#if defined(VKSONAR_TEST_UNDER_ASAN)
    GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer's shadow memory do not mix";
#endif
    Scene scene;
    AcousticMaterial material;
    testing::add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0, material);
    const SonarConfig config = testing::quiet_config();
    RendererOptions options;
    options.backend = Backend::cpu;
    options.host_threads = host::Workers::kMaxThreads;
    EXPECT_EXIT(renderer_child(config, scene, options), ::testing::ExitedWithCode(0), "failed");
}

// Scene::add_mesh out of memory part way (the positions appended, the indices not; or in the spatial
// ordering) leaves the scene as it was and returns an Error.
TEST(OutOfResources, AddMeshLeavesTheSceneUnchanged) {
#if defined(VKSONAR_TEST_UNDER_ASAN)
    GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer's shadow memory do not mix";
#endif
    const std::uint32_t vertices = 1u << 20; // 12 MiB of positions, 12 MiB of indices
    std::vector<float> positions(3 * std::size_t(vertices));
    for (std::size_t i = 0; i < positions.size(); ++i)
        positions[i] = float(i % 1000) * 0.01f;
    std::vector<std::uint32_t> indices(3 * std::size_t(vertices));
    for (std::size_t i = 0; i < indices.size(); ++i)
        indices[i] = std::uint32_t((i * 7919) % vertices);
    EXPECT_EXIT(add_mesh_child(positions, indices), ::testing::ExitedWithCode(0), "failed");
}

// Scene::add_material out of memory returns an Error and leaves the scene as it was (it used to let
// std::bad_alloc out of a function documented "never fails").
TEST(OutOfResources, AddMaterialReturnsAnError) {
#if defined(VKSONAR_TEST_UNDER_ASAN)
    GTEST_SKIP() << "RLIMIT_AS and AddressSanitizer's shadow memory do not mix";
#endif
    EXPECT_EXIT(add_material_child(), ::testing::ExitedWithCode(0), "failed as expected");
}

} // namespace
} // namespace vksonar
