// End-to-end tests of the render path (issue: headless render tool), run on both backends.
#include <algorithm>
#include <cmath>
#include <cstring>

#include "stages/cpu_simd.h"
#include "test_support.h"

namespace vksonar::testing {
namespace {

class RenderTest : public ::testing::TestWithParam<Backend> {
protected:
    void SetUp() override {
        if (GetParam() == Backend::vulkan) VKSONAR_REQUIRE_VULKAN();
    }
    ValidationGuard validation_;
};

std::string backend_name(const ::testing::TestParamInfo<Backend>& info) {
    return info.param == Backend::vulkan ? "vulkan" : "cpu";
}

// Index of the range bin containing range r.
int bin_of(const Plan& plan, double r) {
    return static_cast<int>(std::floor((r - plan.config.range_min_m) / plan.bin_width_m));
}

TEST_P(RenderTest, PlaneAt10mLandsInItsRangeBinAndBeams) {
    SonarConfig config = quiet_config();
    config.effects.horizontal_pattern = EffectMode::off; // so "the beams it covers" has a sharp edge
    config.effects.ambient_noise = EffectMode::on;
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0);
    auto r = render_once(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;

    // First return: the nearest non-empty bin is the bin of 10 m (+-1: the tent kernel splits
    // energy with the neighbouring bin).
    int first_bin = -1;
    for (std::uint32_t k = 0; k < f.bins && first_bin < 0; ++k) {
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            if (f.clean[k * f.beams + j] > 0) {
                first_bin = static_cast<int>(k);
                break;
            }
        }
    }
    EXPECT_NEAR(first_bin, bin_of(plan, 10.0), 1);

    // The plane spans azimuth +-atan(2/10); with the horizontal pattern off a beam only receives
    // columns within one beam spacing (the tent), so beams further out than that are empty.
    const double half_extent = std::atan(2.0 / 10.0);
    const double spacing = plan.beam_angle_rad[0] - plan.beam_angle_rad[1];
    const double noise_floor = std::pow(10.0, config.noise_terms().floor_db() / 10.0);
    int lit_beams = 0;
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        const double a = plan.beam_angle_rad[j];
        double beam_energy = 0;
        for (std::uint32_t k = 0; k < f.bins; ++k)
            beam_energy += f.clean[k * f.beams + j];
        if (std::abs(a) > half_extent + spacing) {
            EXPECT_EQ(beam_energy, 0.0) << "beam " << j << " at " << a << " rad";
            // Exp(1) noise exceeds 30 x its mean with probability e^-30: never in 262k cells.
            for (std::uint32_t k = 0; k < f.bins; ++k)
                ASSERT_LT(f.intensity[k * f.beams + j], 30.0 * noise_floor);
        } else if (std::abs(a) < half_extent - spacing) {
            EXPECT_GT(beam_energy, 0.0) << "beam " << j;
            ++lit_beams;
            // Each covered beam peaks at the plane's range along its axis (elevation 0): 10 / cos(a).
            std::uint32_t peak = 0;
            for (std::uint32_t k = 1; k < f.bins; ++k) {
                if (f.clean[k * f.beams + j] > f.clean[peak * f.beams + j]) peak = k;
            }
            EXPECT_NEAR(static_cast<int>(peak), bin_of(plan, 10.0 / std::cos(a)), 1) << "beam " << j;
        }
    }
    EXPECT_GT(lit_beams, 50); // 22.6 deg of a 130 deg, 512-beam fan: ~89 beams
    // Nothing beyond the plane's far corner (sqrt(10^2 + 2^2 + 2^2) m) plus one bin.
    const int last = bin_of(plan, std::sqrt(108.0)) + 1;
    for (std::uint32_t k = static_cast<std::uint32_t>(last) + 1; k < f.bins; ++k) {
        for (std::uint32_t j = 0; j < f.beams; ++j)
            ASSERT_EQ(f.clean[k * f.beams + j], 0.0f);
    }
}

