// Plan: everything derived once from (SonarConfig, Scene) before the first frame: sizes, beam and
// range tables, beam-pattern constants, absorption, resolved effects and the tables the beamform
// stage needs. Both backends read the same Plan, so they cannot disagree about geometry.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "sonar_shared.h"
#include "vksonar/config.h"
#include "vksonar/frame.h"
#include "vksonar/result.h"
#include "vksonar/scene.h"
#include "vksonar/validity.h"

namespace vksonar {

struct SceneData;

struct ResolvedEffects {
    bool incidence = true, vertical_pattern = true, vertical_sidelobes = false, horizontal_pattern = true,
         spreading = true, absorption = true, speckle = true, ambient_noise = true, tvg = false;
    std::vector<EffectState> states; // name, on, why (for meta.json)
    std::uint32_t shader_flags() const;
};

// A draw that can be a few pixels across somewhere inside the range gate, or a cluster of another draw
// that can be thinner than a pixel there (src/core/subpixel.h): what SubpixelReturns looks at each frame.
struct SubpixelCandidate {
    std::uint32_t cluster_begin = 0, cluster_end = 0; // build_depth_clusters's runs of it
    std::int32_t facing = 0; // +1: counter-clockwise faces out, -1: in, 0: no outside (both sides seen)
    bool thin = false;       // a thin cluster (else a whole draw)
    double centre[3] = {};   // world: the centre of its box, the radius about it that holds its vertices,
    double radius = 0;       // and how wide it is across its length (thin: the cluster's thickness)
    double middle_extent = 0;
};

// One view of the depth pass in double (SliceInfo holds the same, rounded to float): a camera basis in
// the sonar frame, its half extents and the cell of directions it is the one to see (sonar_shared.h).
struct ViewGeometry {
    double forward[3] = {1, 0, 0}, right[3] = {0, -1, 0}, down[3] = {0, 0, -1};
    double tan_half_h = 0, tan_half_v = 0;
    double sin_elevation_min = -2, sin_elevation_max = 2;
    bool wedge = false;                                    // a tier view: azimuths in [start, end)
    double wedge_start[2] = {1, 0}, wedge_end[2] = {1, 0}; // (cos, sin) of the wedge's edges
};

// The grain of speckle and ambient noise across beams (plan_grain.cpp; docs/pipeline.md §5, "Grain"):
// white complex noise on `cells` points `step` apart in the beams' separation variable (angle, or sine with
// Plan::line_array), and beam j's field the sum of the points within its reach, each weighted by the receive
// amplitude pattern at its offset (unit sum of squares per beam, so each cell's draw stays Exp(1)). The beams
// go in chunks [chunk[c], chunk[c + 1]) whose points fit the noise stage's scratch: chunk c's points are
// chunk_low[c] + i (unwrapped: on a circle, modulo cells) for i < chunk_points[c]. Its beams go in blocks of
// kGrainLanes (the last one padded), blocks [chunk_block[c], chunk_block[c + 1]): block b takes the chunk's
// points [block_points[2 b], [2 b + 1]) with kGrainLanes weights each from weight[block_weight[b]] on (0 for a
// beam the point does not reach, and for the padding), so the noise stage sums a block's beams side by side in
// registers, each over its points in increasing order. taps: the most points a beam takes (0: every cell is
// drawn on its own, and `why` says why). A default-constructed one is "no grain".
struct GrainTables {
    std::uint32_t cells = 0, taps = 0;
    double step = 0;
    std::vector<std::uint32_t> chunk, chunk_points, chunk_block;
    std::vector<std::int32_t> chunk_low;
    std::vector<std::uint32_t> block_points, block_weight;
    std::vector<float> weight;
    std::vector<float> phase; // cos and sin of 2 pi i / kGrainPhases, interleaved: a draw's phase
    std::string why;
};

struct Plan {
    SonarConfig config; // the validated config this plan was made from

