// uuv_simulator image sonar (gazebo_ros_image_sonar), step by step as docs/legacy.md describes
// it: depth -> normals -> "multibeam" SNR -> 400-row raw scan -> visual scan. The plugin's quirks are
// kept on purpose (min-max normalizations, 17 m range, off-by-one principal point, overwrite projection);
// the only departures are where the plugin produced NaN or undefined behaviour (documented in legacy.h).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

#include "core/angles.h"
#include "core/sonar_math.hpp"
#include "legacy/legacy.h"
#include "sonar_shared.h"

namespace vksonar::legacy {
namespace {

constexpr double kDegPerRad = 180.0 / kPi;

// Replicated border, as the plugin's filter2D / erode with BORDER_REPLICATE.
inline std::uint32_t clamp_index(std::int64_t i, std::uint32_t n) {
    return static_cast<std::uint32_t>(std::clamp<std::int64_t>(i, 0, static_cast<std::int64_t>(n) - 1));
}

// Min-max normalization in place over `count` values spaced `stride` apart. A constant channel maps to 0:
// the plugin computed (x - min) / 0 there, which is NaN, and no NaN may leave a stage.
void min_max_normalize(float* values, std::size_t count, std::size_t stride) {
    if (count == 0) return;
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    for (std::size_t i = 0; i < count; ++i) {
        const float v = values[i * stride];
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
    const double span = static_cast<double>(hi) - lo;
    for (std::size_t i = 0; i < count; ++i) {
        float& v = values[i * stride];
        v = span > 0 ? static_cast<float>((v - lo) / span) : 0.0f;
    }
}

// Is scan pixel (row, col) inside the sector of `radius` about straight up from the apex (cols/2, rows)?
// This is the region the plugin fills with cv::ellipse(center, (r, r), -90, -fov/2, fov/2, thickness -1).
inline bool in_sector(std::uint32_t row, std::uint32_t col, std::uint32_t rows, std::uint32_t cols, double radius,
                      double half_fov_deg) {
    const double dx = static_cast<double>(col) - static_cast<double>(cols / 2);
    const double dy = static_cast<double>(rows) - static_cast<double>(row);
    if (dx * dx + dy * dy > radius * radius) return false;
    return std::abs(std::atan2(dx, dy)) * kDegPerRad <= half_fov_deg + 1e-9;
}

inline void put_white(host::Image& image, double x, double y) {
    const long col = std::lround(x), row = std::lround(y);
    if (col < 0 || row < 0 || col >= static_cast<long>(image.width) || row >= static_cast<long>(image.height)) return;
    std::uint8_t* px = &image.rgb[(static_cast<std::size_t>(row) * image.width + col) * 3];
    px[0] = px[1] = px[2] = 255;
}

// Arc of `radius` about the apex from angle a0 to a1 (degrees, 0 = straight up, positive = right).
// Sampled finer than a pixel, so it is the 1-pixel line cv::ellipse draws (without its anti-aliasing).
void draw_arc(host::Image& image, double cx, double cy, double radius, double a0_deg, double a1_deg) {
    if (radius <= 0) return;
    const double step = 0.25 / radius;
    for (double a = a0_deg / kDegPerRad; a <= a1_deg / kDegPerRad + 1e-12; a += step)
        put_white(image, cx + radius * std::sin(a), cy - radius * std::cos(a));
}

void draw_line(host::Image& image, double x0, double y0, double x1, double y1) {
    const double length = std::hypot(x1 - x0, y1 - y0);
    const int steps = std::max(1, static_cast<int>(std::ceil(2.0 * length)));
    for (int i = 0; i <= steps; ++i) {
        const double t = static_cast<double>(i) / steps;
        put_white(image, x0 + t * (x1 - x0), y0 + t * (y1 - y0));
    }
}

// The plugin's double -> uchar conversion truncates; clamp first so nothing is undefined.
inline std::uint8_t truncate_channel(double v) {
    if (!(v > 0.0)) return 0;
    if (v >= 255.0) return 255;
    return static_cast<std::uint8_t>(v);
}

} // namespace

UuvIntrinsics uuv_intrinsics(std::uint32_t width, std::uint32_t height, double hfov_rad) {
    UuvIntrinsics k;
    k.f = static_cast<double>(width) / (2.0 * std::tan(0.5 * hfov_rad));
    k.cx = (static_cast<double>(width) + 1.0) / 2.0;
    k.cy = (static_cast<double>(height) + 1.0) / 2.0;
    return k;
}

std::uint32_t uuv_scan_columns(double hfov_rad) {
    if (!(hfov_rad > 0)) return 20;
    const double half = std::min(hfov_rad, kPi) / 2.0;
    return 2u * static_cast<std::uint32_t>(static_cast<float>(kUuvScanRows) * std::sin(half)) + 20u;
}

std::vector<std::uint8_t> uuv_ellipse_element(std::uint32_t width, std::uint32_t height) {
    // OpenCV's getStructuringElement(MORPH_ELLIPSE): row i spans c +- round(c * sqrt(1 - dy^2 / r^2)).
    std::vector<std::uint8_t> element(static_cast<std::size_t>(width) * height, 0);
    const int r = static_cast<int>(height / 2), c = static_cast<int>(width / 2);
    const double inv_r2 = r ? 1.0 / (static_cast<double>(r) * r) : 0.0;
    for (int i = 0; i < static_cast<int>(height); ++i) {
        const int dy = i - r;
        if (std::abs(dy) > r) continue;
        const int dx = static_cast<int>(std::lrint(c * std::sqrt((r * r - dy * dy) * inv_r2)));
        const int j1 = std::max(c - dx, 0), j2 = std::min(c + dx + 1, static_cast<int>(width));
        for (int j = j1; j < j2; ++j)
            element[static_cast<std::size_t>(i) * width + j] = 1;
    }
    return element;
}

void uuv_prepare(std::uint32_t width, std::uint32_t height, double hfov_rad, UuvImages& out) {
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    out.width = width;
    out.height = height;
    out.hfov_rad = hfov_rad;
    out.intrinsics = uuv_intrinsics(width, height, hfov_rad);
    out.scan_rows = kUuvScanRows;
    out.scan_cols = uuv_scan_columns(hfov_rad);
    const std::size_t cells = static_cast<std::size_t>(out.scan_rows) * out.scan_cols;
    // resize() keeps the capacity, so a second call with the same sizes allocates nothing.
    out.normals.resize(pixels * 3);
    out.multibeam.resize(pixels);
    out.gx.resize(pixels);
    out.gy.resize(pixels);
    out.no_reading.resize(pixels);
    out.eroded.resize(pixels);
    out.raw_scan.resize(cells);
    out.dilated.resize(cells);
    out.visual.width = out.scan_cols;
    out.visual.height = out.scan_rows;
    out.visual.rgb.resize(cells * 3);
    if (out.element.size() != static_cast<std::size_t>(kUuvDilateWidth) * kUuvDilateHeight)
        out.element = uuv_ellipse_element(kUuvDilateWidth, kUuvDilateHeight);
}

void uuv_normals(const float* depth, UuvImages& io) {
    const std::uint32_t w = io.width, h = io.height;
    const std::size_t pixels = static_cast<std::size_t>(w) * h;
    if (pixels == 0) return;
    auto at = [&](std::int64_t row, std::int64_t col) {
        return depth[static_cast<std::size_t>(clamp_index(row, h)) * w + clamp_index(col, w)];
    };
    for (std::size_t p = 0; p < pixels; ++p)
        io.no_reading[p] = depth[p] == 0.0f ? 1 : 0;
    // Two 3x3 erosions with replicated borders are one 5x5 erosion.
    for (std::uint32_t r = 0; r < h; ++r) {
        for (std::uint32_t c = 0; c < w; ++c) {
            std::uint8_t all = 1;
            for (int dr = -2; dr <= 2 && all; ++dr)
                for (int dc = -2; dc <= 2 && all; ++dc)
                    all = io.no_reading[static_cast<std::size_t>(clamp_index(std::int64_t(r) + dr, h)) * w +
                                        clamp_index(std::int64_t(c) + dc, w)];
            io.eroded[static_cast<std::size_t>(r) * w + c] = all;
        }
    }
    const double inv_f = io.intrinsics.f > 0 ? 1.0 / io.intrinsics.f : 0.0;
    for (std::uint32_t r = 0; r < h; ++r) {
        for (std::uint32_t c = 0; c < w; ++c) {
            const std::int64_t R = r, C = c;
            const std::size_t p = static_cast<std::size_t>(r) * w + c;
            // filter2D is a correlation; with the flipped kernels these are (below - above) and
            // (right - left), weighted 1 2 1 and divided by 8.
            float vertical = ((at(R + 1, C - 1) + 2.0f * at(R + 1, C) + at(R + 1, C + 1)) -
                              (at(R - 1, C - 1) + 2.0f * at(R - 1, C) + at(R - 1, C + 1))) /
                             8.0f;
            float horizontal = ((at(R - 1, C + 1) + 2.0f * at(R, C + 1) + at(R + 1, C + 1)) -
                                (at(R - 1, C - 1) + 2.0f * at(R, C - 1) + at(R + 1, C - 1))) /
                               8.0f;
            if (io.eroded[p]) vertical = horizontal = 0.0f;
            io.gx[p] = vertical;
            io.gy[p] = horizontal;
            const double n0 = vertical, n1 = horizontal, n2 = inv_f * depth[p];
            const double norm = std::sqrt(n0 * n0 + n1 * n1 + n2 * n2);
            const double scale = norm > 0 && std::isfinite(norm) ? 1.0 / norm : 0.0;
            io.normals[p * 3 + 0] = static_cast<float>(n0 * scale);
            io.normals[p * 3 + 1] = static_cast<float>(n1 * scale);
            io.normals[p * 3 + 2] = static_cast<float>(n2 * scale);
        }
    }
    for (int channel = 0; channel < 3; ++channel)
        min_max_normalize(io.normals.data() + channel, pixels, 3);
}

void uuv_multibeam(const float* depth, UuvImages& io) {
    const std::uint32_t w = io.width, h = io.height;
    const std::size_t pixels = static_cast<std::size_t>(w) * h;
    if (pixels == 0) return;
    const UuvIntrinsics& k = io.intrinsics;
    for (std::uint32_t r = 0; r < h; ++r) {
        const float y = static_cast<float>((static_cast<double>(r) - k.cy) / k.f);
        for (std::uint32_t c = 0; c < w; ++c) {
            const std::size_t p = static_cast<std::size_t>(r) * w + c;
            const float x = static_cast<float>((static_cast<double>(c) - k.cx) / k.f);
            const float target_strength = kUuvIntensity * io.normals[p * 3 + 2];
            const float transmission_loss = 5.0f * depth[p] * std::sqrt(x * x + y * y + 1.0f);
            float snr =
                kUuvSourceLevel - 2.0f * transmission_loss - (kUuvNoiseLevel - kUuvDirectivity) + target_strength;
            if (!(snr >= 0.0f)) snr = 0.0f; // negatives (and a NaN from a non-finite depth) to 0
            io.multibeam[p] = snr;
        }
    }
    min_max_normalize(io.multibeam.data(), pixels, 1);
}

void uuv_scan_prefill(UuvImages& io) {
    const double half_fov_deg = 0.5 * io.hfov_rad * kDegPerRad;
    const std::uint32_t rows = io.scan_rows, cols = io.scan_cols;
    const double full = rows, third = static_cast<double>(rows / 3); // cv::Size(rows/3) is an int
    for (std::uint32_t r = 0; r < rows; ++r) {
        for (std::uint32_t c = 0; c < cols; ++c) {
            float value = 0.0f;
            if (in_sector(r, c, rows, cols, full, half_fov_deg) && !in_sector(r, c, rows, cols, third, half_fov_deg))
                value = kUuvPrefill;
            io.raw_scan[static_cast<std::size_t>(r) * cols + c] = value;
        }
    }
}

bool uuv_project_pixel(float depth, std::uint32_t row, std::uint32_t col, const UuvIntrinsics& k,
                       std::uint32_t scan_cols, int* scan_row, int* scan_col) {
    if (!(depth > 0.0f) || !std::isfinite(depth) || !(k.f > 0)) return false;
    float x = static_cast<float>((static_cast<double>(col) - k.cx) / k.f);
    const float y = static_cast<float>((static_cast<double>(row) - k.cy) / k.f);
    const float z = depth * std::sqrt(y * y + 1.0f);
    x *= z;
    // The range test comes first so the int conversions below never see a huge value.
    if (!(x * x + z * z < kUuvRangeM * kUuvRangeM)) return false;
    const float mapped = static_cast<float>(kUuvScanRows);
    const int pi = static_cast<int>(kUuvScanRows) - 1 - static_cast<int>(z / kUuvRangeM * mapped);
    const int pj = static_cast<int>(scan_cols / 2) + static_cast<int>(x / kUuvRangeM * mapped);
    // The plugin tests pi > 0 and pj > 0 (not >= 0): row 0 and column 0 never receive a return.
    if (!(pi > 0 && pi < static_cast<int>(kUuvScanRows) && pj > 0 && pj < static_cast<int>(scan_cols))) return false;
    *scan_row = pi;
    *scan_col = pj;
    return true;
}

void uuv_scan_project(const float* depth, UuvImages& io) {
    for (std::uint32_t r = 0; r < io.height; ++r) {
        for (std::uint32_t c = 0; c < io.width; ++c) {
            const std::size_t p = static_cast<std::size_t>(r) * io.width + c;
            const float a = io.multibeam[p];
            if (depth[p] == 0.0f || a == 0.0f) continue;
            int sr = 0, sc = 0;
            if (!uuv_project_pixel(depth[p], r, c, io.intrinsics, io.scan_cols, &sr, &sc)) continue;
            io.raw_scan[static_cast<std::size_t>(sr) * io.scan_cols + static_cast<std::size_t>(sc)] = a;
        }
    }
}

void uuv_scan_dilate(UuvImages& io) {
    const std::int64_t rows = io.scan_rows, cols = io.scan_cols;
    const std::int64_t half_w = kUuvDilateWidth / 2, half_h = kUuvDilateHeight / 2;
    for (std::int64_t r = 0; r < rows; ++r) {
        for (std::int64_t c = 0; c < cols; ++c) {
            float best = io.raw_scan[static_cast<std::size_t>(r * cols + c)];
            for (std::int64_t er = 0; er < kUuvDilateHeight; ++er) {
                const std::int64_t sr = r + er - half_h;
                if (sr < 0 || sr >= rows) continue; // a replicated border never raises a max
                for (std::int64_t ec = 0; ec < kUuvDilateWidth; ++ec) {
                    const std::int64_t sc = c + ec - half_w;
                    if (sc < 0 || sc >= cols || !io.element[static_cast<std::size_t>(er * kUuvDilateWidth + ec)])
                        continue;
                    best = std::max(best, io.raw_scan[static_cast<std::size_t>(sr * cols + sc)]);
                }
            }
            io.dilated[static_cast<std::size_t>(r * cols + c)] = best;
        }
    }
    // Only empty cells (0) and untouched sector (exactly the float 0.2 written by the prefill) take the
    // dilated value; real returns keep their own.
    for (std::size_t i = 0; i < io.raw_scan.size(); ++i) {
        const float v = io.raw_scan[i];
        if (v == 0.0f || v == kUuvPrefill) io.raw_scan[i] = io.dilated[i];
    }
}

void uuv_scan_speckle(std::uint64_t seed, std::uint64_t frame_index, UuvImages& io) {
    for (std::uint32_t r = 0; r < io.scan_rows; ++r) {
        for (std::uint32_t c = 0; c < io.scan_cols; ++c) {
            float& a = io.raw_scan[static_cast<std::size_t>(r) * io.scan_cols + c];
            if (a == 0.0f) continue;
            const double n = host::sample_normal01(seed, frame_index, c, r, kUuvSpeckleStream);
            a = static_cast<float>(a * std::abs(1.0 + kUuvSpeckleSigma * n));
        }
    }
}

host::Rgb8 uuv_color(float a) {
    if (std::isnan(a)) return {0, 0, 0};
    const double v = a;
    if (v < 0.8)
        return {truncate_channel(255 * 1.25 * v), truncate_channel(255 * 0.78 * v), truncate_channel(255 * 0.50 * v)};
    if (v < 1.0)
        return {truncate_channel(255 * v), truncate_channel(255 * (1.88 * v - 0.88)),
                truncate_channel(255 * (-1.99 * v + 1.99))};
    return {255, 255, 0};
}

void uuv_visual(UuvImages& io) {
    host::Image& image = io.visual;
    const std::uint32_t rows = io.scan_rows, cols = io.scan_cols;
    const double half_fov_deg = 0.5 * io.hfov_rad * kDegPerRad;
    const double fov_deg = 2.0 * half_fov_deg;
    for (std::uint32_t r = 0; r < rows; ++r) {
        for (std::uint32_t c = 0; c < cols; ++c) {
            const std::size_t i = static_cast<std::size_t>(r) * cols + c;
            host::Rgb8 px = kUuvBackground;
            // The black sector has radius rows + 3, a little beyond the 400-row scan.
            if (in_sector(r, c, rows, cols, rows + 3.0, half_fov_deg)) px = {0, 0, 0};
            const float a = io.raw_scan[i];
            if (a != 0.0f) px = uuv_color(a);
            image.rgb[i * 3 + 0] = px.r;
            image.rgb[i * 3 + 1] = px.g;
            image.rgb[i * 3 + 2] = px.b;
        }
    }
    const double cx = cols / 2, cy = rows;
    // Outer arc (radius rows + 3) starts half a degree left of the sector, as in the plugin; the 2/3 and
    // 1/3 arcs use int radii (cv::Size truncates).
    draw_arc(image, cx, cy, rows + 3.0, -half_fov_deg - 0.5, half_fov_deg);
    draw_arc(image, cx, cy, static_cast<int>(2.0 / 3.0 * rows), -half_fov_deg, half_fov_deg);
    draw_arc(image, cx, cy, static_cast<int>(1.0 / 3.0 * rows), -half_fov_deg, half_fov_deg);
    const double mapped = rows;
    for (int i = 0; i < 5; ++i) {
        const double angle = (-half_fov_deg - 0.5 + (fov_deg + 0.5) * i / 4.0) / kDegPerRad;
        const int corner_x = static_cast<int>(mapped * std::sin(angle));
        const int corner_y = static_cast<int>(mapped * std::cos(angle));
        draw_line(image, cx, cy, cx + corner_x, cy - corner_y);
    }
}

void uuv_legacy(const float* depth, std::uint32_t width, std::uint32_t height, double hfov_rad, std::uint64_t seed,
                std::uint64_t frame_index, UuvImages& out) {
    uuv_prepare(width, height, hfov_rad, out);
    uuv_normals(depth, out);
    uuv_multibeam(depth, out);
    uuv_scan_prefill(out);
    uuv_scan_project(depth, out);
    uuv_scan_dilate(out);
    uuv_scan_speckle(seed, frame_index, out);
    uuv_visual(out);
}

void legacy_depth_from_frame(const Plan& plan, const Frame& frame, std::vector<float>& out) {
    const std::size_t pixels = static_cast<std::size_t>(plan.rows) * plan.columns;
    if (pixels == 0 || frame.depth.size() != pixels) {
        out.clear();
        return;
    }
    out.resize(pixels);
    for (std::size_t p = 0; p < pixels; ++p) {
        const double d = frame.depth[p];
        // Reversed-Z: d = 0 is "nothing hit" (the far plane), the plugin's 0 = no reading.
        double z = d > 0.0 && d > plan.depth_b ? math_f64::view_z_from_depth(d, plan.depth_a, plan.depth_b) : 0.0;
        if (!std::isfinite(z) || z < 0) z = 0;
        out[p] = static_cast<float>(z);
    }
}

std::vector<float> legacy_depth_from_frame(const Plan& plan, const Frame& frame) {
    std::vector<float> out;
    legacy_depth_from_frame(plan, frame, out);
    return out;
}

} // namespace vksonar::legacy