TEST_P(RenderTest, TwiceAsFarLosesSpreadingPlusAbsorption) {
    SonarConfig config = quiet_config();
    // Isolate the range terms: both patterns off so the small target's angular size does not matter.
    // A 2 m quad: at 20 m it still spans ~17 pixel rows, so which rows its edges cover moves its
    // total by at most ~6 % (0.25 dB); a 1 m quad's 8 rows gave +-0.6 dB between pixel grids.
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::on;
    config.absorption_db_per_m = 0.05;
    double total[2];
    for (int i = 0; i < 2; ++i) {
        Scene scene;
        add_quad(scene, 10.0 * (i + 1), 0.0, 0.0, 2.0, 2.0);
        auto r = render_once(GetParam(), config, scene);
        ASSERT_TRUE(r);
        total[i] = sum(r->frame.clean);
    }
    // Model: E ~ A r^-4 10^(-2 alpha r / 10): 40 log10 2 + 2 alpha (20 - 10) dB.
    const double predicted_db = 40.0 * std::log10(2.0) + 2.0 * 0.05 * 10.0;
    EXPECT_NEAR(to_db(total[0] / total[1]), predicted_db, 0.5);
}

TEST_P(RenderTest, RangeWindowAndFovChangeTheGeometry) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0);
    auto peak_bin = [](const Frame& f) {
        std::size_t best = 0;
        for (std::size_t i = 1; i < f.clean.size(); ++i) {
            if (f.clean[i] > f.clean[best]) best = i;
        }
        return static_cast<int>(best / f.beams);
    };
    auto lit_beams = [](const Frame& f) {
        int n = 0;
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            double e = 0;
            for (std::uint32_t k = 0; k < f.bins; ++k)
                e += f.clean[k * f.beams + j];
            n += e > 0;
        }
        return n;
    };
    SonarConfig base = quiet_config();
    base.effects.horizontal_pattern = EffectMode::off;

    SonarConfig near_window = base;
    near_window.range_max_m = 20.0;
    auto a = render_once(GetParam(), base, scene);
    auto b = render_once(GetParam(), near_window, scene);
    ASSERT_TRUE(a && b);
    // Peak at 10 m: bin (10 - 0.5) / (39.5 / 512) ~ 123 vs (10 - 0.5) / (19.5 / 512) ~ 249.
    EXPECT_NEAR(peak_bin(a->frame), bin_of(renderer_plan(a->renderer), 10.0), 1);
    EXPECT_NEAR(peak_bin(b->frame), bin_of(renderer_plan(b->renderer), 10.0), 1);
    EXPECT_GT(peak_bin(b->frame), peak_bin(a->frame) + 100);

    SonarConfig too_short = base;
    too_short.range_max_m = 8.0; // the plane is beyond the window: the far plane must clip it
    auto c = render_once(GetParam(), too_short, scene);
    ASSERT_TRUE(c);
    EXPECT_EQ(sum(c->frame.clean), 0.0);

    SonarConfig too_far = base;
    too_far.range_min_m = 12.0; // the plane is closer than range_min
    auto d = render_once(GetParam(), too_far, scene);
    ASSERT_TRUE(d);
    EXPECT_EQ(sum(d->frame.clean), 0.0);

    // Bins from the bandwidth (docs/pipeline.md, "Frames and grids"): c / 2B = 1500 / 40e3 = 3.75 cm, 1053 bins
    // over 39.5 m; the plane lands in the bin of 10 m on that grid, (10 - 0.5) / 0.0375 = 253.
    SonarConfig from_bandwidth = base;
    from_bandwidth.bandwidth_hz = 20e3;
    auto w = render_once(GetParam(), from_bandwidth, scene);
    ASSERT_TRUE(w);
    EXPECT_EQ(w->frame.bins, 1053u);
    EXPECT_NEAR(peak_bin(w->frame), 253, 1);

    SonarConfig narrow = base;
    narrow.hfov_deg = 65.0; // same 512 beams over half the angle: the plane covers ~twice the beams
    auto e = render_once(GetParam(), narrow, scene);
    ASSERT_TRUE(e);
    const double ratio = static_cast<double>(lit_beams(e->frame)) / lit_beams(a->frame);
    EXPECT_NEAR(ratio, 2.0, 0.1);
}

