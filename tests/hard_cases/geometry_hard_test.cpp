// Hard cases (docs/hard_cases.md), geometry: grazing incidence, surfaces at the edges of the range window,
// nothing in view, the sonar inside a closed mesh, degenerate triangles, a scene 1e5 m from the
// origin, moving scene and sonar together, range_max/range_min = 1e4, hfov 360 and 1 degree,
// 1 and 4096 beams. Every case runs on both backends and checks every stage for NaN/Inf.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include "hard_cases/hard_support.h"

namespace vksonar::testing::hard {
namespace {

using Mat4 = std::array<double, 16>;

Mat4 multiply(const Mat4& a, const Mat4& b) {
    Mat4 c{};
    for (int col = 0; col < 4; ++col)
        for (int row = 0; row < 4; ++row)
            for (int k = 0; k < 4; ++k)
                c[col * 4 + row] += a[k * 4 + row] * b[col * 4 + k];
    return c;
}

// [R | t] with R = Rz(yaw) Ry(pitch) Rx(roll): the pose convention of include/vksonar/scene.h.
Mat4 rigid(const Pose& pose) {
    const double cr = std::cos(pose.roll_deg * kDeg), sr = std::sin(pose.roll_deg * kDeg);
    const double cp = std::cos(pose.pitch_deg * kDeg), sp = std::sin(pose.pitch_deg * kDeg);
    const double cy = std::cos(pose.yaw_deg * kDeg), sy = std::sin(pose.yaw_deg * kDeg);
    const Mat4 rz{cy, sy, 0, 0, -sy, cy, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
    const Mat4 ry{cp, 0, -sp, 0, 0, 1, 0, 0, sp, 0, cp, 0, 0, 0, 0, 1};
    const Mat4 rx{1, 0, 0, 0, 0, cr, sr, 0, 0, -sr, cr, 0, 0, 0, 0, 1};
    Mat4 m = multiply(rz, multiply(ry, rx));
    m[12] = pose.x_m, m[13] = pose.y_m, m[14] = pose.z_m;
    return m;
}

// A scene with a seabed, a facing plate, a tilted plate and a box, every draw pre-multiplied by `place`.
Scene structured_scene(const Mat4& place) {
    Scene scene;
    const auto put = [&](const Mat4& m) { return multiply(place, m); };
    add_mesh_draw(scene, {0, -30, 0, 45, -30, 0, 45, 30, 0, 0, 30, 0}, {0, 1, 2, 0, 2, 3}, put(translation(0, 0, -4)),
                  -30.0);
    add_mesh_draw(scene, {0, -1.5f, -1, 0, 1.5f, -1, 0, 1.5f, 1, 0, -1.5f, 1}, {0, 1, 2, 0, 2, 3},
                  put(translation(12, 3, -3)), -15.0);
    const double a = 35 * kDeg;
    add_mesh_draw(scene, {0, -2, -1, 0, 2, -1, 0, 2, 1, 0, -2, 1}, {0, 1, 2, 0, 2, 3},
                  put({std::cos(a), std::sin(a), 0, 0, -std::sin(a), std::cos(a), 0, 0, 0, 0, 1, 0, 20, -5, -2.5, 1}),
                  -20.0, AcousticMaterial::Model::constant);
    add_box(scene, {-1, -1, -1}, {1, 1, 1}, -18.0, AcousticMaterial::Model::lambert, put(translation(8, -2, -3)));
    return scene;
}

// Cell-by-cell dB comparison over cells above `floor_rel` x peak of either frame.
struct DbDiff {
    double max_db = 0;
    std::size_t compared = 0, over = 0;
};
DbDiff compare_db(const Frame& a, const Frame& b, double floor_rel, double over_db) {
    DbDiff d;
    double peak = 0;
    for (std::size_t i = 0; i < a.clean.size(); ++i)
        peak = std::max({peak, double(a.clean[i]), double(b.clean[i])});
    const double floor = floor_rel * peak;
    for (std::size_t i = 0; i < a.clean.size(); ++i) {
        if (a.clean[i] < floor && b.clean[i] < floor) continue;
        ++d.compared;
        const double diff = std::abs(to_db(std::max<double>(a.clean[i], floor * 1e-3)) -
                                     to_db(std::max<double>(b.clean[i], floor * 1e-3)));
        d.max_db = std::max(d.max_db, diff);
        d.over += diff > over_db;
    }
    return d;
}

// ---- grazing incidence ---------------------------------------------------------------------------

// A flat seabed h = 0.5 m below a level sonar that sees it out to 60 m (cos incidence down to 0.0083),
// with patterns and absorption off to isolate the geometry.
constexpr double kSeabedDepth = 0.5;
SonarConfig grazing_seabed_config() {
    SonarConfig config = small_config();
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.range_max_m = 60.0;
    return config;
}
void add_grazing_seabed(Scene& scene, const AcousticMaterial& material) {
    add_mesh_draw(scene, {0.2f, -80, 0, 80, -80, 0, 80, 80, 0, 0.2f, 80, 0}, {0, 1, 2, 0, 2, 3},
                  translation(0, 0, -kSeabedDepth), material);
}

TEST_P(HardCase, GrazingSeabedEchoFallsSmoothlyToZeroTowardsTheHorizon) {
    // A pixel at elevation -psi hits the seabed at r = h / sin(psi) with cos(incidence) = sin(psi), so
    // E_p / Omega_p = mu sin(psi) / r^2 = mu sin^3(psi) / h^2: it goes to 0 smoothly as the ray approaches
    // the horizon.
    SonarConfig config = grazing_seabed_config();
    // Rows fine enough that some lie between the horizon and 1 degree below it (the row spacing near the
    // horizon is 2 tan_half_v / rows: 1.3 degrees at 16 rows per beamwidth, 0.65 at 32).
    config.rows_per_vfov = 32;
    const double h = kSeabedDepth, mu_db = -20.0;
    Scene scene;
    AcousticMaterial material;
    material.backscatter_db = mu_db;
    add_grazing_seabed(scene, material);
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    const double mu = std::pow(10.0, mu_db / 10.0);
    const double du = 2 * plan.tan_half_h / plan.slice_columns, dv = 2 * plan.tan_half_v / plan.rows;
    // The most grazing pixel of this grid: the smallest sin(psi) of a pixel-centre ray that meets the
    // seabed inside the range gate (slant range h / sin(psi) < gate_max: the echo stage's cut, a kernel
    // half-width past range_max).
    double grazing_cos = 1;
    for (std::uint32_t c = 0; c < plan.columns; ++c) {
        const double u = (2.0 * (c % plan.slice_columns + 0.5) / plan.slice_columns - 1) * plan.tan_half_h;
        for (std::uint32_t j = 0; j < plan.rows; ++j) {
            const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
            const double sin_psi = v / std::sqrt(1 + u * u + v * v);
            if (sin_psi > 0 && h / sin_psi < plan.gate_max_m) grazing_cos = std::min(grazing_cos, sin_psi);
        }
    }
    ASSERT_LT(grazing_cos, std::sin(1.0 * kDeg)) << "the grid must reach grazing (psi -> asin(h / range_max))";
    double max_rel = 0, min_cos = 1;
    int columns_checked = 0;
    for (std::uint32_t c = 0; c < plan.columns; ++c) {
        const double u = (2.0 * (c % plan.slice_columns + 0.5) / plan.slice_columns - 1) * plan.tan_half_h;
        double previous = -1; // E / Omega of the row below: must shrink row by row towards the horizon
        int hits = 0;
        for (std::uint32_t j = plan.rows; j-- > 0;) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            if (f.echo[2 * p] <= 0) continue;
            const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
            const double len = std::sqrt(1 + u * u + v * v);
            const double sin_psi = v / len; // ray (camera) (u, v, 1): down component v
            ASSERT_GT(sin_psi, 0.0) << "only rays pointing down reach the seabed";
            const double omega = du * dv / (len * len * len);
            const double expected = mu * sin_psi * sin_psi * sin_psi / (h * h); // E / Omega
            const double got = f.echo[2 * p] / omega;
            // Sobel on an exact plane gives cos to 1e-3 absolute (tests/stages/normals_test.cpp); relative to
            // cos = sin(psi) >= 0.5/60 that is up to 12%. Range from float depth: 1e-4 (tolerances.h), 2e-4 in r^2.
            const double rel = std::abs(got - expected) / expected;
            EXPECT_LE(std::abs(got - expected), 1.1e-3 * mu * sin_psi * sin_psi / (h * h) + 3e-4 * expected)
                << "column " << c << " row " << j;
            max_rel = std::max(max_rel, rel);
            min_cos = std::min(min_cos, double(f.normals[4 * p + 3]));
            // Monotone towards the horizon (rows decrease upwards): strictly smaller, never a spike.
            if (previous >= 0) {
                EXPECT_LT(got, previous) << "column " << c << " row " << j;
            }
            previous = got;
            ++hits;
        }
        columns_checked += hits > 10;
    }
    std::printf("[grazing seabed] max rel error of E/Omega %.2e, smallest cos %.4f\n", max_rel, min_cos);
    EXPECT_EQ(columns_checked, int(plan.columns));
    // The most grazing pixel is seen, with the Sobel's cos (1e-3 absolute on an exact plane).
    EXPECT_NEAR(min_cos, grazing_cos, 1e-3) << "the view must reach grazing (psi -> asin(h / range_max))";
}

TEST_P(HardCase, RoughSeabedAtGrazingIsFiniteAndTurnsIntoLambertExactly) {
    // The grazing seabed, once Lambert and once rough with the widest lobe allowed
    // (m = 1) and a perfect reflector (R^2 = 1): the facet term exp(-tan^2 / (2 m^2)) / cos^5 must stay
    // finite as cos -> 0.0083 and be exactly 0 past its cut (exponent argument 80: cos < 0.0787 at
    // m = 1), so there the rough echo is the Lambert echo to the bit.
    const SonarConfig config = grazing_seabed_config();
    std::unique_ptr<Rendered> rendered[2];
    for (int rough = 0; rough < 2; ++rough) {
        Scene scene;
        AcousticMaterial material;
        material.backscatter_db = -20.0;
        if (rough) {
            material.model = AcousticMaterial::Model::rough;
            material.rms_slope = 1.0;
            material.reflection_db = 0.0;
        }
        add_grazing_seabed(scene, material);
        rendered[rough] = render_checked(GetParam(), config, scene); // every stage finite
        ASSERT_TRUE(rendered[rough]);
    }
    const Frame& lambert = rendered[0]->frame;
    const Frame& rough = rendered[1]->frame;
    const shared::MaterialGpu& mat = renderer_plan(rendered[1]->renderer).materials.back(); // after "default"
    ASSERT_EQ(mat.model, shared::kScatterRough);
    int cut = 0, lobe = 0;
    for (std::size_t p = 0; p < lambert.echo.size() / 2; ++p) {
        if (lambert.echo[2 * p] <= 0) continue;
        const double c = rough.normals[4 * p + 3];
        ASSERT_EQ(c, lambert.normals[4 * p + 3]) << "same geometry, same normals";
        const double a = mat.inv_two_slope_sq;
        if ((1 - c * c) * a >= 80 * c * c) {
            EXPECT_EQ(rough.echo[2 * p], lambert.echo[2 * p]) << "pixel " << p << " cos " << c;
            ++cut;
        } else {
            // rough / lambert = f / cos = 1 + ratio exp(-(1/c^2 - 1) a) / c^6, in double from the cosine; the
            // float path's exponent argument (<= 80) carries ~4 roundings: 80 * 2.4e-7 relative on the facet term.
            const double facet = mat.specular_ratio * std::exp(-(1 / (c * c) - 1) * a) / std::pow(c, 6);
            const double got = double(rough.echo[2 * p]) / lambert.echo[2 * p];
            EXPECT_NEAR(got, 1 + facet, 2e-5 * facet + 1e-6) << "pixel " << p << " cos " << c;
            ++lobe;
        }
    }
    std::printf("[rough grazing] %d pixels past the facet cut (bit-equal to Lambert), %d on the lobe's tail\n", cut,
                lobe);
    EXPECT_GT(cut, 100) << "the view must reach past the cut";
    EXPECT_GT(lobe, 10) << "and the lobe's tail before it";
}

TEST_P(HardCase, GrazingPlateEchoTendsToZeroMonotonicallyInAngle) {
    SonarConfig config = small_config();
    config.effects.vertical_pattern = EffectMode::off;
    config.effects.horizontal_pattern = EffectMode::off;
    config.effects.absorption = EffectMode::off;
    config.pixels_per_beam = 8.0; // 512 columns over 60 deg: 0.117 deg per column
    config.rows_per_vfov = 64;    // 128 rows over 40 deg: 0.31 deg per row
    const double mu_db = -20.0, half = 1.0, distance = 10.0;
    const double angles[] = {0, 20, 40, 60, 70, 80, 85, 90};
    double previous = std::numeric_limits<double>::infinity();
    for (double deg : angles) {
        Scene scene;
        add_quad(scene, distance, 0.0, 0.0, 2 * half, 2 * half, mu_db, deg);
        auto r = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(r);
        const Plan& plan = renderer_plan(r->renderer);
        const double e = echo_total(r->frame);
        EXPECT_NEAR(total(r->frame.clean), e, 1e-5 * e) << "beamforming keeps the energy (patterns off)";
        if (deg == 90) {
            // Edge-on: the plate projects onto a line through no pixel centre: exactly nothing.
            EXPECT_EQ(e, 0.0);
            EXPECT_EQ(total(r->frame.clean), 0.0);
            continue;
        }
        const double expected = plate_reference(deg * kDeg, half, distance, std::pow(10.0, mu_db / 10.0));
        // Pixel-centre sampling misplaces each straight edge by at most half a pixel: relative error
        // <= 1 / columns covered + 1 / rows covered (the model and the solid angles are exact).
        const double column_rad = config.hfov_deg * kDeg / plan.columns;
        const double row_rad = 2 * std::atan(plan.tan_half_v) / plan.rows;
        const double width_rad = 2 * half * std::cos(deg * kDeg) / distance, height_rad = 2 * half / distance;
        const double bound = 1.0 / (width_rad / column_rad) + 1.0 / (height_rad / row_rad);
        std::printf("[grazing plate] %4.0f deg: E / reference = %.4f (bound %.3f)\n", deg, e / expected, bound);
        EXPECT_NEAR(e / expected, 1.0, bound) << deg << " deg";
        EXPECT_LT(e, previous) << deg << " deg";
        previous = e;
    }
}

// ---- the range window -----------------------------------------------------------------------------

TEST_P(HardCase, SurfaceExactlyAtRangeMaxIsOutAndJustInsideLandsInTheLastBin) {
    SonarConfig config = small_config();
    Scene at_max;
    add_quad(at_max, config.range_max_m, 0.0, 0.0, 20.0, 20.0); // every slant range >= range_max
    {
        // The nearest-bin kernel records a point return in its own bin only: nothing at r >= range_max.
        SonarConfig nearest = config;
        nearest.range_kernel = RangeKernel::nearest;
        auto a = render_checked(GetParam(), nearest, at_max);
        ASSERT_TRUE(a);
        EXPECT_EQ(total(a->frame.clean), 0.0) << "r >= range_max is outside the window";
    }
    // The default footprint kernel on a facing plate (its pixels' ranges equal: a footprint of one bin)
    // is the tent, which splits a return between the two nearest bin centres: on axis, at exactly
    // range_max, half goes to the last bin and half beyond the window, where it is dropped. So the last
    // bin gets half of what the same plate gives at the last bin's centre, where all of it lands there,
    // times the two-way loss over the half bin between (r^-2 of a facing plate's pixels, whose solid
    // angles are the same, and the absorption). The plates (0.5 x 1 m at 40 m) cover the pixels
    // nearest the axis, whose rays are longer than the axis by L = |(u, v, 1)|: at slant range r L each
    // gives the last bin (centre r_c) the share 1 - (r L - r_c) / w of the tent (the rest lies past it),
    // 1 % less of it for L - 1 = 8e-5 at this grid; that share is part of the expected ratio.
    ASSERT_EQ(config.range_kernel, RangeKernel::footprint);
    Scene at_centre;
    const double w = (config.range_max_m - config.range_min_m) / config.bins;
    add_quad(at_centre, config.range_max_m - 0.5 * w, 0.0, 0.0, 0.5, 1.0);
    Scene small_at_max;
    add_quad(small_at_max, config.range_max_m, 0.0, 0.0, 0.5, 1.0);
    auto centre = render_checked(GetParam(), config, at_centre);
    auto edge = render_checked(GetParam(), config, small_at_max);
    ASSERT_TRUE(centre && edge);
    // The pixel rays that meet the plate at range_max (half sizes 0.25 m across, 0.5 m up): all at the
    // same |u| and |v| (the grid is symmetric about the axis), so one L for all of them.
    const Plan& plan = renderer_plan(edge->renderer);
    double L = 0;
    std::size_t covered = 0;
    for (std::uint32_t j = 0; j < plan.rows; ++j) {
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const double u = (2.0 * (c + 0.5) / plan.columns - 1) * plan.tan_half_h;
            const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
            if (std::abs(u) * config.range_max_m >= 0.25 || std::abs(v) * config.range_max_m >= 0.5) continue;
            const double length = std::sqrt(1 + u * u + v * v);
            if (covered++ > 0) {
                ASSERT_NEAR(length, L, 1e-12) << "pixels at different distances from the axis";
            }
            L = length;
        }
    }
    ASSERT_EQ(plan.slices, 1u);
    ASSERT_GT(covered, 0u);
    const auto last_bin = [](const Frame& f) {
        double s = 0;
        for (std::uint32_t j = 0; j < f.beams; ++j)
            s += f.clean[std::size_t(f.bins - 1) * f.beams + j];
        return s;
    };
    const double r_c = config.range_max_m - 0.5 * w, r_m = config.range_max_m;
    const double share_edge = 1 - (r_m * L - r_c) / w, share_centre = 1 - (r_c * L - r_c) / w;
    const double expected = share_edge / share_centre * (r_c * r_c) / (r_m * r_m) *
                            std::pow(10.0, -2.0 * config.absorption_db_per_m * (r_m - r_c) / 10.0);
    ASSERT_GT(last_bin(centre->frame), 0.0);
    EXPECT_NEAR(last_bin(edge->frame) / last_bin(centre->frame), expected, 0.01 * expected);
    EXPECT_NEAR(last_bin(edge->frame), total(edge->frame.clean), 1e-6 * total(edge->frame.clean))
        << "nothing of it anywhere but the last bin";

