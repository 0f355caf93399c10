// SonarConfig: every parameter of a simulated sonar, as a plain struct with defaults.
// Units are in the field names. JSON keys (presets, config files, --set) are the names without the
// unit suffix, grouped as documented in README.md ("Config reference"): e.g. `hfov`, `range_max`,
// `effects.speckle`, `display.db_min`.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "vksonar/result.h"

namespace vksonar {

// Each effect of README "Effects: only what the scene calls for". `automatic` is resolved from scene + config into
// on/off with a reason.
enum class EffectMode : std::uint8_t { automatic, on, off };

// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct EffectsConfig {
    EffectMode incidence = EffectMode::automatic; // Lambert cos(theta); auto: on if a material is angle-dependent
    EffectMode vertical_pattern = EffectMode::automatic; // b_v(psi)^2; auto: on
    // The vertical pattern's side lobes beyond its first null, down to the nadir and up to the zenith
    // (the altitude return): tier views in the depth pass. auto: on where the pattern has side lobes
    // and the beams are a line array's (physical mode).
    EffectMode vertical_sidelobes = EffectMode::automatic;
    EffectMode horizontal_pattern = EffectMode::automatic; // side lobes along beams; auto: on
    EffectMode spreading = EffectMode::automatic;          // r^-4; auto: on
    EffectMode absorption = EffectMode::automatic;         // auto: on if 2 alpha range_max >= 0.1 dB
    EffectMode speckle = EffectMode::automatic;            // auto: on
    EffectMode ambient_noise = EffectMode::automatic;      // auto: on
    EffectMode tvg = EffectMode::automatic;                // time-varied gain; auto: off
};

// The shape of a beam pattern (SonarConfig::vertical_pattern, horizontal_pattern; README "The model");
// chebyshev: all side lobes at SonarConfig::*_sidelobe_db.
enum class BeamPattern : std::uint8_t { box, sinc, hann, gaussian, chebyshev };
// How `beams` beams divide the fan when no explicit table is given: equal angles, or equal steps of
// sin(angle) (as a line array steers them).
enum class BeamSpacing : std::uint8_t { equiangular, equisine };
// How the beams divide the directions (docs/pipeline.md, "Beam geometry"). line_array: a horizontal
// line array (Oculus, Gemini, BlueView) hears a direction by its cosine along the array axis, so a
// beam steered to theta is the cone sin(theta) = cos(elevation) sin(azimuth) and its pattern is a
// function of sin(theta') - sin(theta), widening as 1 / cos(theta). planar: a beam is the half-plane
// of one azimuth and its pattern a function of the azimuth difference, as an acoustic lens (ARIS) forms
// it and as the legacy plugins do. A fan of 180 degrees or more has no single array axis: planar.
enum class BeamGeometry : std::uint8_t { line_array, planar };
// Where the receive beams are focused (docs/pipeline.md, "Focus"). dynamic: at every range (a beamformer
// that focuses as the echo comes in, the far-field pattern everywhere); fixed: at focus_range (an acoustic
// lens, ARIS/DIDSON: sharp there, blurred nearer and further); none: at infinity (an unfocused array, blurred
// inside its far-field distance L^2 / lambda).
enum class BeamFocus : std::uint8_t { dynamic, fixed, none };
// Speckle on the intensity (host stage 5): rayleigh (Exp(1) intensity), gamma (Gamma(L, 1/L) with L =
// speckle_looks), gaussian (the legacy |N(1, sigma)|).
enum class SpeckleModel : std::uint8_t { rayleigh, gamma, gaussian };
// How speckle and ambient noise vary from beam to beam (docs/pipeline.md §5, "Grain"). pattern: as the
// receive beams correlate them (neighbouring beams overlap and hear the same scatterers and the same
// element noise: grains about a beamwidth wide; Rayleigh speckle, ambient noise, and gamma speckle of a whole
// number of looks up to 16; gamma speckle of other looks and the gaussian model stay per cell); none: every cell drawn
// on its own, as earlier builds drew them (grains one beam wide however finely the beams sample the fan).
enum class BeamCorrelation : std::uint8_t { pattern, none };
// How a pixel's echo is spread over range bins: the nearest bin, split between the two nearest, or over
// the pixel's own range extent, at least one bin (README "Accuracy and what it costs").
enum class RangeKernel : std::uint8_t { nearest, tent, footprint };
// geometric: the face normal of the triangle that won each pixel, recorded by the depth pass.
enum class NormalMethod : std::uint8_t { sobel3, sobel5, geometric };
// The palette of the fan and polar images the CLI writes (Frame::display is the value before it).
enum class Colormap : std::uint8_t { gray, viridis, sonar, jet };
// Arithmetic of the CPU backend's stages (the Vulkan backend is always f32).
enum class Precision : std::uint8_t { f32, f64 };
// The CPU backend's vector loops (AVX2, and expf four at a time): automatic where this CPU runs them, off:
// the portable one-at-a-time loops everywhere. Both give the same bytes (tested); off is for that test and
// for tracing a suspected difference on a new CPU.
enum class CpuVectorLoops : std::uint8_t { automatic, off };
// Storage of the per-pixel echo buffer (energy, slant range) between the echo and profile passes.
enum class IntermediatePrecision : std::uint8_t { fp32, fp16 };
// What the renderer reproduces: the physical model (README "The model"), or one of the two legacy Gazebo plugins
// step by step (docs/legacy.md); legacy modes still run the depth pass and the physical chain.
enum class SonarMode : std::uint8_t { physical, uuv_legacy, gtri_legacy };

