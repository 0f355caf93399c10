// CPU reference of the echo stage (docs/pipeline.md §3): per pixel slant range, solid angle,
// vertical pattern, scattering factor and the combined sonar equation of shaders/sonar_math.h.
//
// Constants: float reads the shaders' float values (SonarParams); double reads the Plan's doubles.
// The factors that depend on the pixel's place in the grid alone (its solid angle and the vertical
// pattern) come from a table made once per plan (echo_table), by the kernels echo_of_pixel calls.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/half.h"
#include "core/pixel_views.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_stages.h"

namespace vksonar::cpu {

// Per view of W columns: u per column (W), then (solid angle, vertical power) per pixel (R x W); view s's
// table starts at its first column times (1 + 2 R).
std::size_t echo_table_count(const Plan& plan) {
    return static_cast<std::size_t>(plan.columns) * (1 + 2 * static_cast<std::size_t>(plan.rows));
}

namespace {
std::size_t echo_table_offset(const Plan& plan, std::uint32_t view) {
    return static_cast<std::size_t>(view_first_column(plan, view)) * (1 + 2 * static_cast<std::size_t>(plan.rows));
}
} // namespace

template <class Real> void echo_table(const Plan& plan, Real* table) {
    using M = Math<Real>;
    // the terms without incidence: the table does not depend on it
    const typename M::EchoTerms terms = echo_terms<Real>(plan, false);
    const std::uint32_t R = plan.rows;
    for (std::uint32_t s = 0; s < plan.views; ++s) {
        const std::uint32_t W = view_columns(plan, s);
        const typename M::EchoConstants k = echo_constants<Real>(plan, s);
        const typename M::PixelView view = pixel_view<Real>(plan, s);
        Real* u = table + echo_table_offset(plan, s);
        Real* pixel = u + W;
        for (std::uint32_t x = 0; x < W; ++x)
            u[x] = M::pixel_coord(x, W, k.tan_half_h);
        for (std::uint32_t j = 0; j < R; ++j) {
            const Real v = M::pixel_coord(j, R, k.tan_half_v);
            for (std::uint32_t x = 0; x < W; ++x, pixel += 2) {
                pixel[0] = M::pixel_solid_angle(u[x], v, k.pixel_du, k.pixel_dv);
                pixel[1] = M::pixel_vertical_power(k, terms, u[x], v, view);
            }
        }
    }
}

// echo_of_pixel (shaders/sonar_kernels.h, as echo.comp calls it) with its per-pixel-place factors, the
// solid angle and the vertical power, read from echo_table: the same functions of the same values.
template <class Real>
void echo_rows(const Plan& plan, const float* depth, const std::uint32_t* material, const float* normals4, float* echo2,
               const Real* table, std::uint32_t row_begin, std::uint32_t row_end, const std::uint8_t* view_drawn) {
    using M = Math<Real>;
    const shared::SonarParams& g = plan.params;
    const typename M::EchoTerms terms = echo_terms<Real>(plan, normals4 != nullptr);
    const std::uint32_t C = plan.columns, R = plan.rows;
    const auto material_count = static_cast<std::uint32_t>(plan.materials.size());

    for (std::uint32_t s = 0; s < plan.views; ++s) {
        const typename M::EchoConstants k = echo_constants<Real>(plan, s);
        const Real* u = table + echo_table_offset(plan, s);
        const std::uint32_t c0 = view_first_column(plan, s), W = view_columns(plan, s);
        if (view_drawn != nullptr && view_drawn[s] == 0) { // nothing drawn there: no hits
            for (std::uint32_t j = row_begin; j < row_end; ++j)
                std::fill(echo2 + 2 * (static_cast<std::size_t>(j) * C + c0),
                          echo2 + 2 * (static_cast<std::size_t>(j) * C + c0 + W), 0.0f);
            continue;
        }
        for (std::uint32_t j = row_begin; j < row_end; ++j) {
            const Real v = M::pixel_coord(j, R, k.tan_half_v);
            const Real* row_terms = u + W + 2 * static_cast<std::size_t>(j) * W;
            for (std::uint32_t x = 0; x < W; ++x) {
                const std::size_t p = static_cast<std::size_t>(j) * C + c0 + x;
                float* out = echo2 + 2 * p;
                const float d = depth[p];
                if (!(d > 0.0f) || material_count == 0) {
                    out[0] = 0.0f;
                    out[1] = 0.0f;
                    continue;
                }
                const Real r = M::depth_slant_range(k, static_cast<Real>(d), u[x], v);
                if (r < k.gate_min_m || r >= k.gate_max_m) { // echo_of_pixel's gate
                    out[0] = 0.0f;
                    out[1] = static_cast<float>(r);
                    continue;
                }
                const shared::MaterialGpu& mat = plan.materials[M::material_index(material[p], material_count)];
                const Real cos_incidence = terms.incidence ? static_cast<Real>(normals4[4 * p + 3]) : Real(0);
                const auto e =
                    M::echo_at_range(k, terms, r, mat, cos_incidence, row_terms[2 * x], row_terms[2 * x + 1]);
                out[0] = static_cast<float>(e.x);
                out[1] = static_cast<float>(e.y);
            }
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
    std::vector<Real> table(echo_table_count(plan));
    echo_table<Real>(plan, table.data());
    echo_rows<Real>(plan, depth, material, normals4, echo2, table.data(), 0, plan.rows);
}

template void echo<float>(const Plan&, const float*, const std::uint32_t*, const float*, float*);
template void echo<double>(const Plan&, const float*, const std::uint32_t*, const float*, float*);
template void echo_table<float>(const Plan&, float*);
template void echo_table<double>(const Plan&, double*);
template void echo_rows<float>(const Plan&, const float*, const std::uint32_t*, const float*, float*, const float*,
                               std::uint32_t, std::uint32_t, const std::uint8_t*);
template void echo_rows<double>(const Plan&, const float*, const std::uint32_t*, const float*, float*, const double*,
                                std::uint32_t, std::uint32_t, const std::uint8_t*);

} // namespace vksonar::cpu
