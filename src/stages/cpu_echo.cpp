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

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "core/half.h"
#include "core/pixel_views.h"
#include "core/sonar_math.hpp"
#include "stages/cpu_simd.h"
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

namespace {

#if defined(__x86_64__) && defined(__GNUC__)
// echo_rows's float loop for the four pixels x .. x + 3 of one view row, as SSE lanes: the operations of
// depth_slant_range, the gate and echo_at_range with echo_energy lane by lane, in the same order (no
// FMA but exp4's own, which gives expf's floats: call only where exp4_matches_expf), out = echo2 at
// the first pixel. Returns false, having written nothing, where a lane needs what only the scalar
// kernel does: a rough material's facet term, or an absorption exponent beyond exp4's range.
// material_count > 0; normals4: at the first pixel, or null without incidence.
__attribute__((target("avx2,fma"), always_inline)) inline bool
echo4(const Math<float>::EchoConstants& k, const Math<float>::EchoTerms& terms, const float* depth,
      const std::uint32_t* material, const float* normals4, const float* u, float v, const float* row_terms,
      const shared::MaterialGpu* materials, std::uint32_t material_count, float* out) {
    const __m128 zero = _mm_setzero_ps();
    const __m128 d = _mm_loadu_ps(depth);
    const __m128 hit = _mm_cmpgt_ps(d, zero);
    if (_mm_movemask_ps(hit) == 0) {
        _mm_storeu_ps(out, zero);
        _mm_storeu_ps(out + 4, zero);
        return true;
    }
    // depth_slant_range: (a / (d - b)) sqrt((1 + u u) + v v)
    const __m128 view_z = _mm_div_ps(_mm_set1_ps(k.depth_a), _mm_sub_ps(d, _mm_set1_ps(k.depth_b)));
    const __m128 uu = _mm_loadu_ps(u);
    const __m128 root = _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(_mm_set1_ps(1.0f), _mm_mul_ps(uu, uu)), _mm_set1_ps(v * v)));
    const __m128 r = _mm_and_ps(hit, _mm_mul_ps(view_z, root));
    // the gate (r < min || r >= max: out), then a vertical power > 0; (solid angle, vertical) pairs
    const __m128 gated =
        _mm_or_ps(_mm_cmplt_ps(r, _mm_set1_ps(k.gate_min_m)), _mm_cmpge_ps(r, _mm_set1_ps(k.gate_max_m)));
    const __m128 pair0 = _mm_loadu_ps(row_terms), pair1 = _mm_loadu_ps(row_terms + 4);
    const __m128 omega = _mm_shuffle_ps(pair0, pair1, _MM_SHUFFLE(2, 0, 2, 0));
    const __m128 vertical = _mm_shuffle_ps(pair0, pair1, _MM_SHUFFLE(3, 1, 3, 1));
    const __m128 live = _mm_and_ps(_mm_andnot_ps(gated, hit), _mm_cmpgt_ps(vertical, zero));
    const int live_mask = _mm_movemask_ps(live);
    __m128 e = zero;
    if (live_mask != 0) {
        // per lane: the material's backscatter (0 in a lane not live) and the scattering factor echo_at_range
        // picks (1 in a lane not live), built in registers: lanes written one by one to memory and read back
        // as a vector stall on store forwarding
        const __m128 one = _mm_set1_ps(1.0f);
        __m128 backscatter, scatter = one;
        const __m128i ids = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(material)),
                                          _mm_set1_epi32(static_cast<int>(shared::kMaterialIdMask)));
        // cos incidence of the four pixels: the w of each normal
        auto normal_w = [&] {
            const __m128 t0 = _mm_unpackhi_ps(_mm_loadu_ps(normals4), _mm_loadu_ps(normals4 + 4));      // z0 z1 w0 w1
            const __m128 t1 = _mm_unpackhi_ps(_mm_loadu_ps(normals4 + 8), _mm_loadu_ps(normals4 + 12)); // z2 z3 w2 w3
            return _mm_movehl_ps(t1, t0);
        };
        if (_mm_movemask_epi8(_mm_cmpeq_epi32(ids, _mm_shuffle_epi32(ids, 0))) == 0xffff) {
            // one material under all four pixels (a seabed): one lookup
            const std::uint32_t id = material[0] & shared::kMaterialIdMask;
            const shared::MaterialGpu& mat = materials[id < material_count ? id : 0u];
            if (terms.incidence && terms.rough_materials && mat.model == shared::kScatterRough) return false;
            backscatter = _mm_and_ps(live, _mm_set1_ps(mat.backscatter_linear));
            if (terms.incidence && mat.model == shared::kScatterLambert) scatter = _mm_blendv_ps(one, normal_w(), live);
        } else {
            float b[4], lambert[4];
            for (int l = 0; l < 4; ++l) {
                b[l] = 0.0f;
                lambert[l] = 0.0f;
                if (!(live_mask & (1 << l))) continue;
                const std::uint32_t id = material[l] & shared::kMaterialIdMask;
                const shared::MaterialGpu& mat = materials[id < material_count ? id : 0u];
                b[l] = mat.backscatter_linear;
                if (terms.incidence && terms.rough_materials && mat.model == shared::kScatterRough) return false;
                if (terms.incidence && mat.model == shared::kScatterLambert) lambert[l] = 1.0f;
            }
            backscatter = _mm_setr_ps(b[0], b[1], b[2], b[3]);
            if (terms.incidence) {
                const __m128 lambert_lanes =
                    _mm_cmpneq_ps(_mm_setr_ps(lambert[0], lambert[1], lambert[2], lambert[3]), zero);
                scatter = _mm_blendv_ps(one, normal_w(), lambert_lanes);
            }
        }
        e = _mm_mul_ps(_mm_mul_ps(_mm_mul_ps(backscatter, scatter), omega), vertical);
        const __m128 r2 = _mm_mul_ps(r, r);
        e = terms.spreading ? _mm_div_ps(e, r2) : _mm_mul_ps(_mm_mul_ps(e, r), r);
        if (terms.absorption) {
            const float rate = -0.2302585092994046f * k.alpha_db_per_m; // echo_energy's first product
            const __m128 exponent = _mm_mul_ps(_mm_mul_ps(_mm_set1_ps(rate), r), _mm_set1_ps(2.0f));
            const __m128 abs_exponent = _mm_andnot_ps(_mm_set1_ps(-0.0f), exponent);
            if ((_mm_movemask_ps(_mm_and_ps(live, _mm_cmpnlt_ps(abs_exponent, _mm_set1_ps(80.0f)))) != 0)) return false;
            e = _mm_mul_ps(e, exp4(_mm256_cvtps_pd(_mm_and_ps(live, exponent))));
        }
        e = _mm_and_ps(live, e);
    }
    _mm_storeu_ps(out, _mm_unpacklo_ps(e, r));
    _mm_storeu_ps(out + 4, _mm_unpackhi_ps(e, r));
    return true;
}