// The noise terms of the sonar equation, resolved (SonarConfig::noise_terms).
struct NoiseTerms {
    double noise_level_db = 0;       // NL, dB re 1 uPa, in the receive band
    double band_hz = 0;              // the receive band B it is summed over (centred on the frequency)
    double directivity_index_db = 0; // DI of the broadside beam (a line array's steered beams: less)
    // NL - DI: the broadside beam's noise floor, dB re 1 uPa.
    double floor_db() const { return noise_level_db - directivity_index_db; }
};

// Every parameter of one sonar; the defaults are the `default` preset's. A plain value, copied by
// whatever takes it (Renderer::create validates its copy). Its member functions are pure.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct SonarConfig {
    std::string name = "default";
    std::string description;
    std::string source;                   // where the device figures come from (presets cite it)
    SonarMode mode = SonarMode::physical; // JSON key `mode`: "physical" | "uuv-legacy" | "gtri-legacy"

    // Geometry (docs/pipeline.md, "Frames and grids"). Azimuth is positive to port; beam 0 is the port-most beam.
    double frequency_hz = 750e3;
    double hfov_deg = 130.0;
    double vfov_deg = 20.0;                // two-way -3 dB vertical beamwidth
    double horizontal_beamwidth_deg = 1.0; // two-way -3 dB receive beamwidth of one beam
    std::uint32_t beams = 512;
    BeamSpacing beam_spacing = BeamSpacing::equiangular;
    BeamGeometry beam_geometry = BeamGeometry::line_array; // the default sonar (an Oculus) is a line array
    std::vector<double> beam_angles_deg; // explicit table (port first); overrides beams/spacing if non-empty
    std::uint32_t bins = 512;
    double range_min_m = 0.5;
    double range_max_m = 40.0;
    double sound_speed_mps = 1500.0;
    double bandwidth_hz = 0.0; // > 0: the range bins follow the resolution c / 2B instead of `bins`

    // Sonar equation (README "The model"). Levels in dB re 1 uPa (at 1 m for SL).
    double source_level_db = 210.0;
    double noise_level_db = -1.0;          // < 0: "auto", the sea's noise spectrum over the receive band
    double directivity_index_db = -1.0;    // < 0: "auto", from the receive patterns (broadside beam)
    double wind_speed_mps = 5.0;           // for the auto noise level (Wenz/Coates wind term)
    double shipping_activity = 0.5;        // 0..1, for the auto noise level (the shipping term)
    double default_backscatter_db = -30.0; // materials whose extras say nothing
    double absorption_db_per_m = -1.0;     // < 0: Francois-Garrison from the water below
    double temperature_c = 10.0;
    double salinity_ppt = 35.0;
    double water_depth_m = 10.0;
    double ph = 8.0;

    BeamPattern vertical_pattern = BeamPattern::sinc;
    BeamPattern horizontal_pattern = BeamPattern::sinc;
    BeamFocus beam_focus = BeamFocus::dynamic; // the horizontal pattern's focus (sinc and hann patterns)
    double focus_range_m = 10.0;               // beam_focus fixed: the range the beams are focused at
    double element_width = 0.0;            // a line array's element width along it, in wavelengths (0: point elements)
    double vertical_sidelobe_db = -30.0;   // chebyshev only: the equal side-lobe level, dB re the main lobe
    double horizontal_sidelobe_db = -30.0; // chebyshev only: likewise for the horizontal pattern

    // Noise (host stage 5). Noise uses a counter-based RNG keyed by (seed, frame, beam, bin).
    SpeckleModel speckle = SpeckleModel::rayleigh;
    double speckle_looks = 1.0;                                  // L for the gamma model
    double speckle_gaussian_sigma = 0.1;                         // for the legacy gaussian model: |N(1, sigma)|
    BeamCorrelation beam_correlation = BeamCorrelation::pattern; // speckle and noise grain across beams
    double tvg_db_per_decade = 20.0;                             // TVG = k log10 r + 2 alpha r

    // Display (host stage 6).
    double db_min = 60.0;  // dB re 1 uPa mapped to 0
    double db_max = 140.0; // mapped to 1
    Colormap colormap = Colormap::sonar;
    std::uint32_t fan_width_px = 1024;

    // Accuracy knobs (README "Accuracy and what it costs").
    double pixels_per_beam = 2.0;     // horizontal oversampling (pixel columns per beam spacing)
    std::uint32_t rows_per_vfov = 64; // pixel rows per vertical beamwidth
    double vertical_coverage = 2.0;   // depth pass covers at least this many vertical beamwidths
    double max_slice_deg = 60.0;      // widest frustum slice
    NormalMethod normal_method = NormalMethod::sobel3;
    RangeKernel range_kernel = RangeKernel::footprint;
    double sidelobe_kernel_beamwidths = 3.0; // side-lobe kernel reaches +- this many beamwidths
    // Far side lobes: beyond that reach the pattern is carried on a coarse grid whose cells are this
    // fraction of the reach wide (0: none, the kernel stops at the reach).
    double far_sidelobe_cell = 0.5;
    // Vertical side lobes (effects.vertical_sidelobes): the tier views' pixels at most this many times a
    // slice's in angle; the fewest views per band that hold it (up to 8), and the fewest columns (at most a
    // slice's) that hold it with those views.
    double tier_pixel_ratio = 4.0;
    IntermediatePrecision intermediates = IntermediatePrecision::fp32; // echo buffer storage
    Precision cpu_precision = Precision::f32;
    CpuVectorLoops cpu_vector_loops = CpuVectorLoops::automatic;

    EffectsConfig effects;

    // How the CLI loads the scene (SceneLoadOptions): the folder every file named inside it (external
    // buffers) must lie in, empty: the scene file's own folder (--asset-root overrides it); and a
    // uniform scale for a model exported in other units (0.001 for millimetres).
    std::string scene_asset_root;
    double scene_scale = 1.0;

    // Checks every key against its physical range and the rules that tie keys together. Returns
    // success, or ErrorCode::invalid_argument whose message names the first problem (key and value,
    // e.g. "hfov = 400: must be in (0, 360] deg"). Pure: no allocation beyond the message.
    [[nodiscard]] Result<void> validate() const;

    // Number of range bins: `bins`, or with bandwidth_hz > 0 the window (range_max - range_min) over the
    // range resolution c / 2B, rounded to the nearest integer and at least 1 (the bins then tile the
    // window exactly, within half a bin of c / 2B each). Meaningful for a config that validates.
    std::uint32_t range_bins() const;

    // The sonar equation's noise terms as the renderer uses them, "auto" resolved (README "The model"):
    // the ambient noise level in the receive band and the broadside beam's directivity index. Meaningful
    // for a config that validates.
    NoiseTerms noise_terms() const;
};

