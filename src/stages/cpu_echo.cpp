// CPU reference of the echo stage (docs/pipeline.md §3): per pixel slant range, solid angle,
// vertical pattern, scattering factor and the combined sonar equation of shaders/sonar_math.h.
//
// Constants: float reads the shaders' float values (SonarParams); double reads the Plan's doubles.
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "core/half.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {

template <class Real>
void echo(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2) {
    using M = Math<Real>;
    const shared::SonarParams& g = plan.params;
    Real tan_h, tan_v, depth_a, depth_b, gate_min, gate_max, alpha, vk, vhalf, vcheb; // gate: Plan::gate_min_m
    if constexpr (std::is_same_v<Real, float>) {
        tan_h = g.tan_half_h;
        tan_v = g.tan_half_v;
        depth_a = g.depth_a;
        depth_b = g.depth_b;
        gate_min = g.gate_min_m;
        gate_max = g.gate_max_m;
        alpha = g.alpha_db_per_m;
        vk = g.vpattern_k;
        vhalf = g.vpattern_halfwidth_rad;
        vcheb = g.vpattern_chebyshev_a;
    } else {
        tan_h = plan.tan_half_h;
        tan_v = plan.tan_half_v;
        depth_a = plan.depth_a;
        depth_b = plan.depth_b;
        gate_min = plan.gate_min_m;
        gate_max = plan.gate_max_m;
        alpha = plan.alpha_db_per_m;
        vk = plan.vpattern_k;
        vhalf = plan.vpattern_halfwidth_rad;
        vcheb = plan.vpattern_chebyshev_a;
    }
    const std::uint32_t vshape = g.vpattern_shape;
    const bool incidence = plan.effects.incidence && normals4 != nullptr;
    const bool vertical = plan.effects.vertical_pattern;
    const bool spreading = plan.effects.spreading;
    const bool absorption = plan.effects.absorption;
    const std::uint32_t C = plan.columns, R = plan.rows, W = plan.slice_columns;
    const Real du = Real(2) * tan_h / static_cast<Real>(W);
    const Real dv = Real(2) * tan_v / static_cast<Real>(R);
    const std::size_t material_count = plan.materials.size();

    for (std::uint32_t j = 0; j < R; ++j) {
        const Real v = M::pixel_coord(j, R, tan_v);
        for (std::uint32_t c = 0; c < C; ++c) {
            const std::size_t p = static_cast<std::size_t>(j) * C + c;
            float* out = echo2 + 2 * p;
            const float d = depth[p];
            if (!(d > 0.0f)) {
                out[0] = out[1] = 0.0f;
                continue;
            }
            const Real u = M::pixel_coord(c % W, W, tan_h);
            const Real z = M::view_z_from_depth(static_cast<Real>(d), depth_a, depth_b);
            const Real r = M::slant_range(z, u, v);
            if (r < gate_min || r >= gate_max || material_count == 0) {
                out[0] = 0.0f;
                out[1] = static_cast<float>(r);
                continue;
            }
            std::uint32_t m = material[p];
            if (m == shared::kNoMaterial || m >= material_count) m = 0;
            const shared::MaterialGpu& mat = plan.materials[m];
            const Real f = incidence ? M::scatter_factor(mat.model, static_cast<Real>(normals4[4 * p + 3]),
                                                         static_cast<Real>(mat.specular_ratio),
                                                         static_cast<Real>(mat.inv_two_slope_sq))
                                     : Real(1);
            const Real omega = M::pixel_solid_angle(u, v, du, dv);
            const Real b = vertical ? M::pattern_power(vshape, vk, vhalf, vcheb, M::pixel_elevation(u, v)) : Real(1);
            const Real e =
                M::echo_energy(static_cast<Real>(mat.backscatter_linear), f, omega, r, alpha, b, spreading, absorption);
            out[0] = static_cast<float>(e);
            out[1] = static_cast<float>(r);
        }
    }
    if (g.echo_half != 0u) {
        // fp16 storage, as echo.comp stores it: energy * echo_scale (a power of 2) and range as halves.
        const std::size_t pixels = static_cast<std::size_t>(R) * C;
        for (std::size_t p = 0; p < pixels; ++p) {
            echo2[2 * p] = round_to_half(echo2[2 * p] * g.echo_scale) / g.echo_scale;
            echo2[2 * p + 1] = round_to_half(echo2[2 * p + 1]);
        }
    }
}

template void echo<float>(const Plan&, const float*, const std::uint32_t*, const float*, float*);
template void echo<double>(const Plan&, const float*, const std::uint32_t*, const float*, float*);

} // namespace vksonar::cpu