TEST_P(RenderTest, SameSeedSameBytesDifferentSeedDifferent) {
    SonarConfig config = quiet_config();
    config.effects.speckle = EffectMode::on;
    config.effects.ambient_noise = EffectMode::on;
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0);
    auto a = render_once(GetParam(), config, scene, {}, SaveFlags::none, 42);
    auto b = render_once(GetParam(), config, scene, {}, SaveFlags::none, 42);
    auto c = render_once(GetParam(), config, scene, {}, SaveFlags::none, 43);
    ASSERT_TRUE(a && b && c);
    EXPECT_EQ(a->frame.intensity, b->frame.intensity);
    EXPECT_NE(a->frame.intensity, c->frame.intensity);
    EXPECT_TRUE(all_finite(a->frame.intensity));
}

TEST_P(RenderTest, DrawTransformIsHonoured) {
    // The same quad placed 15 m out at azimuth +30 deg (port) by its world matrix.
    SonarConfig config = quiet_config();
    config.effects.horizontal_pattern = EffectMode::off;
    Scene scene;
    const double a = 30.0 * 3.14159265358979323846 / 180.0;
    add_quad(scene, 15.0 * std::cos(a), 15.0 * std::sin(a), 0.0, 1.0, 1.0, -20.0, 30.0);
    auto r = render_once(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    // Energy centroid in azimuth and range: robust to the tent kernel splitting a cell's energy.
    double total = 0, azimuth = 0, range = 0;
    for (std::uint32_t k = 0; k < r->frame.bins; ++k) {
        for (std::uint32_t j = 0; j < r->frame.beams; ++j) {
            const double e = r->frame.clean[k * r->frame.beams + j];
            total += e;
            azimuth += e * plan.beam_angle_rad[j];
            range += e * plan.bin_range_m[k];
        }
    }
    ASSERT_GT(total, 0.0);
    const double spacing = plan.beam_angle_rad[0] - plan.beam_angle_rad[1];
    EXPECT_NEAR(azimuth / total, a, spacing);           // symmetric target: centroid on its axis
    EXPECT_NEAR(range / total, 15.0, plan.bin_width_m); // 1 m square at 15 m: ranges 15.000..15.017
}

INSTANTIATE_TEST_SUITE_P(Backends, RenderTest, ::testing::Values(Backend::vulkan, Backend::cpu), backend_name);

// One frame on the CPU backend with `threads` host threads (null, and a test failure, if it cannot render).
std::unique_ptr<Rendered> render_on_threads(const SonarConfig& config, const Scene& scene, const Pose& pose,
                                            std::uint32_t threads, SaveFlags save_mask) {
    RendererOptions options;
    options.backend = Backend::cpu;
    options.host_threads = threads;
    options.save_mask = save_mask;
    auto r = Renderer::create(cpu_context(), config, scene, options);
    if (!r) {
        ADD_FAILURE() << r.error().message;
        return nullptr;
    }
    auto rendered = std::make_unique<Rendered>(Rendered{std::move(r.value()), {}});
    rendered->frame = rendered->renderer.make_frame();
    if (auto ok = rendered->renderer.render(pose, 0, rendered->frame); !ok) {
        ADD_FAILURE() << ok.error().message;
        return nullptr;
    }
    return rendered;
}

// StageTiming::passes on the CPU backend: the beamform stage's row is followed by its two passes' rows,
// which lie inside it (host clocks: profile + beams <= the stage), and nothing else changes.
// A frame another renderer made with the same bins x beams is taken (its arrays fit), and then carries
// this renderer's axes: its bin ranges and beam angles stayed the other's before (an audit's: 0.5-10 m
// of data labelled up to 19.7 m).
TEST(RenderAxes, AFrameOfAnotherRendererGetsThisRenderersAxes) {
    SonarConfig near = quiet_config(), far = quiet_config();
    near.range_max_m = 10.0;
    far.range_max_m = 20.0;
    far.hfov_deg = 90.0;
    Scene scene;
    auto a = render_once(Backend::cpu, far, scene);
    auto b = render_once(Backend::cpu, near, scene);
    ASSERT_TRUE(a && b);
    Frame borrowed = a->renderer.make_frame();
    ASSERT_NE(borrowed.bin_ranges_m, b->frame.bin_ranges_m);
    ASSERT_TRUE(b->renderer.render(Pose{}, 0, borrowed));
    EXPECT_EQ(borrowed.bin_ranges_m, b->frame.bin_ranges_m);
    EXPECT_EQ(borrowed.beam_angles_rad, b->frame.beam_angles_rad);
    EXPECT_LT(borrowed.bin_ranges_m.back(), 10.0);
}

TEST(CpuBackendTiming, PassesFollowTheBeamformStageAndChangeNothingElse) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 10.0;
    RendererOptions passes;
    passes.stage_timing = StageTiming::passes;
    auto plain = render_once(Backend::cpu, quiet_config(), scene.value(), pose);
    auto by_pass = render_once(Backend::cpu, quiet_config(), scene.value(), pose, SaveFlags::none, 1, passes);
    ASSERT_TRUE(plain && by_pass);
    EXPECT_EQ(by_pass->frame.clean, plain->frame.clean);
    EXPECT_EQ(by_pass->frame.stages_run, plain->frame.stages_run);
    std::vector<std::string> expected, got;
    for (const StageTime& t : plain->frame.times) {
        expected.push_back(t.stage);
        if (t.stage == "beamform") {
            expected.push_back("bf:profile");
            expected.push_back("bf:beams");
        }
    }
    double beamform = -1.0, inside = 0.0;
    for (const StageTime& t : by_pass->frame.times) {
        got.push_back(t.stage);
        EXPECT_GE(t.ms, 0.0) << t.stage;
        if (t.stage == "beamform") beamform = t.ms;
        if (t.stage.rfind("bf:", 0) == 0) inside += t.ms;
    }
    EXPECT_EQ(got, expected);
    EXPECT_GT(beamform, 0.0);
    EXPECT_LE(inside, beamform);
}

