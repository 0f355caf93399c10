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
void echo_rows(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2,
               std::uint32_t row_begin, std::uint32_t row_end) {
    using M = Math<Real>;
    const shared::SonarParams& g = plan.params;
    typename M::EchoConstants k;
    if constexpr (std::is_same_v<Real, float>) {
        k = {g.tan_half_h,
             g.tan_half_v,
             0.0f,
             0.0f,
             g.depth_a,
             g.depth_b,
             g.gate_min_m,
             g.gate_max_m,
             g.alpha_db_per_m,
             g.vpattern_k,
             g.vpattern_halfwidth_rad,
             g.vpattern_chebyshev_a};
    } else {
        k = {plan.tan_half_h,
             plan.tan_half_v,
             0.0,
             0.0,
             plan.depth_a,
             plan.depth_b,
             plan.gate_min_m,
             plan.gate_max_m,
             plan.alpha_db_per_m,
             plan.vpattern_k,
             plan.vpattern_halfwidth_rad,
             plan.vpattern_chebyshev_a};
    }
    const std::uint32_t C = plan.columns, R = plan.rows, W = plan.slice_columns;
    k.pixel_du = Real(2) * k.tan_half_h / static_cast<Real>(W);
    k.pixel_dv = Real(2) * k.tan_half_v / static_cast<Real>(R);
    const typename M::EchoTerms terms{plan.effects.incidence && normals4 != nullptr,
                                      plan.rough_materials,
                                      plan.effects.vertical_pattern,
                                      g.vpattern_shape,
                                      plan.effects.spreading,
                                      plan.effects.absorption};
    const auto material_count = static_cast<std::uint32_t>(plan.materials.size());

    for (std::uint32_t j = row_begin; j < row_end; ++j) {
        const Real v = M::pixel_coord(j, R, k.tan_half_v);
        for (std::uint32_t c = 0; c < C; ++c) {
            const std::size_t p = static_cast<std::size_t>(j) * C + c;
            float* out = echo2 + 2 * p;
            const float d = depth[p];
            if (!(d > 0.0f) || material_count == 0) {
                out[0] = 0.0f;
                out[1] = 0.0f;
                continue;
            }
            const Real u = M::pixel_coord(c % W, W, k.tan_half_h);
            const shared::MaterialGpu& mat = plan.materials[M::material_index(material[p], material_count)];
            const Real cos_incidence = terms.incidence ? static_cast<Real>(normals4[4 * p + 3]) : Real(0);
            const auto e = M::echo_of_pixel(k, terms, static_cast<Real>(d), u, v, mat, cos_incidence);
            out[0] = static_cast<float>(e.x);
            out[1] = static_cast<float>(e.y);
        }
    }
    if (g.echo_half != 0u) {
        // fp16 storage, as echo.comp stores it: energy * echo_scale (a power of 2) and range as halves.
        const std::size_t end = static_cast<std::size_t>(row_end) * C;
        for (std::size_t p = static_cast<std::size_t>(row_begin) * C; p < end; ++p) {
            echo2[2 * p] = round_to_half(echo2[2 * p] * g.echo_scale) / g.echo_scale;
            echo2[2 * p + 1] = round_to_half(echo2[2 * p + 1]);
        }
    }
}

template <class Real>
void echo(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2) {
    echo_rows<Real>(plan, depth, material, normals4, echo2, 0, plan.rows);
}

template void echo<float>(const Plan&, const float*, const std::uint32_t*, const float*, float*);
template void echo<double>(const Plan&, const float*, const std::uint32_t*, const float*, float*);
template void echo_rows<float>(const Plan&, const float*, const std::uint32_t*, const float*, float*, std::uint32_t,
                               std::uint32_t);
template void echo_rows<double>(const Plan&, const float*, const std::uint32_t*, const float*, float*, std::uint32_t,
                                std::uint32_t);

} // namespace vksonar::cpu
