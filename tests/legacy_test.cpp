// Legacy modes (src/legacy, docs/legacy.md): the uuv_simulator and GTRI chains step by step. Every
// expected value comes from docs/legacy.md or a closed form written out here, never from a
// previous run of the code under test.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cli_support.h"
#include "legacy/legacy.h"
#include "test_support.h"

namespace fs = std::filesystem;
using namespace vksonar;
using namespace vksonar::legacy;
using vksonar::testing::fresh_test_dir;
using vksonar::testing::remove_test_dir;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

std::size_t cell(const UuvImages& io, int row, int col) {
    return static_cast<std::size_t>(row) * io.scan_cols + static_cast<std::size_t>(col);
}

void expect_rgb(host::Rgb8 got, int r, int g, int b, const std::string& what) {
    EXPECT_EQ(got.r, r) << what;
    EXPECT_EQ(got.g, g) << what;
    EXPECT_EQ(got.b, b) << what;
}

host::Rgb8 pixel(const host::Image& image, std::uint32_t row, std::uint32_t col) {
    const std::uint8_t* p = &image.rgb[(static_cast<std::size_t>(row) * image.width + col) * 3];
    return {p[0], p[1], p[2]};
}

} // namespace

// ---- uuv_simulator image sonar -------------------------------------------------------------------

TEST(LegacyUuv, RawScanSizeFormula) {
    // docs/legacy.md, step 3: cols = 2 * int(400 sin(hfov/2)) + 20, rows = 400. For the notes' 88.6 deg:
    // 400 sin(44.3 deg) = 279.37 -> 2 * 279 + 20 = 578.
    EXPECT_EQ(uuv_scan_columns(88.6 * kDeg), 578u);
    for (double hfov_deg : {10.0, 45.0, 88.6, 130.0, 170.0}) {
        const double half = 0.5 * hfov_deg * kDeg;
        const auto expected = static_cast<std::uint32_t>(2 * std::floor(400.0 * std::sin(half)) + 20);
        EXPECT_EQ(uuv_scan_columns(hfov_deg * kDeg), expected) << hfov_deg;
    }
    UuvImages io;
    uuv_prepare(64, 16, 88.6 * kDeg, io);
    EXPECT_EQ(io.scan_rows, 400u);
    EXPECT_EQ(io.scan_cols, 578u);
    EXPECT_EQ(io.raw_scan.size(), 400u * 578u);
    EXPECT_EQ(io.visual.width, 578u);
    EXPECT_EQ(io.visual.height, 400u);
    // GazeboRosCameraUtils intrinsics: f = w / (2 tan(hfov/2)), principal point (w+1)/2, (h+1)/2.
    EXPECT_NEAR(io.intrinsics.f, 64.0 / (2.0 * std::tan(44.3 * kDeg)), 1e-9);
    EXPECT_DOUBLE_EQ(io.intrinsics.cx, 32.5);
    EXPECT_DOUBLE_EQ(io.intrinsics.cy, 8.5);
    // A second prepare with the same sizes must not reallocate (no allocation per frame).
    const float* before = io.raw_scan.data();
    uuv_prepare(64, 16, 88.6 * kDeg, io);
    EXPECT_EQ(io.raw_scan.data(), before);
}