    // A plate 10 mm inside range_max on axis, covering the same pixels nearest the axis: their rays are
    // L times the axis (8e-5 longer at this grid), so their slant ranges are 39.99 L = 39.993 m < range_max,
    // inside the last bin [39.69, 40) m; nothing out of bounds.
    ASSERT_LT((config.range_max_m - 1e-2) * L, config.range_max_m);
    Scene inside;
    add_quad(inside, config.range_max_m - 1e-2, 0.0, 0.0, 0.5, 1.0);
    auto b = render_checked(GetParam(), config, inside);
    ASSERT_TRUE(b);
    const Frame& f = b->frame;
    double last = 0;
    for (std::uint32_t j = 0; j < f.beams; ++j)
        last += f.clean[std::size_t(f.bins - 1) * f.beams + j];
    EXPECT_GT(last, 0.0);
    EXPECT_NEAR(last, total(f.clean), 1e-6 * last) << "all energy in the last bin";
}

TEST_P(HardCase, SurfaceExactlyAtRangeMinLandsInTheFirstBins) {
    SonarConfig config = small_config();
    Scene scene;
    add_quad(scene, config.range_min_m, 0.0, 0.0, 4.0, 4.0); // fills the view at view z = range_min
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    // Slant ranges run from range_min (axis) to range_min * |(u, v, 1)| at the corners.
    const double corner =
        config.range_min_m * std::sqrt(1 + plan.tan_half_h * plan.tan_half_h + plan.tan_half_v * plan.tan_half_v);
    const int last_bin = int((corner - config.range_min_m) / plan.bin_width_m) + 1; // + 1: kernel spread
    double in = 0, beyond = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        for (std::uint32_t j = 0; j < f.beams; ++j)
            (int(k) <= last_bin ? in : beyond) += f.clean[k * f.beams + j];
    EXPECT_GT(in, 0.0);
    EXPECT_EQ(beyond, 0.0);
    for (std::size_t p = 0; p < f.echo.size() / 2; ++p) {
        if (f.echo[2 * p] > 0) {
            ASSERT_GE(f.echo[2 * p + 1], float(config.range_min_m) * (1 - 1e-6f));
        }
    }
}

// ---- nothing in view, dB of zero -------------------------------------------------------------------

TEST_P(HardCase, NothingInViewGivesZerosAndTheNoiseFloor) {
    SonarConfig config = small_config();
    Scene empty;
    Scene behind; // a wall behind the sonar and one above the vertical coverage: both outside every frustum
    add_quad(behind, -10.0, 0.0, 0.0, 20.0, 20.0);
    add_quad(behind, 5.0, 0.0, 30.0, 4.0, 4.0);
    for (const Scene* scene : {&empty, &behind}) {
        auto r = render_checked(GetParam(), config, *scene);
        ASSERT_TRUE(r);
        const Frame& f = r->frame;
        EXPECT_EQ(total(f.clean), 0.0);
        EXPECT_EQ(echo_total(f), 0.0);
        for (float d : f.depth) {
            ASSERT_EQ(d, 0.0f);
        }
        // No noise: intensity is exactly 0 and its dB is the bottom of the display window, not NaN.
        for (float v : f.intensity) {
            ASSERT_EQ(v, 0.0f);
        }
        for (float v : f.display) {
            ASSERT_EQ(v, 0.0f);
        }
    }
    // With ambient noise the frame is the noise floor: mean N = 10^((NL - DI)/10) (Exp(1) draws).
    config.effects.ambient_noise = EffectMode::on;
    auto r = render_checked(GetParam(), config, empty);
    ASSERT_TRUE(r);
    const double floor = std::pow(10.0, config.noise_terms().floor_db() / 10.0);
    const double mean = total(r->frame.intensity) / r->frame.intensity.size();
    // 8192 Exp(1) draws: standard error 1.1%; 5% is 4.5 sigma.
    EXPECT_NEAR(mean / floor, 1.0, 0.05);
}

// ---- inside a closed mesh -----------------------------------------------------------------------

TEST_P(HardCase, SonarInsideAClosedBoxSeesWallsAllAroundAtTheRightRanges) {
    SonarConfig config = small_config();
    config.hfov_deg = 360.0; // 6 slices: every direction
    config.beams = 128;
    config.horizontal_beamwidth_deg = 3.0;
    Scene scene;
    add_box(scene, {-5, -5, -5}, {5, 5, 5});
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    std::size_t hits = 0, wrong = 0;
    double r_min = 1e9, r_max = 0, farthest = 0;
    for (std::size_t p = 0; p < f.depth.size(); ++p) {
        hits += f.depth[p] > 0;
        // Each pixel-centre ray D = f_s + u r_s + v d (docs/pipeline.md) leaves the box (walls at 5 m) at
        // slant range 5 |D| / max(|D_x|, |D_y|, |D_z|): its range, whatever the grid's coverage.
        const std::uint32_t c = std::uint32_t(p % plan.columns), j = std::uint32_t(p / plan.columns);
        const double u = (2.0 * (c % plan.slice_columns + 0.5) / plan.slice_columns - 1) * plan.tan_half_h;
        const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
        const double phi = plan.slice_info[c / plan.slice_columns].center_azimuth_rad;
        const double D[3] = {std::cos(phi) + u * std::sin(phi), std::sin(phi) - u * std::cos(phi), -v};
        const double expected = 5.0 * std::sqrt(D[0] * D[0] + D[1] * D[1] + D[2] * D[2]) /
                                std::max({std::abs(D[0]), std::abs(D[1]), std::abs(D[2])});
        farthest = std::max(farthest, expected);
        if (f.echo[2 * p] > 0) {
            r_min = std::min(r_min, double(f.echo[2 * p + 1]));
            r_max = std::max(r_max, double(f.echo[2 * p + 1]));
            // Float depth: 1e-4 relative (tolerances.h).
            wrong += std::abs(f.echo[2 * p + 1] - expected) > 1e-4 * expected;
        }
    }
    EXPECT_EQ(hits, f.depth.size()) << "every ray hits a wall";
    EXPECT_EQ(wrong, 0u) << "pixels whose slant range is not their ray's exit from the box";
    // Walls at 5 m; the farthest pixel ray leaves through a vertical edge (5 sqrt(2) horizontally) at
    // the top or bottom of the coverage.
    EXPECT_GE(r_min, 5.0 * (1 - 1e-4));
    EXPECT_LE(r_max, farthest * (1 + 1e-4));
    EXPECT_GT(farthest, 5.0 * std::sqrt(2.0));
    const int k_lo = int((5.0 - config.range_min_m) / plan.bin_width_m) - 1;
    const int k_hi = int((r_max - config.range_min_m) / plan.bin_width_m) + 1;
    double outside = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        for (std::uint32_t j = 0; j < f.beams; ++j)
            if (int(k) < k_lo || int(k) > k_hi) outside += f.clean[k * f.beams + j];
    EXPECT_GT(total(f.clean), 0.0);
    EXPECT_EQ(outside, 0.0);
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        EXPECT_GT(beam_energy(f, j), 0.0) << "beam " << j;
    }
}