// Loading: presets are embedded in the library; files are JSON. Errors are one line naming file, key
// and value. Every function below returns a new value and changes none of its arguments; none keeps
// state between calls, so all may be called from any thread at once.

// The embedded preset `name` (assets/presets/NAME.json on top of the defaults), validated. Fails with
// ErrorCode::invalid_argument listing the valid names for an unknown one.
[[nodiscard]] Result<SonarConfig> load_preset(const std::string& name);
// The embedded presets' names, sorted.
[[nodiscard]] std::vector<std::string> preset_names();
// `base` with a JSON object's keys (text; // comments allowed) applied on top; `origin` names the
// source in error messages. Fails with ErrorCode::parse for malformed JSON or a non-object, and
// ErrorCode::invalid_argument for an unknown key or a bad value. Checks each key, not the whole config
// (validate() does, as Renderer::create).
[[nodiscard]] Result<SonarConfig> apply_config_json(const SonarConfig& base, const std::string& json_text,
                                                    const std::string& origin);
// apply_config_json on a file's text; ErrorCode::io if it cannot be read.
[[nodiscard]] Result<SonarConfig> apply_config_file(const SonarConfig& base, const std::string& path);
// `base` with one `key=value` override applied (dotted keys, e.g. effects.speckle=off). Fails with
// ErrorCode::invalid_argument for text that is not key=value, an unknown key, a bad value or text
// that is not UTF-8.
[[nodiscard]] Result<SonarConfig> apply_config_override(const SonarConfig& base, const std::string& key_equals_value);
// `base` with an accuracy preset fast | balanced (the defaults) | accurate applied: sets the accuracy.*
// keys (README, "Accuracy and what it costs"). ErrorCode::invalid_argument for another name.
[[nodiscard]] Result<SonarConfig> apply_quality(const SonarConfig& base, const std::string& name);
// "fast", "balanced", "accurate".
[[nodiscard]] std::vector<std::string> quality_names();
// The `key=value` overrides a quality stands for (empty for an unknown name).
[[nodiscard]] std::vector<std::string> quality_settings(const std::string& name);
// The fully resolved config as JSON text, every key (for meta.json and `vksonar presets --show`);
// apply_config_json of it gives the config back, except a text key holding bytes that are not UTF-8
// (e.g. a Latin-1 folder name in scene.asset_root): those bytes are written as U+FFFD. Never throws.
[[nodiscard]] std::string config_to_json(const SonarConfig& config);

} // namespace vksonar