    // Pixel grid of the depth pass: `views` frusta side by side: first the `slices` of the main band,
    // port to starboard, slice_columns wide each (level cameras rotated about z, seeing elevations
    // within the elevation gate), then the tier views, tier_columns wide each, that see the elevations
    // beyond it where the vertical side lobes are simulated (docs/pipeline.md, "Vertical side lobes").
    // A tier view has its own width: its pixels are as coarse as accuracy.tier_pixel_ratio allows,
    // not as many as a slice's (view_first_column, view_columns, view_of_column below).
    std::uint32_t slices = 1;
    std::uint32_t views = 1;
    std::uint32_t slice_columns = 0; // pixel columns per slice
    std::uint32_t tier_columns = 0;  // pixel columns per tier view (0: none)
    std::uint32_t columns = 0;       // slices * slice_columns + (views - slices) * tier_columns
    std::uint32_t rows = 0;
    double slice_width_rad = 0; // horizontal angle covered by one slice
    double vertical_coverage_rad = 0;
    // |sin elevation| of the widest elevation every azimuth sees (physical mode, 2 otherwise: no gate;
    // the vertical pattern applies it, sonar_kernels.h). A slice's rows reach further at its centre than at its edges,
    // and rays beyond this get no vertical power: otherwise the elevations seen, and so the first seabed returns of the
    // side lobes there, would follow where the slice seams fall (+5 to +28 dB at the leading edge on a tilted seabed
    // with 60-degree slices).
    double elevation_gate_sin = 2.0;
    double tan_half_h = 0, tan_half_v = 0;
    double near_m = 0, far_m = 0;    // depth-pass clip planes (near < range_min so slant ranges are not clipped)
    double depth_a = 0, depth_b = 0; // view z = depth_a / (d - depth_b); d = 1 at near, 0 at far
    std::vector<ViewGeometry> view_geometry;   // views
    std::vector<shared::SliceInfo> slice_info; // views: view_geometry in float, as the shaders read it
    std::string vertical_sidelobes_why;        // the tier views: how many, or why there are none

    // Beam geometry (docs/pipeline.md, "Beam geometry"): line_array as resolved from the config (planar
    // for the legacy modes and for fans of 180 degrees or more, which have no single array axis), and why.
    bool line_array = false;
    std::string beam_geometry_why;
    // The columns of the range profiles, which the beamform tables map onto beams: the pixel columns
    // (planar), or the cone columns (line_array), uniform in the steering angle over the fan,
    // cone_step_rad apart. With line_array the pixel grid reaches past the fan's azimuths: a cone at
    // the fan's edge leans out to larger azimuths as its elevation grows.
    std::uint32_t profile_columns = 0;
    double cone_step_rad = 0;
    // line_array: each pixel's cone coordinate (rows * columns; sonar_kernels.h cone_coord, in float
    // from the same float inputs as the GPU's), for the CPU backend's scatter onto cone columns.
    std::vector<float> pixel_cone_coord;
    // line_array with tier views: how far a tier pixel's cone extent (core/tier_extent.h) reaches from
    // its cone coordinate, with a margin: the profile's searches widen a cone column's pixels by it.
    float tier_cone_reach = 0;

    // Beams and range bins.
    std::uint32_t beams = 0, bins = 0;
    std::vector<double> beam_angle_rad; // beams, strictly decreasing (port first)
    double bin_width_m = 0;
    // The echo stage's range gate: the window widened by the range kernel's widest half width
    // (gate_margin_m), so that a footprint straddling range_min or range_max puts its inside part into
    // the edge bin. The depth pass's clip planes enclose the gate.
    double gate_margin_m = 0, gate_min_m = 0, gate_max_m = 0;
    std::vector<double> bin_range_m; // bin centres

