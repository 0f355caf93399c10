// The SonarConfig key table (see config_keys.h). Accessors are generated from pointers to members so
// each row names its field once.
#include "config/config_keys.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>

namespace vksonar::config_keys {
namespace {

// Short description of a JSON value for error messages: the value itself, clipped.
std::string describe(const Json& value) {
    // JSON has no NaN or infinity (dump() writes null); they come from --set (nan, inf, 1e999)
    if (value.is_number_float() && !std::isfinite(value.get<double>()))
        return std::isnan(value.get<double>()) ? "nan" : (value.get<double>() > 0 ? "inf" : "-inf");
    std::string text = value.dump(-1, ' ', false, Json::error_handler_t::replace); // never throws on bad UTF-8
    if (text.size() > 40) text = text.substr(0, 37) + "...";
    return text;
}

// ---- enum names --------------------------------------------------------------------------------

template <class E> struct EnumNames;
template <> struct EnumNames<BeamPattern> {
    static constexpr std::array<const char*, 5> names{"box", "sinc", "hann", "gaussian", "chebyshev"};
};
template <> struct EnumNames<BeamSpacing> {
    static constexpr std::array<const char*, 2> names{"equiangular", "equisine"};
};
template <> struct EnumNames<BeamGeometry> {
    static constexpr std::array<const char*, 2> names{"line_array", "planar"};
};
template <> struct EnumNames<BeamFocus> {
    static constexpr std::array<const char*, 3> names{"dynamic", "fixed", "none"};
};
template <> struct EnumNames<SpeckleModel> {
    static constexpr std::array<const char*, 3> names{"rayleigh", "gamma", "gaussian"};
};
template <> struct EnumNames<BeamCorrelation> { static constexpr std::array<const char*, 2> names{"pattern", "none"}; };
template <> struct EnumNames<RangeKernel> {
    static constexpr std::array<const char*, 3> names{"nearest", "tent", "footprint"};
};
template <> struct EnumNames<NormalMethod> {
    static constexpr std::array<const char*, 3> names{"sobel3", "sobel5", "geometric"};
};
template <> struct EnumNames<Colormap> {
    static constexpr std::array<const char*, 4> names{"gray", "viridis", "sonar", "jet"};
};
template <> struct EnumNames<IntermediatePrecision> {
    static constexpr std::array<const char*, 2> names{"fp32", "fp16"};
};
template <> struct EnumNames<Precision> { static constexpr std::array<const char*, 2> names{"float", "double"}; };
template <> struct EnumNames<CpuVectorLoops> { static constexpr std::array<const char*, 2> names{"auto", "off"}; };
template <> struct EnumNames<SonarMode> {
    static constexpr std::array<const char*, 3> names{"physical", "uuv-legacy", "gtri-legacy"};
};
template <> struct EnumNames<EffectMode> { static constexpr std::array<const char*, 3> names{"auto", "on", "off"}; };

template <class E> std::string choices_text() {
    std::string text;
    for (const char* name : EnumNames<E>::names) {
        if (!text.empty()) text += '|';
        text += name;
    }
    return text;
}

// ---- generic accessors -------------------------------------------------------------------------

template <double SonarConfig::*M> Json get_number(const SonarConfig& c) {
    return c.*M;
}
template <double SonarConfig::*M> std::string set_number(SonarConfig& c, const Json& v) {
    if (!v.is_number()) return "expected a number, got " + describe(v);
    c.*M = v.get<double>();
    return {};
}

template <std::uint32_t SonarConfig::*M> Json get_count(const SonarConfig& c) {
    return c.*M;
}
template <std::uint32_t SonarConfig::*M> std::string set_count(SonarConfig& c, const Json& v) {
    if (!v.is_number()) return "expected a whole number, got " + describe(v);
    const double x = v.get<double>();
    if (!std::isfinite(x) || x != std::floor(x) || x < 0 ||
        x > static_cast<double>(std::numeric_limits<std::uint32_t>::max()))
        return "expected a whole number >= 0, got " + describe(v);
    c.*M = static_cast<std::uint32_t>(x);
    return {};
}

template <std::string SonarConfig::*M> Json get_text(const SonarConfig& c) {
    return c.*M;
}
template <std::string SonarConfig::*M> std::string set_text(SonarConfig& c, const Json& v) {
    if (!v.is_string()) return "expected a string, got " + describe(v);
    c.*M = v.get<std::string>();
    return {};
}

template <class E> std::string set_enum_value(E& field, const Json& v) {
    if (v.is_string()) {
        const auto text = v.get<std::string>();
        const auto& names = EnumNames<E>::names;
        for (std::size_t i = 0; i < names.size(); ++i) {
            if (text == names[i]) {
                field = static_cast<E>(i);
                return {};
            }
        }
    }
    return "expected one of " + choices_text<E>() + ", got " + describe(v);
}

// A value outside the enum's names (a C++ caller's static_cast) reads as its number, which validate()
// refuses (a choice key must read as one of its names).
template <class E> Json enum_json(E value) {
    const auto index = static_cast<std::size_t>(value);
    if (index >= EnumNames<E>::names.size()) return static_cast<std::uint64_t>(index);
    return EnumNames<E>::names[index];
}
template <class E, E SonarConfig::*M> Json get_enum(const SonarConfig& c) {
    return enum_json(c.*M);
}
template <class E, E SonarConfig::*M> std::string set_enum(SonarConfig& c, const Json& v) {
    return set_enum_value(c.*M, v);
}

template <EffectMode EffectsConfig::*M> Json get_effect(const SonarConfig& c) {
    return enum_json(c.effects.*M);
}
template <EffectMode EffectsConfig::*M> std::string set_effect(SonarConfig& c, const Json& v) {
    if (v.is_boolean()) { // true/false read naturally in JSON files
        c.effects.*M = v.get<bool>() ? EffectMode::on : EffectMode::off;
        return {};
    }
    return set_enum_value(c.effects.*M, v);
}

// ---- special keys ------------------------------------------------------------------------------

Json get_beam_angles(const SonarConfig& c) {
    return c.beam_angles_deg;
}
std::string set_beam_angles(SonarConfig& c, const Json& v) {
    if (!v.is_array()) return "expected an array of angles in degrees, got " + describe(v);
    std::vector<double> angles;
    angles.reserve(v.size());
    for (std::size_t i = 0; i < v.size(); ++i) {
        if (!v[i].is_number()) return "entry " + std::to_string(i) + " is not a number: " + describe(v[i]);
        if (!std::isfinite(v[i].get<double>())) // as every number key (NaN from Python or C++)
            return "entry " + std::to_string(i) + " is not a finite number: " + describe(v[i]);
        angles.push_back(v[i].get<double>());
    }
    c.beam_angles_deg = std::move(angles);
    // The table defines the beam count; keeping `beams` in step lets validate() catch a later,
    // contradictory `beams`.
    if (!c.beam_angles_deg.empty()) c.beams = static_cast<std::uint32_t>(c.beam_angles_deg.size());
    return {};
}

// A number >= 0, or "auto" (stored as -1: the plan derives the value; absorption, noise_level,
// directivity_index).
template <double SonarConfig::*M> Json get_number_or_auto(const SonarConfig& c) {
    if (c.*M < 0) return "auto";
    return c.*M;
}
template <double SonarConfig::*M> std::string set_number_or_auto(SonarConfig& c, const Json& v, const char* unit) {
    if (v.is_string() && v.get<std::string>() == "auto") {
        c.*M = -1.0;
        return {};
    }
    if (!v.is_number()) return std::string("expected a number (") + unit + ") or \"auto\", got " + describe(v);
    const double x = v.get<double>();
    if (x < 0) return std::string("expected a number >= 0 (") + unit + ") or \"auto\", got " + describe(v);
    c.*M = x;
    return {};
}
std::string set_absorption(SonarConfig& c, const Json& v) {
    return set_number_or_auto<&SonarConfig::absorption_db_per_m>(c, v, "dB/m");
}
std::string set_noise_level(SonarConfig& c, const Json& v) {
    return set_number_or_auto<&SonarConfig::noise_level_db>(c, v, "dB re 1 uPa");
}
std::string set_directivity_index(SonarConfig& c, const Json& v) {
    return set_number_or_auto<&SonarConfig::directivity_index_db>(c, v, "dB");
}

// ---- the table ---------------------------------------------------------------------------------

#define VKS_NUMBER(key, member, unit, doc, range)                                                                      \
    ConfigKey {                                                                                                        \
        key, KeyType::number, unit, "", doc, &get_number<&SonarConfig::member>, &set_number<&SonarConfig::member>,     \
            range                                                                                                      \
    }
#define VKS_COUNT(key, member, unit, doc, range)                                                                       \
    ConfigKey {                                                                                                        \
        key, KeyType::count, unit, "", doc, &get_count<&SonarConfig::member>, &set_count<&SonarConfig::member>, range  \
    }
#define VKS_TEXT(key, member, doc)                                                                                     \
    ConfigKey {                                                                                                        \
        key, KeyType::text, "", "", doc, &get_text<&SonarConfig::member>, &set_text<&SonarConfig::member>              \
    }
#define VKS_ENUM(key, E, member, choices, doc)                                                                         \
    ConfigKey {                                                                                                        \
        key, KeyType::choice, "", choices, doc, &get_enum<E, &SonarConfig::member>, &set_enum<E, &SonarConfig::member> \
    }
#define VKS_EFFECT(name, doc)                                                                                          \
    ConfigKey {                                                                                                        \
        "effects." #name, KeyType::choice, "", "auto|on|off", doc, &get_effect<&EffectsConfig::name>,                  \
            &set_effect<&EffectsConfig::name>                                                                          \
    }

// Ranges: [lo, hi], (lo, hi], [lo, hi), (lo, hi).
constexpr KeyRange closed(double lo, double hi, const char* why) {
    return {lo, hi, false, false, why};
}
constexpr KeyRange open_low(double lo, double hi, const char* why) {
    return {lo, hi, true, false, why};
}
constexpr KeyRange open_both(double lo, double hi, const char* why) {
    return {lo, hi, true, true, why};
}

std::vector<ConfigKey> make_table() {
    return {
        VKS_TEXT("name", name, "Preset or device name"),
        VKS_TEXT("description", description, "One-line description"),
        VKS_TEXT("source", source, "Where the device figures come from (datasheet citation)"),
        VKS_ENUM("mode", SonarMode, mode, "physical|uuv-legacy|gtri-legacy",
                 "Image model: the physical model, or a step-by-step legacy plugin (docs/legacy.md)"),

        VKS_NUMBER("frequency", frequency_hz, "Hz", "Centre frequency (sets absorption and wavelength)",
                   closed(1e3, 1e7,
                          "1 kHz (1.5 m wavelength) to 10 MHz, where water absorbs about 30 dB/m (Francois-Garrison's "
                          "pure-water term): the span of active sonar")),
        VKS_NUMBER("hfov", hfov_deg, "deg", "Horizontal field of view, (0, 360]",
                   open_low(0, 360, "a fan is at most a full circle")),
        VKS_NUMBER("vfov", vfov_deg, "deg", "Vertical beamwidth (two-way -3 dB), (0, 180)",
                   open_both(0, 180, "a vertical beam spans less than from straight down to straight up")),
        VKS_NUMBER(
            "horizontal_beamwidth", horizontal_beamwidth_deg, "deg", "Two-way -3 dB receive beamwidth of one beam",
            open_low(0, 180,
                     "as vfov; and at most hfov (a beam wider than the whole fan: checked with the other keys)")),
        VKS_COUNT("beams", beams, "", "Number of beams (set by beam_angles when that table is given)",
                  closed(1, 16384, "one beam to one per column of the widest depth pass (16384 columns)")),
        VKS_ENUM("beam_spacing", BeamSpacing, beam_spacing, "equiangular|equisine",
                 "Beam centres uniform in angle, or uniform in sine of the angle"),
        VKS_ENUM("beam_geometry", BeamGeometry, beam_geometry, "line_array|planar",
                 "Beams as a horizontal line array forms them (cones around the array axis, patterns in sine "
                 "space), or as half-planes of one azimuth (an acoustic lens; the legacy modes); a fan of 180 "
                 "deg or more is planar"),
        ConfigKey{"beam_angles", KeyType::number_list, "deg", "",
                  "Explicit beam-centre table, port first (strictly decreasing, within +-hfov/2); overrides "
                  "beams and beam_spacing when non-empty",
                  &get_beam_angles, &set_beam_angles},
        VKS_COUNT("bins", bins, "", "Number of range bins",
                  closed(1, 65536, "one bin to 65536 (the largest polar scan vksonar allocates)")),
        VKS_NUMBER("range_min", range_min_m, "m", "Start of the range window, > 0",
                   open_both(0, 1e5, "in front of the array; and below range_max")),
        VKS_NUMBER("range_max", range_max_m, "m", "End of the range window, > range_min",
                   open_low(0, 1e5, "100 km: past the reach of any active sonar")),
        VKS_NUMBER("sound_speed", sound_speed_mps, "m/s", "Speed of sound in water",
                   closed(1400, 1650,
                          "fresh water at 0 degC (1402 m/s) to seawater at full ocean depth (about 1640 m/s; "
                          "Mackenzie, JASA 70(3) 1981)")),
        VKS_NUMBER("bandwidth", bandwidth_hz, "Hz",
                   "Pulse bandwidth B; > 0: range bins of the resolution c / 2B over the window (rounded), "
                   "replacing bins; 0: use bins",
                   closed(0, 2e7,
                          "0: use bins; at most twice the frequency, so that the band f +- B/2 stays above 0 Hz "
                          "(checked with frequency)")),

        VKS_NUMBER("source_level", source_level_db, "dB re 1 uPa at 1 m", "Source level SL",
                   closed(100, 260,
                          "below 100 dB no echo clears the sea's noise; the loudest sonars reach about 240 dB, and "
                          "near 260 dB the water cavitates and linear acoustics fails")),
        ConfigKey{"noise_level", KeyType::number_or_auto, "dB re 1 uPa", "",
                  "Ambient noise level NL in the receive band, or \"auto\": the sea's noise spectrum (thermal, "
                  "wind, shipping, turbulence) over the band f +- B/2 (B = bandwidth, else c / 2 x the bin width)",
                  &get_number_or_auto<&SonarConfig::noise_level_db>, &set_noise_level,
                  closed(0, 180,
                         "0 dB is below the thermal noise of any sonar band; storms, rain, shipping and snapping "
                         "shrimp stay well below 180 dB")},
        ConfigKey{"directivity_index", KeyType::number_or_auto, "dB", "",
                  "Receive directivity index DI of the broadside beam, or \"auto\": 4 pi over the receive "
                  "pattern's solid angle (horizontal x vertical pattern); line_array beams steered to theta "
                  "lose 10 log10(1 / cos theta)",
                  &get_number_or_auto<&SonarConfig::directivity_index_db>, &set_directivity_index,
                  closed(0, 80,
                         "0 dB: an omnidirectional receiver; 80 dB: past a 1 m x 1 m aperture at 3 MHz (4 pi A / "
                         "lambda^2 = 77 dB)")},
        VKS_NUMBER("wind_speed", wind_speed_mps, "m/s", "Wind speed over the sea (for auto noise_level)",
                   closed(0, 50, "calm to past hurricane force (Beaufort 12 begins at 32.7 m/s)")),
        VKS_NUMBER("shipping", shipping_activity, "", "Shipping activity 0 (none) to 1 (heavy) (for auto noise_level)",
                   closed(0, 1, "the range of the Wenz/Coates shipping term's activity factor")),
        VKS_NUMBER("default_backscatter", default_backscatter_db, "dB",
                   "Backscatter strength of materials whose glTF extras say nothing",
                   closed(-100, 0,
                          "0 dB (1 m^2 per m^2 per sr) is past a perfect Lambertian reflector (-5 dB); below -100 dB "
                          "no echo reaches a display")),
        ConfigKey{"absorption", KeyType::number_or_auto, "dB/m", "",
                  "One-way absorption, or \"auto\" for Francois-Garrison from frequency and the water below",
                  &get_number_or_auto<&SonarConfig::absorption_db_per_m>, &set_absorption,
                  closed(0, 100, "no loss to three times Francois-Garrison at 10 MHz (about 30 dB/m)")},
        VKS_NUMBER("temperature", temperature_c, "degC", "Water temperature (for auto absorption)",
                   closed(-2.5, 40,
                          "seawater freezes near -1.9 degC; 40 degC is above the warmest natural water (shallow "
                          "lagoons, about 35 degC)")),
        VKS_NUMBER("salinity", salinity_ppt, "ppt", "Salinity (for auto absorption)",
                   closed(0, 45, "fresh water to the saltiest open sea (Red Sea, about 41 ppt)")),
        VKS_NUMBER("water_depth", water_depth_m, "m", "Depth of the sonar (for auto absorption)",
                   closed(0, 11000, "the surface to the Challenger Deep (about 10 935 m)")),
        VKS_NUMBER("ph", ph, "", "pH (for auto absorption)",
                   closed(6, 9, "natural waters: seawater 7.5 to 8.4, fresh water mostly 6 to 9")),

        VKS_ENUM("vertical_pattern", BeamPattern, vertical_pattern, "box|sinc|hann|gaussian|chebyshev",
                 "Shape of the vertical beam pattern b_v"),
        VKS_ENUM("horizontal_pattern", BeamPattern, horizontal_pattern, "box|sinc|hann|gaussian|chebyshev",
                 "Shape of the horizontal beam pattern b_h (side lobes)"),
        VKS_NUMBER("vertical_sidelobe_db", vertical_sidelobe_db, "dB",
                   "Side-lobe level of a chebyshev vertical pattern (all equal), re the main lobe, -100 to -10",
                   closed(-100, -10,
                          "below -10 dB the -3 dB beamwidth lies in the main lobe; above -100 dB acosh(R) and cosh "
                          "stay inside float range on the GPU")),
        VKS_NUMBER("horizontal_sidelobe_db", horizontal_sidelobe_db, "dB",
                   "Side-lobe level of a chebyshev horizontal pattern (all equal), re the main lobe, -100 to -10",
                   closed(-100, -10, "as vertical_sidelobe_db")),
        VKS_ENUM("beam_focus", BeamFocus, beam_focus, "dynamic|fixed|none",
                 "Where the receive beams are focused: at every range (the far-field pattern everywhere), at "
                 "focus_range (an acoustic lens), or at infinity (an unfocused array); fixed and none blur the "
                 "horizontal pattern inside the array's far-field distance (sinc and hann patterns)"),
        VKS_NUMBER("element_width", element_width, "wavelengths",
                   "A line array's element width along the array: every echo times the element's pattern "
                   "sinc^2(pi element_width sin theta), theta from broadside; 0: point elements (none)",
                   closed(0, 2,
                          "0: point elements; a 130 deg fan steered without grating lobes needs elements at most "
                          "0.52 wavelengths apart, and an element 2 wavelengths wide has its first null at 30 deg")),
        VKS_NUMBER("focus_range", focus_range_m, "m", "beam_focus fixed: the range the beams are focused at",
                   open_low(0, 1e5, "in front of the array; 100 km as range_max")),

        VKS_ENUM("speckle", SpeckleModel, speckle, "rayleigh|gamma|gaussian",
                 "Speckle model: Exp(1) intensity, Gamma(L, 1/L), or legacy |N(1, sigma)|"),
        VKS_NUMBER("speckle_looks", speckle_looks, "", "Number of looks L of the gamma model, >= 1",
                   closed(1, 1000, "at least one look (fewer is not averaging); 1000 looks leave 0.14 dB of speckle")),
        VKS_NUMBER("speckle_sigma", speckle_gaussian_sigma, "", "Sigma of the legacy gaussian model, >= 0",
                   closed(0, 10,
                          "0: no speckle; far above 1, |N(1, sigma)| is a half-normal gain, not speckle (the legacy "
                          "plugin uses 0.1)")),
        VKS_ENUM("beam_correlation", BeamCorrelation, beam_correlation, "pattern|none",
                 "Speckle and ambient noise from beam to beam: correlated as the receive beams' overlap correlates "
                 "them (pattern: grains about a beamwidth wide; Rayleigh speckle, gamma speckle of a whole number "
                 "of looks up to 16, and the noise), or drawn per cell (none: as earlier builds)"),
        VKS_NUMBER("tvg_db_per_decade", tvg_db_per_decade, "dB/decade",
                   "Time-varied gain k in k log10 r + 2 alpha r (when effects.tvg is on)",
                   closed(0, 60,
                          "0: none; 20 (volume scattering), 30 (a seabed at grazing incidence, pulse-limited) and 40 "
                          "(point targets, two-way spherical spreading) are the spreading laws; 60 is past all of "
                          "them")),

        VKS_NUMBER(
            "display.db_min", db_min, "dB re 1 uPa", "Intensity shown as black (display value 0)",
            closed(-100, 300, "dB re 1 uPa: below any noise floor to beyond any sound in water; below display.db_max")),
        VKS_NUMBER("display.db_max", db_max, "dB re 1 uPa", "Intensity shown as full scale (display value 1)",
                   closed(-100, 300, "as display.db_min")),
        VKS_ENUM("display.colormap", Colormap, colormap, "gray|viridis|sonar|jet", "Colormap of the PNG images"),
        VKS_COUNT("display.fan_width", fan_width_px, "px", "Width of the fan image",
                  closed(16, 16384, "a readable fan to the largest image vksonar writes")),

        VKS_NUMBER("accuracy.pixels_per_beam", pixels_per_beam, "",
                   "Depth-pass pixel columns per beam spacing (horizontal oversampling), > 0",
                   open_low(0, 64, "above 0; past 64 columns per beam the pass costs without resolving more")),
        VKS_COUNT("accuracy.rows_per_vfov", rows_per_vfov, "", "Depth-pass pixel rows per vertical beamwidth, >= 1",
                  closed(1, 4096, "one row to the tallest depth pass (4096 rows)")),
        VKS_NUMBER("accuracy.vertical_coverage", vertical_coverage, "",
                   "Depth pass covers at least this many vertical beamwidths, >= 1; physical mode: also the "
                   "vertical pattern to its first null, at every azimuth of a slice",
                   closed(1, 10, "the beam itself to its pattern tails 10 beamwidths out")),
        VKS_NUMBER("accuracy.max_slice", max_slice_deg, "deg", "Widest perspective slice of the depth pass, (0, 120]",
                   open_low(0, 120, "a perspective slice wider than 120 deg stretches its edge pixels by over 4x")),
        VKS_ENUM("accuracy.normal_method", NormalMethod, normal_method, "sobel3|sobel5|geometric",
                 "Normal estimation: Sobel 3x3 / 5x5 on depth, or the triangles' face normals (not with a host depth "
                 "image)"),
        VKS_ENUM("accuracy.range_kernel", RangeKernel, range_kernel, "nearest|tent|footprint",
                 "Range kernel K_r: nearest bin, split between the two nearest bins, or spread over the "
                 "pixel's own range extent (down its column and along its row)"),
        VKS_NUMBER("accuracy.sidelobe_kernel_beamwidths", sidelobe_kernel_beamwidths, "",
                   "Side-lobe kernel reaches +- this many beamwidths, >= 0",
                   closed(0, 1000, "0: main lobe only; 1000 beamwidths is past any fan")),
        VKS_NUMBER("accuracy.far_sidelobe_cell", far_sidelobe_cell, "",
                   "Far side lobes beyond the kernel's reach, on a grid of cells this fraction of the reach wide",
                   closed(0, 1, "0: no far side lobes (the kernel stops at its reach)")),
        VKS_NUMBER("accuracy.tier_pixel_ratio", tier_pixel_ratio, "",
                   "Vertical side lobes: the tier views' pixels at most this many times a slice's (in angle)",
                   closed(1, 4, "as fine as the slices' to the coarsest that holds the side lobes (4x)")),
        VKS_ENUM("accuracy.intermediates", IntermediatePrecision, intermediates, "fp32|fp16",
                 "Storage of the per-pixel echo buffer (energy scaled by a power of 2, slant range); fp16 "
                 "halves its memory traffic and rounds both to 11 significant bits"),
        VKS_ENUM("cpu.precision", Precision, cpu_precision, "float|double", "Arithmetic of the CPU backend"),
        VKS_ENUM("cpu.vector_loops", CpuVectorLoops, cpu_vector_loops, "auto|off",
                 "The CPU backend's vector loops (AVX2): auto where the CPU has them, off: the portable loops "
                 "(the same bytes; for tests)"),

        VKS_EFFECT(incidence, "cos(theta) terms, the normals pass (auto: on if a drawn material is lambert or rough)"),
        VKS_EFFECT(vertical_pattern, "Vertical beam pattern b_v^2 (auto: on)"),
        VKS_EFFECT(vertical_sidelobes,
                   "The vertical pattern's side lobes at every elevation, the altitude return (auto: on with a "
                   "line array and a pattern that has side lobes)"),
        VKS_EFFECT(
            horizontal_pattern,
            "Side lobes along beams (auto: on; main lobe only when the side lobes stay below the display window)"),
        VKS_EFFECT(spreading, "Two-way spherical spreading r^-4 (auto: on)"),
        VKS_EFFECT(absorption, "Absorption (auto: on if 2 alpha range_max >= 0.1 dB)"),
        VKS_EFFECT(speckle, "Speckle (auto: on)"),
        VKS_EFFECT(ambient_noise, "Ambient noise floor (auto: on)"),
        VKS_EFFECT(tvg, "Time-varied gain (auto: off)"),

        VKS_TEXT("scene.asset_root", scene_asset_root,
                 "Folder that files named inside the scene must lie in (empty: the scene's folder; CLI --asset-root)"),
        VKS_NUMBER(
            "scene.scale", scene_scale, "", "Scale applied to the scene as it loads (0.001: a model in mm)",
            closed(1e-6, 1e6, "a unit mistake is at most km for mm (1e6); beyond that it is not a unit mistake")),
    };
}

#undef VKS_NUMBER
#undef VKS_COUNT
#undef VKS_TEXT
#undef VKS_ENUM
#undef VKS_EFFECT

bool parse_double(const std::string& text, double& out) {
    // Spaces around the number are the shell's, not the value's (" 16" and "16 " alike); hexadecimal
    // ("0x10", "0x1p3", which strtod reads) is no config number a person means.
    const auto first = text.find_first_not_of(" \t"), last = text.find_last_not_of(" \t");
    if (first == std::string::npos) return false;
    const std::string number = text.substr(first, last - first + 1);
    if (number.find_first_of("xX") != std::string::npos) return false;
    errno = 0;
    char* end = nullptr;
    out = std::strtod(number.c_str(), &end);
    return end == number.c_str() + number.size();
}

std::string markdown_cell(std::string text) {
    std::string out;
    for (char ch : text) {
        if (ch == '|')
            out += "\\|";
        else
            out += ch;
    }
    return out;
}

std::string format_number(double value) {
    std::ostringstream out;
    out.precision(10);
    out << value;
    return out.str();
}

} // namespace

std::string range_text(const KeyRange& range) {
    const bool low = range.min > -std::numeric_limits<double>::infinity();
    const bool high = range.max < std::numeric_limits<double>::infinity();
    if (low && high)
        return std::string(range.min_open ? "(" : "[") + format_number(range.min) + ", " + format_number(range.max) +
               (range.max_open ? ")" : "]");
    if (low) return std::string(range.min_open ? "> " : ">= ") + format_number(range.min);
    if (high) return std::string(range.max_open ? "< " : "<= ") + format_number(range.max);
    return "any";
}

std::string check_ranges(const SonarConfig& config) {
    for (const auto& key : all()) {
        if (!key.range.bounded()) continue;
        const Json value = key.get(config);
        if (!value.is_number()) continue; // text, choices, lists, and "auto"
        const double x = value.get<double>();
        if (!key.range.contains(x)) {
            std::string unit = key.unit;
            return std::string(key.name) + " = " + format_number(x) + ": must be in " + range_text(key.range) +
                   (unit.empty() ? "" : " " + unit);
        }
    }
    return {};
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j)
        row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diagonal = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t above = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
            diagonal = above;
        }
    }
    return row[b.size()];
}