TEST(LegacyUuv, ColormapAndBackgroundAtBreakpoints) {
    // docs/legacy.md, step 4, each channel truncated like the plugin's double -> uchar conversion:
    // a = 0.5 (a < 0.8): (1.25, 0.78, 0.50) * 0.5 * 255 = (159.375, 99.45, 63.75) -> (159, 99, 63).
    expect_rgb(uuv_color(0.5f), 159, 99, 63, "a = 0.5");
    // a = 0.9 (0.8 <= a < 1): (0.9, 1.88*0.9 - 0.88, 1.99 - 1.99*0.9) * 255 = (229.5-, 207.06, 50.75)
    // (0.9f is just below 0.9, so 229.49... truncates to 229).
    expect_rgb(uuv_color(0.9f), 229, 207, 50, "a = 0.9");
    // a >= 1: yellow.
    expect_rgb(uuv_color(1.0f), 255, 255, 0, "a = 1.0");
    expect_rgb(uuv_color(1.7f), 255, 255, 0, "a = 1.7 (speckle can push values above 1)");
    // The map jumps at 0.8: 0.79 -> R = 251.8 (first piece), 0.8 -> R = 204 (second piece).
    EXPECT_EQ(uuv_color(0.79f).r, 251);
    EXPECT_EQ(uuv_color(0.8f).r, 204);
    expect_rgb(kUuvBackground, 15, 48, 102, "background");

    // In the visual scan: background outside the fan, black inside where the scan is 0, the colormap
    // where it is not.
    UuvImages io;
    uuv_prepare(32, 8, 88.6 * kDeg, io);
    std::fill(io.raw_scan.begin(), io.raw_scan.end(), 0.0f);
    // A cell at 10 deg right of straight up, radius 180 (between the 133 and 266 arcs, away from the
    // bearing lines at -44.8, -22.5, -0.25, 22.0 and 44.3 deg).
    const int apex_col = static_cast<int>(io.scan_cols / 2), apex_row = 400;
    const int r_cell = apex_row - static_cast<int>(std::lround(180 * std::cos(10 * kDeg)));
    const int c_cell = apex_col + static_cast<int>(std::lround(180 * std::sin(10 * kDeg)));
    io.raw_scan[cell(io, r_cell, c_cell)] = 0.5f;
    uuv_visual(io);
    expect_rgb(pixel(io.visual, 0, 0), 15, 48, 102, "top-left corner is outside the fan");
    expect_rgb(pixel(io.visual, r_cell, c_cell), 159, 99, 63, "scan value 0.5");
    expect_rgb(pixel(io.visual, r_cell + 3, c_cell), 0, 0, 0, "empty fan cell");
}

TEST(LegacyUuv, ProjectionOfAPlaneAtKnownDepth) {
    // 5 x 5 pixels over 90 deg: f = 5 / (2 tan 45) = 2.5, principal point (3, 3).
    const UuvIntrinsics k = uuv_intrinsics(5, 5, 90 * kDeg);
    ASSERT_DOUBLE_EQ(k.f, 2.5);
    const std::uint32_t cols = uuv_scan_columns(90 * kDeg); // 2 * int(282.84) + 20 = 584
    ASSERT_EQ(cols, 584u);
    int row = -1, col = -1;
    // On the axis at 10 m: z = 10, row = 399 - int(10/17*400) = 399 - int(235.29) = 164, col = 292.
    ASSERT_TRUE(uuv_project_pixel(10.0f, 3, 3, k, cols, &row, &col));
    EXPECT_EQ(row, 164);
    EXPECT_EQ(col, 292);
    // Pixel (1, 4): y = -2/2.5 = -0.8, x = 1/2.5 = 0.4; z = 10 sqrt(1.64) = 12.806, x z = 5.1225:
    // row = 399 - int(301.32) = 98, col = 292 + int(120.53) = 412.
    ASSERT_TRUE(uuv_project_pixel(10.0f, 1, 4, k, cols, &row, &col));
    EXPECT_EQ(row, 98);
    EXPECT_EQ(col, 412);
    // The 17 m range is hard-coded (legacy bug): 17.5 m on the axis is dropped whatever range_max says,
    // and so is 16.96 m, which maps to row 399 - 399 = 0 (the plugin skips row 0).
    EXPECT_FALSE(uuv_project_pixel(17.5f, 3, 3, k, cols, &row, &col));
    EXPECT_FALSE(uuv_project_pixel(16.96f, 3, 3, k, cols, &row, &col));
    EXPECT_FALSE(uuv_project_pixel(0.0f, 3, 3, k, cols, &row, &col));
}