    // Beam patterns.
    double vpattern_k = 0, vpattern_halfwidth_rad = 0, vpattern_chebyshev_a = 0;
    double hpattern_k = 0, hpattern_halfwidth_rad = 0, hpattern_chebyshev_a = 0;
    // A line array's element pattern sinc^2(element_k u) on every echo (SonarConfig::element_width; u the
    // direction's sine along the array): pi element_width, 0 without it (planar beams, the legacy modes).
    double element_k = 0;
    double alpha_db_per_m = 0; // one-way absorption actually used (0 if the effect is off)
    // The noise floor (noise_floor.cpp): NL and the broadside DI, each beam's floor NL - DI_j in dB (a
    // line array's steered beams hear more of the sea; plus the element pattern's 10 log10 sinc^2 at the
    // beam with element_width), and 10^(floor / 10) as the noise stage adds it
    // (0 with ambient_noise off).
    NoiseTerms noise;
    std::vector<double> beam_floor_db;
    std::vector<float> beam_noise;
    // The grain of speckle and ambient noise across beams (GrainTables above; plan_grain.cpp).
    GrainTables grain;

    // Beamform tables over the profile columns. Column c (azimuth, or steering angle with line_array,
    // column_azimuth_rad[c]) gives weight column_weight[c] to beam column_beam[c] and
    // 1 - column_weight[c] to column_beam[c] + 1 (tent on the beam table; columns outside the beam fan
    // give their energy only to the nearest edge beam... see plan_beams.cpp).
    std::vector<double> column_azimuth_rad; // profile_columns
    std::vector<std::uint32_t> column_beam; // profile_columns
    std::vector<float> column_weight;       // profile_columns
    // Beam j gathers from columns [beam_column_begin[j], beam_column_end[j]).
    std::vector<std::uint32_t> beam_column_begin, beam_column_end;
    // The horizontal pattern's reach in beams: the near kernel reaches K = (sidelobe_taps - 1) / 2 beams
    // either side (the pattern out to the reach R; the far side lobes beyond, below).
    std::uint32_t sidelobe_taps = 1; // 2K + 1
    // The near kernel over the profile columns (docs/pipeline.md §4, "Side lobes"): beam j hears column
    // c = near_column_begin[j] + t, t < near_column_count[j], with weight near_column_weight[j *
    // near_column_taps + t], the horizontal pattern at the separation of the column's direction and the
    // beam's (in angle, planar; in sine, line_array), less what the far grid gives the same column there. Each column
    // is weighted at its own direction, so the main lobe and the nulls are the pattern's wherever a target falls
    // between beams. begin is unwrapped: with circular, columns wrap modulo profile_columns. Built only with the
    // horizontal pattern on; with no kernel (K = 0, the effect forced on) it is the tent.
    // With beam_focus fixed or none the pattern depends on range (docs/pipeline.md, "Focus"): the weights
    // come in near_bands bands, bin k reading band near_band_of_bin[k] at near_column_weight[(band * beams
    // + j) * near_column_taps + t]; the columns [begin, begin + count) are every band's.
    std::uint32_t near_column_taps = 0;           // the widest beam's column count
    std::vector<float> near_column_weight;        // near_bands * beams * near_column_taps, 0 past a beam's count
    std::vector<std::int32_t> near_column_begin;  // beams
    std::vector<std::uint32_t> near_column_count; // beams
    // The focus bands (plan_focus.cpp): band b's pattern is the aperture's defocused by the quadratic phase
    // near_band_phase[b] at its ends (radians; a line array's beam steered to theta by cos^2 theta of it).
    // One band of phase 0 (the far-field pattern) with beam_focus dynamic, or with no near kernel.
    std::uint32_t near_bands = 1;
    std::vector<std::uint32_t> near_band_of_bin; // bins
    std::vector<double> near_band_phase;         // near_bands
    // Far side lobes (docs/pipeline.md, "Side lobes"): the pattern beyond the kernel's reach R, on a
    // coarse grid of far_cells cells uniform in the separation variable (0: none). Each profile column
    // puts its energy into its two nearest cells (far_column_cell, 8 per column: first cell, second
    // cell, share of the second, 0, then the column's phase cos 2k u, sin 2k u, 0, 0; a column that feeds
    // no beam has both cells = far_cells, none), the cells are convolved with far_weight, and each beam
    // reads its two cells back with its own shares and phase (far_beam_cell, 8 per beam, the same layout).
    // far_channels is 3 for a
    // line array's sinc^2 (the energy, and the energy times cos and sin of the phase: the pattern's
    // crests and nulls are exact, only its smooth envelope goes on the grid), else 1 (the lobes' mean).
    // far_weight[far_cells - 1 + a - b] is cell b's weight into cell a, fitted so that a column and a
    // beam past the reach read the envelope (or the pattern's mean over a cell) through their cells'
    // shares; within the reach the kernel's taps carry the pattern less what the grid gives.
    std::uint32_t far_cells = 0;
    std::uint32_t far_channels = 1;
    std::vector<float> far_beam_cell;            // beams * 8
    std::vector<float> far_column_cell;          // profile_columns * 8
    std::vector<std::uint32_t> far_cell_columns; // far_cells * 2: the columns [first, end) that feed cell c
    std::vector<float> far_weight;               // 2 * far_cells - 1
    // hfov = 360 deg: the fan is a full circle, beam beams-1 and beam 0 are neighbours across the
    // +-180 deg seam. Then column_beam[c] + 1 wraps modulo beams and a beam's near columns modulo profile_columns,
    // and seam columns split their energy between beam beams-1 and beam 0 (docs/pipeline.md §4).
    bool circular = false;