// ---- degenerate triangles -------------------------------------------------------------------------

TEST_P(HardCase, DegenerateTrianglesAddNothing) {
    SonarConfig config = small_config();
    Scene clean_scene, with_degenerates;
    for (Scene* s : {&clean_scene, &with_degenerates})
        add_quad(*s, 10.0, 0.0, 0.0, 4.0, 4.0);
    // In view at 8 m: collinear, a repeated vertex, all three at one point, a 1e-9 m sliver,
    // and a triangle whose vertices coincide in float after the world transform.
    add_mesh_draw(with_degenerates, {8, -1,   0,    8, 0,    0,     8, 1,    0,    //
                                     8, -1,   -1,   8, 1,    1,     8, 1,    1,    //
                                     8, 0.5f, 0.5f, 8, 0.5f, 0.5f,  8, 0.5f, 0.5f, //
                                     8, -1,   0,    8, 1,    1e-9f, 8, 0,    0.5e-9f},
                  {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11}, translation(0, 0, 0));
    auto a = render_checked(GetParam(), config, clean_scene);
    auto b = render_checked(GetParam(), config, with_degenerates);
    ASSERT_TRUE(a && b);
    EXPECT_GT(total(a->frame.clean), 0.0);
    EXPECT_EQ(a->frame.depth, b->frame.depth) << "a zero-area triangle covers no pixel centre";
    EXPECT_EQ(a->frame.clean, b->frame.clean);
}

