// Host stages 5 (noise + gain) and 6 (images), shared by both backends.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/plan.h"
#include "host/colormap.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"

namespace vksonar::host {

// Counter-based RNG: a uniform double in (0, 1) from (seed, frame, beam, bin, stream), stateless,
// identical on every backend and rerun.
double uniform01(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin, std::uint32_t stream);
// Samplers on top of uniform01 (still counter-based: same key -> same draw). `stream` is the first
// stream used; exp1 uses 1 stream, normal01 2, gamma_unit_mean kGammaStreams.
constexpr std::uint32_t kGammaAttempts = 16;                    // Marsaglia-Tsang tries before the mean
constexpr std::uint32_t kGammaStreams = 3 * kGammaAttempts + 1; // 3 per try + 1 for looks < 1
double sample_exp1(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                   std::uint32_t stream);
double sample_normal01(std::uint64_t seed, std::uint64_t frame, std::uint32_t beam, std::uint32_t bin,
                       std::uint32_t stream);
// Gamma(looks, 1/looks): mean 1, variance 1/looks.
double sample_gamma_unit_mean(double looks, std::uint64_t seed, std::uint64_t frame, std::uint32_t beam,
                              std::uint32_t bin, std::uint32_t stream);

// Stage 5: frame.clean -> frame.intensity (speckle, ambient noise, TVG; uPa^2) -> frame.display ([0,1]).
// With `workers`, the bins are split across its threads (same output for any thread count). With
// `clean_source` (a backend's pending_clean()), each bin's row of it is first copied into frame.clean.
// With `draws` (from noise_draws, same seed and frame), the random draws are read instead of made.
class Workers;
struct NoiseDraws {
    float* speckle = nullptr; // bins * beams, as frame.clean
    float* noise = nullptr;
};
void noise_and_gain(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, Frame& frame,
                    Workers* workers = nullptr, const float* clean_source = nullptr, const NoiseDraws* draws = nullptr);
// The random draws of a frame depend on its seed and index alone, not on its scan: where it has rows of
// them (Rayleigh or grained gamma speckle, ambient noise or both; noise_draws_ahead), the renderer makes
// them while the GPU renders (StageBackend::set_gpu_overlap), and noise_and_gain then only reads them.
bool noise_draws_ahead(const Plan& plan);
// Which rows of draws the noise stage makes (and noise_draws makes ahead): Rayleigh speckle's and ambient
// noise's, each where its effect is on, through the 32-bit row path; with Plan::grain.taps > 0 these are the
// rows the grain correlates across beams (meta.json noise.grain says so from this), and gamma speckle of a
// whole number of looks L <= kGrainMaxLooks joins them: each cell the mean of L grained fields' draws, so
// Gamma(L, 1/L) in every cell and correlated between beams as one look is (speckle_looks = L; 1 otherwise).
// Other gamma speckle, and the gaussian model, are drawn per cell.
constexpr std::uint32_t kGrainMaxLooks = 16;
struct RowDraws {
    bool speckle = false, noise = false;
    std::uint32_t speckle_looks = 1;
};
RowDraws row_draws_of(const Plan& plan);
void noise_draws(const Plan& plan, std::uint64_t seed, std::uint64_t frame_index, const NoiseDraws& draws,
                 Workers* workers);

Rgb8 colormap(Colormap map, float value01); // (host/colormap.h: colormap_of, inline)

// Stage 6 images: 8-bit RGB, row-major, preallocated by the caller through the *Image structs.
struct Image {
    std::uint32_t width = 0, height = 0;
    std::vector<std::uint8_t> rgb; // width * height * 3
};
// Polar image: one column per beam (port left), one row per bin (far range at the top).
void polar_image(const Plan& plan, const Frame& frame, Image& out);
// Cartesian fan (apex at bottom centre, or centre for hfov > 180) with range rings and bearing lines.
class FanRenderer {
public:
    // Precomputes the pixel -> (beam, bin) lookup once; workers: its bands of rows shared out among the
    // threads (the same tables); null: on the caller alone.
    explicit FanRenderer(const Plan& plan, Workers* workers = nullptr);
    // workers: rows shared out among its threads (the same bytes); null: on the caller alone.
    void render(const Frame& frame, Image& out, Workers* workers = nullptr) const;
    // A per-cell id array (bins * beams, e.g. Frame::instance) on the fan image's pixels, by the
    // nearest cell (never interpolated: ids stay ids); 0 outside the fan. out: width * height.
    void nearest_cell(const std::vector<std::uint16_t>& cells, std::vector<std::uint16_t>& out) const;
    std::uint32_t width() const;
    std::uint32_t height() const;

private:
    template <Colormap Map>
    void render_rows(const Frame& frame, Image& out, std::uint32_t row_begin, std::uint32_t row_end) const;
    std::vector<std::int32_t> beam0_, bin0_; // -1: outside the fan
    std::vector<float> beam_t_, bin_t_;
    std::vector<std::int32_t> nearest_; // nearest_cell's cell (bin * beams + beam), -1 outside the fan
    std::vector<std::uint8_t> overlay_; // 1 where rings/bearing lines are drawn
    std::uint32_t width_ = 0, height_ = 0;
    std::uint32_t beams_ = 0, bins_ = 0;
    Colormap colormap_ = Colormap::sonar;
};

// Ids (width * height, 0 = none) as colours for looking at: 0 black, every other id a fixed colour
// of its own (a hash of the id, bright enough to see), the same in every frame and run.
void label_image(const std::vector<std::uint16_t>& ids, std::uint32_t width, std::uint32_t height, Image& out);

// Files. Errors name the path.
[[nodiscard]] Result<void> write_png(const std::string& path, const Image& image);
[[nodiscard]] Result<void> write_npy_f32(const std::string& path, const float* data, std::uint32_t rows,
                                         std::uint32_t cols, std::uint32_t channels = 1);
[[nodiscard]] Result<void> write_npy_u16(const std::string& path, const std::uint16_t* data, std::uint32_t rows,
                                         std::uint32_t cols);
// Point cloud of the polar scan: one point per (beam, bin) above the display floor at elevation 0,
// binary little-endian PLY with float x y z intensity.
[[nodiscard]] Result<void> write_cloud_ply(const std::string& path, const Plan& plan, const Frame& frame);
// Any point cloud as the same PLY: `xyzi` holds `count` points of 4 floats (x y z intensity, sonar frame);
// `comment` (one line) says what the intensity is.
[[nodiscard]] Result<void> write_points_ply(const std::string& path, const float* xyzi, std::size_t count,
                                            const std::string& comment);
// Any text (a JSON document) as the file's whole content.
[[nodiscard]] Result<void> write_text_file(const std::string& path, const std::string& text);
// meta.json: beam angles, bin ranges, resolved config, effects, stage times, seed, frame convention.
[[nodiscard]] Result<void> write_meta_json(const std::string& path, const Plan& plan, const Frame& frame,
                                           const std::string& extra_json_fields,
                                           const std::string* plan_part = nullptr);
// The same JSON as text (the Python module's Frame.meta); empty if `extra_json_fields` is not an object.
// `plan_part`: meta_json_plan_part(plan), made once for a run of frames (its beam and range tables are
// most of the file and the same every frame).
std::string meta_json_text(const Plan& plan, const Frame& frame, const std::string& extra_json_fields,
                           const std::string* plan_part = nullptr);
// The fields of meta.json that come from the plan alone, as the start of the JSON text.
std::string meta_json_plan_part(const Plan& plan);

// Arrays as the CLI writes them (polar_u16.npy, depth.npy), shared with the Python module.
// polar_u16: the display value [0, 1] as 0..65535 (non-finite as 0).
void quantize_display(const Frame& frame, std::vector<std::uint16_t>& quantized);
// Reversed-Z depth -> slant range (m) along each pixel's ray, 0 where nothing was hit.
void depth_to_view_range(const Plan& plan, const Frame& frame, std::vector<float>& range);

} // namespace vksonar::host
