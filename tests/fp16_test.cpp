// accuracy.intermediates = fp16: the echo buffer (energy * echo_scale, slant range) stored as two
// IEEE halves. Checks the conversion against IEEE binary16 facts, the GPU against the CPU reference
// on the same input, and the quantization bound against fp32.
#include <algorithm>
#include <cmath>

#include "core/half.h"
#include "core/host_plan.h"
#include "stages/cpu_stages.h"
#include "test_support.h"
#include "tolerances.h"

namespace vksonar::testing {
namespace {

TEST(Half, ConversionFollowsIeeeBinary16) {
    EXPECT_EQ(float_to_half(1.0f), 0x3c00);
    EXPECT_EQ(float_to_half(-2.0f), 0xc000);
    EXPECT_EQ(float_to_half(65504.0f), 0x7bff);                     // largest finite half
    EXPECT_EQ(float_to_half(65519.0f), 0x7bff);                     // below the halfway point to 2^16
    EXPECT_EQ(float_to_half(65520.0f), 0x7c00);                     // the tie rounds to even: infinity
    EXPECT_EQ(float_to_half(std::ldexp(1.0f, -24)), 0x0001);        // smallest subnormal
    EXPECT_EQ(float_to_half(std::ldexp(1.0f, -25)), 0x0000);        // tie between 0 and 2^-24: even (0)
    EXPECT_EQ(float_to_half(std::ldexp(3.0f, -26)), 0x0001);        // 0.75 * 2^-24 rounds up
    EXPECT_EQ(float_to_half(std::ldexp(1.0f, -14)), 0x0400);        // smallest normal
    EXPECT_EQ(float_to_half(1.0f + std::ldexp(1.0f, -11)), 0x3c00); // tie: stays on the even 1.0
    EXPECT_EQ(float_to_half(1.0f + std::ldexp(3.0f, -11)), 0x3c02); // tie: up to the even neighbour
    for (std::uint32_t h = 0; h < 0x7c00; ++h) {                    // every finite positive half survives a round trip
        ASSERT_EQ(float_to_half(half_to_float(static_cast<std::uint16_t>(h))), h) << h;
    }
}

// The GPU's fp16 echo against the CPU reference fed the GPU's own depth, materials and normals.
TEST(Fp16Echo, GpuMatchesCpuReferenceWithinOneHalfUlp) {
    VKSONAR_REQUIRE_VULKAN();
    ValidationGuard validation;
    SonarConfig config = quiet_config();
    config.intermediates = IntermediatePrecision::fp16;
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    auto g = render_once(Backend::vulkan, config, scene.value(), pose,
                         SaveFlags::depth | SaveFlags::normals | SaveFlags::echo);
    ASSERT_TRUE(g);
    const Plan& plan = renderer_plan(g->renderer);
    ASSERT_EQ(plan.params.echo_half, 1u);
    const Frame& f = g->frame;
    const std::size_t pixels = static_cast<std::size_t>(f.rows) * f.columns;
    std::vector<float> echo(pixels * 2);
    cpu::echo<float>(plan, f.depth.data(), f.material.data(), f.normals.data(), echo.data());
    double max_energy = 0;
    for (std::size_t i = 0; i < pixels; ++i)
        max_energy = std::max(max_energy, double(echo[2 * i]));
    ASSERT_GT(max_energy, 0.0);
    std::size_t identical = 0;
    double max_rel = 0, max_range_rel = 0;
    for (std::size_t i = 0; i < pixels; ++i) {
        identical += f.echo[2 * i] == echo[2 * i] && f.echo[2 * i + 1] == echo[2 * i + 1];
        const double a = f.echo[2 * i], b = echo[2 * i];
        // Below the smallest normal half (2^-14 after scaling) the step is the subnormal 2^-24.
        const double floor = std::max(kEchoRelFloor * max_energy, std::ldexp(1.0, -14) / plan.params.echo_scale);
        max_rel = std::max(max_rel, std::abs(a - b) / std::max(std::abs(b), floor));
        const double ra = f.echo[2 * i + 1], rb = echo[2 * i + 1];
        max_range_rel = std::max(max_range_rel, std::abs(ra - rb) / std::max(rb, 1e-3));
    }
    std::printf("[fp16 echo] %zu of %zu pixels identical, max rel energy %.2e, range %.2e\n", identical, pixels,
                max_rel, max_range_rel);
    // One half ulp (2^-10 relative): the float values before rounding differ by a few float ulps
    // (tests/tolerances.h kEchoRelTol), so a value next to a rounding boundary may land on the
    // neighbouring half on one backend. Nothing else differs.
    EXPECT_LE(max_rel, std::ldexp(1.0, -10));
    EXPECT_LE(max_range_rel, std::ldexp(1.0, -10));
    EXPECT_GT(identical, pixels * 9 / 10);
}

// On the same input the fp16 echo is the fp32 echo rounded to 11 significant bits: relative error
// <= 2^-11 for energy (the power-of-2 scale is exact) and range; energies more than 2^29 below the
// brightest possible pixel are subnormal halves (absolute step 2^-24 / scale), and those below half
// that step, 2^-25 / scale, round to 0. Some do in this scene: the depth pass covers the vertical
// pattern out to its first null, where the pixels' energy goes to 0 with the pattern. Any other
// zero would be a bug, so each one is checked against that threshold.
TEST(Fp16Echo, QuantizationIsHalfAnUlpOfBinary16) {
    SonarConfig config = quiet_config();
    auto scene = Scene::load_gltf(VKSONAR_ASSET_DIR "/scenes/default.gltf");
    ASSERT_TRUE(scene) << scene.error().message;
    Pose pose;
    pose.pitch_deg = 15.0;
    auto full = render_once(Backend::cpu, config, scene.value(), pose, SaveFlags::echo);
    config.intermediates = IntermediatePrecision::fp16;
    auto half = render_once(Backend::cpu, config, scene.value(), pose, SaveFlags::echo);
    ASSERT_TRUE(full && half);
    const auto& a = full->frame.echo;
    const auto& b = half->frame.echo;
    ASSERT_EQ(a.size(), b.size());
    // Subnormal halves (scaled energy below 2^-14) keep an absolute step of 2^-24 / scale instead.
    const double echo_scale = renderer_plan(half->renderer).params.echo_scale;
    const double smallest_normal = std::ldexp(1.0, -14) / echo_scale;
    const double rounds_to_zero = std::ldexp(1.0, -25) / echo_scale; // half the smallest subnormal (ties to even)
    double max_rel = 0, max_range_rel = 0;
    std::size_t changed = 0, lit = 0, subnormal = 0, underflowed = 0;
    for (std::size_t i = 0; i < a.size(); i += 2) {
        if (a[i] > 0) {
            ++lit;
            if (b[i] == 0.0f) {
                ++underflowed;
                ASSERT_LE(a[i], rounds_to_zero) << "pixel " << i / 2 << " underflowed";
            }
            subnormal += a[i] < smallest_normal;
            max_rel = std::max(max_rel, std::abs(double(b[i]) - a[i]) / std::max(double(a[i]), smallest_normal));
        }
        if (a[i + 1] > 0) max_range_rel = std::max(max_range_rel, std::abs(double(b[i + 1]) - a[i + 1]) / a[i + 1]);
        changed += a[i] != b[i];
    }
    std::printf("[fp16 quantization] %zu lit pixels (%zu subnormal, %zu rounded to 0), %zu changed, max rel energy "
                "%.2e, range %.2e\n",
                lit, subnormal, underflowed, changed, max_rel, max_range_rel);
    ASSERT_GT(lit, 1000u);
    EXPECT_LT(underflowed, lit / 100); // only pixels next to the pattern's null, a thin band of rows
    EXPECT_LE(max_rel, std::ldexp(1.0, -11));
    EXPECT_LE(max_range_rel, std::ldexp(1.0, -11));
    EXPECT_GT(changed, lit / 2); // it does quantize
}

// The fp16 echo scale follows the pixel grid it is used on. A host depth image of few, large pixels
// (a coarse engine camera) collects far more energy per pixel than vksonar's own grid: the brightest
// pixel it can produce, computed here from the image's geometry, must still fit a half (< 65504)
// after scaling, and the scale must not waste range either (> 2^14, the scale brings it near 2^15).
// The host-depth plan once kept the scale of vksonar's own grid: 2^8 too large for this image.
TEST(Fp16Echo, HostDepthScaleFitsTheHostImagesPixels) {
    SonarConfig config = quiet_config();
    config.intermediates = IntermediatePrecision::fp16;
    HostDepthDesc desc;
    desc.width = 48;
    desc.height = 12;
    desc.fx_px = 0.5 * desc.width / std::tan(70.0 * 3.14159265358979323846 / 180.0);  // +-70 deg
    desc.fy_px = 0.5 * desc.height / std::tan(15.0 * 3.14159265358979323846 / 180.0); // +-15 deg
    desc.cx_px = 0.5 * desc.width;
    desc.cy_px = 0.5 * desc.height;
    auto plan = make_host_depth_plan(config, desc);
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    // Brightest pixel: the centre pixel (largest solid angle), facing (Lambert f = 1), on the vertical
    // axis, at the nearest range the echo stage keeps (its gate), the default backscatter.
    const double du = 2.0 * (0.5 * desc.width / desc.fx_px) / desc.width;
    const double dv = 2.0 * (0.5 * desc.height / desc.fy_px) / desc.height;
    const double r = plan->gate_min_m;
    const double brightest = std::pow(10.0, config.default_backscatter_db / 10.0) * du * dv / (r * r);
    const double scaled = brightest * plan->params.echo_scale;
    EXPECT_LT(scaled, 65504.0) << "echo_scale " << plan->params.echo_scale;
    EXPECT_GT(scaled, 16384.0) << "echo_scale " << plan->params.echo_scale;
}

} // namespace
} // namespace vksonar::testing