// The same mapping end to end: a wall 10 m ahead rendered by vksonar's depth pass on each backend.
TEST(LegacyUuv, PlaneAtKnownDepthThroughTheDepthPass) {
    auto preset = load_preset("uuv-legacy");
    ASSERT_TRUE(preset.ok()) << preset.error().message;
    ASSERT_EQ(preset->mode, SonarMode::uuv_legacy);
    Scene scene;
    vksonar::testing::add_quad(scene, 10.0, 0.0, 0.0, 60.0, 60.0);
    std::vector<std::vector<float>> raw_scans; // full chain per backend, same seed
    for (Backend backend : {Backend::cpu, Backend::vulkan}) {
        if (backend == Backend::vulkan && vksonar::testing::vulkan_context() == nullptr) continue;
        vksonar::testing::ValidationGuard guard;
        auto rendered = vksonar::testing::render_once(backend, *preset, scene, {}, SaveFlags::depth);
        ASSERT_NE(rendered, nullptr);
        const Plan& plan = renderer_plan(rendered->renderer);
        ASSERT_EQ(plan.slices, 1u);
        EXPECT_EQ(plan.columns, 512u); // the preset's 512 x 114 depth image
        EXPECT_EQ(plan.rows, 114u);
        const std::vector<float> depth = legacy_depth_from_frame(plan, rendered->frame);
        ASSERT_EQ(depth.size(), static_cast<std::size_t>(plan.rows) * plan.columns);
        // Depth along the optical axis of a wall facing the sonar is 10 m at every pixel (float
        // reversed-Z over a 0.1-17 m window resolves ~1e-6 relative, so 1e-3 m is generous).
        for (float d : depth)
            ASSERT_NEAR(d, 10.0f, 1e-3f);

        UuvImages io;
        uuv_prepare(plan.columns, plan.rows, plan.config.hfov_deg * kDeg, io);
        uuv_normals(depth.data(), io);
        uuv_multibeam(depth.data(), io);
        uuv_scan_prefill(io);
        uuv_scan_project(depth.data(), io);
        // z = 10 sqrt(1 + y^2) >= 10 m, so every return lies at or above row 164, and the most oblique row
        // (y = (0 - cy)/f) bounds it from above.
        const double y_max = (0.0 - io.intrinsics.cy) / io.intrinsics.f;
        const int lowest_row = 399 - static_cast<int>(10.0 * std::sqrt(1 + y_max * y_max) / 17.0 * 400.0);
        int written = 0;
        for (int r = 0; r < 400; ++r) {
            for (int c = 0; c < static_cast<int>(io.scan_cols); ++c) {
                const float v = io.raw_scan[cell(io, r, c)];
                if (v == 0.0f || v == kUuvPrefill) continue;
                ++written;
                EXPECT_LE(r, 164);
                EXPECT_GE(r, lowest_row - 1);
            }
        }
        EXPECT_GT(written, 100);
        const float axis = io.raw_scan[cell(io, 164, static_cast<int>(io.scan_cols / 2))];
        EXPECT_TRUE(axis != 0.0f && axis != kUuvPrefill) << "no return on the axis at 10 m";

        UuvImages full;
        uuv_legacy(depth.data(), plan.columns, plan.rows, plan.config.hfov_deg * kDeg, 1, 0, full);
        raw_scans.push_back(full.raw_scan);
    }
    // Both backends feed the same chain: their depths agree to ~1e-6 relative, so the scans agree except
    // where a pixel sits within ~1e-4 of a scan-cell boundary and lands one cell over (a handful of cells;
    // neighbouring cells hold nearly the same value on a plane).
    if (raw_scans.size() == 2) {
        std::size_t differing = 0;
        for (std::size_t i = 0; i < raw_scans[0].size(); ++i)
            if (std::abs(raw_scans[0][i] - raw_scans[1][i]) > 0.02f) ++differing;
        EXPECT_LT(differing, raw_scans[0].size() / 200) << "cells differing by > 0.02 between backends";
    }
}