// ---- far from the origin, rigid motion ---------------------------------------------------------------

// Renders structured_scene placed by `place` from pose `place * local_pose` and compares with the scene
// at the origin seen from local_pose. The host composes view x model in double (docs/pipeline.md, "Frames and grids"),
// so the float matrices uploaded differ by rounding only.
void expect_same_frame_when_moved_together(Backend backend, const Pose& move, const char* label,
                                           double max_db_allowed) {
    SonarConfig config = small_config();
    config.rows_per_vfov = 32;
    Pose local;
    local.pitch_deg = 12, local.yaw_deg = 5, local.roll_deg = 3, local.x_m = 1, local.y_m = -0.5;
    const Scene here = structured_scene(translation(0, 0, 0));
    const Scene there = structured_scene(rigid(move));
    // The moved pose: rigid(move) * rigid(local) as (position, roll, pitch, yaw). Only yaw composes
    // exactly with a moved yaw; `move` has roll = pitch = 0 so the angles add.
    ASSERT_EQ(move.roll_deg, 0.0);
    ASSERT_EQ(move.pitch_deg, 0.0);
    const Mat4 m = multiply(rigid(move), rigid(local));
    Pose moved = local;
    moved.x_m = m[12], moved.y_m = m[13], moved.z_m = m[14];
    moved.yaw_deg = local.yaw_deg + move.yaw_deg;
    auto a = render_checked(backend, config, here, local);
    auto b = render_checked(backend, config, there, moved);
    ASSERT_TRUE(a && b);
    const DbDiff d = compare_db(a->frame, b->frame, 1e-6, 0.01);
    std::size_t depth_flips = 0;
    for (std::size_t p = 0; p < a->frame.depth.size(); ++p)
        depth_flips += (a->frame.depth[p] > 0) != (b->frame.depth[p] > 0);
    std::printf("[%s] %zu cells compared, max diff %.2e dB, %zu over 0.01 dB, %zu coverage flips\n", label, d.compared,
                d.max_db, d.over, depth_flips);
    ASSERT_GT(d.compared, 100u);
    EXPECT_LE(d.max_db, max_db_allowed) << label;
}

