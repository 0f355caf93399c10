// Shared between import_depth.comp and src/vk/host_depth.cpp: the push constants of the import pass
// that turns a host engine's depth image into vksonar's depth buffer (docs/embedding.md). Kept apart
// from sonar_shared.h because only the embedding path uses it; same rules (scalars only, size assert).
#ifndef VKSONAR_HOST_DEPTH_SHARED_H
#define VKSONAR_HOST_DEPTH_SHARED_H

#ifdef __cplusplus
#include <cstdint>
namespace vksonar::shared {
using uint = std::uint32_t;
#define VKS_CONST constexpr
#else
#define VKS_CONST const
#endif

// ImportDepthPush.encoding
VKS_CONST uint kHostDepthStandard = 0u; // d = 0 at near, 1 at far; 1 = no hit
VKS_CONST uint kHostDepthReversed = 1u; // d = 1 at near, 0 at far; 0 = no hit
VKS_CONST uint kHostDepthLinear = 2u;   // d = view z in metres; <= 0, NaN, inf = no hit

// Perspective encodings invert as z = near_m / (z_a + z_b * d):
//   standard: z_a = 1, z_b = -(1 - near/far); reversed: z_a = near/far, z_b = 1 - near/far (far = inf: 0, 1).
struct ImportDepthPush {
    uint encoding;
    float near_m;
    float z_a;
    float z_b;
};
#ifdef __cplusplus
static_assert(sizeof(ImportDepthPush) == 16, "ImportDepthPush must match the GLSL push constant block");
} // namespace vksonar::shared
#undef VKS_CONST
#endif

#endif
