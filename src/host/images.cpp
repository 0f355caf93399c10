// Host stage 6 images: the polar image and the Cartesian fan.
#include <algorithm>
#include <cmath>
#include <cstddef>

#include "core/angles.h"
#include "host/host_stages.h"
#include "host/table_interval.h"
#include "host/workers.h"

namespace vksonar::host {
namespace {

constexpr Rgb8 kBackground{14, 18, 24};
constexpr Rgb8 kOverlay{200, 200, 200};
constexpr float kOverlayAlpha = 0.55f;   // overlay = mix(data colour, light grey, alpha)
constexpr double kLineHalfWidthPx = 0.6; // rings and bearing lines are ~1.2 px wide

inline void ensure_size(Image& out, std::uint32_t w, std::uint32_t h) {
    out.width = w;
    out.height = h;
    const std::size_t n = static_cast<std::size_t>(w) * h * 3;
    if (out.rgb.size() != n) out.rgb.resize(n); // only the first time for a given image
}

inline void put(Image& out, std::size_t pixel, Rgb8 c) {
    std::uint8_t* p = &out.rgb[pixel * 3];
    p[0] = c.r;
    p[1] = c.g;
    p[2] = c.b;
}

inline float finite_or_zero(float v) {
    return std::isfinite(v) ? v : 0.0f;
}

// A "nice" ring spacing (1, 2, 2.5 or 5 x 10^k) giving about 4-5 rings up to range_max.
double ring_step(double range_max) {
    const double raw = range_max / 4.5;
    const double p = std::pow(10.0, std::floor(std::log10(raw)));
    for (double m : {1.0, 2.0, 2.5, 5.0, 10.0})
        if (m * p >= raw * 0.75) return m * p;
    return 10.0 * p;
}

// Smallest signed angle difference a - b in (-pi, pi].
inline double angle_diff(double a, double b) {
    double d = std::fmod(a - b, 2.0 * kPi);
    if (d > kPi) d -= 2.0 * kPi;
    if (d <= -kPi) d += 2.0 * kPi;
    return d;
}

} // namespace

void polar_image(const Plan& plan, const Frame& frame, Image& out) {
    const std::uint32_t beams = plan.beams, bins = plan.bins;
    ensure_size(out, beams, bins);
    const Colormap map = plan.config.colormap;
    const std::size_t n = static_cast<std::size_t>(beams) * bins;
    for (std::uint32_t k = 0; k < bins; ++k) {
        const std::size_t row = bins - 1 - k; // far range at the top
        for (std::uint32_t j = 0; j < beams; ++j) {
            const std::size_t i = static_cast<std::size_t>(k) * beams + j;
            const float v = i < frame.display.size() && i < n ? finite_or_zero(frame.display[i]) : 0.0f;
            put(out, row * beams + j, colormap(map, v)); // beam 0 (port) on the left
        }
    }
}

FanRenderer::FanRenderer(const Plan& plan, Workers* workers) {
    const SonarConfig& cfg = plan.config;
    beams_ = plan.beams;
    bins_ = plan.bins;
    colormap_ = cfg.colormap;

    const double rmax = cfg.range_max_m > 0.0 ? cfg.range_max_m : 1.0;
    const double rmin = std::clamp(cfg.range_min_m, 0.0, rmax);
    // Angular extent: the configured fan, widened to cover the beam table if that reaches further.
    double az_hi = 0.5 * cfg.hfov_deg * kPi / 180.0, az_lo = -az_hi;
    if (!plan.beam_angle_rad.empty()) {
        az_hi = std::max(az_hi, plan.beam_angle_rad.front());
        az_lo = std::min(az_lo, plan.beam_angle_rad.back());
    }
    const bool full_circle = az_hi - az_lo >= 2.0 * kPi - 1e-9;
    const bool centred = cfg.hfov_deg > 180.0 || az_hi > 0.5 * kPi || az_lo < -0.5 * kPi;

    // Layout: apex at the bottom centre (hfov <= 180) or at the centre (wider fans, square image).
    const std::uint32_t w = std::max<std::uint32_t>(cfg.fan_width_px, 16);
    const double margin = std::max(4.0, w / 64.0);
    double scale, cx, cy; // pixels per metre, apex position in pixel coordinates
    std::uint32_t h;
    if (centred) {
        h = w;
        scale = (0.5 * w - margin) / rmax;
        cx = 0.5 * w;
        cy = 0.5 * h;
    } else {
        // Half-width of the fan in metres; a narrow fan still gets an image at least 0.3 R wide each
        // side so that the image does not become a tall sliver.
        const double half_extent = rmax * std::max(std::sin(std::max(az_hi, -az_lo)), 0.3);
        scale = (0.5 * w - margin) / half_extent;
        h = static_cast<std::uint32_t>(std::ceil(rmax * scale + 2.0 * margin));
        cx = 0.5 * w;
        cy = h - margin;
    }
    width_ = w;
    height_ = h;

    const std::size_t npix = static_cast<std::size_t>(w) * h;
    beam0_.assign(npix, -1);
    bin0_.assign(npix, 0);
    beam_t_.assign(npix, 0.0f);
    bin_t_.assign(npix, 0.0f);
    overlay_.assign(npix, 0);

    // Overlay geometry.
    const double step = ring_step(rmax);
    const double line_m = kLineHalfWidthPx / scale;
    std::vector<double> bearings;
    if (!full_circle) {
        bearings.push_back(az_hi);
        bearings.push_back(az_lo);
    }
    for (int deg = -180; deg < 180; deg += 30) {
        const double a = deg * kPi / 180.0;
        if (full_circle || (a < az_hi - 1e-6 && a > az_lo + 1e-6)) bearings.push_back(a);
    }
    const bool interpolate_wrap = full_circle && beams_ > 1;
    // The bearings' directions: a pixel's distance from a bearing's line is |x sin b - y cos b|, which equals
    // the exact test's r |sin(az - b)| up to rounding (a few 1e-16 of r); only pixels within a margin far
    // above that take the exact test, so the overlay is the same bytes at a fraction of the sines.
    std::vector<double> bearing_cos(bearings.size()), bearing_sin(bearings.size());
    for (std::size_t b = 0; b < bearings.size(); ++b) {
        bearing_cos[b] = std::cos(bearings[b]);
        bearing_sin[b] = std::sin(bearings[b]);
    }
    // Pixels surely beyond the outline (r past rmax + line_m by a margin) are neither fan nor overlay: skipped
    // before their atan2.
    const double outside_m = (rmax + line_m) * (1.0 + 1e-9);
    nearest_.assign(npix, -1);

    // The pixels of rows [row_begin, row_end): each a pure function of its position (the search hints only
    // shorten its walks), so the bands of rows can go to any thread.
    const auto build_rows = [&](std::uint32_t row_begin, std::uint32_t row_end) {
        std::int32_t beam_hint = 0, bin_hint = 0; // locate_in_table's, from pixel to pixel
        for (std::uint32_t py = row_begin; py < row_end; ++py) {
            for (std::uint32_t px = 0; px < w; ++px) {
                const std::size_t p = static_cast<std::size_t>(py) * w + px;
                // Sonar frame: x forward = up the image, y port = left in the image.
                const double x = (cy - (py + 0.5)) / scale;
                const double y = (cx - (px + 0.5)) / scale;
                if (x * x + y * y > outside_m * outside_m) continue;
                const double r = std::hypot(x, y);
                const double az = std::atan2(y, x);
                const bool in_angle = full_circle || (az <= az_hi && az >= az_lo);
                const bool in_range = r >= rmin && r <= rmax;

                // Overlay: rings and bearing lines, drawn within the fan and on its outline.
                const double ang_tol = r > 0.0 ? line_m / r : kPi;
                const bool near_fan = (full_circle || (az <= az_hi + ang_tol && az >= az_lo - ang_tol)) &&
                                      r >= rmin - line_m && r <= rmax + line_m;
                if (near_fan) {
                    bool line = false;
                    for (double ring = step; ring < rmax && !line; ring += step)
                        line = ring > rmin && std::abs(r - ring) <= line_m;
                    line = line || std::abs(r - rmax) <= line_m || (rmin > 0.0 && std::abs(r - rmin) <= line_m);
                    for (std::size_t b = 0; b < bearings.size() && !line; ++b) {
                        if (std::abs(x * bearing_sin[b] - y * bearing_cos[b]) > line_m + 1e-9 * (r + 1.0)) continue;
                        const double d = angle_diff(az, bearings[b]);
                        line = std::abs(d) < 0.5 * kPi && r * std::abs(std::sin(d)) <= line_m;
                    }
                    overlay_[p] = line ? 1 : 0;
                }

                if (!(in_angle && in_range) || beams_ == 0 || bins_ == 0) continue;
                std::int32_t j0 = 0, k0 = 0;
                float jt = 0.0f, kt = 0.0f;
                if (interpolate_wrap && az > plan.beam_angle_rad.front()) {
                    // Between beam 0 and the last beam, across the +-180 deg seam.
                    const double span = plan.beam_angle_rad.front() - plan.beam_angle_rad.back();
                    const double gap = 2.0 * kPi - span;
                    j0 = static_cast<std::int32_t>(beams_ - 1);
                    jt = gap > 0.0 ? static_cast<float>(1.0 - (az - plan.beam_angle_rad.front()) / gap) : 0.0f;
                } else if (interpolate_wrap && az < plan.beam_angle_rad.back()) {
                    const double span = plan.beam_angle_rad.front() - plan.beam_angle_rad.back();
                    const double gap = 2.0 * kPi - span;
                    j0 = static_cast<std::int32_t>(beams_ - 1);
                    jt = gap > 0.0 ? static_cast<float>((plan.beam_angle_rad.back() - az) / gap) : 0.0f;
                } else {
                    locate_in_table(plan.beam_angle_rad, beams_, az, /*decreasing=*/true, j0, jt, beam_hint);
                }
                locate_in_table(plan.bin_range_m, bins_, r, /*decreasing=*/false, k0, kt, bin_hint);
                beam0_[p] = j0;
                beam_t_[p] = std::clamp(jt, 0.0f, 1.0f);
                bin0_[p] = k0;
                bin_t_[p] = kt;
                // the pixel's nearest cell: the nearer of the two beams and of the two bins that render() blends
                std::size_t j = static_cast<std::size_t>(j0);
                if (beam_t_[p] >= 0.5f) j = j + 1 < beams_ ? j + 1 : 0;
                std::size_t k = static_cast<std::size_t>(k0);
                if (kt >= 0.5f && k + 1 < bins_) ++k;
                nearest_[p] = static_cast<std::int32_t>(k * beams_ + j);
            }
        }
    };
    // bands of kBandRows rows, taken by the threads as they come (44 -> 20 ms on one thread for the default's
    // 1024 x 580 fan with the prefilters above; the bands halve that again on two)
    constexpr std::uint32_t kBandRows = 16;
    const std::uint32_t bands = (h + kBandRows - 1) / kBandRows;
    if (workers == nullptr || workers->count() == 1) {
        build_rows(0, h);
    } else {
        using BuildRows = decltype(build_rows);
        struct Bands {
            const BuildRows* build;
            std::uint32_t height;
        } job{&build_rows, h};
        workers->run_blocks(
            [](void* context, std::uint32_t band, std::uint32_t) {
                const Bands& b = *static_cast<const Bands*>(context);
                (*b.build)(band * kBandRows, std::min(b.height, (band + 1) * kBandRows));
            },
            &job, bands);
    }
}

std::uint32_t FanRenderer::width() const {
    return width_;
}
std::uint32_t FanRenderer::height() const {
    return height_;
}

void FanRenderer::render(const Frame& frame, Image& out, Workers* workers) const {
    ensure_size(out, width_, height_);
    struct Job {
        const FanRenderer* fan;
        const Frame* frame;
        Image* out;
    } job{this, &frame, &out};
    // one loop per map, the map's formula inlined (host/colormap.h); part of parts: a band of rows
    const auto band = [](void* context, std::uint32_t part, std::uint32_t parts) {
        const Job& j = *static_cast<const Job*>(context);
        const std::uint64_t rows = j.fan->height_;
        const auto begin = static_cast<std::uint32_t>(rows * part / parts);
        const auto end = static_cast<std::uint32_t>(rows * (part + 1) / parts);
        switch (j.fan->colormap_) {
        case Colormap::gray:
            return j.fan->render_rows<Colormap::gray>(*j.frame, *j.out, begin, end);
        case Colormap::viridis:
            return j.fan->render_rows<Colormap::viridis>(*j.frame, *j.out, begin, end);
        case Colormap::sonar:
            return j.fan->render_rows<Colormap::sonar>(*j.frame, *j.out, begin, end);
        case Colormap::jet:
            return j.fan->render_rows<Colormap::jet>(*j.frame, *j.out, begin, end);
        }
    };
    run_parts(workers, band, &job);
}

template <Colormap Map>
void FanRenderer::render_rows(const Frame& frame, Image& out, std::uint32_t row_begin, std::uint32_t row_end) const {
    const std::size_t beams = beams_;
    const bool sized = frame.display.size() >= beams * bins_;
    const float* d = frame.display.data();
    const std::size_t pixel_end = std::size_t(row_end) * width_;
    for (std::size_t p = std::size_t(row_begin) * width_; p < pixel_end; ++p) {
        Rgb8 c = kBackground;
        const std::int32_t j0 = beam0_[p];
        if (j0 >= 0 && sized) {
            // Bilinear over (beam, bin); the next beam after the last one is beam 0 (used only by the
            // 360 deg seam; elsewhere its weight is 0 at the table's end).
            const std::size_t ja = static_cast<std::size_t>(j0);
            const std::size_t jb = ja + 1 < beams ? ja + 1 : 0;
            const std::size_t ka = static_cast<std::size_t>(bin0_[p]);
            const std::size_t kb = ka + 1 < bins_ ? ka + 1 : ka;
            const float tj = beam_t_[p], tk = bin_t_[p];
            const float v_near =
                (1.0f - tj) * finite_or_zero(d[ka * beams + ja]) + tj * finite_or_zero(d[ka * beams + jb]);
            const float v_far =
                (1.0f - tj) * finite_or_zero(d[kb * beams + ja]) + tj * finite_or_zero(d[kb * beams + jb]);
            c = colormap_of<Map>((1.0f - tk) * v_near + tk * v_far);
        }
        if (overlay_[p]) {
            auto mix = [](std::uint8_t a, std::uint8_t b) {
                return static_cast<std::uint8_t>(a + (static_cast<float>(b) - a) * kOverlayAlpha + 0.5f);
            };
            c = {mix(c.r, kOverlay.r), mix(c.g, kOverlay.g), mix(c.b, kOverlay.b)};
        }
        put(out, p, c);
    }
}

void FanRenderer::nearest_cell(const std::vector<std::uint16_t>& cells, std::vector<std::uint16_t>& out) const {
    const std::size_t npix = static_cast<std::size_t>(width_) * height_;
    out.resize(npix);
    if (cells.size() < static_cast<std::size_t>(beams_) * bins_) {
        std::fill(out.begin(), out.end(), std::uint16_t(0));
        return;
    }
    for (std::size_t p = 0; p < npix; ++p) {
        const std::int32_t cell = nearest_[p];
        out[p] = cell >= 0 ? cells[static_cast<std::size_t>(cell)] : 0;
    }
}

void label_image(const std::vector<std::uint16_t>& ids, std::uint32_t width, std::uint32_t height, Image& out) {
    ensure_size(out, width, height);
    const auto colour_of = [](std::uint16_t id) -> Rgb8 {
        if (id == 0) return {0, 0, 0};
        // splitmix-style bit mixing of the id, each channel lifted into [64, 255]
        std::uint32_t h = id * 0x9e3779b9u;
        h ^= h >> 16;
        h *= 0x85ebca6bu;
        h ^= h >> 13;
        return {static_cast<std::uint8_t>(64 + (h & 0xff) * 191 / 255),
                static_cast<std::uint8_t>(64 + ((h >> 8) & 0xff) * 191 / 255),
                static_cast<std::uint8_t>(64 + ((h >> 16) & 0xff) * 191 / 255)};
    };
    // ids come in runs along a row (an object's pixels side by side): a colour is made when the id changes
    std::uint16_t id = 0;
    Rgb8 c = colour_of(0);
    const std::size_t npix = static_cast<std::size_t>(width) * height;
    for (std::size_t p = 0; p < npix && p < ids.size(); ++p) {
        if (ids[p] != id) {
            id = ids[p];
            c = colour_of(id);
        }
        put(out, p, c);
    }
}

} // namespace vksonar::host
