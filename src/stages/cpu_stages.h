// CPU reference of every GPU stage, with the same math (shaders/sonar_math.h) and the same data
// layouts as the shaders. Real is the arithmetic precision (float or double); storage is float so
// that any stage can take the GPU's output of the previous stage as input.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/plan.h"
#include "core/sonar_math.hpp"
#include "core/subpixel.h"
#include "scene/scene_data.h"
#include "sonar_shared.h"
#include "stages/stage_backend.h"

namespace vksonar::host {
class Workers;
}

namespace vksonar::cpu {

// Stage 1: rasterizes every draw into every slice with Vulkan's rules (top-left fill convention,
// pixel-centre sampling, reversed-Z, depth test GREATER, clip 0 <= z <= w).
// depth: rows * columns (cleared to 0); material: rows * columns (cleared to kNoMaterial);
// face_normal: null, or rows * columns * 4 (cleared to 0) receiving the unit plane normal of the
// winning triangle in clip-linear coordinates (x_clip, y_clip, w_clip), as the GPU's attachment.
// clusters: null (every draw's whole mesh), or the scene as build_depth_clusters's runs with
// cull_depth_clusters's flags: the runs flagged 0 in a slice are skipped there, which changes nothing
// but the time (each of their triangles would be rejected).
struct DepthClusters {
    const std::vector<DepthCluster>& runs;
    const std::vector<std::uint8_t>& drawn; // slices * runs
};
// region: only the rows [row_begin, row_end) of views [view_begin, view_end) are cleared and written,
// each pixel by the same triangles in the same order as a pass over the whole image, so regions run on
// different threads give the same bytes (each region transforms and sets up its views' triangles
// again: a few bands per view, not many). simd: the pixels four at a time where the CPU has AVX2 and
// cpu.vector_loops is not off (false: one at a time; the same bytes, tested). vertex_cache: a run's
// vertices transformed and projected once each where its indices span few enough (false: once per
// corner of every triangle; the same bytes, tested). clear = false: the caller has the region's depth at
// 0 already (nothing drawn) and does not read its material where the depth is 0, so neither is cleared
// (the labels' objects drawn alone, one after another into one image). drawn: where not null, widened to
// hold the pixel box of every triangle that reached the rasterizer, so every pixel the pass wrote lies
// inside it (columns and rows of the whole image; x0 >= x1 while nothing was drawn).
struct PixelBox {
    std::int64_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
};
struct DepthRegion {
    std::uint32_t row_begin = 0, row_end = ~0u;
    std::uint32_t view_begin = 0, view_end = ~0u;
    bool simd = true;
    bool vertex_cache = true;
    bool clear = true;
    PixelBox* drawn = nullptr;
};
void depth_pass(const Plan& plan, const SceneData& scene, const std::vector<shared::DepthPush>& draws, float* depth,
                std::uint32_t* material, float* face_normal = nullptr, const DepthClusters* clusters = nullptr,
                const DepthRegion& region = {});

// Stage 2: normals4 = rows * columns * 4 (nx, ny, nz in the sonar frame, cos incidence).
template <class Real> void normals(const Plan& plan, const float* depth, float* normals4);
// The same with caller-owned scratch of normals_scratch_count(plan) values (the overload above allocates it).
template <class Real> void normals(const Plan& plan, const float* depth, float* normals4, Real* scratch);
std::size_t normals_scratch_count(const Plan& plan);
// Stage 2 with normal_method = geometric: face4 is depth_pass's face_normal output; each hit pixel's
// face normal is mapped to the sonar frame, turned to face the sonar, and given its cos incidence.
template <class Real> void geometric_normals(const Plan& plan, const float* depth, const float* face4, float* normals4);

// Stage 3: echo2 = rows * columns * 2 (energy, slant range). normals4 may be null when the
// incidence effect is off.
template <class Real>
void echo(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2);

// Stage 4: per-column range profiles (bins * columns), beam profiles (bins * beams) and the polar
// scan after the side-lobe convolution (bins * beams).
template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar);
// The same with caller-owned scratch of beamform_scratch_count(plan) values (the overload above allocates it):
// the accumulators (beamform_accumulator_count), then the resample weights (resample_weight_count).
template <class Real>
void beamform(const Plan& plan, const float* echo2, float* profiles, float* beam_profiles, float* polar, Real* scratch);
std::size_t beamform_scratch_count(const Plan& plan);
std::size_t beamform_accumulator_count(const Plan& plan); // bins x (profile_columns + padding)
// The accumulators of profile column c start at c * profile_column_stride: its bins, then 16 values of
// padding, so that neighbouring columns' bins do not fall into the same cache sets (512 bins of floats
// are 2 KiB) and the profile's four-lane adds past a column's last bin stay inside the column.
inline std::size_t profile_column_stride(const Plan& plan) {
    return plan.bins + 16u;
}
// The resample's weights, beam after beam, each beam's columns in increasing order, then (with far side
// lobes) each beam's and then each profile column's far side-lobe cells, shares and deposit weights (beams
// read the cells back, columns deposit into them), then (with the horizontal pattern and
// cpu.vector_loops) the near kernel's weights by groups of eight beams (a function of the plan alone:
// filled once).
std::size_t resample_weight_count(const Plan& plan);
template <class Real> void resample_weights(const Plan& plan, Real* weights);