// The CPU backend splits its stages between the Renderer's threads: the depth pass by views and bands
// of rows (more bands per view with more threads), normals and echo by blocks of rows (fused), beamform
// by pixel columns and bins. Every value is computed by one thread in the order of the single-threaded
// loops, so any thread count gives the same bytes, intermediates included; 3 and 5 threads split
// unevenly.
TEST(CpuThreads, AnyThreadCountGivesTheSameBytes) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/harbour.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    for (NormalMethod method : {NormalMethod::sobel3, NormalMethod::sobel5, NormalMethod::geometric}) {
        SonarConfig config = quiet_config();
        config.normal_method = method;
        std::unique_ptr<Rendered> one;
        for (std::uint32_t threads : {1u, 2u, 3u, 5u}) {
            auto rendered =
                render_on_threads(config, scene.value(), pose, threads,
                                  SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles);
            ASSERT_TRUE(rendered);
            if (!one) {
                EXPECT_GT(sum(rendered->frame.clean), 0.0);
                one = std::move(rendered);
                continue;
            }
            const Frame& a = one->frame;
            const Frame& b = rendered->frame;
            EXPECT_EQ(a.depth, b.depth) << threads << " threads";
            EXPECT_EQ(a.material, b.material) << threads << " threads";
            EXPECT_EQ(a.normals, b.normals) << threads << " threads";
            EXPECT_EQ(a.echo, b.echo) << threads << " threads";
            EXPECT_EQ(a.profiles, b.profiles) << threads << " threads";
            EXPECT_EQ(a.beam_profiles, b.beam_profiles) << threads << " threads";
            EXPECT_EQ(a.clean, b.clean) << threads << " threads";
        }
    }
}