TEST_P(HardCase, SceneAndSonar1e5mFromTheOriginRenderLikeAtTheOrigin) {
    // Translation only: world coordinates of 1e5 m carry ~1e-11 m of double rounding, far below
    // float's 1e-6 relative; the frames must agree to float rounding: 1e-3 dB.
    Pose move;
    move.x_m = 1e5, move.y_m = -1e5, move.z_m = 1e5;
    expect_same_frame_when_moved_together(GetParam(), move, "1e5 m from origin", 1e-3);
}

TEST_P(HardCase, MovingAndRotatingSceneAndSonarTogetherLeavesTheFrameUnchanged) {
    // A rotation by 37 deg re-rounds every uploaded matrix entry (relative 6e-8), which moves
    // triangle edges by ~1e-6 pixel: pixel centres that close to an edge are rare; energy per cell
    // changes by float rounding of the per-pixel math: 1e-3 dB.
    Pose move;
    move.x_m = 123.25, move.y_m = -45.5, move.z_m = 6.0, move.yaw_deg = 37.0;
    expect_same_frame_when_moved_together(GetParam(), move, "rigid motion", 1e-3);
}

// ---- extreme windows and fans -------------------------------------------------------------------------

TEST_P(HardCase, RangeRatio1e4ResolvesANearAndAFarTarget) {
    SonarConfig config = small_config();
    config.range_min_m = 0.01;
    config.range_max_m = 100.0; // ratio 1e4
    config.bins = 1000;         // 0.1 m bins
    config.effects.horizontal_pattern = EffectMode::off;
    Scene scene;
    const double a = 10 * kDeg;
    add_quad(scene, 0.5 * std::cos(a), 0.5 * std::sin(a), 0.0, 0.1, 0.1, -20.0, 10.0);        // near, port
    add_quad(scene, 80.0 * std::cos(-a), 80.0 * std::sin(-a), 0.0, 10.0, 10.0, -10.0, -10.0); // far, starboard
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    // Split the scan at beam azimuth 0: port = near target, starboard = far target.
    double e_near = 0, r_near = 0, e_far = 0, r_far = 0;
    for (std::uint32_t k = 0; k < f.bins; ++k)
        for (std::uint32_t j = 0; j < f.beams; ++j) {
            const double e = f.clean[k * f.beams + j];
            (plan.beam_angle_rad[j] > 0 ? e_near : e_far) += e;
            (plan.beam_angle_rad[j] > 0 ? r_near : r_far) += e * plan.bin_range_m[k];
        }
    ASSERT_GT(e_near, 0.0);
    ASSERT_GT(e_far, 0.0);
    // Near plate: ranges 0.5..0.5036 m; far plate: 80..80.3 m (corners). Centroids within 1 bin + extent.
    EXPECT_NEAR(r_near / e_near, 0.5, plan.bin_width_m + 0.004);
    EXPECT_NEAR(r_far / e_far, 80.0, plan.bin_width_m + 0.3);
    // Echo ranges of the far plate against the exact slant range of each pixel ray to the plane
    // n.X = 80 with n = (cos a, -sin a, 0): reversed-Z float keeps 1e-4 relative (tolerances.h) even
    // with near/far = 1e-4.
    double max_rel = 0;
    const double du = 2 * plan.tan_half_h / plan.slice_columns;
    for (std::uint32_t j = 0; j < plan.rows; ++j)
        for (std::uint32_t c = 0; c < plan.columns; ++c) {
            const std::size_t p = std::size_t(j) * plan.columns + c;
            if (f.echo[2 * p] <= 0 || f.echo[2 * p + 1] < 10) continue;
            const double u = -plan.tan_half_h + (c % plan.slice_columns + 0.5) * du;
            const double v = (2.0 * (j + 0.5) / plan.rows - 1) * plan.tan_half_v;
            const double phi = plan.slice_info[c / plan.slice_columns].center_azimuth_rad;
            const double D[3] = {std::cos(phi) + u * std::sin(phi), std::sin(phi) - u * std::cos(phi), -v};
            const double t = 80.0 / (std::cos(a) * D[0] - std::sin(a) * D[1]);
            const double exact = t * std::sqrt(D[0] * D[0] + D[1] * D[1] + D[2] * D[2]);
            max_rel = std::max(max_rel, std::abs(f.echo[2 * p + 1] - exact) / exact);
        }
    std::printf("[range ratio 1e4] far-plate slant range max rel error %.2e\n", max_rel);
    EXPECT_LE(max_rel, 1e-4);
}