TEST(LegacyUuv, ProjectionOverwritesInsteadOfAccumulating) {
    // 5 x 5 pixels, principal point (3, 3): rows 2 and 4 are symmetric about cy, so in the same column and
    // at the same depth they land on the same scan cell.
    UuvImages io;
    uuv_prepare(5, 5, 90 * kDeg, io);
    std::vector<float> depth(25, 0.0f);
    depth[2 * 5 + 3] = 8.0f;
    depth[4 * 5 + 3] = 8.0f;
    int r1 = 0, c1 = 0, r2 = 0, c2 = 0;
    ASSERT_TRUE(uuv_project_pixel(8.0f, 2, 3, io.intrinsics, io.scan_cols, &r1, &c1));
    ASSERT_TRUE(uuv_project_pixel(8.0f, 4, 3, io.intrinsics, io.scan_cols, &r2, &c2));
    ASSERT_EQ(r1, r2);
    ASSERT_EQ(c1, c2);
    std::fill(io.multibeam.begin(), io.multibeam.end(), 0.0f);
    io.multibeam[2 * 5 + 3] = 0.7f; // written first (row-major)
    io.multibeam[4 * 5 + 3] = 0.3f; // written last
    uuv_scan_prefill(io);
    uuv_scan_project(depth.data(), io);
    // Overwrite: the last writer's 0.3; accumulation would give 1.0 (or 1.2 on top of the prefill),
    // a max 0.7.
    EXPECT_EQ(io.raw_scan[cell(io, r1, c1)], 0.3f);
}

TEST(LegacyUuv, DilationElementAndWhichCellsItFills) {
    // getStructuringElement(MORPH_ELLIPSE, 3 wide x 9 high): r = 4, c = 1, row dy spans
    // 1 +- round(sqrt(1 - dy^2/16)): dy = +-4 -> only the centre; |dy| <= 3 -> round(>= 0.66) = 1 -> all 3.
    const std::vector<std::uint8_t> element = uuv_ellipse_element(3, 9);
    ASSERT_EQ(element.size(), 27u);
    for (int row = 0; row < 9; ++row) {
        const bool tip = row == 0 || row == 8;
        EXPECT_EQ(element[row * 3 + 0], tip ? 0 : 1) << row;
        EXPECT_EQ(element[row * 3 + 1], 1) << row;
        EXPECT_EQ(element[row * 3 + 2], tip ? 0 : 1) << row;
    }
    UuvImages io;
    uuv_prepare(8, 8, 88.6 * kDeg, io);
    uuv_scan_prefill(io);
    const int r = 200, c = static_cast<int>(io.scan_cols / 2);
    ASSERT_EQ(io.raw_scan[cell(io, r, c)], kUuvPrefill);
    io.raw_scan[cell(io, r, c)] = 0.9f;
    io.raw_scan[cell(io, r, c + 40)] = 0.6f; // a return keeps its own value next to a brighter one
    io.raw_scan[cell(io, r, c + 41)] = 0.9f;
    uuv_scan_dilate(io);
    EXPECT_EQ(io.raw_scan[cell(io, r + 4, c)], 0.9f);            // 4 rows below: inside the element
    EXPECT_EQ(io.raw_scan[cell(io, r - 3, c + 1)], 0.9f);        // 3 up, 1 across: inside
    EXPECT_EQ(io.raw_scan[cell(io, r + 5, c)], kUuvPrefill);     // 5 rows below: outside
    EXPECT_EQ(io.raw_scan[cell(io, r + 4, c + 1)], kUuvPrefill); // the element's clipped corner
    EXPECT_EQ(io.raw_scan[cell(io, r, c + 40)], 0.6f);
}

