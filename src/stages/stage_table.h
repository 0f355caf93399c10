// The pipeline's stages, in order: the one list that the Vulkan backend (src/vk/vulkan_frame.cpp),
// the host-depth path (src/vk/host_depth.cpp) and the CPU backend (src/stages/cpu_backend.cpp) walk.
// A backend holds no list and no switch of its own: it calls the entry's function for its side, so a
// stage added, removed or reordered here is added, removed or reordered everywhere at once, and
// tests/stages/stage_table_test.cpp checks the entries against each other (every buffer read was
// written earlier, every shader is built, every dispatch covers its grid).
//
// The functions are declared here and defined next to the buffers they touch (the contexts stay
// opaque, so this header needs no Vulkan and no CPU-stage headers):
//   cpu::run_*       src/stages/cpu_backend.cpp  (the loops: src/stages/cpu_<stage>*.cpp)
//   vk::record_*     src/vk/vulkan_frame.cpp, vk::record_import src/vk/host_depth.cpp
// The per-pixel kernels of normals, echo and the range kernel of beamform are written once, in
// shaders/sonar_kernels.h, for both backends. The host stages (noise, gain, images) follow in
// src/host/ and are shared by both backends. docs/pipeline.md has the math.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/plan.h"
#include "sonar_shared.h"
#include "vksonar/frame.h"