// Four identical plates at 10 m, at azimuth 0, +90, -90 and 180 deg.
Scene four_plates() {
    Scene scene;
    for (double deg : {0.0, 90.0, -90.0, 180.0}) {
        add_quad(scene, 10 * std::cos(deg * kDeg), 10 * std::sin(deg * kDeg), 0.0, 2.0, 2.0, -20.0, deg);
    }
    return scene;
}

TEST_P(HardCase, Hfov360SeesEveryDirectionWithEqualEnergy) {
    SonarConfig config = small_config();
    config.hfov_deg = 360.0;
    config.beams = 360;
    config.horizontal_beamwidth_deg = 1.0;
    config.effects.horizontal_pattern = EffectMode::off;
    config.rows_per_vfov = 32;
    auto r = render_checked(GetParam(), config, four_plates());
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    const Frame& f = r->frame;
    EXPECT_EQ(plan.slices, 6u);
    EXPECT_NEAR(total(f.clean), echo_total(f), 1e-5 * echo_total(f)) << "pattern off: beamforming keeps energy";
    // Energy per quadrant: a plate at 0 deg straddles two slices, at 90 it sits mid-slice, at 180 it
    // straddles the +-180 seam (beam 0 and beam 359). Exact pixel solid angles make them equal up to
    // half a pixel per edge: 1 / 19 columns + 1 / 18 rows (2 m at 10 m = 11.4 deg; 0.375 deg columns,
    // 0.625 deg rows).
    double quadrant[4] = {0, 0, 0, 0}; // 0, +90, 180, -90
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        const double az = plan.beam_angle_rad[j] / kDeg;
        const int q = std::abs(az) < 45 ? 0 : (az >= 45 && az < 135) ? 1 : (az <= -45 && az > -135) ? 3 : 2;
        quadrant[q] += beam_energy(f, j);
    }
    const double column_deg = 360.0 / plan.columns, row_deg = 2 * std::atan(plan.tan_half_v) / kDeg / plan.rows;
    const double bound = column_deg / 11.4 + row_deg / 11.4;
    for (int q = 1; q < 4; ++q) {
        EXPECT_NEAR(quadrant[q] / quadrant[0], 1.0, 2 * bound) << "quadrant " << q;
    }
    std::printf("[hfov 360] quadrant energy / quadrant 0: %.4f %.4f %.4f (bound %.3f)\n", quadrant[1] / quadrant[0],
                quadrant[2] / quadrant[0], quadrant[3] / quadrant[0], 2 * bound);
    // The seam: both edge beams see the plate at 180 deg.
    EXPECT_GT(beam_energy(f, 0), 0.0);
    EXPECT_GT(beam_energy(f, f.beams - 1), 0.0);
}