TEST(LegacyUuv, SnrOfAPlaneIsTheClosedForm) {
    // A constant depth d: the gradients vanish, n = (0, 0, 1) everywhere, so the normalized n_z channel
    // is constant and becomes 0 (TS = 0). SNR = 200 - 2 * 5 d sqrt(1 + x^2 + y^2) - 30, min-max normalized.
    const std::uint32_t w = 9, h = 5;
    const float d = 6.0f;
    UuvImages io;
    uuv_prepare(w, h, 60 * kDeg, io);
    std::vector<float> depth(w * h, d);
    uuv_normals(depth.data(), io);
    uuv_multibeam(depth.data(), io);
    const UuvIntrinsics& k = io.intrinsics;
    std::vector<double> snr(w * h);
    for (std::uint32_t r = 0; r < h; ++r)
        for (std::uint32_t c = 0; c < w; ++c) {
            const double x = (c - k.cx) / k.f, y = (r - k.cy) / k.f;
            snr[r * w + c] = std::max(0.0, 200.0 - 10.0 * d * std::sqrt(1 + x * x + y * y) - 30.0);
        }
    const double lo = *std::min_element(snr.begin(), snr.end()), hi = *std::max_element(snr.begin(), snr.end());
    for (std::size_t p = 0; p < snr.size(); ++p) {
        EXPECT_EQ(io.normals[p * 3 + 2], 0.0f) << p;
        EXPECT_NEAR(io.multibeam[p], (snr[p] - lo) / (hi - lo), 1e-5) << p;
    }
}

TEST(LegacyUuv, SpeckleStatistics) {
    UuvImages io;
    uuv_prepare(16, 4, 88.6 * kDeg, io);
    std::fill(io.raw_scan.begin(), io.raw_scan.end(), 1.0f);
    for (std::size_t i = 0; i < io.raw_scan.size(); i += 97)
        io.raw_scan[i] = 0.0f; // zeros stay zero
    uuv_scan_speckle(7, 3, io);
    double sum = 0, sum_sq = 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < io.raw_scan.size(); ++i) {
        if (i % 97 == 0) {
            EXPECT_EQ(io.raw_scan[i], 0.0f);
            continue;
        }
        sum += io.raw_scan[i];
        sum_sq += static_cast<double>(io.raw_scan[i]) * io.raw_scan[i];
        ++n;
    }
    const double mean = sum / n, sd = std::sqrt((sum_sq - n * mean * mean) / (n - 1));
    // |N(1, 0.1)|: folding below 0 is 10 sigma away, so mean 1 and sd 0.1 to any precision that matters.
    // n = 400 * 578 - 2384 = 228,816 draws: the standard error of the mean is 0.1 / sqrt(n) = 2.1e-4 and
    // that of the sample sd is 0.1 / sqrt(2 n) = 1.5e-4. Bounds of 1e-3 (4.8 SE) and 7.5e-4 (5 SE) fail a
    // correct sampler with probability < 1e-5 and catch a wrong sigma (0.09 or 0.11) or a biased mean.
    RecordProperty("speckle_mean", std::to_string(mean));
    RecordProperty("speckle_sd", std::to_string(sd));
    std::printf("speckle over %zu cells: mean %.6f, sd %.6f\n", n, mean, sd);
    EXPECT_NEAR(mean, 1.0, 1e-3);
    EXPECT_NEAR(sd, 0.1, 7.5e-4);

    // Seeded: the same key gives the same scan, another seed another one.
    std::vector<float> first = io.raw_scan;
    std::fill(io.raw_scan.begin(), io.raw_scan.end(), 1.0f);
    uuv_scan_speckle(7, 3, io);
    std::vector<float> again = io.raw_scan;
    std::fill(io.raw_scan.begin(), io.raw_scan.end(), 1.0f);
    uuv_scan_speckle(8, 3, io);
    EXPECT_EQ(again[1], first[1]);
    EXPECT_NE(io.raw_scan[1], first[1]);
}

// ---- GTRI-based sonar ----------------------------------------------------------------------------

