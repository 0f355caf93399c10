// GTRI-based sonar (gtri_based_fls, from SyllogismRXS syllo-gazebo), step by step as
// docs/legacy.md describes it: point cloud -> x jitter -> 600x600 image of radius-1 discs ->
// 3x3 median -> jet -> black outside the fan -> 180-degree rotation. Also the two legacy point clouds
// built from vksonar's depth pass.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/sonar_math.hpp"
#include "legacy/legacy.h"

namespace vksonar::legacy {
namespace {

static_assert(sizeof(GtriPoint) == 4 * sizeof(float), "GtriPoint is written to PLY files as 4 packed floats");

constexpr std::uint32_t kNoHit = 0xffffffffu;

// Sonar-frame point of depth pixel p, or false when nothing was hit or its slant range lies outside
// [range_min, range_max). Camera frame is x right, y down, z forward (shaders/sonar_math.h); the sonar
// frame is x forward, y port, z up, and each slice is turned by its centre azimuth about z.
bool pixel_point(const Plan& plan, const Frame& frame, std::uint32_t row, std::uint32_t col, GtriPoint& point) {
    const std::size_t p = static_cast<std::size_t>(row) * plan.columns + col;
    const double d = frame.depth[p];
    if (!(d > 0.0) || !(d > plan.depth_b) || plan.slice_columns == 0) return false;
    const std::uint32_t slice = col / plan.slice_columns;
    if (slice >= plan.slice_info.size()) return false;
    const double u = math_f64::pixel_coord(col % plan.slice_columns, plan.slice_columns, plan.tan_half_h);
    const double v = math_f64::pixel_coord(row, plan.rows, plan.tan_half_v);
    const double z = math_f64::view_z_from_depth(d, plan.depth_a, plan.depth_b);
    const double r = math_f64::slant_range(z, u, v);
    if (!std::isfinite(r) || r < plan.config.range_min_m || r >= plan.config.range_max_m) return false;
    const double forward = z, port = -u * z, up = -v * z;
    const double a = plan.slice_info[slice].center_azimuth_rad;
    point.x = static_cast<float>(forward * std::cos(a) - port * std::sin(a));
    point.y = static_cast<float>(forward * std::sin(a) + port * std::cos(a));
    point.z = static_cast<float>(up);
    return true;
}

inline std::uint8_t round_channel(double v) {
    if (!(v > 0.0)) return 0;
    if (v >= 255.0) return 255;
    return static_cast<std::uint8_t>(std::floor(v + 0.5));
}

inline std::uint8_t retro_value(float retro) {
    if (!(retro > 0.0f)) return 0;
    return round_channel(retro);
}

} // namespace

bool gtri_pixel(float x, float y, double range_max_m, int* row, int* col) {
    if (!(range_max_m > 0) || !std::isfinite(x) || !std::isfinite(y)) return false;
    const double scale = kGtriRangePixels / range_max_m;
    const double centre = kGtriImageSize / 2;
    const double fr = centre + std::floor(x * scale + 0.5), fc = centre + std::floor(y * scale + 0.5);
    // Far outside the image: report a pixel that is still outside, without overflowing int.
    *row = static_cast<int>(std::clamp(fr, -1e6, 1e6));
    *col = static_cast<int>(std::clamp(fc, -1e6, 1e6));
    return true;
}

host::Rgb8 gtri_jet(std::uint8_t value) {
    // GetColor_matlab(v, 0, 255): five linear pieces with mx = 4 v, dark blue -> blue -> cyan/yellow ->
    // red -> dark red; each channel rounded half up.
    const double v = value, mx = 4.0 * v;
    if (v < 0.125 * 255) return {0, 0, round_channel(mx + 127.5)};
    if (v < 0.375 * 255) return {0, round_channel(mx - 127.5), 255};
    if (v < 0.625 * 255) return {round_channel(mx - 382.5), 255, round_channel(-mx + 637.5)};
    if (v < 0.875 * 255) return {255, round_channel(-mx + 892.5), 0};
    return {round_channel(-mx + 1147.5), 0, 0};
}

void gtri_jitter(const std::vector<GtriPoint>& in, std::uint64_t seed, std::uint64_t frame_index, double sigma,
                 std::vector<GtriPoint>& out) {
    out.resize(in.size());
    for (std::size_t i = 0; i < in.size(); ++i) {
        out[i] = in[i];
        const double n = host::sample_normal01(seed, frame_index, static_cast<std::uint32_t>(i), 0, kGtriJitterStream);
        out[i].x = static_cast<float>(in[i].x + sigma * n);
    }
}

void gtri_median3(const std::uint8_t* in, std::uint32_t width, std::uint32_t height, std::uint8_t* out) {
    std::array<std::uint8_t, 9> window{};
    for (std::uint32_t r = 0; r < height; ++r) {
        for (std::uint32_t c = 0; c < width; ++c) {
            int k = 0;
            for (int dr = -1; dr <= 1; ++dr) {
                const std::uint32_t rr =
                    static_cast<std::uint32_t>(std::clamp<std::int64_t>(std::int64_t(r) + dr, 0, height - 1));
                for (int dc = -1; dc <= 1; ++dc) {
                    const std::uint32_t cc =
                        static_cast<std::uint32_t>(std::clamp<std::int64_t>(std::int64_t(c) + dc, 0, width - 1));
                    window[k++] = in[static_cast<std::size_t>(rr) * width + cc];
                }
            }
            std::nth_element(window.begin(), window.begin() + 4, window.end());
            out[static_cast<std::size_t>(r) * width + c] = window[4];
        }
    }
}

void gtri_legacy(const std::vector<GtriPoint>& cloud, double hfov_rad, double range_max_m, std::uint64_t seed,
                 std::uint64_t frame_index, GtriImages& out) {
    constexpr std::uint32_t n = kGtriImageSize;
    constexpr std::size_t pixels = static_cast<std::size_t>(n) * n;
    gtri_jitter(cloud, seed, frame_index, kGtriJitterSigma, out.jittered);
    out.gray.assign(pixels, 0);
    out.blurred.resize(pixels);
    out.color.width = n;
    out.color.height = n;
    out.color.rgb.resize(pixels * 3);

    // cv::circle(radius 1, filled) covers the centre and its four neighbours; later points overwrite.
    constexpr int kDisc[5][2] = {{0, 0}, {-1, 0}, {1, 0}, {0, -1}, {0, 1}};
    for (const GtriPoint& point : out.jittered) {
        int row = 0, col = 0;
        if (!gtri_pixel(point.x, point.y, range_max_m, &row, &col)) continue;
        const std::uint8_t value = retro_value(point.retro);
        for (const auto& offset : kDisc) {
            const int r = row + offset[0], c = col + offset[1];
            if (r < 0 || c < 0 || r >= static_cast<int>(n) || c >= static_cast<int>(n)) continue;
            out.gray[static_cast<std::size_t>(r) * n + c] = value;
        }
    }
    gtri_median3(out.gray.data(), n, n, out.blurred.data());

    const double centre = n / 2, half_fov = 0.5 * hfov_rad;
    for (std::uint32_t r = 0; r < n; ++r) {
        for (std::uint32_t c = 0; c < n; ++c) {
            // 180-degree rotation: output (r, c) shows pre-rotation pixel (n-1-r, n-1-c).
            const std::uint32_t sr = n - 1 - r, sc = n - 1 - c;
            const double forward = sr - centre, port = sc - centre;
            const bool inside = std::hypot(forward, port) <= kGtriRangePixels &&
                                std::abs(std::atan2(port, forward)) <= half_fov + 1e-12;
            const host::Rgb8 px =
                inside ? gtri_jet(out.blurred[static_cast<std::size_t>(sr) * n + sc]) : host::Rgb8{0, 0, 0};
            std::uint8_t* dst = &out.color.rgb[(static_cast<std::size_t>(r) * n + c) * 3];
            dst[0] = px.r;
            dst[1] = px.g;
            dst[2] = px.b;
        }
    }
}

void gtri_cloud_from_frame(const Plan& plan, const Frame& frame, std::vector<GtriPoint>& out) {
    out.clear();
    const std::size_t pixels = static_cast<std::size_t>(plan.rows) * plan.columns;
    if (pixels == 0 || frame.depth.size() != pixels || frame.material.size() != pixels) return;
    float brightest = 0.0f;
    for (const auto& material : plan.materials)
        brightest = std::max(brightest, material.backscatter_linear);
    for (std::uint32_t row = 0; row < plan.rows; ++row) {
        for (std::uint32_t col = 0; col < plan.columns; ++col) {
            const std::uint32_t id = frame.material[static_cast<std::size_t>(row) * plan.columns + col];
            if (id == kNoHit || id >= plan.materials.size()) continue;
            GtriPoint point;
            if (!pixel_point(plan, frame, row, col, point)) continue;
            // GTRI's "retro" is the ray's laser retro-reflectivity; here the material's backscatter, scaled
            // so the brightest material in the scene gives 255.
            point.retro = brightest > 0.0f ? 255.0f * plan.materials[id].backscatter_linear / brightest : 0.0f;
            out.push_back(point);
        }
    }
}

std::vector<GtriPoint> gtri_cloud_from_frame(const Plan& plan, const Frame& frame) {
    std::vector<GtriPoint> out;
    gtri_cloud_from_frame(plan, frame, out);
    return out;
}

void uuv_cloud_from_frame(const Plan& plan, const Frame& frame, const UuvImages& images, std::vector<GtriPoint>& out) {
    out.clear();
    const std::size_t pixels = static_cast<std::size_t>(plan.rows) * plan.columns;
    if (pixels == 0 || frame.depth.size() != pixels || images.width != plan.columns || images.height != plan.rows ||
        images.multibeam.size() != pixels)
        return;
    for (std::uint32_t row = 0; row < plan.rows; ++row) {
        for (std::uint32_t col = 0; col < plan.columns; ++col) {
            GtriPoint point;
            if (!pixel_point(plan, frame, row, col, point)) continue;
            point.retro = images.multibeam[static_cast<std::size_t>(row) * plan.columns + col];
            out.push_back(point);
        }
    }
}

} // namespace vksonar::legacy