// A terrain of many clusters (300 x 300 quads: 352 clusters in 5 views) is culled on the threads, a
// view each (cpu_backend.cpp, kParallelCullClusterViews), and drawn from its per-run vertex cache
// (cpu_depth.cpp): any thread count gives the same bytes as one thread, which culls it alone.
TEST(CpuThreads, ABigTerrainGivesTheSameBytesOnAnyThreadCount) {
    const std::uint32_t n = 300;
    std::vector<float> positions;
    std::vector<std::uint32_t> indices;
    for (std::uint32_t j = 0; j <= n; ++j) {
        for (std::uint32_t i = 0; i <= n; ++i) {
            const float x = -10.0f + 60.0f * float(i) / n, y = -30.0f + 60.0f * float(j) / n;
            positions.insert(positions.end(), {x, y, -3.0f + 0.2f * std::sin(0.3f * x) * std::cos(0.21f * y)});
        }
    }
    for (std::uint32_t j = 0; j < n; ++j) {
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::uint32_t a = j * (n + 1) + i;
            indices.insert(indices.end(), {a, a + 1, a + n + 2, a, a + n + 2, a + n + 1});
        }
    }
    Scene scene;
    auto mesh = scene.add_mesh(positions.data(), std::uint32_t(positions.size() / 3), indices.data(),
                               std::uint32_t(indices.size()));
    ASSERT_TRUE(mesh) << mesh.error().message;
    SceneDraw draw;
    draw.mesh = mesh.value();
    auto material_index = scene.add_material(AcousticMaterial{});
    ASSERT_TRUE(material_index) << material_index.error().message;
    draw.material = material_index.value();
    ASSERT_TRUE(scene.add_draw(draw));
    Pose pose;
    pose.pitch_deg = 10.0;
    const SonarConfig config = quiet_config();
    std::unique_ptr<Rendered> one;
    for (std::uint32_t threads : {1u, 2u, 3u}) {
        auto rendered = render_on_threads(config, scene, pose, threads, SaveFlags::depth | SaveFlags::echo);
        ASSERT_TRUE(rendered);
        if (!one) {
            ASSERT_GT(std::count_if(rendered->frame.depth.begin(), rendered->frame.depth.end(),
                                    [](float d) { return d > 0.0f; }),
                      10000);
            one = std::move(rendered);
            continue;
        }
        EXPECT_EQ(one->frame.depth, rendered->frame.depth) << threads << " threads";
        EXPECT_EQ(one->frame.material, rendered->frame.material) << threads << " threads";
        EXPECT_EQ(one->frame.echo, rendered->frame.echo) << threads << " threads";
        EXPECT_EQ(one->frame.clean, rendered->frame.clean) << threads << " threads";
    }
}

// The labels stage splits its work between the Renderer's threads too: the pixel cache by rows, the
// beams in blocks of kBeamBlock dealt out in turn (a block's beams interleaved row by row), the labelled
// objects drawn alone as (object, band of rows) pairs taken by whichever thread is free, each into its
// own image; the flow to a next frame in blocks of cells. Every cell is still filled by one thread from
// its pixels in one order, the visibility counts are sums of integers, and a cell's flow depends on the
// two frames alone: any thread count gives the same bytes (compared as bytes: the arrays hold NaN where
// a cell has no label). 3 and 5 threads split unevenly; both beam geometries. The beams per block
// follow the thread count too (512 beams: 32 on 1-3 threads, 16 on 5), so this also checks that a
// block's size leaves every beam's cells as that beam labelled alone.
TEST(CpuThreads, LabelsDoNotDependOnTheThreadCount) {
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 10.0;
    auto same_bytes = [](const auto& a, const auto& b) {
        return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(a[0])) == 0;
    };
    // and the flow to a frame 0.4 m ahead and turned 2 degrees (cells in blocks between the threads)
    Pose next_pose = pose;
    next_pose.x_m = 0.4;
    next_pose.yaw_deg = 2.0;
    for (BeamGeometry geometry : {BeamGeometry::line_array, BeamGeometry::planar}) {
        SonarConfig config = quiet_config();
        config.beam_geometry = geometry;
        std::unique_ptr<Rendered> one;
        std::vector<float> first_flow;
        for (std::uint32_t threads : {1u, 2u, 3u, 5u}) {
            auto rendered = render_on_threads(config, scene.value(), pose, threads, SaveFlags::labels);
            ASSERT_TRUE(rendered);
            Frame next = rendered->renderer.make_frame();
            ASSERT_TRUE(rendered->renderer.render(next_pose, 1, next));
            std::vector<float> flow;
            ASSERT_TRUE(rendered->renderer.label_flow(rendered->frame, pose, next, next_pose, flow));
            if (first_flow.empty()) {
                ASSERT_GT(std::count_if(flow.begin(), flow.end(), [](float v) { return !std::isnan(v); }), 10000);
                first_flow = flow;
            } else {
                EXPECT_TRUE(same_bytes(first_flow, flow)) << threads << " threads";
            }
            if (!one) {
                ASSERT_GE(rendered->frame.visibility.size(), 5u); // seabed, pilings, pipe, crate, sphere
                ASSERT_GT(std::count_if(rendered->frame.instance.begin(), rendered->frame.instance.end(),
                                        [](std::uint16_t id) { return id != 0; }),
                          10000);
                one = std::move(rendered);
                continue;
            }
            const Frame& a = one->frame;
            const Frame& b = rendered->frame;
            EXPECT_TRUE(same_bytes(a.instance, b.instance)) << threads << " threads";
            EXPECT_TRUE(same_bytes(a.object_class, b.object_class)) << threads << " threads";
            EXPECT_TRUE(same_bytes(a.instance_fraction, b.instance_fraction)) << threads << " threads";
            EXPECT_TRUE(same_bytes(a.elevation, b.elevation)) << threads << " threads";
            EXPECT_TRUE(same_bytes(a.elevation_spread, b.elevation_spread)) << threads << " threads";
            EXPECT_TRUE(same_bytes(a.point, b.point)) << threads << " threads";
            ASSERT_EQ(a.visibility.size(), b.visibility.size()) << threads << " threads";
            for (std::size_t i = 0; i < a.visibility.size(); ++i) {
                const ObjectVisibility &va = a.visibility[i], &vb = b.visibility[i];
                EXPECT_EQ(va.instance, vb.instance) << threads << " threads";
                EXPECT_EQ(va.pixels, vb.pixels) << threads << " threads, instance " << va.instance;
                EXPECT_EQ(va.hidden, vb.hidden) << threads << " threads, instance " << va.instance;
                EXPECT_EQ(va.outside, vb.outside) << threads << " threads, instance " << va.instance;
            }
        }
    }
}