// --quality on the uuv-legacy preset: every quality keeps its one pinhole image as wide as the 88.6 deg fan
// (max_slice 90 from the preset, where each quality's is 60 or 15: all three refused the config before);
// a physical config takes the quality's slices.
TEST(LegacyUuv, EveryQualityKeepsTheOneDepthImage) {
    auto uuv = load_preset("uuv-legacy");
    ASSERT_TRUE(uuv) << uuv.error().message;
    for (const char* quality : {"fast", "balanced", "accurate"}) {
        auto applied = apply_quality(uuv.value(), quality);
        ASSERT_TRUE(applied) << quality << ": " << applied.error().message;
        EXPECT_EQ(applied->max_slice_deg, uuv->max_slice_deg) << quality;
        EXPECT_TRUE(applied->validate()) << quality;
    }
    auto physical = apply_quality(SonarConfig{}, "accurate");
    ASSERT_TRUE(physical) << physical.error().message;
    EXPECT_EQ(physical->max_slice_deg, 15.0);
}

TEST(LegacyGtri, ImageSize) {
    GtriImages out;
    gtri_legacy({}, 90 * kDeg, 10.0, 1, 0, out);
    EXPECT_EQ(out.color.width, 600u);
    EXPECT_EQ(out.color.height, 600u);
    EXPECT_EQ(out.color.rgb.size(), 600u * 600u * 3u);
    EXPECT_EQ(out.gray.size(), 600u * 600u);
    EXPECT_EQ(out.blurred.size(), 600u * 600u);
}

TEST(LegacyGtri, JitterStatistics) {
    const std::size_t n = 100000;
    std::vector<GtriPoint> cloud(n, GtriPoint{1.0f, 2.0f, 3.0f, 7.0f});
    std::vector<GtriPoint> out;
    gtri_jitter(cloud, 5, 0, kGtriJitterSigma, out);
    ASSERT_EQ(out.size(), n);
    double sum = 0, sum_sq = 0;
    for (const GtriPoint& p : out) {
        ASSERT_EQ(p.y, 2.0f); // only x is jittered
        ASSERT_EQ(p.z, 3.0f);
        ASSERT_EQ(p.retro, 7.0f);
        const double e = static_cast<double>(p.x) - 1.0;
        sum += e;
        sum_sq += e * e;
    }
    const double mean = sum / n, sd = std::sqrt((sum_sq - n * mean * mean) / (n - 1));
    // N(0, 0.01) over 1e5 draws: SE of the mean 0.01 / sqrt(1e5) = 3.2e-5, of the sd 0.01 / sqrt(2e5) =
    // 2.2e-5 (plus float rounding of x near 1, ~6e-8). Bounds at 5 SE.
    std::printf("gtri jitter over %zu points: mean %.3g, sd %.6f\n", n, mean, sd);
    EXPECT_NEAR(mean, 0.0, 1.6e-4);
    EXPECT_NEAR(sd, 0.01, 1.1e-4);
}

TEST(LegacyGtri, JetEndpoints) {
    // GetColor_matlab(v, 0, 255) with mx = 4 v: v = 0 -> b = 0 + 127.5; v = 255 -> r = -1020 + 1147.5 = 127.5;
    // v = 128 (third piece) -> (512 - 382.5, 255, -512 + 637.5) = (129.5, 255, 125.5); halves round up.
    expect_rgb(gtri_jet(0), 0, 0, 128, "jet(0)");
    expect_rgb(gtri_jet(255), 128, 0, 0, "jet(255)");
    expect_rgb(gtri_jet(128), 130, 255, 126, "jet(128)");
}

TEST(LegacyGtri, MedianKeepsOnlyTheCentreOfAnIsolatedDisc) {
    // A radius-1 disc is 5 pixels: its centre sees 5 of 9 set (median = value), an arm sees 4 (median 0).
    std::vector<std::uint8_t> in(7 * 7, 0), out(7 * 7, 1);
    for (auto [r, c] : {std::pair{3, 3}, {2, 3}, {4, 3}, {3, 2}, {3, 4}})
        in[r * 7 + c] = 200;
    gtri_median3(in.data(), 7, 7, out.data());
    EXPECT_EQ(out[3 * 7 + 3], 200);
    EXPECT_EQ(out[2 * 7 + 3], 0);
    EXPECT_EQ(out[3 * 7 + 4], 0);
}

