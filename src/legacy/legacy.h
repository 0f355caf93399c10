// Legacy modes (docs/legacy.md): step-by-step reproductions of the
// uuv_simulator image sonar (gazebo_ros_image_sonar) and the GTRI-based sonar, so users of those Gazebo
// plugins get the picture they know. Own code written from the plugins' published notes; no OpenCV.
//
// Everything here is a pure function of its inputs: noise comes from the counter-based RNG
// host::uniform01(seed, frame, beam, bin, stream), so runs are seeded and reproducible. Outputs live in
// caller-owned structs: after the first call with a given size nothing is allocated. Nothing throws
// (beyond std::bad_alloc from the first sizing).
#pragma once

#include <cstdint>
#include <vector>

#include "core/plan.h"
#include "host/host_stages.h"
#include "vksonar/frame.h"

namespace vksonar::legacy {

// ------------------------------------------------------------------------------------------------
// uuv_simulator image sonar
// ------------------------------------------------------------------------------------------------

constexpr std::uint32_t kUuvScanRows = 400; // raw/visual scan height (hard-coded in the plugin)
constexpr float kUuvRangeM = 17.0f;         // raw scan range, hard-coded (legacy bug: ignores range_max)
constexpr float kUuvPrefill = 0.2f;         // value of the fan sector before projection
// Sonar-equation constants of the plugin (dB, arbitrary).
constexpr float kUuvSourceLevel = 200.0f, kUuvNoiseLevel = 30.0f, kUuvDirectivity = 0.0f, kUuvIntensity = 100.0f;
constexpr float kUuvSpeckleSigma = 0.1f; // multiplicative speckle |N(1, sigma)|
// Dilation element: OpenCV getStructuringElement(MORPH_ELLIPSE, Size(width 3, height 9)), i.e. 9 rows
// (range) by 3 columns (cross-range); see docs/legacy.md for why this orientation.
constexpr std::uint32_t kUuvDilateWidth = 3, kUuvDilateHeight = 9;
// RNG streams used by the legacy noise (distinct from the physical model's streams).
constexpr std::uint32_t kUuvSpeckleStream = 101; // uses 101, 102 (Box-Muller)
constexpr std::uint32_t kGtriJitterStream = 111; // uses 111, 112

// Camera intrinsics of GazeboRosCameraUtils: f = width / (2 tan(hfov/2)), cx = (width+1)/2,
// cy = (height+1)/2 (the legacy off-by-one is kept).
struct UuvIntrinsics {
    double f = 0, cx = 0, cy = 0;
};
UuvIntrinsics uuv_intrinsics(std::uint32_t width, std::uint32_t height, double hfov_rad);

// Raw-scan width: 2 * int(400 * sin(hfov/2)) + 20 (float arithmetic as in the plugin).
// hfov_rad in (0, pi]; returns 20 for hfov <= 0.
std::uint32_t uuv_scan_columns(double hfov_rad);

// OpenCV getStructuringElement(MORPH_ELLIPSE, Size(width, height)) with the centre anchor:
// width * height bytes, row-major, 1 = in the element.
std::vector<std::uint8_t> uuv_ellipse_element(std::uint32_t width, std::uint32_t height);

// Every intermediate of one uuv frame, sized by uuv_prepare (first call allocates, later calls with
// the same sizes do not). Images are row-major.
struct UuvImages {
    std::uint32_t width = 0, height = 0; // depth image size
    double hfov_rad = 0;
    UuvIntrinsics intrinsics;
    // height * width * 3, the plugin's channel order: (vertical-kernel gradient, horizontal-kernel gradient,
    // depth/f), normalized to unit length, then each channel min-max normalized over the image.
    std::vector<float> normals;
    std::vector<float> multibeam; // height * width: SNR min-max normalized to [0, 1]
    std::uint32_t scan_rows = kUuvScanRows, scan_cols = 0;
    std::vector<float> raw_scan; // scan_rows * scan_cols, after dilation and speckle
    host::Image visual;          // scan_cols x scan_rows RGB
    // Scratch (kept to avoid per-frame allocation).
    std::vector<float> gx, gy, dilated;
    std::vector<std::uint8_t> no_reading, eroded, element;
};

// Sizes `out` for a width x height depth image and the given hfov; idempotent.
// Contract: allocates only when a size changes; never reads out's previous contents.
void uuv_prepare(std::uint32_t width, std::uint32_t height, double hfov_rad, UuvImages& out);

// Step 1, normals: Sobel/8 (flipped kernels, replicated borders), gradients zeroed where the
// no-reading mask (depth == 0) eroded twice (3x3) is set, normalize(gx, gy, depth/f), per-channel min-max.
// A channel that is constant over the image becomes 0 (the plugin divided 0 by 0 there and got NaN).
// Contract: depth has io.width * io.height values (metres along the axis, 0 = no hit); writes io.normals.
void uuv_normals(const float* depth, UuvImages& io);

// Step 2, sonar equation: SNR = SL - 2 TL - (NL - DI) + TS with TS = 100 n_z, TL = 5 depth sqrt(1+x^2+y^2);
// negatives to 0; min-max normalized to [0, 1] (a constant SNR image becomes 0, not the plugin's NaN).
// Contract: needs io.normals (step 1); writes io.multibeam.
void uuv_multibeam(const float* depth, UuvImages& io);

// Step 3a: raw scan cleared to 0, fan sector (radius 400, +-hfov/2 about straight up, apex at
// (cols/2, 400)) filled with 0.2, inner third (radius 133) with 0. Contract: writes io.raw_scan only.
void uuv_scan_prefill(UuvImages& io);

// Projection of one depth pixel into the raw scan: z = depth sqrt(1+y^2), x = (col-cx)/f z,
// row = 399 - int(z/17*400), col = cols/2 + int(x/17*400). Contract: false (outputs untouched) when
// depth <= 0 or is not finite, x^2 + z^2 >= 17^2, or the cell is not strictly inside (the plugin skips
// row 0 and column 0 too); else true with the cell in *scan_row, *scan_col.
bool uuv_project_pixel(float depth, std::uint32_t row, std::uint32_t col, const UuvIntrinsics& k,
                       std::uint32_t scan_cols, int* scan_row, int* scan_col);

// Step 3b: every hit pixel with a non-zero multibeam value, in row-major order, overwrites its scan cell
// with that value (no accumulation: the last writer wins). Contract: needs io.multibeam and a prefilled
// io.raw_scan.
void uuv_scan_project(const float* depth, UuvImages& io);

// Step 3c: grey dilation (max) with the 3-wide x 9-high elliptical element, copied only into cells
// that are exactly 0 or 0.2 (out-of-image neighbours ignored). Contract: in place on io.raw_scan.
void uuv_scan_dilate(UuvImages& io);

// Step 3d: every non-zero cell is multiplied by |N(1, 0.1)| drawn from host::sample_normal01 keyed by
// (seed, frame, beam = scan column, bin = scan row, kUuvSpeckleStream). Contract: in place on io.raw_scan.
void uuv_scan_speckle(std::uint64_t seed, std::uint64_t frame_index, UuvImages& io);

// The plugin's hard-coded colormap: a < 0.8 -> (1.25a, 0.78a, 0.5a)*255; 0.8 <= a < 1 ->
// (a, 1.88a - 0.88, 1.99 - 1.99a)*255; else (255, 255, 0). Truncated towards zero like the plugin's
// double -> uchar conversion, clamped to [0, 255]; NaN gives black.
host::Rgb8 uuv_color(float a);
constexpr host::Rgb8 kUuvBackground{15, 48, 102};

// Step 4, visual scan: background (15, 48, 102), fan sector black, colormap of the raw scan wherever
// it is > 0, white range arcs at 1/3, 2/3 and full radius and 5 white bearing lines. Writes io.visual.
void uuv_visual(UuvImages& io);

// All steps in order. Contract: depth is width * height metres along the optical axis (0 = no hit);
// fills every intermediate of `out` (allocating only on the first call for these sizes).
void uuv_legacy(const float* depth, std::uint32_t width, std::uint32_t height, double hfov_rad, std::uint64_t seed,
                std::uint64_t frame_index, UuvImages& out);

// vksonar's reversed-Z depth -> metres along the optical axis: view_z = depth_a / (d - depth_b), 0 where
// d == 0. Contract: frame.depth must hold plan.rows * plan.columns values (SaveFlags::depth); else out is empty.
void legacy_depth_from_frame(const Plan& plan, const Frame& frame, std::vector<float>& out);
std::vector<float> legacy_depth_from_frame(const Plan& plan, const Frame& frame);

struct GtriPoint; // x, y, z, value: the point type of both legacy clouds (GTRI section below)

// The uuv plugin's point cloud: one sonar-frame point per pixel of a one-slice depth pass with a hit,
// `retro` = the pixel's multibeam value (0..1). Contract: needs frame.depth (SaveFlags::depth) and `images`
// filled by uuv_legacy for the same frame; else out is empty. No allocation once out is large enough.
void uuv_cloud_from_frame(const Plan& plan, const Frame& frame, const UuvImages& images, std::vector<GtriPoint>& out);

// ------------------------------------------------------------------------------------------------
// GTRI-based sonar
// ------------------------------------------------------------------------------------------------

constexpr std::uint32_t kGtriImageSize = 600; // square 8-bit image
constexpr float kGtriJitterSigma = 0.01f;     // N(0, 0.01) m added to x
constexpr double kGtriRangePixels = 300.0;    // range_max maps to 300 px from the apex

struct GtriPoint {
    float x = 0, y = 0, z = 0; // sonar frame: x forward, y port, z up (m)
    float retro = 0;           // 0..255
};

struct GtriImages {
    std::vector<GtriPoint> jittered;   // the cloud after the x jitter
    std::vector<std::uint8_t> gray;    // 600 * 600 drawn circles (before the rotation)
    std::vector<std::uint8_t> blurred; // after the 3x3 median
    host::Image color;                 // 600 x 600 RGB: jet, black edges, rotated 180 deg (published)
};

// Pre-rotation pixel of a sonar-frame point: apex at the image centre (300, 300), forward x along +rows,
// port y along +columns, scale 300 / range_max px per metre, rounded to nearest.
// Contract: returns false when range_max <= 0; the pixel may lie outside the image.
bool gtri_pixel(float x, float y, double range_max_m, int* row, int* col);

// MATLAB "jet" (256 levels): 0 -> dark blue (0, 0, 128), 255 -> dark red (128, 0, 0).
host::Rgb8 gtri_jet(std::uint8_t value);

// Adds N(0, sigma) to each x (key: seed, frame, beam = point index, bin = 0, kGtriJitterStream).
// Contract: out is resized to in.size() (no allocation once large enough); y, z, retro copied.
void gtri_jitter(const std::vector<GtriPoint>& in, std::uint64_t seed, std::uint64_t frame_index, double sigma,
                 std::vector<GtriPoint>& out);

// 3x3 median of an 8-bit image with replicated borders (OpenCV medianBlur ksize 3).
// Contract: in and out are width * height and must not alias.
void gtri_median3(const std::uint8_t* in, std::uint32_t width, std::uint32_t height, std::uint8_t* out);

// All steps: jitter x, draw each point as a filled radius-1 disc (the 5-pixel plus OpenCV draws) of
// value retro, 3x3 median, jet, pixels outside the fan (range > range_max or |azimuth| > hfov/2) black,
// 180-degree rotation. Contract: fills every field of out; allocates only on the first call.
void gtri_legacy(const std::vector<GtriPoint>& cloud, double hfov_rad, double range_max_m, std::uint64_t seed,
                 std::uint64_t frame_index, GtriImages& out);

// Point cloud of a depth pass: one point per pixel with a hit and slant range in [range_min, range_max),
// sonar-frame position from the pixel's slice frame, retro = 255 * backscatter_linear / (brightest
// material's backscatter_linear). Contract: frame.depth and frame.material must be rows * columns
// (SaveFlags::depth); else the result is empty.
std::vector<GtriPoint> gtri_cloud_from_frame(const Plan& plan, const Frame& frame);
// Same, into a caller-owned vector (no allocation once it is large enough).
void gtri_cloud_from_frame(const Plan& plan, const Frame& frame, std::vector<GtriPoint>& out);

} // namespace vksonar::legacy