// echo4 along one view row of W pixels from its first (depth, material, normals4 (null without incidence),
// out: at that pixel), four at a time: returns the pixels done, a multiple of 4 (the rest, from the first
// block echo4 declines, take the scalar loop).
__attribute__((target("avx2,fma"))) std::uint32_t
echo_row4(const Math<float>::EchoConstants& k, const Math<float>::EchoTerms& terms, const float* depth,
          const std::uint32_t* material, const float* normals4, const float* u, float v, const float* row_terms,
          const shared::MaterialGpu* materials, std::uint32_t material_count, float* out, std::uint32_t W) {
    std::uint32_t x = 0;
    for (; x + 4 <= W; x += 4)
        if (!echo4(k, terms, depth + x, material + x, normals4 != nullptr ? normals4 + 4 * x : nullptr, u + x, v,
                   row_terms + 2 * x, materials, material_count, out + 2 * x))
            break;
    return x;
}
#else
std::uint32_t echo_row4(const Math<float>::EchoConstants&, const Math<float>::EchoTerms&, const float*,
                        const std::uint32_t*, const float*, const float*, float, const float*,
                        const shared::MaterialGpu*, std::uint32_t, float*, std::uint32_t) {
    return 0;
}
#endif

} // namespace

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
    const bool simd = use_exp4(plan.config);

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
            std::uint32_t x = 0;
            if constexpr (std::is_same_v<Real, float>) {
                // four pixels at a time where echo4 can (the same floats), the others one by one below
                if (simd && material_count > 0) {
                    const std::size_t p = static_cast<std::size_t>(j) * C + c0;
                    x = echo_row4(k, terms, depth + p, material + p, terms.incidence ? normals4 + 4 * p : nullptr, u, v,
                                  row_terms, plan.materials.data(), material_count, echo2 + 2 * p, W);
                }
            }
            for (; x < W; ++x) {
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