TEST(LegacyGtri, Rotation180PutsForwardUpAndPortLeft) {
    // A 7 x 7 pixel patch of points 5 m forward, 2 m to port, range_max 10 m (30 px/m): before the
    // rotation its centre is pixel (300 + 150, 300 + 60) = (450, 360); after a 180-degree rotation it must
    // be at (599 - 450, 599 - 360) = (149, 239), i.e. forward is up and port on the left.
    std::vector<GtriPoint> cloud;
    for (int i = -3; i <= 3; ++i)
        for (int j = -3; j <= 3; ++j)
            cloud.push_back({5.0f + i / 30.0f, 2.0f + j / 30.0f, 0.0f, 200.0f});
    int row = 0, col = 0;
    ASSERT_TRUE(gtri_pixel(5.0f, 2.0f, 10.0, &row, &col));
    ASSERT_EQ(row, 450);
    ASSERT_EQ(col, 360);
    GtriImages out;
    gtri_legacy(cloud, 90 * kDeg, 10.0, 3, 0, out);
    const host::Rgb8 target = gtri_jet(200);
    double sum_r = 0, sum_c = 0;
    int count = 0;
    for (std::uint32_t r = 0; r < 600; ++r)
        for (std::uint32_t c = 0; c < 600; ++c) {
            const host::Rgb8 px = pixel(out.color, r, c);
            if (px.r == target.r && px.g == target.g && px.b == target.b) {
                sum_r += r;
                sum_c += c;
                ++count;
            }
        }
    ASSERT_GT(count, 25);
    // Jitter (0.3 px sd on x) moves single pixels, not the patch: its centroid stays within a pixel.
    EXPECT_NEAR(sum_r / count, 149.0, 1.0);
    EXPECT_NEAR(sum_c / count, 239.0, 1.0);
    // The un-rotated position is behind the sonar after the rotation: black; the fan's empty inside is jet(0).
    expect_rgb(pixel(out.color, 450, 360), 0, 0, 0, "behind the apex");
    expect_rgb(pixel(out.color, 0, 0), 0, 0, 0, "corner outside the fan");
    expect_rgb(pixel(out.color, 200, 299), 0, 0, 128, "empty fan");
}

// ---- CLI -----------------------------------------------------------------------------------------

namespace {

struct LegacyCliRun {
    int exit_code = -1;
    std::string err;
};

LegacyCliRun run_cli(const std::vector<std::string>& args, const fs::path& dir) {
    std::string command = std::string("'") + VKSONAR_CLI + "'";
    for (const auto& arg : args)
        command += " '" + arg + "'";
    const fs::path err = dir / "stderr.txt";
    command += " > /dev/null 2> '" + err.string() + "' < /dev/null";
    const int status = std::system(command.c_str());
    LegacyCliRun run;
    run.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::ifstream file(err);
    std::stringstream text;
    text << file.rdbuf();
    run.err = text.str();
    return run;
}

std::string read_file(const fs::path& path) {
    std::ifstream file(path, std::ios::binary);
    std::stringstream text;
    text << file.rdbuf();
    return text.str();
}

// Width and height from a PNG's IHDR chunk.
std::pair<std::uint32_t, std::uint32_t> png_size(const fs::path& path) {
    const std::string bytes = read_file(path);
    if (bytes.size() < 24) return {0, 0};
    auto be32 = [&](std::size_t at) {
        return (std::uint32_t(std::uint8_t(bytes[at])) << 24) | (std::uint32_t(std::uint8_t(bytes[at + 1])) << 16) |
               (std::uint32_t(std::uint8_t(bytes[at + 2])) << 8) | std::uint32_t(std::uint8_t(bytes[at + 3]));
    };
    return {be32(16), be32(20)};
}

// Vertex count of a binary PLY, checking that the body is exactly count * 4 floats.
long ply_vertices(const fs::path& path) {
    const std::string bytes = read_file(path);
    const auto end = bytes.find("end_header\n");
    if (bytes.rfind("ply\nformat binary_little_endian 1.0\n", 0) != 0 || end == std::string::npos) return -1;
    const auto at = bytes.find("element vertex ");
    if (at == std::string::npos) return -1;
    const long count = std::stol(bytes.substr(at + 15));
    const std::size_t body = bytes.size() - (end + 11);
    return body == static_cast<std::size_t>(count) * 16 ? count : -2;
}

class LegacyCli : public ::testing::Test {
protected:
    void SetUp() override { dir_ = fresh_test_dir("vksonar_legacy_cli_"); }
    void TearDown() override { remove_test_dir(dir_); }
    fs::path dir_;
};

} // namespace