// The same stages over a part of the image, for splitting a stage between threads: rows
// [row_begin, row_end) of normals and echo (the normals scratch is the part's own), pixel columns
// [column_begin, column_end) of the range profiles (acc: the beamform_accumulator_count accumulators of
// the whole stage, each part touching its columns only; profiles: null, or receives them as floats,
// bins x profile_columns), bins [bin_begin, bin_end) of the resample (from acc, with resample_weights)
// and side-lobe passes (after every column's profile is done). Each output value is
// computed by one part, in the same order as the whole-image functions above, so the result does not
// depend on how the image is split. view_drawn (optional, one byte per view): 0 where the depth pass
// drew nothing in that view this frame (its pixels are all empty: the loops only zero their outputs).
template <class Real>
void normals_rows(const Plan& plan, const float* depth, float* normals4, Real* scratch, std::uint32_t row_begin,
                  std::uint32_t row_end, const std::uint8_t* view_drawn = nullptr);
template <class Real>
void geometric_normals_rows(const Plan& plan, const float* depth, const float* face4, float* normals4,
                            std::uint32_t row_begin, std::uint32_t row_end);
// table: echo_table's, made once per plan.
template <class Real>
void echo_rows(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2,
               const Real* table, std::uint32_t row_begin, std::uint32_t row_end,
               const std::uint8_t* view_drawn = nullptr);
// The echo stage's factors of a pixel's place in the grid: u per slice column, then (solid angle,
// vertical power) per row and slice column (echo_table_count values).
std::size_t echo_table_count(const Plan& plan);
template <class Real> void echo_table(const Plan& plan, Real* table);
// The frame's sub-pixel returns (src/core/subpixel.h) and the depth and material images that may hide them.
struct SubpixelInput {
    const SubpixelReturns& returns;
    const float* depth;
    const std::uint32_t* material;
};
// line_array: which pixel columns of each row and view feed a block of cone columns [cone_begin,
// cone_end). They depend on the plan alone, so the CPU backend finds them once per block of its own
// (cone_span_count values a block: a [first, end) pair per row and view) instead of searching every row
// of every frame.
std::size_t cone_span_count(const Plan& plan);
void cone_column_spans(const Plan& plan, std::uint32_t cone_begin, std::uint32_t cone_end, std::uint32_t* spans);
// subpixel: null, or the returns each column adds after its pixels (as profile.comp does). cone_spans:
// null, or cone_column_spans of exactly [column_begin, column_end).
template <class Real>
void beamform_profiles(const Plan& plan, const float* echo2, float* profiles, Real* acc, std::uint32_t column_begin,
                       std::uint32_t column_end, const SubpixelInput* subpixel = nullptr,
                       const std::uint8_t* view_drawn = nullptr, const std::uint32_t* cone_spans = nullptr);
template <class Real>
void beamform_beams(const Plan& plan, const Real* acc, const Real* resample_w, float* beam_profiles, float* polar,
                    std::uint32_t bin_begin, std::uint32_t bin_end);

// The range spreads and shares of the hit pixels of row `row`, columns [column_begin, column_end) of the
// view whose columns are [view_first, view_end), as the float profile loop makes them (the same values:
// the same code): fn(context, column, spread, spread_bins, shares) in increasing column order, shares[i]
// the share of bin spread.k_first + i, i < spread_bins. The labels stage spreads pixels with it.
using SpreadPixelFn = void (*)(void* context, std::uint32_t column, const Math<float>::RangeSpread& spread,
                               int spread_bins, const float* shares);
void spread_row_pixels(const Plan& plan, const float* echo2, std::uint32_t row, std::uint32_t column_begin,
                       std::uint32_t column_end, std::uint32_t view_first, std::uint32_t view_end, SpreadPixelFn fn,
                       void* context);

// workers: the Renderer's threads (borrowed; null or one thread: everything on the caller). The
// normals, echo and beamform stages are split between them; the depth pass runs on the caller.
// pass_timing (StageTiming::passes): the beamform stage's row in Frame::times is followed by its passes'
// ("bf:profile", "bf:beams"; host clocks).
std::unique_ptr<StageBackend> make_backend(const Plan& plan, const SceneData& scene, host::Workers* workers = nullptr,
                                           bool pass_timing = false);

} // namespace vksonar::cpu