    // Acoustic materials as uploaded (index = material id written by the depth pass).
    std::vector<shared::MaterialGpu> materials;
    bool rough_materials = false; // a material has kScatterRough: the echo kernel carries the facet term

    ResolvedEffects effects;
    // Each model this plan uses, checked against its validity domain (validity.h; meta.json "validity").
    std::vector<ModelValidity> validity;
    // The depth pass records each pixel's face normal (normal_method = geometric with the incidence
    // effect on); otherwise no attachment is created, recorded or copied.
    bool face_normals = false;
    // Ground-truth labels were asked for (SaveFlags::labels): the depth pass writes each draw's instance
    // id into the high 16 bits of the material image (compose_depth_draws), for the labels stage.
    bool labels = false;
    // The most sub-pixel returns a frame can list (src/core/subpixel.h; 0: the scene has no cluster that
    // could be smaller or thinner than a pixel inside the range gate, and the profile step adds none).
    std::uint32_t subpixel_capacity = 0;
    std::vector<SubpixelCandidate> subpixel_candidates; // in draw and cluster order
    // With subpixel_capacity > 0: the material (appended to `materials`, no backscatter) that objects a few
    // pixels across are drawn with, so that their depth hides what lies behind them while their echo comes
    // from their returns alone.
    std::uint32_t subpixel_silent_material = 0;
    shared::SonarParams params{}; // the uniform block of the compute stages
};

// The first pixel column of a view, its width, and the view of pixel column c (the slices' widths, then
// the tier views'; sonar_math.h's first_column_of_view, columns_of_view and view_of_pixel_column are the
// shaders' twins, the last without an integer divide).
inline std::uint32_t view_first_column(const Plan& p, std::uint32_t view) {
    return view < p.slices ? view * p.slice_columns : p.slices * p.slice_columns + (view - p.slices) * p.tier_columns;
}
inline std::uint32_t view_columns(const Plan& p, std::uint32_t view) {
    return view < p.slices ? p.slice_columns : p.tier_columns;
}
inline std::uint32_t view_of_column(const Plan& p, std::uint32_t c) {
    const std::uint32_t main = p.slices * p.slice_columns;
    return c < main ? c / p.slice_columns : p.slices + (c - main) / p.tier_columns;
}

// A pixel grid given from outside instead of vksonar's own (a host engine's depth image, host_plan.h):
// one slice of columns x rows pixels whose centre rays span +-tan_half_h, +-tan_half_v (focal-normalized).
struct HostPixelGrid {
    std::uint32_t columns = 0, rows = 0;
    double tan_half_h = 0, tan_half_v = 0;
};

// Validates the config and derives the plan, in named steps (plan.cpp, plan_grid.cpp, plan_beams.cpp): beams and bins,
// the pixel grid (vksonar's own, or host_grid), the range window and clip planes, patterns, materials, effects, the
// beamform tables, and the GPU parameters last. Errors name the config field and value.
[[nodiscard]] Result<Plan> make_plan(const SonarConfig& config, const SceneData& scene,
                                     const HostPixelGrid* host_grid = nullptr);

// Francois & Garrison (1982) absorption in dB/m for frequency (Hz), temperature (C), salinity (ppt),
// depth (m), pH and sound speed (m/s).
double francois_garrison_db_per_m(double frequency_hz, double temperature_c, double salinity_ppt, double depth_m,
                                  double ph, double sound_speed_mps);

// The profile columns that beams [first_beam, end_beam) hear through the near kernel, together: the first
// (unwrapped, as Plan::near_column_begin) and how many (0: none). A run of beams walks them once (the
// GPU's runs, the CPU's groups).
struct NearColumnSpan {
    std::int64_t first = 0;
    std::uint32_t count = 0;
};
inline NearColumnSpan near_column_span(const Plan& p, std::uint32_t first_beam, std::uint32_t end_beam) {
    std::int64_t lo = std::numeric_limits<std::int64_t>::max(), hi = std::numeric_limits<std::int64_t>::min();
    for (std::uint32_t j = first_beam; j < end_beam && j < p.near_column_count.size(); ++j) {
        if (p.near_column_count[j] == 0) continue;
        lo = std::min<std::int64_t>(lo, p.near_column_begin[j]);
        hi = std::max<std::int64_t>(hi, std::int64_t(p.near_column_begin[j]) + p.near_column_count[j]);
    }
    return lo < hi ? NearColumnSpan{lo, static_cast<std::uint32_t>(hi - lo)} : NearColumnSpan{};
}

// The beam centres in radians, port first (strictly decreasing): the config's table, or `beams` centres of
// equal sectors in angle or in sine. Fails for a table that is not strictly decreasing.
Result<std::vector<double>> beam_table(const SonarConfig& c);
// Whether the config's beams are a line array's cones (else planar), and in `why` (if not null) the reason.
bool resolves_to_line_array(const SonarConfig& c, std::string* why);
// The side-lobe kernel's reach `reach` (an angle from the beam's axis) in the unit the beams are
// separated in: the angle (planar), or its sine (line_array: the pattern is a function of
// sin(theta') - sin(theta)). plan_steps::sidelobe_reach for a plan.
double sidelobe_reach_units(bool line_array, double reach);
// model_validity (validity.h) with the plan's own near kernel for beam_sampling: whether it weighs each
// column by the pattern (the horizontal pattern on and K >= 1) and how far it reaches (sidelobe_reach);
// model_validity(config) judges both from the config alone, before the main-lobe-only rule.
std::vector<ModelValidity> model_validity(const SonarConfig& c, const std::vector<AcousticMaterial>& materials,
                                          bool near_kernel, double near_reach_units);
// The noise terms (noise_floor.cpp; SonarConfig::noise_terms resolves "auto" with them): the sea's ambient
// noise spectrum level at frequency_hz (dB re 1 uPa^2/Hz; Coates' fits to the Wenz curves: turbulence,
// shipping, wind and thermal noise); that spectrum summed over frequency_hz +- band_hz / 2 (dB re 1 uPa);
// the receive band (bandwidth, else the range bins' c / 2 dr); and the directivity index of the broadside
// beam from the config's horizontal and vertical patterns (dB).
double ambient_noise_spectrum_db(double frequency_hz, double wind_speed_mps, double shipping_activity);
double band_noise_level_db(double frequency_hz, double band_hz, double wind_speed_mps, double shipping_activity);
double receive_band_hz(const SonarConfig& c);
double beam_directivity_index_db(const SonarConfig& c, bool line_array);
// p.noise, p.beam_floor_db and p.beam_noise from p.config, p.effects, p.line_array and the beam table:
// make_plan's step after the effects; again after changing any of them (tests build plans by hand).
void resolve_noise_floor(Plan& p);
// The grain tables (Plan::grain) from p.config, p.line_array, the horizontal pattern's constants and the
// beam table: make_plan's step after the noise floor.
void plan_grain(Plan& p);
// Plan::grain.phase's phases; the noise stage's scratch per chunk of beams: at most kGrainChunkBeams beams
// and kGrainChunkPoints grid points (a beam's own taps always fit).
// kGrainLanes: the beams of a block, summed side by side.
constexpr std::uint32_t kGrainPhases = 4096, kGrainChunkBeams = 256, kGrainChunkPoints = 1024, kGrainLanes = 16;

// Pattern constant k for a power pattern that is 0.5 at +-beamwidth/2 (see pattern_power in sonar_math.h).
double pattern_constant(BeamPattern shape, double beamwidth_rad, double chebyshev_a = 0.0);
// A = acosh(R) of a chebyshev pattern whose side lobes are all at sidelobe_db (power, dB re the main
// lobe): R = 10^(-sidelobe_db / 20) is the amplitude ratio of main lobe to side lobes.
double chebyshev_a(double sidelobe_db);
// The horizontal power pattern's first null (0 if it has none within reach_rad, e.g. gaussian or box)
// and its strongest side lobe beyond it in dB re the axis (-inf if none), found by sampling.
struct HorizontalLobes {
    double first_null_rad = 0.0;
    double peak_sidelobe_db = 0.0;
};
HorizontalLobes horizontal_lobes(std::uint32_t shape, double k, double half_width_rad, double chebyshev_a,
                                 double reach_rad);
// Largest scattering factor f(theta) of a material over all incidences (1 unless model is rough):
// the plan scales fp16 echo storage by the brightest pixel it can produce.
double scatter_factor_peak(const shared::MaterialGpu& material);
// Beamform tables from p.column_azimuth_rad and p.beam_angle_rad (tent between the two nearest beam
// centres, edge columns to the edge beams, across the seam on a full circle): column_beam,
// column_weight, beam_column_begin/end. Columns with |azimuth| > exclude_beyond_rad feed no beam.
void assign_columns_to_beams(Plan& p, double exclude_beyond_rad = std::numeric_limits<double>::infinity());

// The per-draw, per-slice clip_from_local matrices of the depth pass, composed in double relative
// to the sonar and rounded to float once. out is resized to slices * draws (slice-major);
// no allocation once it has that size.
// The sonar frame from the world (column-major 4 x 4, double): the inverse of the pose's
// [Rz(yaw) Ry(pitch) Rx(roll) | x y z]. Shared by the depth pass and the labels' flow.
std::array<double, 16> sonar_from_world(const Pose& pose);

void compose_depth_draws(const Plan& plan, const SceneData& scene, const Pose& pose,
                         std::vector<shared::DepthPush>& out);
// The depth pass draws each draw's triangles as runs ("clusters") of at most kClusterTriangles
// consecutive triangles, each with the mesh-local bounding box of its vertices, so that a slice can
// skip the runs it cannot reach: a large seabed mesh spans every slice, but each of its runs only a
// few. Draw order and triangle order are kept, so drawing every cluster draws exactly the scene.
constexpr std::uint32_t kClusterTriangles = 512;
struct DepthCluster {
    std::uint32_t draw = 0;         // index into SceneData::draws: its DepthPush
    std::uint32_t first_index = 0;  // into SceneData::indices
    std::uint32_t index_count = 0;  // a multiple of 3
    std::uint32_t first_vertex = 0; // the mesh's, added to every index
    std::uint32_t index_min = 0;    // the least and the greatest of its indices (the vertices it spans)
    std::uint32_t index_max = 0;
    float bounds_min[3] = {0.0f, 0.0f, 0.0f};
    float bounds_max[3] = {0.0f, 0.0f, 0.0f};
};
// Draws whose mesh or index range is out of bounds, and indices past the vertex data, get no cluster.
void build_depth_clusters(const SceneData& scene, std::vector<DepthCluster>& out);

// One indexed draw call of the depth pass in one view: a run of consecutive clusters drawn in the view,
// of one draw, each starting where the one before ends in the index buffer (for_each_depth_draw_call).
// The same triangles in the same order as one call per cluster, in fewer calls: a GPU's host records
// every call, and a terrain in spatial order (scene.cpp) is drawn in long runs of neighbouring clusters.
struct DepthDrawCall {
    std::uint32_t cluster = 0; // the run's first cluster (its draw's DepthPush)
    std::uint32_t first_index = 0;
    std::uint32_t index_count = 0;
    std::uint32_t first_vertex = 0;
};
// fn(const DepthDrawCall&) for each call of a view, in cluster order; drawn: the view's clusters.size()
// flags of cull_depth_clusters.
template <class Fn>
void for_each_depth_draw_call(const std::vector<DepthCluster>& clusters, const std::uint8_t* drawn, Fn&& fn) {
    const std::size_t count = clusters.size();
    for (std::size_t c = 0; c < count;) {
        if (!drawn[c]) {
            ++c;
            continue;
        }
        const DepthCluster& first = clusters[c];
        DepthDrawCall call{static_cast<std::uint32_t>(c), first.first_index, first.index_count, first.first_vertex};
        for (++c; c < count && drawn[c]; ++c) {
            const DepthCluster& next = clusters[c];
            if (next.draw != first.draw || next.first_vertex != first.first_vertex ||
                next.first_index != call.first_index + call.index_count)
                break;
            call.index_count += next.index_count;
        }
        fn(call);
    }
}

// Clip coordinates (x, y, z, w) of corner `corner` (bit 0: max x, bit 1: max y, bit 2: max z) of the
// cluster's bounding box through clip_from_local (column-major float, as DepthPush), summed in double,
// and for each the sum of its terms' magnitudes: the scale of the float rounding a GPU adds to it.
void cluster_corner_clip(const DepthCluster& cluster, const float* clip_from_local, int corner, double clip[4],
                         double magnitude[4]);

// drawn[s * clusters.size() + c] = 0 where cluster c cannot put a fragment in slice s: its bounding
// box, through the draw's composed (float) clip_from_local, lies wholly outside one plane of the clip
// volume -w <= x, y <= w, 0 <= z <= w (clearly outside: by more than the GPU's rounding of the
// transform). Then so does each of its triangles, which both rasterizers reject anyway, so the frame
// is the same bit for bit; what goes is the cost (lavapipe shades, clips and bins every vertex and
// triangle it is given, in every slice). pushes: compose_depth_draws's slices * draws table. drawn is
// resized to slices * clusters; no allocation once sized.
void cull_depth_clusters(const std::vector<DepthCluster>& clusters, std::size_t draws,
                         const std::vector<shared::DepthPush>& pushes, std::vector<std::uint8_t>& drawn);
// The same for slice `slice` alone, into drawn_row[0 .. clusters.size()) (threads may cull different
// slices at once).
void cull_depth_clusters_in_slice(const std::vector<DepthCluster>& clusters, std::size_t draws,
                                  const std::vector<shared::DepthPush>& pushes, std::size_t slice,
                                  std::uint8_t* drawn_row);

} // namespace vksonar