TEST_P(HardCase, Hfov360IsRotationallySymmetricAcrossTheSeamWithSideLobes) {
    // A full circle has no edge: beam 0 (+179.5 deg) and beam 359 (-179.5 deg) are neighbours. A plate
    // at 180 deg must give the same beam profile as the same plate at 0 deg, rotated by 180 beams,
    // side lobes included. Slice boundaries lie at 0 and 180 deg alike, so the pixel grids are mirror
    // images and the only differences are float rounding (1e-4 of the beam energy).
    SonarConfig config = small_config();
    config.hfov_deg = 360.0;
    config.beams = 360;
    config.horizontal_beamwidth_deg = 1.5; // side-lobe kernel: +-4.5 deg, 9 beams each side
    config.rows_per_vfov = 16;
    Scene front, back;
    add_quad(front, 10.0, 0.0, 0.0, 1.0, 1.0);
    add_quad(back, -10.0, 0.0, 0.0, 1.0, 1.0, -20.0, 180.0);
    auto a = render_checked(GetParam(), config, front);
    auto b = render_checked(GetParam(), config, back);
    ASSERT_TRUE(a && b);
    ASSERT_TRUE(renderer_plan(a->renderer).effects.horizontal_pattern);
    double peak = 0;
    for (std::uint32_t j = 0; j < a->frame.beams; ++j)
        peak = std::max(peak, beam_energy(a->frame, j));
    ASSERT_GT(peak, 0.0);
    double max_rel = 0;
    for (std::uint32_t j = 0; j < a->frame.beams; ++j) {
        const double ea = beam_energy(a->frame, j), eb = beam_energy(b->frame, (j + 180) % 360);
        max_rel = std::max(max_rel, std::abs(ea - eb) / peak);
        EXPECT_NEAR(eb, ea, 1e-4 * peak) << "beam " << j << " vs " << (j + 180) % 360;
    }
    std::printf("[hfov 360 seam] max |front - back rotated| / peak = %.2e\n", max_rel);
}

