// Shared between GLSL (compute/graphics shaders) and C++ (CPU reference and Vulkan host code).
// Everything that crosses the CPU/GPU boundary is declared here exactly once: buffer layouts,
// workgroup sizes, effect bits and sentinel values. The formulas live in sonar_math.h.
//
// Rules for this file: scalars only in structs that cross (no vec3: std140/std430 padding differs),
// every struct has a static_assert on its size on the C++ side.
#ifndef VKSONAR_SONAR_SHARED_H
#define VKSONAR_SONAR_SHARED_H

#ifdef __cplusplus
#include <cstdint>
namespace vksonar::shared {
using uint = std::uint32_t;
#define VKS_CONST constexpr
#else
#define VKS_CONST const
#endif

VKS_CONST uint kWorkgroupSize = 64u; // 1-D compute workgroups (per pixel, per column, per cell)
VKS_CONST uint kMaxSlices = 16u;     // hfov 360 deg at >= 22.5 deg per slice
// Views of the depth pass: the slices, then the vertical side lobes' tier views (Plan::views).
VKS_CONST uint kMaxViews = 40u;
VKS_CONST uint kMaxFarCells = 256u;       // far side lobes' grid (Plan::far_cells): far_sidelobe.comp's shared array
VKS_CONST uint kNoMaterial = 0xffffffffu; // material attachment clear value: no geometry hit
// The material attachment holds material_id | instance << kInstanceShift (the instance only when
// labels are asked for, else 0): the material is the low 16 bits.
VKS_CONST uint kMaterialIdMask = 0xffffu;
VKS_CONST uint kInstanceShift = 16u;
VKS_CONST float kPi = 3.14159265358979323846f;

// The compute stages' shader interface, declared once. Descriptor bindings of set 0: every shader
// names the ones it uses, the host builds the one set layout from the same names (src/vk/pipelines.h).
// The four small tables have a storage and a uniform binding on the same buffer (pipelines.h says why).
VKS_CONST uint kBindingParams = 0u; // uniform SonarParams (std140)
VKS_CONST uint kBindingDepth = 1u;
VKS_CONST uint kBindingMaterialId = 2u;
VKS_CONST uint kBindingNormals = 3u;
VKS_CONST uint kBindingEcho = 4u;
VKS_CONST uint kBindingProfiles = 5u;
VKS_CONST uint kBindingBeamProfiles = 6u;
VKS_CONST uint kBindingPolar = 7u;
VKS_CONST uint kBindingSliceInfo = 8u; // uniform SliceInfo[kMaxSlices] (std140)
VKS_CONST uint kBindingMaterials = 9u;
VKS_CONST uint kBindingColumnTable = 10u; // uvec2 per pixel column: (beam, weight bits), see resample.comp
VKS_CONST uint kBindingBeamTable = 11u;   // uvec2 per beam: (first column, end column)
VKS_CONST uint kBindingSidelobeWeight = 12u;
VKS_CONST uint kBindingConeCoord = 13u; // float per pixel: its cone coordinate (line_array; profile.comp)
// Far side lobes (Plan::far_cells): the table (beam cells, cell beam spans, weights; far_sidelobe.comp),
// the cells' energies and the convolved cells, vec4 over four range bins: [c * bins_padded / 4 + quad].
VKS_CONST uint kBindingFarTable = 14u;
VKS_CONST uint kBindingFarEnergy = 15u;
VKS_CONST uint kBindingFarCells = 16u;
VKS_CONST uint kBindingMaterialsUniform = 17u; // the uniform views: the last five bindings
VKS_CONST uint kBindingColumnTableUniform = 18u;
VKS_CONST uint kBindingBeamTableUniform = 19u;
VKS_CONST uint kBindingSidelobeWeightUniform = 20u;
VKS_CONST uint kBindingFarTableUniform = 21u;
// The frame's sub-pixel returns (src/core/subpixel.h): profile.comp adds them to its columns' profiles.
// After the uniform views, so that their numbers stay as they are.
VKS_CONST uint kBindingSubpixel = 22u;
// A frame's status word (uint), zeroed before the beamform stage and read back with the frame: a shader
// that finds its work cut short sets a bit (kStatus*).
VKS_CONST uint kBindingStatus = 23u;
VKS_CONST uint kBindingCount = 24u;
VKS_CONST uint kStatusLoopLimit = 1u; // an invocation's loops were ended early (lavapipe's loop limit)

// profile.comp's push constants: the rows one dispatch walks (src/vk/profile_bands.h), and the trip count
// of the loop it runs last to see whether the device let its loops run to the end (2, a push constant so
// that no compiler unrolls that loop).
struct ProfileRowBand {
    uint row_begin;
    uint row_end;
    uint loop_check;
    uint pad;
};
#ifdef __cplusplus
static_assert(sizeof(ProfileRowBand) == 16, "ProfileRowBand must match the std430 push constant block");
#endif

// Set 1 of import_depth.comp: the host engine's depth image.
VKS_CONST uint kBindingHostDepthImage = 0u;

// Specialization constant ids of the compute shaders, one per meaning (a shader declares the ones it
// has; the host's per-shader structs in src/vk/pipelines.h set them by these names).
VKS_CONST uint kSpecEffectFlags = 0u; // echo: the kEffect* bits
VKS_CONST uint kSpecPerInvocation =
    1u; // normals, echo: pixels per invocation; resample, sidelobe: beams; profile: cone columns
VKS_CONST uint kSpecNormalMethod = 2u;   // normals: kNormals*
VKS_CONST uint kSpecUniformTables = 3u;  // echo, resample, sidelobe: 1 = read the tables' uniform blocks
VKS_CONST uint kSpecTableVec4s0 = 4u;    // sizes of those blocks in vec4s: materials, columns, weights
VKS_CONST uint kSpecTableVec4s1 = 5u;    // resample: the beam table; sidelobe: the far table
VKS_CONST uint kSpecEchoHalf = 6u;       // echo, profile: SonarParams::echo_half
VKS_CONST uint kSpecRoughMaterials = 7u; // echo: 1 = a material has kScatterRough (the facet term)
VKS_CONST uint kSpecVerticalShape = 8u;  // echo: the vertical pattern's kPattern*
VKS_CONST uint kSpecRangeKernel = 9u;    // profile: kRangeKernel*
VKS_CONST uint kSpecBeamMajorOut = 10u;  // resample: 1 = beam-major vec4 output (the side-lobe pass follows)
VKS_CONST uint kSpecResampleWalk = 11u;  // resample: 1 = walk each run's columns once (src/vk/resample_walk.h)
VKS_CONST uint kSpecVec4Out = 12u;       // sidelobe: 1 = store polar as vec4s (beams % 4 == 0)
VKS_CONST uint kSpecLineArray = 13u;     // profile: 1 = gather pixels onto cone columns (SonarParams::line_array)
VKS_CONST uint kSpecFarSidelobes = 14u;  // sidelobe: 1 = add the far side lobes' cells (far_sidelobe.comp)
VKS_CONST uint kSpecFarPass = 15u;       // far_sidelobe: 0 = deposit beams into cells, 1 = convolve the cells,
                                         // 2 = convolve, a workgroup row per output cell (a GPU)
VKS_CONST uint kSpecSubpixel = 16u;      // profile: 1 = add the frame's sub-pixel returns (Plan::subpixel_capacity > 0)
VKS_CONST uint kSpecTierViews = 17u;     // normals, echo, profile: 1 = the grid has tier views (Plan::views > slices)
VKS_CONST uint kSpecBinLanes = 18u;      // profile: invocations sharing one column's bins (a power of 2)
VKS_CONST uint kSpecGatherRows = 19u;    // profile, line_array on a GPU: 1 = a block of rows' pixels at once
VKS_CONST uint kSpecRowCandidates = 20u; // profile: the most pixels one row gives one cone column (host-counted)
VKS_CONST uint kSpecSharedBins = 21u;    // profile: bins_padded, the shared accumulators' length
VKS_CONST uint kSpecNearBands = 22u;     // sidelobe: Plan::near_bands, the focus bands of the near kernel's weights

// Effect bits (SonarParams.effect_flags and the shaders' specialization constant 0).
VKS_CONST uint kEffectIncidence = 1u << 0;         // Lambert cos(theta) term; needs the normals pass
VKS_CONST uint kEffectVerticalPattern = 1u << 1;   // b_v(psi)^2
VKS_CONST uint kEffectHorizontalPattern = 1u << 2; // side-lobe convolution along beams
VKS_CONST uint kEffectSpreading = 1u << 3;         // r^-4 two-way spherical spreading
VKS_CONST uint kEffectAbsorption = 1u << 4;        // 10^(-2 alpha r / 10)
// speckle, ambient noise and TVG are host stages and never reach a shader.

// Beam pattern shapes (b_v, b_h). Power patterns, 1 on axis, 0.5 (-3 dB) at +-beamwidth/2.
VKS_CONST uint kPatternBox = 0u;      // 1 inside +-beamwidth/2, 0 outside (legacy; energy tests)
VKS_CONST uint kPatternSinc = 1u;     // uniform line array: sinc^2(k sin a)
VKS_CONST uint kPatternHann = 2u;     // Hann-tapered aperture: lower side lobes, wider main lobe
VKS_CONST uint kPatternGaussian = 3u; // exp(-k a^2): no side lobes
// Dolph-Chebyshev shading in its large-array limit: every side lobe at the same set level, the
// narrowest main lobe for that level. Its second parameter is A = acosh(R), R = 10^(-level_db / 20).
VKS_CONST uint kPatternChebyshev = 4u;

// Scattering models (Material.model). The value stored is f(theta) = s(theta) / cos(theta),
// the factor that multiplies 10^(mu/10) * Omega * r^-2 in the combined sonar equation.
VKS_CONST uint kScatterLambert = 0u;  // s = mu cos^2(theta) -> f = cos(theta): angle-dependent
VKS_CONST uint kScatterConstant = 1u; // f = 1: angle-independent, needs no normals (= Lommel-Seeliger, monostatic)
// Lambert plus the facet (Kirchhoff) term of a rough interface with Gaussian slopes:
// f = cos(theta) + specular_ratio * specular_facet(cos(theta), inv_two_slope_sq) (sonar_math.h).
VKS_CONST uint kScatterRough = 2u;

// Range kernels K_r.
VKS_CONST uint kRangeKernelNearest = 0u;
VKS_CONST uint kRangeKernelTent = 1u;
// Box over the pixel's own range extent (from its edges half way to its neighbours on the same surface,
// down its column and along its row; range_spread), at least kMinFootprintBins wide, a bin (the tent)
// where no neighbour is on its surface. Wide, it fills the range gaps that a coarse row grid leaves on a
// grazing seabed (without it the fan shows bright/dark stripes there); narrow, it keeps a sharp onset
// (the seabed at the altitude) in its bin.
VKS_CONST uint kRangeKernelFootprint = 2u;
VKS_CONST float kMaxFootprintBins = 256.0f; // caps the per-pixel loop; wider footprints are truncated to it
// The narrowest footprint the kernel spreads (bins): a pixel's range extent from its neighbours can be far
// below a bin (a surface facing the sonar, the seabed at the nadir) and is kept (a box of a sixteenth of
// a bin puts its energy into the right bin but for 1/32 of a bin either side); a pixel without any
// neighbour on its surface (an isolated hit: no extent known) gets a bin, the tent.
VKS_CONST float kMinFootprintBins = 0.0625f;
// SonarParams::absorption_per_bin's cap: 0.65 dB a bin (an alpha of 32 dB/m at 1 cm bins). Past it the
// exponents of range_spread's absorption terms over a footprint of kMaxFootprintBins could leave a float.
VKS_CONST float kMaxAbsorptionPerBin = 0.15f;

// Normal methods.
VKS_CONST uint kNormalsSobel3 = 0u;
VKS_CONST uint kNormalsSobel5 = 1u;
// The depth pass also writes each pixel's face normal (the triangle that won the depth test) into a
// colour attachment, as the plane normal in clip-linear coordinates q = (x_clip, y_clip, w_clip);
// the normals stage only maps it to the sonar frame and turns it to face the sonar.
VKS_CONST uint kNormalsGeometric = 2u;

// Per-frame-constant parameters of the compute stages (uniform buffer, std140; scalars only).
// Pixel grid: `columns` = slices * slice_columns + tier views * tier_columns pixel columns (left to right
// = port to starboard for the slices),
// `rows` rows (top to bottom = up to down). Buffers are row-major: index = row * columns + column.
struct SonarParams {
    uint columns;
    uint rows;
    uint slice_columns;
    uint slices; // the main band's views (Plan::slices), which join at their seams; the tier views follow