TEST_F(LegacyCli, UuvWritesTheLegacyImageAndIntermediates) {
    const fs::path out = dir_ / "uuv";
    const LegacyCliRun run = run_cli({"render", "--sonar", "uuv-legacy", "--backend", "cpu", "--save",
                                      "default,normals,multibeam,raw_scan,cloud", "--out", out.string()},
                                     dir_);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_EQ(png_size(out / "fan.png"), std::make_pair(578u, 400u));
    EXPECT_EQ(png_size(out / "raw_scan.png"), std::make_pair(578u, 400u));
    EXPECT_EQ(png_size(out / "multibeam.png"), std::make_pair(512u, 114u));
    EXPECT_EQ(png_size(out / "normals.png"), std::make_pair(512u, 114u));
    EXPECT_TRUE(fs::exists(out / "raw_scan.npy"));
    EXPECT_TRUE(fs::exists(out / "polar.npy"));
    EXPECT_GT(ply_vertices(out / "cloud.ply"), 1000);
    const auto meta = nlohmann::json::parse(read_file(out / "meta.json"));
    EXPECT_EQ(meta["mode"], "uuv-legacy");
    EXPECT_EQ(meta["config"]["mode"], "uuv-legacy");
    EXPECT_EQ(meta["legacy"]["scan_cols"], 578);
}

TEST_F(LegacyCli, GtriWritesA600SquareImageAndItsCloud) {
    const fs::path out = dir_ / "gtri";
    const LegacyCliRun run = run_cli(
        {"render", "--sonar", "gtri-legacy", "--backend", "cpu", "--save", "fan,polar,cloud", "--out", out.string()},
        dir_);
    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_EQ(png_size(out / "fan.png"), std::make_pair(600u, 600u));
    EXPECT_GT(ply_vertices(out / "cloud.ply"), 1000);
    const auto meta = nlohmann::json::parse(read_file(out / "meta.json"));
    EXPECT_EQ(meta["mode"], "gtri-legacy");
}

TEST_F(LegacyCli, BadModeAndLegacyOnlyOutputsAreOneLineErrors) {
    LegacyCliRun run =
        run_cli({"render", "--set", "mode=uuv", "--backend", "cpu", "--out", (dir_ / "a").string()}, dir_);
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_EQ(std::count(run.err.begin(), run.err.end(), '\n'), 1) << run.err;
    EXPECT_EQ(run.err.rfind("error: ", 0), 0u) << run.err;
    EXPECT_NE(run.err.find("physical|uuv-legacy|gtri-legacy"), std::string::npos) << run.err;
    EXPECT_FALSE(fs::exists(dir_ / "a"));

    run = run_cli({"render", "--save", "raw_scan", "--backend", "cpu", "--out", (dir_ / "b").string()}, dir_);
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("uuv-legacy"), std::string::npos) << run.err;
    EXPECT_FALSE(fs::exists(dir_ / "b"));

    // A wide fan cannot be one pinhole image.
    run = run_cli(
        {"render", "--sonar", "uuv-legacy", "--set", "hfov=130", "--backend", "cpu", "--out", (dir_ / "c").string()},
        dir_);
    EXPECT_EQ(run.exit_code, 2);
    EXPECT_NE(run.err.find("max_slice"), std::string::npos) << run.err;
}