TEST_P(HardCase, Hfov1DegreeLightsEveryBeamOfAFacingPlateAndNothingBeside) {
    SonarConfig config = small_config();
    config.hfov_deg = 1.0;
    config.beams = 8;
    config.horizontal_beamwidth_deg = 0.125;
    config.effects.horizontal_pattern = EffectMode::off;
    config.effects.vertical_pattern = EffectMode::off;
    Scene facing, beside;
    add_quad(facing, 10.0, 0.0, 0.0, 1.0, 4.0);                       // covers +-2.9 deg: the whole fan
    add_quad(beside, 10.0, 10.0 * std::tan(3 * kDeg), 0.0, 0.2, 4.0); // 2.4..3.6 deg: outside the fan
    auto a = render_checked(GetParam(), config, facing);
    auto b = render_checked(GetParam(), config, beside);
    ASSERT_TRUE(a && b);
    EXPECT_EQ(total(b->frame.clean), 0.0);
    const Frame& f = a->frame;
    double mean = total(f.clean) / f.beams;
    ASSERT_GT(mean, 0.0);
    // Over 1 deg, cos(incidence), range and pixel solid angle vary by < 1e-4; every beam gathers the
    // same total column weight (2 columns per beam, edge beams included): equal to 1e-3.
    for (std::uint32_t j = 0; j < f.beams; ++j) {
        EXPECT_NEAR(beam_energy(f, j) / mean, 1.0, 1e-3) << "beam " << j;
    }
}

TEST_P(HardCase, OneBeamGathersAllEnergy) {
    SonarConfig config = small_config();
    config.beams = 1;
    config.horizontal_beamwidth_deg = 60.0;
    Scene scene;
    add_quad(scene, 10.0, 2.0, 0.0, 3.0, 3.0);
    add_quad(scene, 20.0, -8.0, -1.0, 3.0, 3.0);
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    EXPECT_EQ(plan.beam_angle_rad.size(), 1u);
    EXPECT_EQ(plan.beam_angle_rad[0], 0.0);
    EXPECT_EQ(plan.sidelobe_taps, 1u);
    // The energy into the resample: the range profiles (the pixels' echo, and here the quads' sub-pixel
    // returns: two pixel columns of 30 degrees make 3 m quads at 10 and 20 m "a few pixels across", drawn
    // silent, their echo added by the profile step; docs/pipeline.md "Sub-pixel objects").
    const double e = total(r->frame.profiles);
    ASSERT_GT(e, 0.0);
    // Every column maps to the single beam with weight 1: energy in = energy out, float sums (1e-5).
    EXPECT_NEAR(total(r->frame.clean), e, 1e-5 * e);
}

TEST_P(HardCase, FourThousandNinetySixBeamsPlaceATargetOnItsBeam) {
    SonarConfig config = small_config();
    config.hfov_deg = 130.0;
    config.beams = 4096; // 8192 columns
    config.horizontal_beamwidth_deg = 0.5;
    // The kernel's exact part only: the far side lobes (tests/far_sidelobes_test.cpp) would give every
    // beam of the fan some energy and pull the centroid towards the fan's wider side.
    config.far_sidelobe_cell = 0.0;
    config.rows_per_vfov = 8;
    config.bins = 64;
    Scene scene;
    const double a = 10 * kDeg;
    add_quad(scene, 10 * std::cos(a), 10 * std::sin(a), 0.0, 0.5, 1.0, -20.0, 10.0);
    auto r = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(r);
    const Plan& plan = renderer_plan(r->renderer);
    EXPECT_GE(plan.columns, 8192u);
    const Centroid c = centroid(r->frame, plan);
    ASSERT_GT(c.energy, 0.0);
    const double spacing = plan.beam_angle_rad[0] - plan.beam_angle_rad[1];
    // A symmetric plate (+-1.43 deg) and a symmetric side-lobe kernel: the centroid is on its axis to
    // within a beam spacing (0.032 deg).
    EXPECT_NEAR(c.azimuth_rad, a, spacing);
    // Nothing beyond the plate's edge plus the side-lobe reach (3 beamwidths) plus one spacing.
    const double reach = std::atan(0.25 / 10) + config.sidelobe_kernel_beamwidths * 0.5 * kDeg + spacing;
    for (std::uint32_t j = 0; j < r->frame.beams; ++j) {
        if (std::abs(plan.beam_angle_rad[j] - a) > reach) {
            ASSERT_EQ(beam_energy(r->frame, j), 0.0) << "beam " << j;
        }
    }
}

INSTANTIATE_TEST_SUITE_P(Backends, HardCase, ::testing::Values(Backend::vulkan, Backend::cpu), backend_name);

} // namespace
} // namespace vksonar::testing::hard