    uint beams;
    uint bins;
    uint effect_flags;
    uint near_column_taps; // the near kernel's weights per beam (Plan::near_column_taps)

    float tan_half_h; // tan(slice width / 2): horizontal half extent of one slice, focal-normalized
    float tan_half_v; // tan(vertical coverage / 2)
    float depth_a;    // view z = depth_a / (d - depth_b) for reversed-Z depth d (see sonar_math.h)
    float depth_b;

    float range_min_m;
    float range_max_m;
    float bin_width_m;
    float alpha_db_per_m; // absorption, one way

    float vpattern_k; // pattern constant for the vertical pattern, see pattern_power()
    uint vpattern_shape;
    uint range_kernel;
    uint normal_method;

    float edge_relative_jump;     // neighbours whose range differs by more than this fraction are not the same surface
    float vpattern_halfwidth_rad; // for the box pattern
    uint bins_padded;             // GPU only: bins rounded up to a multiple of 4 (vec4 layouts of the beamform stage)
    uint circular;                // 1 for a full circle (hfov 360): beam 0 and the last beam are neighbours

    uint echo_half;   // 1: echo buffer stored as two halves (energy * echo_scale, range), see echo.comp
    float echo_scale; // power of 2 that brings the brightest possible pixel energy to ~2^15
    // 1 / bin_width_m rounded once on the host: both backends multiply by it. A GPU may divide with an
    // error of ulps (Vulkan allows 2.5), and a bin coordinate off by ulps moves energy between bins.
    float inv_bin_width_m;
    float vpattern_chebyshev_a; // A = acosh(R) of a chebyshev vertical pattern (pattern_power), else 0