namespace vksonar {

namespace cpu {
template <class Real> struct StageContext; // cpu_backend.cpp: the CPU backend's buffers and the frame's pose
template <class Real> void run_depth(StageContext<Real>& stage);
// row stages (CpuStage::rows): rows [row_begin, row_end) on worker thread `thread`
template <class Real>
void rows_normals(StageContext<Real>& stage, std::uint32_t row_begin, std::uint32_t row_end, std::uint32_t thread);
template <class Real>
void rows_echo(StageContext<Real>& stage, std::uint32_t row_begin, std::uint32_t row_end, std::uint32_t thread);
template <class Real> void run_beamform(StageContext<Real>& stage);
} // namespace cpu

namespace vk {
struct RecordContext; // vulkan_backend_impl.h: the backend and the command buffer being recorded
void record_depth(RecordContext& record);
void record_import(RecordContext& record); // the host's depth image in the depth pass's place
void record_normals(RecordContext& record);
void record_echo(RecordContext& record);
void record_beamform(RecordContext& record);
} // namespace vk

enum class StageId : std::uint8_t { depth, normals, echo, beamform };

// The frame's working buffers (each backend allocates each once), as a set.
enum class StageBuffers : std::uint16_t {
    none = 0,
    scene = 1u << 0,  // input: the scene's meshes and the pose, or a host engine's depth image
    tables = 1u << 1, // input: what make_plan computed once (materials, column/beam/side-lobe tables)
    depth = 1u << 2,
    material = 1u << 3,
    face_normals = 1u << 4, // normal_method = geometric: the depth pass's face normals
    normals = 1u << 5,
    echo = 1u << 6,
    profiles = 1u << 7,
    beam_profiles = 1u << 8,
    far_sidelobes = 1u << 9, // the far side lobes' deposited energy and convolved cells
    polar = 1u << 10,
    // The frame's sub-pixel returns (core/subpixel.h, Plan::subpixel_capacity > 0): listed with the depth
    // pass, which leaves their clusters out; the profile step adds them where the depth image shows them.
    subpixel = 1u << 11,
};
constexpr StageBuffers operator|(StageBuffers a, StageBuffers b) {
    return static_cast<StageBuffers>(static_cast<std::uint16_t>(a) | static_cast<std::uint16_t>(b));
}
constexpr StageBuffers operator&(StageBuffers a, StageBuffers b) {
    return static_cast<StageBuffers>(static_cast<std::uint16_t>(a) & static_cast<std::uint16_t>(b));
}
constexpr StageBuffers operator~(StageBuffers a) {
    return static_cast<StageBuffers>(~static_cast<std::uint16_t>(a));
}
constexpr bool any(StageBuffers a) {
    return a != StageBuffers::none;
}
constexpr StageBuffers kStageInputs = StageBuffers::scene | StageBuffers::tables;
// f(buffer) for each buffer of the set, in the order above.
template <class F> constexpr void for_each_buffer(StageBuffers set, F&& f) {
    for (std::uint32_t bit = 1; bit <= 0x8000u; bit <<= 1)
        if (any(set & static_cast<StageBuffers>(bit))) f(static_cast<StageBuffers>(bit));
}

// Work per invocation (specialization constant 1 of the shaders): more work per invocation pays on
// lavapipe (docs/benchmarks.md) and costs nothing on a GPU at these sizes.
constexpr std::uint32_t kNormalsRun = 8; // pixels of one row per normals invocation
constexpr std::uint32_t kEchoPixels = 4; // consecutive pixels per echo invocation
// Beams per resample/sidelobe workgroup (each invocation one bin of them); sidelobe.comp holds at most 32.
constexpr std::uint32_t kBeamsPerInvocation = 16;
// line_array: cone columns per profile invocation; a pixel between two of them is loaded once, not
// twice (a quarter of the pixels a gather touches at 4, against all of them at 1).
constexpr std::uint32_t kConesPerInvocation = 4;
// Profile invocations sharing one column's bins on a GPU (shaders/profile.comp): one subgroup.
constexpr std::uint32_t kProfileBinLanes = 32;

// Beams per resample/sidelobe invocation on a GPU (a multiple of 4: sidelobe.comp stores vec4s of beams).
constexpr std::uint32_t kGpuBeamsPerInvocation = 4;

// How a device runs the beamform passes, whose best layout depends on it (RendererOptions::layout). A
// CPU device (lavapipe) runs a workgroup's lanes as loops over the same work, so there few invocations
// that each do much pay; a GPU needs 10^4-10^5 of them to be busy at all (the default preset: 1k
// profile invocations and 128 resample/sidelobe warps on a 132-SM chip). Frames are bit-identical for
// every shape (tested): each output keeps its one writer and the order of its additions.
struct DeviceShape {
    std::uint32_t cones_per_invocation = kConesPerInvocation; // profile, line_array
    std::uint32_t bin_lanes = 1;                              // profile: invocations per column (a power of 2)
    std::uint32_t beams_per_invocation = kBeamsPerInvocation; // resample, sidelobe
    // far side lobes' convolution: a workgroup row per output cell (channels x cells rows, each cell's sum
    // over the cells' energies loaded from memory), else per channel (each lane every cell of its bins,
    // the energies in registers: a CPU device runs a storage load as a loop over the lanes)
    bool far_cell_groups = false;
    // profile: a block of kProfileBinLanes rows at once (profile.comp gather_block_rows, line_array, with
    // one cone column per unit; column_block_rows, planar), where the plan allows it (VulkanBackend)
    bool gather_rows = false;
};
constexpr DeviceShape kCpuDeviceShape{kConesPerInvocation, 1, kBeamsPerInvocation, false, false};
constexpr DeviceShape kGpuDeviceShape{1, kProfileBinLanes, kGpuBeamsPerInvocation, true, true};

constexpr std::uint64_t ceil_div(std::uint64_t a, std::uint64_t b) {
    return (a + b - 1) / b;
}
constexpr std::uint32_t group_count(std::uint64_t invocations) {
    return static_cast<std::uint32_t>(ceil_div(invocations, shared::kWorkgroupSize));
}

// One vkCmdDispatch: its shader (a file of shaders/) and its workgroups.
struct Dispatch {
    const char* shader = nullptr; // null: not dispatched with this plan
    std::uint32_t x = 0, y = 1, z = 1;
};
constexpr std::size_t kMaxDispatches = 5;
using Dispatches = std::array<Dispatch, kMaxDispatches>; // in recording order; the record function indexes it

struct VulkanStage {
    std::array<const char*, 4> shaders; // every shader file it may run, null-padded
    void (*record)(vk::RecordContext&); // its commands, barriers after its writes included
    Dispatches (*dispatches)(const Plan&, const DeviceShape&);
};

// In both of the CPU backend's precisions (SonarConfig::cpu_precision), picked at compile time: the
// whole stage (f32, f64), or a row stage (rows_f32, rows_f64), whose row j of output reads no row but j
// of the row stages before it. The CPU backend runs consecutive row stages fused: each block of rows
// through all of them while it is in cache (normals then echo: the normals of a block are read back
// from cache, not from memory), and shares the pass's wall time among them by their summed block times.
struct CpuStage {
    void (*f32)(cpu::StageContext<float>&) = nullptr;
    void (*f64)(cpu::StageContext<double>&) = nullptr;
    void (*rows_f32)(cpu::StageContext<float>&, std::uint32_t, std::uint32_t, std::uint32_t) = nullptr;
    void (*rows_f64)(cpu::StageContext<double>&, std::uint32_t, std::uint32_t, std::uint32_t) = nullptr;
};

struct StageInfo {
    StageId id;
    const char* name;                    // Frame::stages_run, Frame::times, `vksonar bench` columns
    bool (*runs)(const Plan&);           // whether the plan needs it (effects on demand)
    StageBuffers (*reads)(const Plan&);  // with this plan, when it runs
    StageBuffers (*writes)(const Plan&); // with this plan, when it runs
    CpuStage cpu;                        // on the CPU backend
    VulkanStage vulkan;                  // on the Vulkan backend, which draws the scene itself
    const char* host_depth_name;         // the name and the code with a host engine's depth image
    VulkanStage host_depth;              // (HostDepthRenderer): only the depth stage differs
    SaveFlags saves;                     // the Frame images its outputs fill when asked for ...
    StageBuffers saved;                  // ... read back from these buffers after the last stage
};

namespace stage_table { // the table's entries, named

constexpr Dispatches no_dispatch(const Plan&, const DeviceShape&) {
    return {}; // a render pass: its draws follow the scene (vk::record_depth)
}
constexpr Dispatches import_dispatch(const Plan& plan, const DeviceShape&) {
    return {{{"import_depth.comp", group_count(std::uint64_t(plan.columns) * plan.rows)}}};
}
constexpr Dispatches normals_dispatch(const Plan& plan, const DeviceShape&) {
    return {{{"normals.comp", group_count(std::uint64_t(plan.rows) * ceil_div(plan.columns, kNormalsRun))}}};
}
constexpr Dispatches echo_dispatch(const Plan& plan, const DeviceShape&) {
    return {{{"echo.comp", group_count(ceil_div(plan.columns, kEchoPixels)), plan.rows}}};
}
// profile: shape.bin_lanes invocations per pixel column (planar) or per shape.cones_per_invocation
// cone columns (line_array). resample, far_sidelobe and sidelobe: x = groups of 4-bin quads, y = runs of
// shape.beams_per_invocation beams, or
// channels x cells (far deposit), or channels (far convolve; channels x cells with far_cell_groups).
enum BeamformDispatch : std::size_t { profile, resample, far_deposit, far_convolve, sidelobe };
constexpr bool far_sidelobes(const Plan& plan) {
    return plan.effects.horizontal_pattern && plan.far_cells > 0;
}
// The far convolve's per-channel form runs about cells * (cells + 3) loop turns in one invocation.
// Lavapipe ends an invocation's loops after 65535 iterations in all (gallivm's loop limiter, shared by
// every loop of a shader) without a word: with 255 or 256 cells the last cells were never written. Past
// this many cells the convolve takes a workgroup row per cell (as on a GPU) on every device.
constexpr std::uint32_t kFarCellsInOneInvocation = 176; // 176 * 179 + 2 = 31506 turns: under half the limit
constexpr bool far_cell_groups(const Plan& plan, const DeviceShape& shape) {
    return shape.far_cell_groups || plan.far_cells > kFarCellsInOneInvocation;
}
constexpr std::uint64_t profile_invocations(const Plan& plan, const DeviceShape& shape) {
    const std::uint64_t units =
        plan.line_array ? ceil_div(plan.profile_columns, shape.cones_per_invocation) : plan.profile_columns;
    return units * shape.bin_lanes;
}
constexpr Dispatches beamform_dispatch(const Plan& plan, const DeviceShape& shape) {
    const std::uint32_t bin_groups = group_count(ceil_div(plan.bins, 4));
    const auto beam_runs = static_cast<std::uint32_t>(ceil_div(plan.beams, shape.beams_per_invocation));
    Dispatches d{};
    d[profile] = {"profile.comp", group_count(profile_invocations(plan, shape))};
    d[resample] = {"resample.comp", bin_groups, beam_runs};
    if (far_sidelobes(plan)) {
        d[far_deposit] = {"far_sidelobe.comp", bin_groups, plan.far_cells * plan.far_channels};
        d[far_convolve] = {"far_sidelobe.comp", bin_groups,
                           far_cell_groups(plan, shape) ? plan.far_cells * plan.far_channels : plan.far_channels};
    }
    if (plan.effects.horizontal_pattern) d[sidelobe] = {"sidelobe.comp", bin_groups, beam_runs};
    return d;
}

inline constexpr VulkanStage kDepthPass{
    {"depth.vert", "depth.frag", "depth_geometric.vert", "depth_geometric.frag"}, vk::record_depth, no_dispatch};
inline constexpr VulkanStage kImport{{"import_depth.comp"}, vk::record_import, import_dispatch};
inline constexpr VulkanStage kNormals{{"normals.comp"}, vk::record_normals, normals_dispatch};
inline constexpr VulkanStage kEcho{{"echo.comp"}, vk::record_echo, echo_dispatch};
inline constexpr VulkanStage kBeamform{
    {"profile.comp", "resample.comp", "far_sidelobe.comp", "sidelobe.comp"}, vk::record_beamform, beamform_dispatch};

constexpr bool always(const Plan&) {
    return true;
}
constexpr bool incidence(const Plan& plan) {
    return plan.effects.incidence; // only the incidence effect reads normals
}

constexpr StageBuffers depth_reads(const Plan&) {
    return StageBuffers::scene;
}
constexpr StageBuffers depth_writes(const Plan& plan) {
    return StageBuffers::depth | StageBuffers::material |
           (plan.face_normals ? StageBuffers::face_normals : StageBuffers::none) |
           (plan.subpixel_capacity > 0 ? StageBuffers::subpixel : StageBuffers::none);
}
constexpr StageBuffers normals_reads(const Plan& plan) {
    return StageBuffers::depth | StageBuffers::tables |
           (plan.face_normals ? StageBuffers::face_normals : StageBuffers::none);
}
constexpr StageBuffers normals_writes(const Plan&) {
    return StageBuffers::normals;
}
constexpr StageBuffers echo_reads(const Plan& plan) {
    return StageBuffers::depth | StageBuffers::material | StageBuffers::tables |
           (plan.effects.incidence ? StageBuffers::normals : StageBuffers::none);
}
constexpr StageBuffers echo_writes(const Plan&) {
    return StageBuffers::echo;
}
constexpr StageBuffers beamform_reads(const Plan& plan) {
    return StageBuffers::echo | StageBuffers::tables |
           (plan.subpixel_capacity > 0 ? StageBuffers::subpixel | StageBuffers::depth | StageBuffers::material
                                       : StageBuffers::none);
}
// every column's profile before any beam reads it; the far side lobes before the near ones
constexpr StageBuffers beamform_writes(const Plan& plan) {
    return StageBuffers::profiles | StageBuffers::beam_profiles | StageBuffers::polar |
           (far_sidelobes(plan) ? StageBuffers::far_sidelobes : StageBuffers::none);
}

} // namespace stage_table

inline constexpr std::array<StageInfo, 4> kStageTable{{
    {.id = StageId::depth,
     .name = "depth",
     .runs = stage_table::always,
     .reads = stage_table::depth_reads,
     .writes = stage_table::depth_writes,
     .cpu = {cpu::run_depth<float>, cpu::run_depth<double>},
     .vulkan = stage_table::kDepthPass,
     .host_depth_name = "import",
     .host_depth = stage_table::kImport,
     .saves = SaveFlags::depth,
     .saved = StageBuffers::depth | StageBuffers::material},
    {.id = StageId::normals,
     .name = "normals",
     .runs = stage_table::incidence,
     .reads = stage_table::normals_reads,
     .writes = stage_table::normals_writes,
     .cpu = {.rows_f32 = cpu::rows_normals<float>, .rows_f64 = cpu::rows_normals<double>},
     .vulkan = stage_table::kNormals,
     .host_depth_name = "normals",
     .host_depth = stage_table::kNormals,
     .saves = SaveFlags::normals,
     .saved = StageBuffers::normals},
    {.id = StageId::echo,
     .name = "echo",
     .runs = stage_table::always,
     .reads = stage_table::echo_reads,
     .writes = stage_table::echo_writes,
     .cpu = {.rows_f32 = cpu::rows_echo<float>, .rows_f64 = cpu::rows_echo<double>},
     .vulkan = stage_table::kEcho,
     .host_depth_name = "echo",
     .host_depth = stage_table::kEcho,
     .saves = SaveFlags::echo,
     .saved = StageBuffers::echo},
    {.id = StageId::beamform,
     .name = "beamform",
     .runs = stage_table::always,
     .reads = stage_table::beamform_reads,
     .writes = stage_table::beamform_writes,
     .cpu = {cpu::run_beamform<float>, cpu::run_beamform<double>},
     .vulkan = stage_table::kBeamform,
     .host_depth_name = "beamform",
     .host_depth = stage_table::kBeamform,
     .saves = SaveFlags::profiles,
     .saved = StageBuffers::profiles | StageBuffers::beam_profiles},
}};
inline constexpr std::size_t kStageCount = kStageTable.size();

constexpr bool stage_table_in_order() {
    for (std::size_t i = 0; i < kStageCount; ++i)
        if (static_cast<std::size_t>(kStageTable[i].id) != i) return false;
    return true;
}
static_assert(stage_table_in_order(), "kStageTable[i].id == i: backends index their per-stage arrays by StageId");

// The CPU backend's functions for its precision: the whole stage, or its rows (null for the other kind).
template <class Real> constexpr auto cpu_function(const CpuStage& stage) {
    if constexpr (std::is_same_v<Real, double>) {
        return stage.f64;
    } else {
        return stage.f32;
    }
}
template <class Real> constexpr auto cpu_rows_function(const CpuStage& stage) {
    if constexpr (std::is_same_v<Real, double>) {
        return stage.rows_f64;
    } else {
        return stage.rows_f32;
    }
}

} // namespace vksonar
