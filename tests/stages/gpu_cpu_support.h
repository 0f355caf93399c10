// GPU-vs-CPU helpers shared by the stage tests (tests/stages/<stage>_test.cpp hold each stage's CPU
// checks and its GPU-vs-CPU match) and the whole-frame suite (tests/gpu_cpu_test.cpp): the bundled
// scenes, a scene rendered on both backends, the clean-scan agreement. Tolerances: tests/tolerances.h.
#pragma once

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/renderer_access.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_stages.h"
#include "test_support.h"
#include "tolerances.h"

namespace vksonar::testing {

constexpr SaveFlags kSaveAll = SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles;

struct SceneCase {
    std::string file;
    Pose pose;
};

inline std::vector<SceneCase> bundled_scenes() {
    std::vector<SceneCase> out;
    Pose look_down;
    look_down.pitch_deg = 15.0; // positive pitch tilts the nose down (REP-103): the seabed is in view
    for (const auto& entry : std::filesystem::directory_iterator(VKSONAR_ASSET_DIR "/scenes")) {
        const std::string ext = entry.path().extension().string();
        if (ext == ".gltf" || ext == ".glb") out.push_back({entry.path().string(), look_down});
    }
    std::sort(out.begin(), out.end(), [](const SceneCase& a, const SceneCase& b) { return a.file < b.file; });
    return out;
}

struct Pair {
    Scene scene;
    std::unique_ptr<Rendered> gpu, cpu;
};

inline std::unique_ptr<Pair> render_pair(const std::string& file, const SonarConfig& config, const Pose& pose,
                                         SaveFlags save_mask) {
    auto pair = std::make_unique<Pair>();
    auto scene = Scene::load_gltf(file);
    if (!scene) {
        ADD_FAILURE() << scene.error().message;
        return nullptr;
    }
    pair->scene = std::move(scene.value());
    pair->gpu = render_once(Backend::vulkan, config, pair->scene, pose, save_mask);
    pair->cpu = render_once(Backend::cpu, config, pair->scene, pose, save_mask);
    if (!pair->gpu || !pair->cpu) return nullptr;
    return pair;
}

// Cells where either backend's clean scan is above the noise floor NL - DI - SL, and how many of them
// differ by more than kFrameDbTol (tests/tolerances.h); a value below the floor counts as the floor.
struct CleanAgreement {
    std::size_t above = 0, over = 0;
    double max_db = 0;
};

// Per-pixel echo without the vertical pattern (E0 = E / b), from the same depth, materials and normals
// through the CPU reference: the scale of the pattern's absolute error (kVerticalPatternAbsTol), which
// near the pattern's null no relative tolerance can hold.
inline std::vector<float> echo_without_vertical_pattern(const Plan& plan, const Frame& f) {
    Plan flat = plan;
    flat.effects.vertical_pattern = false;
    std::vector<float> echo(f.depth.size() * 2);
    cpu::echo<float>(flat, f.depth.data(), f.material.data(), f.normals.data(), echo.data());
    return echo;
}

inline CleanAgreement compare_clean(const SonarConfig& config, const Frame& g, const Frame& c) {
    const double floor = std::pow(10.0, (config.noise_terms().floor_db() - config.source_level_db) / 10.0);
    CleanAgreement a;
    for (std::size_t i = 0; i < g.clean.size(); ++i) {
        if (g.clean[i] < floor && c.clean[i] < floor) continue;
        ++a.above;
        const double d = std::abs(to_db(std::max<double>(g.clean[i], floor * 1e-3)) -
                                  to_db(std::max<double>(c.clean[i], floor * 1e-3)));
        a.max_db = std::max(a.max_db, d);
        a.over += d > kFrameDbTol;
    }
    return a;
}

// A bundled scene rendered on both backends, with the validation layer on (one fixture per stage file).
class GpuCpuScene : public ::testing::TestWithParam<SceneCase> {
protected:
    void SetUp() override { VKSONAR_REQUIRE_VULKAN(); }
    ValidationGuard validation_;
};

inline std::string scene_name(const ::testing::TestParamInfo<SceneCase>& info) {
    return std::filesystem::path(info.param.file).stem().string();
}

} // namespace vksonar::testing