    // The echo stage's range gate [gate_min_m, gate_max_m): the window widened by the half width of
    // the widest range kernel, so that a pixel just outside the window still puts the part of its
    // footprint that lies inside into the edge bins (and the part outside is dropped, not folded in).
    float gate_min_m;
    float gate_max_m;
    // The columns of the range profiles that the resample stage maps onto beams: the pixel columns
    // (planar beam geometry), or with line_array = 1 the cone columns, uniform in the beam steering angle
    // theta over the fan: column c centred at cone_half_fov_rad - (c + 0.5) / inv_cone_step
    // (sonar_kernels.h, cone_coord).
    uint profile_columns;
    uint line_array;

    float cone_half_fov_rad;
    float inv_cone_step;
    uint far_cells;    // far side lobes: cells of the coarse grid (Plan::far_cells), 0: none
    uint far_channels; // 3: sinc^2's phase channels, 1: the lobes' mean (Plan::far_channels)

    // The elevation gate (Plan::elevation_gate_sin): a pixel ray whose |sin elevation| is above it gets
    // no vertical power, so that every azimuth sees the same elevations; 2 (no gate) where none applies.
    float elevation_gate_sin;
    uint tier_columns; // pixel columns of each tier view (Plan::tier_columns; 0: none), after the slices
    // how far a tier view's pixel reaches from its cone coordinate (Plan::tier_cone_reach; 0: no tiers)
    float tier_cone_reach;
    // Absorption's slope along range, two-way, per bin: 2 alpha ln(10) / 10 x bin width (0 with the effect
    // off), at most kMaxAbsorptionPerBin. The echo stage takes absorption at each pixel's own range; the
    // range kernel averages it over the pixel's footprint (range_spread), which a grazing seabed's reaches
    // metres.
    float absorption_per_bin;
    // A line array's elements' own pattern (SonarConfig::element_width): each pixel's echo times
    // sinc^2(element_k u), u its direction's sine along the array (pixel_vertical_power); 0: none.
    float element_k;
    uint element_pad0;
    uint element_pad1;
    uint element_pad2;
};
#ifdef __cplusplus
static_assert(sizeof(SonarParams) == 44 * 4, "SonarParams must match the GLSL std140 block");
#endif

// Per-view table (uniform block of kMaxViews, std140): one entry per view of the depth pass, which
// lie side by side in the pixel grid, slice_columns columns each, the tier views tier_columns each (Plan::views). A
// view is a camera (forward, right, down: an orthonormal basis in the sonar frame, so that pixel (u, v) looks along
// forward + u right + v down) with its own focal-normalized half extents, and the cell of directions
// it is the one to see: elevations whose sine lies in [sin_elevation_min, sin_elevation_max] and, for
// a tier view, azimuths in its wedge. The slices of the main band (views 0 .. slices - 1) are level
// cameras rotated about z; their azimuths are held by their side planes, so they have no wedge.
struct SliceInfo {
    float center_azimuth_rad; // positive to port (left): the slice's, or the tier view's wedge centre
    float tan_half_h;
    float tan_half_v;
    uint pad0;
    float forward_x;
    float forward_y;
    float forward_z;
    float sin_elevation_min;
    float right_x;
    float right_y;
    float right_z;
    float sin_elevation_max;
    float down_x;
    float down_y;
    float down_z;
    uint wedge;          // 1: a tier view, its azimuths limited to its wedge [wedge_start, wedge_end)
    float wedge_start_x; // (cos, sin) of the wedge's starboard edge azimuth
    float wedge_start_y;
    float wedge_end_x; // (cos, sin) of its port edge azimuth
    float wedge_end_y;
};
#ifdef __cplusplus
static_assert(sizeof(SliceInfo) == 80, "SliceInfo must match std140 (scalars, 16-byte multiple)");
#endif

// Acoustic material (storage buffer, std430), indexed by the material id the depth pass writes.
struct MaterialGpu {
    float backscatter_linear; // 10^(backscatter_db / 10)
    uint model;               // kScatter*
    // kScatterRough only (0 otherwise): R^2 / (8 pi m^2) / backscatter_linear, the facet term's
    // strength at normal incidence relative to the Lambert term, and 1 / (2 m^2) for rms slope m.
    float specular_ratio;
    float inv_two_slope_sq;
};
#ifdef __cplusplus
static_assert(sizeof(MaterialGpu) == 16, "MaterialGpu must match std430");
#endif

// One sub-pixel return (src/core/subpixel.h, docs/pipeline.md "Sub-pixel objects"): a piece of a triangle of
// an object too small (or too thin) for the pixel grid, its echo computed on the host from its area and
// material. The list of a frame is sorted by profile column; the buffer (binding kBindingSubpixel, uints)
// holds the columns' first returns, profile_columns + 1 of them, then the silent material (word
// profile_columns + 1), then, from the next multiple of 4 ((profile_columns + 2 + 3) & ~3), the returns.
struct SubpixelReturn {
    uint pixel;    // row * columns + column: the pixel whose depth may hide it (its direction's)
    float range_m; // slant range of its centroid
    float energy;  // relative to SL, times its share of the profile column (line_array: cone_share)
    float view_z;  // its centroid's view z in that pixel's slice (the occlusion test, subpixel_visible)
};
#ifdef __cplusplus
static_assert(sizeof(SubpixelReturn) == 16, "SubpixelReturn must match std430");
#endif

// Push constants of the depth pass: one draw (node x primitive) in one slice.
struct DepthPush {
    float clip_from_local[16]; // column-major, composed in double on the host, sonar-relative
    uint material_id;
    uint pad0;
    uint pad1;
    uint pad2;
};
#ifdef __cplusplus
static_assert(sizeof(DepthPush) == 80, "DepthPush must fit push constants");
} // namespace vksonar::shared
#undef VKS_CONST
#endif

#endif