// cpu.vector_loops off runs the CPU backend's portable loops where this CPU would take its AVX2 ones
// (depth rows four pixels at a time, echo and footprint spreads four at a time with expf as exp4, the
// side-lobe runs of 16 beams): every output byte is the same. The configurations reach each vector loop
// and its ways out: the planar and cone profiles, a circular fan, a beam count that leaves a short last
// run, double precision, and an absorption whose exponent lies outside exp4's range beyond 35 m.
TEST(CpuVectorLoops, OffGivesTheSameBytes) {
    if (!cpu::use_exp4(SonarConfig{})) GTEST_SKIP() << "this CPU has no AVX2 and FMA: both settings run the same loops";
    auto harbour = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/harbour.gltf");
    auto seabed = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(harbour && seabed);
    Pose pose;
    pose.pitch_deg = 15.0;
    std::vector<std::pair<const char*, SonarConfig>> configs;
    configs.emplace_back("default", quiet_config());
    configs.emplace_back("planar", quiet_config());
    configs.back().second.beam_geometry = BeamGeometry::planar;
    configs.emplace_back("hfov 360", quiet_config());
    configs.back().second.hfov_deg = 360.0;
    configs.emplace_back("37 beams", quiet_config());
    configs.back().second.beams = 37;
    configs.emplace_back("double", quiet_config());
    configs.back().second.cpu_precision = Precision::f64;
    configs.emplace_back("absorption 5 dB/m", quiet_config());
    configs.back().second.absorption_db_per_m = 5.0; // exp4 out of range past 35 m
    for (const Scene* scene : {&harbour.value(), &seabed.value()}) {
        for (const auto& [name, config] : configs) {
            Frame frames[2];
            for (int off = 0; off < 2; ++off) {
                SonarConfig c = config;
                c.cpu_vector_loops = off ? CpuVectorLoops::off : CpuVectorLoops::automatic;
                RendererOptions options;
                options.backend = Backend::cpu;
                options.save_mask = SaveFlags::depth | SaveFlags::normals | SaveFlags::echo | SaveFlags::profiles;
                auto r = Renderer::create(cpu_context(), c, *scene, options);
                ASSERT_TRUE(r) << name << ": " << r.error().message;
                frames[off] = r.value().make_frame();
                ASSERT_TRUE(r.value().render(pose, 0, frames[off])) << name;
            }
            const Frame& a = frames[0];
            const Frame& b = frames[1];
            EXPECT_GT(sum(a.clean), 0.0) << name;
            expect_same_images(a, b, name);
        }
    }
}

} // namespace
} // namespace vksonar::testing