const std::vector<ConfigKey>& all() {
    static const std::vector<ConfigKey> table = make_table();
    return table;
}

const ConfigKey* find(std::string_view name) {
    for (const auto& key : all())
        if (name == key.name) return &key;
    return nullptr;
}

bool is_group(std::string_view prefix) {
    if (prefix.empty()) return false;
    for (const auto& key : all()) {
        const std::string_view name = key.name;
        if (name.size() > prefix.size() && name.compare(0, prefix.size(), prefix) == 0 && name[prefix.size()] == '.')
            return true;
    }
    return false;
}

std::string closest(std::string_view name) {
    std::string best;
    std::size_t best_distance = std::numeric_limits<std::size_t>::max();
    for (const auto& key : all()) {
        const std::string_view full = key.name;
        std::size_t distance = edit_distance(name, full);
        // "db_min" should find "display.db_min": also compare with the part after the group.
        const auto dot = full.rfind('.');
        if (dot != std::string_view::npos && name.find('.') == std::string_view::npos)
            distance = std::min(distance, edit_distance(name, full.substr(dot + 1)) + 1);
        if (distance < best_distance) {
            best_distance = distance;
            best = key.name;
        }
    }
    return best;
}

Json parse_override_value(const ConfigKey& key, const std::string& text) {
    double number = 0;
    switch (key.type) {
    case KeyType::text:
    case KeyType::choice:
        return text;
    case KeyType::number:
    case KeyType::count:
        if (parse_double(text, number)) return number;
        return text; // the setter reports "expected a number, got ..."
    case KeyType::number_or_auto:
        if (text != "auto" && parse_double(text, number)) return number;
        return text;
    case KeyType::number_list: {
        // Accept "[1, 2, 3]", "1,2,3" and "" (an empty table).
        std::string body = text;
        if (!body.empty() && body.front() == '[' && body.back() == ']') body = body.substr(1, body.size() - 2);
        Json list = Json::array();
        std::stringstream stream(body);
        std::string item;
        bool any = false;
        while (std::getline(stream, item, ',')) {
            any = true;
            const auto first = item.find_first_not_of(" \t");
            const auto last = item.find_last_not_of(" \t");
            item = first == std::string::npos ? std::string() : item.substr(first, last - first + 1);
            if (parse_double(item, number))
                list.push_back(number);
            else
                list.push_back(item);
        }
        if (!any && body.find_first_not_of(" \t") != std::string::npos) return text;
        return list;
    }
    }
    return text;
}

std::string reference_markdown() {
    const SonarConfig defaults;
    std::string out;
    out += "| key | type | unit | default | range | description | why this range |\n";
    out += "|---|---|---|---|---|---|---|\n";
    for (const auto& key : all()) {
        std::string type;
        switch (key.type) {
        case KeyType::number:
            type = "number";
            break;
        case KeyType::count:
            type = "integer";
            break;
        case KeyType::text:
            type = "string";
            break;
        case KeyType::choice:
            type = key.choices;
            break;
        case KeyType::number_list:
            type = "array of numbers";
            break;
        case KeyType::number_or_auto:
            type = "number or \"auto\"";
            break;
        }
        std::string default_text = key.get(defaults).dump();
        if (default_text == "\"\"" || default_text == "[]") default_text = "(empty)";
        out += "| `" + std::string(key.name) + "` | " + markdown_cell(type) + " | " + markdown_cell(key.unit) + " | " +
               markdown_cell(default_text) + " | " +
               (key.range.bounded() ? markdown_cell(range_text(key.range)) : std::string()) + " | " +
               markdown_cell(key.doc) + " | " + markdown_cell(key.range.reason) + " |\n";
    }
    return out;
}

} // namespace vksonar::config_keys
