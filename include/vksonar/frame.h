// Frame: one ping's result. Allocated once by Renderer::make_frame(); render() refills it without
// allocating. Polar arrays are range-major: index = bin * beams + beam (beam 0 = port-most).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vksonar {

// Which intermediates a render keeps (RendererOptions::save_mask): flags combined with | and tested
// with any(mask & SaveFlags::depth).
enum class SaveFlags : std::uint32_t {
    none = 0,
    depth = 1u << 0,    // reversed-Z depth per pixel, and view range
    normals = 1u << 1,  // sonar-frame normal + cos(incidence) per pixel
    echo = 1u << 2,     // per-pixel echo energy and slant range
    profiles = 1u << 3, // per-column range profiles and beam profiles before side lobes
    // Ground-truth labels per polar cell (Frame::instance ... point). They are computed from the depth
    // pass's material/instance image and the echo, so a labels frame also keeps depth, material and echo.
    labels = 1u << 4,
};

// Set operations on SaveFlags (constexpr, pure); ~ keeps only the flags above.
constexpr SaveFlags operator|(SaveFlags a, SaveFlags b) {
    return static_cast<SaveFlags>(static_cast<std::uint32_t>(a) | static_cast<std::uint32_t>(b));
}
constexpr SaveFlags operator&(SaveFlags a, SaveFlags b) {
    return static_cast<SaveFlags>(static_cast<std::uint32_t>(a) & static_cast<std::uint32_t>(b));
}
constexpr SaveFlags operator~(SaveFlags a) {
    return static_cast<SaveFlags>(~static_cast<std::uint32_t>(a) & 0x1fu);
}
constexpr SaveFlags& operator|=(SaveFlags& a, SaveFlags b) {
    return a = a | b;
}
constexpr SaveFlags& operator&=(SaveFlags& a, SaveFlags b) {
    return a = a & b;
}
// True if any flag is set: any(mask & SaveFlags::echo).
constexpr bool any(SaveFlags flags) {
    return flags != SaveFlags::none;
}

// How much of an object the sonar sees (labels, docs/labels.md): over the depth pass's pixels that the
// object covers when drawn alone (its projection inside the depth pass's view: the fan, the vertical
// coverage and the near/far planes), how many a nearer object hides and how many of the rest lie
// outside the range window.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct ObjectVisibility {
    std::uint32_t instance = 0; // SceneInstance::id
    std::uint32_t pixels = 0;   // covered when drawn alone (an object below the pixel size: its returns)
    std::uint32_t hidden = 0;   // of those, where the depth pass's nearest surface is another object's
    std::uint32_t outside = 0;  // of the rest, slant range outside [range_min, range_max)
};

// How long one stage of a frame took (Frame::times, in the order they ran): GPU timestamps or host
// clocks around the stage's submission (RendererOptions::stage_timing); host stages on host clocks.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct StageTime {
    std::string stage; // "depth" ("import" on a HostDepthRenderer), "normals", "echo", "beamform", "noise",
                       // and "labels" with SaveFlags::labels
    double ms = 0;
};

// One effect as the renderer resolved it from config and scene (Frame::effects; EffectsConfig): on or
// off, and why ("auto: fully developed speckle", "off in config").
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct EffectState {
    std::string name;
    bool on = false;
    std::string why;
};

// One ping's output and what it was made from. Make it with the renderer's make_frame() (sized for that
// renderer; render refuses a frame of another size) and reuse it: render, process and read_back
// overwrite the arrays they fill and allocate nothing. Owned by the caller; it refers to nothing else.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one (a Renderer
// writes it only inside render, process and read_back).
struct Frame {
    std::uint32_t beams = 0, bins = 0;
    std::uint32_t columns = 0, rows = 0; // pixel grid of the depth pass (all slices side by side)
    // Columns of `profiles`: the pixel columns, or with the line_array beam geometry the cone columns,
    // uniform in the beam steering angle over the fan (docs/pipeline.md, "Beam geometry").
    std::uint32_t profile_columns = 0;
    std::uint64_t frame_index = 0;
    std::uint64_t seed = 0;

    std::vector<double> beam_angles_rad; // beams, port (positive) to starboard
    std::vector<double> bin_ranges_m;    // bins, centre of each range bin

    // Echo intensity before noise, linear, relative to the source level (10 log10 + SL = dB re 1 uPa).
    std::vector<float> clean;
    // Received intensity after speckle, ambient noise and TVG, linear in uPa^2 (10 log10 = dB re 1 uPa).
    std::vector<float> intensity;
    // Display value in [0, 1] after the dB window.
    std::vector<float> display;

    // Intermediates, filled when requested in RendererOptions::save_mask (else empty).
    std::vector<float> depth;            // rows * columns reversed-Z depth, 0 = no hit
    std::vector<std::uint32_t> material; // rows * columns material id, 0xffffffff = no hit
    std::vector<float> normals;          // rows * columns * 4: nx ny nz (sonar frame) cos_incidence
    std::vector<float> echo;             // rows * columns * 2: energy, slant range m
    std::vector<float> profiles;         // bins * profile_columns
    std::vector<float> beam_profiles;    // bins * beams, before the side-lobe convolution

    // Ground-truth labels (SaveFlags::labels, else empty), bins * beams like `clean` (docs/labels.md).
    // They follow each pixel's energy along the main lobe: the pixel's range shares, its columns and
    // their beams, exactly as the beamform stage spreads it, before side lobes, speckle and noise.
    std::vector<std::uint16_t> instance;     // SceneInstance::id with the most energy in the cell (0: none)
    std::vector<float> instance_fraction;    // that instance's share of the cell's energy (0: no energy)
    std::vector<std::uint16_t> object_class; // SceneInstance::class_id of `instance` (0: none)
    std::vector<float> elevation;            // energy-weighted mean elevation, rad, up positive (NaN: no energy)
    std::vector<float> elevation_spread;     // its energy-weighted standard deviation, rad (NaN: no energy)
    // bins * beams * 3: the point of the instance's strongest return in the cell (the pixel that put the
    // most energy there, at the range of the part of its footprint inside the bin), sonar frame, m (NaN)
    std::vector<float> point;
    // One entry per object with a labelled cell, in increasing id (empty without a scene: a host's depth
    // image names no objects).
    std::vector<ObjectVisibility> visibility;

    std::vector<StageTime> times;
    std::vector<EffectState> effects;
    std::vector<std::string> stages_run;
};

} // namespace vksonar
