// Colormaps for the display images, [0, 1] -> 8-bit RGB, inline: the fan image calls one per pixel
// (about 600,000 a frame at the default, 1024 x 580), so its loop is built once per map with the map's
// formula in it (FanRenderer::render) instead of a call and a switch per pixel. host::colormap is the
// same values.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "vksonar/config.h"

namespace vksonar::host {

struct Rgb8 {
    std::uint8_t r, g, b;
};

namespace colormaps {

struct Knot {
    float r, g, b;
};

// matplotlib's viridis sampled at 16 evenly spaced points (t = i / 15; R's viridis(16)), linearly
// interpolated between them: within ~2 levels of the 256-entry table everywhere.
inline constexpr Knot kViridis[] = {
    {68, 1, 84},    {72, 26, 108},  {71, 47, 125},  {65, 68, 135},  {57, 86, 140},  {49, 104, 142},
    {42, 120, 142}, {35, 136, 142}, {31, 152, 139}, {34, 168, 132}, {53, 183, 121}, {84, 197, 104},
    {122, 209, 81}, {165, 219, 54}, {210, 226, 27}, {253, 231, 37},
};

// "Sonar display" amber ramp: black -> dark brown -> orange -> amber -> pale yellow/white
// (evenly spaced knots).
inline constexpr Knot kSonar[] = {
    {0, 0, 0},      {40, 16, 2},    {96, 42, 6},     {168, 80, 10},
    {232, 128, 18}, {255, 180, 60}, {255, 222, 140}, {255, 250, 225},
};

template <std::size_t N> inline Rgb8 interpolate(const Knot (&table)[N], float v) {
    const float x = v * static_cast<float>(N - 1);
    const std::size_t i = std::min(static_cast<std::size_t>(x), N - 2);
    const float t = x - static_cast<float>(i);
    const Knot& a = table[i];
    const Knot& b = table[i + 1];
    auto channel = [t](float p, float q) {
        return static_cast<std::uint8_t>(std::clamp(p + (q - p) * t + 0.5f, 0.0f, 255.0f));
    };
    return {channel(a.r, b.r), channel(a.g, b.g), channel(a.b, b.b)};
}

inline std::uint8_t to8(float x) {
    return static_cast<std::uint8_t>(std::clamp(x, 0.0f, 1.0f) * 255.0f + 0.5f);
}

} // namespace colormaps

// value01 outside [0, 1] is clamped, NaN is 0.
template <Colormap Map> inline Rgb8 colormap_of(float value01) {
    using namespace colormaps;
    const float v = std::isnan(value01) ? 0.0f : std::clamp(value01, 0.0f, 1.0f);
    if constexpr (Map == Colormap::gray) {
        const std::uint8_t g = to8(v);
        return {g, g, g};
    } else if constexpr (Map == Colormap::viridis) {
        return interpolate(kViridis, v);
    } else if constexpr (Map == Colormap::sonar) {
        return interpolate(kSonar, v);
    } else {
        // MATLAB jet: dark blue -> blue -> cyan -> yellow -> red -> dark red.
        return {to8(1.5f - std::abs(4.0f * v - 3.0f)), to8(1.5f - std::abs(4.0f * v - 2.0f)),
                to8(1.5f - std::abs(4.0f * v - 1.0f))};
    }
}

} // namespace vksonar::host
