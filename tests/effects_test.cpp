// Effects on demand (README "Effects: only what the scene calls for", issue 5), on both backends. For each effect:
//  - on vs off changes the output the way the model says (the expected values come from the model's
//    closed form in README "The model" / docs/pipeline.md, evaluated here in double, not from the code under test);
//  - off leaves the rest of the frame exactly as a run where the effect was never considered (a
//    config in which the effect's term is the identity, or the stages upstream of the effect);
//  - `auto` resolves from scene + config with a reason, and the plan builds only the passes it needs
//    (asserted on Frame::stages_run and the plan, never on time).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "scene/scene_data.h"
#include "test_support.h"

namespace vksonar::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

class EffectsTest : public BackendTest {};

std::string backend_param_name(const ::testing::TestParamInfo<Backend>& info) {
    return info.param == Backend::vulkan ? "vulkan" : "cpu";
}

// ---- closed forms (README "The model", docs/pipeline.md "Frames and grids"), in double ----------------------

// Power pattern of a uniform line array whose two-way -3 dB beamwidth is `beamwidth_rad`:
// sinc^2(x_3dB sin(a) / sin(bw / 2)).
double sinc_pattern(double beamwidth_rad, double a) {
    const double x = sinc_half_power_x() * std::sin(a) / std::sin(0.5 * beamwidth_rad);
    if (std::abs(x) < 1e-12) return 1.0;
    const double s = std::sin(x) / x;
    return s * s;
}

struct PixelRay {
    double u = 0, v = 0;
    double dir[3] = {0, 0, 0}; // sonar frame, not normalized: f_s + u r_s + v d
};

// Pixel (column c, row j) per the grid contract: slices of equal width side by side, port first.
PixelRay pixel_ray(const Plan& plan, std::uint32_t c, std::uint32_t j) {
    // The grid's azimuths: the fan, or with line_array the wider span its edge cones reach
    // (docs/pipeline.md, "Beam geometry"): the pixel grid as laid out, not a physics reference.
    const double covered = plan.slice_width_rad * plan.slices;
    const std::uint32_t W = plan.slice_columns, s = c / W;
    const double centre = 0.5 * covered - (s + 0.5) * covered / plan.slices;
    const double tan_half_h = std::tan(0.5 * covered / plan.slices);
    const double tan_half_v = std::tan(0.5 * plan.vertical_coverage_rad);
    PixelRay ray;
    ray.u = (2.0 * ((c % W) + 0.5) / W - 1.0) * tan_half_h;
    ray.v = (2.0 * (j + 0.5) / plan.rows - 1.0) * tan_half_v;
    const double f[3] = {std::cos(centre), std::sin(centre), 0.0};
    const double r[3] = {std::sin(centre), -std::cos(centre), 0.0};
    const double d[3] = {0.0, 0.0, -1.0};
    for (int k = 0; k < 3; ++k)
        ray.dir[k] = f[k] + ray.u * r[k] + ray.v * d[k];
    return ray;
}

double pixel_elevation(const PixelRay& ray) {
    return std::atan2(-ray.v, std::sqrt(1.0 + ray.u * ray.u));
}

// Pixels whose 5x5 neighbourhood is all echo (E > 0): away from silhouettes, where the Sobel falls back
// to one-sided differences and the depth rasterizers of the two backends may differ.
std::vector<std::size_t> interior_pixels(const Frame& f) {
    std::vector<std::size_t> out;
    auto lit = [&](std::int64_t c, std::int64_t j) {
        if (c < 0 || j < 0 || c >= f.columns || j >= f.rows) return false;
        return f.echo[2 * (static_cast<std::size_t>(j) * f.columns + static_cast<std::size_t>(c))] > 0.0f;
    };
    for (std::int64_t j = 0; j < f.rows; ++j) {
        for (std::int64_t c = 0; c < f.columns; ++c) {
            bool all = true;
            for (int dj = -2; dj <= 2 && all; ++dj)
                for (int dc = -2; dc <= 2 && all; ++dc)
                    all = lit(c + dc, j + dj);
            if (all) out.push_back(static_cast<std::size_t>(j) * f.columns + static_cast<std::size_t>(c));
        }
    }
    return out;
}

// A thin quad facing the sonar at azimuth `azimuth_rad`, range `range_m` and elevation `elevation_rad`.
void add_facing_quad(Scene& scene, double range_m, double azimuth_rad, double elevation_rad, double width_m,
                     double height_m, AcousticMaterial::Model model = AcousticMaterial::Model::lambert) {
    const double horizontal = range_m * std::cos(elevation_rad);
    add_quad(scene, horizontal * std::cos(azimuth_rad), horizontal * std::sin(azimuth_rad),
             range_m * std::sin(elevation_rad), width_m, height_m, -20.0, azimuth_rad / kDeg, model);
}

SonarConfig clean_config() {
    SonarConfig c = quiet_config(); // speckle, ambient noise and TVG off
    c.absorption_db_per_m = 0.05;   // a fixed alpha so the expected values are simple
    return c;
}

const EffectState* effect_state(const Frame& f, const std::string& name) {
    for (const auto& e : f.effects)
        if (e.name == name) return &e;
    return nullptr;
}

bool ran(const Frame& f, const std::string& stage) {
    return std::find(f.stages_run.begin(), f.stages_run.end(), stage) != f.stages_run.end();
}

// Bit-identical float arrays (EXPECT_EQ on vectors prints megabytes on failure).
::testing::AssertionResult same_bits(const std::vector<float>& a, const std::vector<float>& b) {
    if (a.size() != b.size()) return ::testing::AssertionFailure() << "sizes " << a.size() << " vs " << b.size();
    for (std::size_t i = 0; i < a.size(); ++i) {
        if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0)
            return ::testing::AssertionFailure() << "first difference at " << i << ": " << a[i] << " vs " << b[i];
    }
    return ::testing::AssertionSuccess();
}

constexpr SaveFlags kEchoAndDepth = SaveFlags::echo | SaveFlags::depth;

// ---- incidence -------------------------------------------------------------------------------------

TEST_P(EffectsTest, IncidenceIsLambertCosineOnAndFlatOff) {
    // A 6 x 4 m Lambert quad at 10 m turned 60 deg about z: incidence 60 deg at its centre.
    Scene scene;
    const double yaw = 60.0;
    add_quad(scene, 10.0, 0.0, 0.0, 6.0, 4.0, -20.0, yaw);
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.incidence = EffectMode::on;
    off.effects.incidence = EffectMode::off;
    auto a = render_once(GetParam(), on, scene, {}, kEchoAndDepth | SaveFlags::normals);
    auto b = render_once(GetParam(), off, scene, {}, kEchoAndDepth | SaveFlags::normals);
    ASSERT_TRUE(a && b);
    EXPECT_TRUE(ran(a->frame, "normals"));
    EXPECT_FALSE(ran(b->frame, "normals")); // off: the normals pass is not built at all
    EXPECT_TRUE(same_bits(a->frame.depth, b->frame.depth));

    // Lambert: s(theta) = mu cos^2(theta); with the footprint's 1/cos(theta) the pixel echo scales by
    // cos(theta) (README "The model"). Off: scatter factor 1. So E_on / E_off = cos(theta), with theta between
    // the pixel ray and the plane normal n = (cos yaw, sin yaw, 0).
    const Plan& plan = renderer_plan(a->renderer);
    const double n[3] = {std::cos(yaw * kDeg), std::sin(yaw * kDeg), 0.0};
    const std::vector<std::size_t> interior = interior_pixels(a->frame);
    ASSERT_GT(interior.size(), 1000u);
    double worst = 0;
    for (std::size_t p : interior) {
        const PixelRay ray =
            pixel_ray(plan, static_cast<std::uint32_t>(p % plan.columns), static_cast<std::uint32_t>(p / plan.columns));
        const double len = std::sqrt(ray.dir[0] * ray.dir[0] + ray.dir[1] * ray.dir[1] + ray.dir[2] * ray.dir[2]);
        const double cos_theta = std::abs(n[0] * ray.dir[0] + n[1] * ray.dir[1] + n[2] * ray.dir[2]) / len;
        const double ratio = double(a->frame.echo[2 * p]) / double(b->frame.echo[2 * p]);
        worst = std::max(worst, std::abs(ratio - cos_theta));
        // The contract's tolerance for Sobel normals of a plane from float depth is 1e-3 in cos(theta)
        // (see CpuNormals.TiltedPlaneMatchesClosedFormIncidence); the two float products add ~1e-7.
        ASSERT_NEAR(ratio, cos_theta, 1e-3) << "pixel " << p;
    }
    RecordProperty("worst_cos_error", std::to_string(worst));
    // Not an identity: the ratio spans well below 1 on this plane (cos 60 deg = 0.5 at its centre).
    EXPECT_LT(sum(a->frame.clean), 0.7 * sum(b->frame.clean));
}

TEST_P(EffectsTest, NoAngleDependentMaterialMeansNoNormalsPassAndTheSameFrameAsIncidenceOff) {
    SonarConfig config = clean_config(); // incidence stays auto
    ASSERT_EQ(config.effects.incidence, EffectMode::automatic);
    Scene constant, lambert;
    add_quad(constant, 10.0, 1.0, 0.0, 4.0, 4.0, -20.0, 30.0, AcousticMaterial::Model::constant);
    add_quad(lambert, 10.0, 1.0, 0.0, 4.0, 4.0, -20.0, 30.0, AcousticMaterial::Model::lambert);

    auto c = render_once(GetParam(), config, constant, {}, kEchoAndDepth);
    auto l = render_once(GetParam(), config, lambert, {}, kEchoAndDepth);
    ASSERT_TRUE(c && l);
    // The plan for the constant-only scene has no normals pass; the Lambert scene's has one.
    EXPECT_FALSE(renderer_plan(c->renderer).effects.incidence);
    EXPECT_TRUE(renderer_plan(l->renderer).effects.incidence);
    EXPECT_EQ(c->frame.stages_run, (std::vector<std::string>{"depth", "echo", "beamform", "noise"}));
    EXPECT_EQ(l->frame.stages_run, (std::vector<std::string>{"depth", "normals", "echo", "beamform", "noise"}));
    const EffectState* why = effect_state(c->frame, "incidence");
    ASSERT_NE(why, nullptr);
    EXPECT_FALSE(why->on);
    EXPECT_NE(why->why.find("auto"), std::string::npos) << why->why;
    EXPECT_NE(why->why.find("no normals pass"), std::string::npos) << why->why;

    // Off on the Lambert scene = the effect never considered (constant material, auto -> off):
    // identical bits all the way to the display values.
    SonarConfig off = config;
    off.effects.incidence = EffectMode::off;
    auto o = render_once(GetParam(), off, lambert, {}, kEchoAndDepth);
    ASSERT_TRUE(o);
    EXPECT_EQ(o->frame.stages_run, c->frame.stages_run);
    EXPECT_TRUE(same_bits(o->frame.echo, c->frame.echo));
    EXPECT_TRUE(same_bits(o->frame.clean, c->frame.clean));
    EXPECT_TRUE(same_bits(o->frame.intensity, c->frame.intensity));
    EXPECT_TRUE(same_bits(o->frame.display, c->frame.display));
}

TEST_P(EffectsTest, EveryRenderReportsItsOwnStagesOnce) {
    // The frame is reused for every render: stages_run and times describe the last render only.
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 2.0);
    auto r = render_once(GetParam(), clean_config(), scene);
    ASSERT_TRUE(r);
    const std::vector<std::string> once = r->frame.stages_run;
    EXPECT_EQ(once, (std::vector<std::string>{"depth", "normals", "echo", "beamform", "noise"}));
    for (std::uint64_t i = 1; i <= 3; ++i)
        ASSERT_TRUE(r->renderer.render({}, i, r->frame).ok());
    EXPECT_EQ(r->frame.stages_run, once);
    ASSERT_EQ(r->frame.times.size(), once.size());
    for (std::size_t i = 0; i < once.size(); ++i)
        EXPECT_EQ(r->frame.times[i].stage, once[i]);
}

// ---- vertical beam pattern -------------------------------------------------------------------------

TEST_P(EffectsTest, VerticalPatternWeightsEachPixelByThePatternAtItsElevation) {
    // A quad taller than the depth pass's vertical coverage at 10 m (+-31 deg).
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 2.0, 12.0);
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.vertical_pattern = EffectMode::on;
    off.effects.vertical_pattern = EffectMode::off;
    // The main band's pattern and gate; beyond the gate the tier views' side lobes have their own test
    // (SeabedClosedForm.TheSideLobesBringTheSeabedFromTheAltitudeOn).
    on.effects.vertical_sidelobes = EffectMode::off;
    // The same pixel grid both ways: with the pattern on the coverage reaches at least its first null
    // (23.1 deg for this 20-degree sinc), off it is vertical_coverage x vfov / 2. 2.5 beamwidths (+-25 deg,
    // past the null) is the larger of the two either way, so both renders share rows and tan_half_v.
    on.vertical_coverage = off.vertical_coverage = 2.5;
    ASSERT_EQ(on.vertical_pattern, BeamPattern::sinc);
    auto a = render_once(GetParam(), on, scene, {}, kEchoAndDepth);
    auto b = render_once(GetParam(), off, scene, {}, kEchoAndDepth);
    ASSERT_TRUE(a && b);
    const Plan& plan = renderer_plan(a->renderer);
    ASSERT_EQ(plan.rows, renderer_plan(b->renderer).rows);
    ASSERT_EQ(plan.tan_half_v, renderer_plan(b->renderer).tan_half_v);
    const double vfov = plan.config.vfov_deg * kDeg;
    // Rows at a slice's centre reach past the coverage (they hold it at the slice's edges); every
    // azimuth sees the same elevations: beyond 25 deg the pattern gives nothing. A pixel within a row's
    // height of that gate is partly inside it: between 0 and the pattern there.
    const double gate = 25.0 * kDeg;
    const double row_height = 2.0 * std::atan(plan.tan_half_v) / plan.rows;
    std::size_t checked = 0, gated = 0;
    double min_expected = 1.0;
    for (std::size_t p = 0; p < a->frame.rows * std::size_t(a->frame.columns); ++p) {
        ASSERT_EQ(a->frame.echo[2 * p + 1], b->frame.echo[2 * p + 1]); // same ranges: only the weight changes
        if (!(b->frame.echo[2 * p] > 0.0f)) continue;
        const PixelRay ray =
            pixel_ray(plan, static_cast<std::uint32_t>(p % plan.columns), static_cast<std::uint32_t>(p / plan.columns));
        const double elevation = pixel_elevation(ray);
        const double ratio = double(a->frame.echo[2 * p]) / double(b->frame.echo[2 * p]);
        const double pattern = sinc_pattern(vfov, elevation);
        if (std::abs(std::abs(elevation) - gate) < row_height) {
            ASSERT_LE(ratio, pattern + 1e-4) << "pixel " << p;
            continue;
        }
        const double expected = std::abs(elevation) > gate ? 0.0 : pattern;
        gated += expected == 0.0;
        min_expected = std::min(min_expected, pattern);
        // The shaders evaluate k sin(psi) and sinc^2 in float (k itself is a float uniform): ~1e-6
        // relative in x, and |d sinc^2 / dx| < 1, so 1e-4 absolute leaves two decades of headroom.
        ASSERT_NEAR(ratio, expected, 1e-4) << "pixel " << p;
        ++checked;
    }
    EXPECT_GT(checked, 10000u);
    EXPECT_GT(gated, 100u);       // the slices' centre columns reach past the gate
    EXPECT_LT(min_expected, 0.1); // the quad fills the coverage, past the pattern's first null
}

TEST_P(EffectsTest, VerticalPatternHalvesATargetAtHalfTheBeamwidth) {
    // The vertical beamwidth is the two-way -3 dB width: a small target at elevation vfov/2 returns
    // half of what it returns with the pattern off; one on the axis returns all of it.
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.vertical_pattern = EffectMode::on;
    off.effects.vertical_pattern = EffectMode::off;
    // The same pixel grid both ways (the pattern's first null, 23.1 deg, sets the coverage when it is on;
    // 2.5 beamwidths lies past it), so the target's partly covered edge rows are the same pixels in both.
    on.vertical_coverage = off.vertical_coverage = 2.5;
    const double half = 0.5 * on.vfov_deg * kDeg;
    for (const double elevation : {0.0, half}) {
        // 0.35 m at 10 m spans +-1 deg of elevation: over that span the sinc^2's curvature changes the
        // mean by < 0.2%, and the partly covered edge rows (0.31 deg each) move the target's elevation
        // centroid by < 0.03 deg, < 0.5% of the pattern at 10 deg (slope -0.15 per deg there): 2% in all.
        Scene scene;
        add_facing_quad(scene, 10.0, 0.0, elevation, 0.6, 0.35);
        auto a = render_once(GetParam(), on, scene);
        auto b = render_once(GetParam(), off, scene);
        ASSERT_TRUE(a && b);
        ASSERT_GT(sum(b->frame.clean), 0.0);
        EXPECT_NEAR(sum(a->frame.clean) / sum(b->frame.clean), elevation == 0.0 ? 1.0 : 0.5, 0.02)
            << "elevation " << elevation / kDeg << " deg";
    }
}

TEST_P(EffectsTest, VerticalPatternOffIsAnAllOnePattern) {
    // Never considered = a box pattern over exactly the covered elevations (every pixel weighs 1).
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 4.0, 12.0);
    SonarConfig off = clean_config(), box = clean_config();
    off.effects.vertical_pattern = EffectMode::off;
    off.vertical_coverage = 1.0;
    box.effects.vertical_pattern = EffectMode::on;
    box.vertical_pattern = BeamPattern::box;
    box.vertical_coverage = 1.0; // a box has no null: both cover +-vfov/2 at the slices' edge columns
    // Every pixel centre must lie inside +-vfov/2. The coverage holds that elevation at a slice's edge
    // columns, so towards its centre column v reaches sqrt(1 + tan^2(half slice)) higher: 15-degree
    // slices stretch it by 1.008, less than the half row the outermost pixel centres keep from the edge
    // (1 - 1 / rows, 65 rows). With 60-degree slices (1.076) the top and bottom rows' centre columns see
    // past +-vfov/2, where the box is 0.
    off.max_slice_deg = box.max_slice_deg = 15.0;
    auto a = render_once(GetParam(), off, scene, {}, SaveFlags::echo);
    auto b = render_once(GetParam(), box, scene, {}, SaveFlags::echo);
    ASSERT_TRUE(a && b);
    const Plan& plan = renderer_plan(b->renderer);
    const double top_v = plan.tan_half_v * (1.0 - 1.0 / plan.rows);
    ASSERT_LE(std::atan(top_v), 0.5 * box.vfov_deg * kDeg) << "a pixel centre lies outside the box";
    EXPECT_GT(sum(a->frame.clean), 0.0);
    EXPECT_TRUE(same_bits(a->frame.echo, b->frame.echo));
    EXPECT_TRUE(same_bits(a->frame.clean, b->frame.clean));
}

// ---- horizontal beam pattern and side lobes -----------------------------------------------------

TEST_P(EffectsTest, HorizontalPatternConvolvesBeamsWithTheArraysSidelobes) {
    // A narrow pole (0.05 m = 0.29 deg at 10 m) on the axis of beam 200: it feeds 2-3 beams before
    // the side-lobe pass.
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.horizontal_pattern = EffectMode::on;
    off.effects.horizontal_pattern = EffectMode::off;
    on.far_sidelobe_cell = 0.0; // the kernel's exact taps (far side lobes: tests/far_sidelobes_test.cpp)
    // Beam centres, port first: angle_j = (1 - (2j + 1) / N) hfov / 2 (equi-angular table).
    const std::uint32_t j0 = 200;
    const double azimuth = (1.0 - (2.0 * j0 + 1.0) / on.beams) * 0.5 * on.hfov_deg * kDeg;

    Scene scene;
    add_facing_quad(scene, 10.0, azimuth, 0.0, 0.05, 1.0);
    auto a = render_once(GetParam(), on, scene, {}, SaveFlags::profiles);
    auto b = render_once(GetParam(), off, scene, {}, SaveFlags::profiles);
    ASSERT_TRUE(a && b);
    const Plan& plan = renderer_plan(a->renderer);
    const Frame& fa = a->frame;
    const Frame& fb = b->frame;
    ASSERT_GT(sum(fb.clean), 0.0);
    ASSERT_NEAR(plan.beam_angle_rad[j0], azimuth, 1e-12);

    // Everything before the side-lobe pass is the same; off, the scan is the beam profiles as they are.
    EXPECT_TRUE(same_bits(fa.beam_profiles, fb.beam_profiles));
    EXPECT_TRUE(same_bits(fb.clean, fb.beam_profiles));
    EXPECT_FALSE(ran(fb, "sidelobe")); // no stage of that name either way: it is part of beamform

    // On: polar(j) = sum over the profile columns c within the kernel reach of b_h^2 P(c), b_h^2 the sinc^2
    // of a uniform line array whose two-way -3 dB width is the horizontal beamwidth, at the separation
    // of the column's direction and the beam's, in sine (line_array: b_h^2(asin(sin a_c - sin a_j)) =
    // sinc^2(k (sin a_c - sin a_j))), within sin(reach) (docs/pipeline.md, "Beam geometry", "Side
    // lobes"). The line array's cone columns are uniform in steering angle over the fan: column c at
    // (1 - (2c + 1) / profile_columns) hfov / 2.
    ASSERT_TRUE(plan.line_array) << "the default sonar is a line array";
    const double hbw = plan.config.horizontal_beamwidth_deg * kDeg;
    const double reach = plan.config.sidelobe_kernel_beamwidths * hbw;
    double peak = 0;
    for (float x : fa.clean)
        peak = std::max(peak, double(x));
    const std::uint32_t P = fa.profile_columns;
    ASSERT_EQ(fa.profiles.size(), std::size_t(fa.bins) * P);
    std::vector<double> column_sine(P);
    for (std::uint32_t c = 0; c < P; ++c)
        column_sine[c] = std::sin((1.0 - (2.0 * c + 1.0) / P) * 0.5 * on.hfov_deg * kDeg);
    const double reach_units = std::sin(reach);
    for (std::uint32_t j = 0; j < fa.beams; ++j) {
        std::vector<std::pair<std::uint32_t, double>> weights; // (column, b_h^2) within the reach
        const double sine_j = std::sin(fa.beam_angles_rad[j]);
        for (std::uint32_t c = 0; c < P; ++c) {
            const double sep = column_sine[c] - sine_j;
            if (std::abs(sep) <= reach_units + 1e-12) weights.emplace_back(c, sinc_pattern(hbw, std::asin(sep)));
        }
        for (std::uint32_t k = 0; k < fa.bins; ++k) {
            double expected = 0;
            for (const auto& [c, w] : weights)
                expected += w * fa.profiles[std::size_t(k) * P + c];
            // Float weights (rel 6e-8) and a float sum of <= ~120 terms: 1e-5 relative, with a floor at
            // 1e-6 of the frame's peak for cells near the pattern's nulls (small differences of floats).
            ASSERT_NEAR(fa.clean[std::size_t(k) * fa.beams + j], expected, 1e-5 * expected + 1e-6 * peak)
                << "bin " << k << " beam " << j;
        }
    }

    // The first side lobe of a uniform line array is -13.26 dB. Per-beam energy (summed over bins):
    // the strongest beam 4..9 beams from the peak vs the peak beam. The input spans ~3 beams and the
    // beams sample the lobe (1.13 deg wide) every 0.25 deg: the measured level may sit up to ~1 dB
    // below the lobe's peak, or ~0.5 dB above it from the input's spread; a missing side lobe (0) or a
    // tapered one (hann: -31.5 dB, sinc^4: -26.5 dB) fails.
    std::vector<double> per_beam(fa.beams, 0.0);
    for (std::uint32_t k = 0; k < fa.bins; ++k)
        for (std::uint32_t j = 0; j < fa.beams; ++j)
            per_beam[j] += fa.clean[std::size_t(k) * fa.beams + j];
    const auto top = static_cast<std::uint32_t>(std::max_element(per_beam.begin(), per_beam.end()) - per_beam.begin());
    EXPECT_NEAR(top, j0, 1);
    double lobe = 0;
    for (std::uint32_t d = 4; d <= 9; ++d)
        lobe = std::max({lobe, per_beam[top + d], per_beam[top - d]});
    EXPECT_NEAR(to_db(lobe / per_beam[top]), -13.26, 1.5);
    // Off: nothing leaks that far.
    std::vector<double> per_beam_off(fb.beams, 0.0);
    for (std::uint32_t k = 0; k < fb.bins; ++k)
        for (std::uint32_t j = 0; j < fb.beams; ++j)
            per_beam_off[j] += fb.clean[std::size_t(k) * fb.beams + j];
    for (std::uint32_t d = 4; d <= 9; ++d) {
        EXPECT_EQ(per_beam_off[top + d], 0.0);
        EXPECT_EQ(per_beam_off[top - d], 0.0);
    }
}

// ---- spreading and absorption -------------------------------------------------------------------

// Two Lambert quads at 10 m (port) and 30 m (starboard).
Scene near_and_far() {
    Scene scene;
    add_facing_quad(scene, 10.0, 15.0 * kDeg, 0.0, 1.0, 1.0);
    add_facing_quad(scene, 30.0, -15.0 * kDeg, 0.0, 2.0, 2.0);
    return scene;
}

TEST_P(EffectsTest, SpreadingIsFortyLogR) {
    const Scene scene = near_and_far();
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.spreading = EffectMode::on;
    off.effects.spreading = EffectMode::off;
    auto a = render_once(GetParam(), on, scene, {}, kEchoAndDepth);
    auto b = render_once(GetParam(), off, scene, {}, kEchoAndDepth);
    ASSERT_TRUE(a && b);
    EXPECT_TRUE(same_bits(a->frame.depth, b->frame.depth));
    // Two-way spherical spreading: the echo of a pixel at slant range r loses 40 log10 r dB; off,
    // the footprint r^2 Omega stays (docs/pipeline.md §3), so E_off / E_on = r^4.
    std::size_t checked = 0;
    bool near = false, far = false;
    for (std::size_t p = 0; p < a->frame.rows * std::size_t(a->frame.columns); ++p) {
        const double r = a->frame.echo[2 * p + 1];
        ASSERT_EQ(a->frame.echo[2 * p + 1], b->frame.echo[2 * p + 1]);
        if (!(a->frame.echo[2 * p] > 0.0f)) continue;
        near |= r < 11.0;
        far |= r > 29.0;
        // Float: E is a product of ~6 float factors each way (~1e-6 relative): 1e-4 dB.
        ASSERT_NEAR(to_db(double(b->frame.echo[2 * p]) / double(a->frame.echo[2 * p])), 40.0 * std::log10(r), 1e-4);
        ++checked;
    }
    EXPECT_TRUE(near && far);
    EXPECT_GT(checked, 100u);
}

TEST_P(EffectsTest, AbsorptionLowersFarEchoesByTwoAlphaR) {
    const Scene scene = near_and_far();
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.absorption = EffectMode::on;
    off.effects.absorption = EffectMode::off;
    const double alpha = on.absorption_db_per_m; // 0.05 dB/m, one way
    auto a = render_once(GetParam(), on, scene, {}, kEchoAndDepth);
    auto b = render_once(GetParam(), off, scene, {}, kEchoAndDepth);
    ASSERT_TRUE(a && b);
    // Per pixel: 10^(-2 alpha r / 10), i.e. 2 alpha r dB (1.0 dB at 10 m, 3.0 dB at 30 m).
    for (std::size_t p = 0; p < a->frame.rows * std::size_t(a->frame.columns); ++p) {
        if (!(a->frame.echo[2 * p] > 0.0f)) continue;
        const double r = a->frame.echo[2 * p + 1];
        // float exp of an argument <= 0.7: a few ulp (1e-6 relative) each: 1e-4 dB.
        ASSERT_NEAR(to_db(double(b->frame.echo[2 * p]) / double(a->frame.echo[2 * p])), 2.0 * alpha * r, 1e-4);
    }
    // Per target in the scan: cells nearer than 20 m hold the 10 m quad, farther ones the 30 m quad.
    const Plan& plan = renderer_plan(a->renderer);
    double on_near = 0, off_near = 0, on_far = 0, off_far = 0;
    for (std::uint32_t k = 0; k < plan.bins; ++k) {
        for (std::uint32_t j = 0; j < plan.beams; ++j) {
            const std::size_t i = std::size_t(k) * plan.beams + j;
            (plan.bin_range_m[k] < 20.0 ? on_near : on_far) += a->frame.clean[i];
            (plan.bin_range_m[k] < 20.0 ? off_near : off_far) += b->frame.clean[i];
        }
    }
    ASSERT_GT(on_near * on_far, 0.0);
    // The quads' pixels lie within 10.00..10.02 m and 30.00..30.03 m: 2 alpha r within 0.003 dB of
    // 2 alpha x nominal range; 0.01 dB.
    EXPECT_NEAR(to_db(off_near / on_near), 2.0 * alpha * 10.0, 0.01);
    EXPECT_NEAR(to_db(off_far / on_far), 2.0 * alpha * 30.0, 0.01);
}

TEST_P(EffectsTest, AbsorptionOffIsAlphaZero) {
    const Scene scene = near_and_far();
    SonarConfig off = clean_config(), zero = clean_config();
    off.effects.absorption = EffectMode::off;
    zero.effects.absorption = EffectMode::on;
    zero.absorption_db_per_m = 0.0;
    auto a = render_once(GetParam(), off, scene, {}, SaveFlags::echo);
    auto b = render_once(GetParam(), zero, scene, {}, SaveFlags::echo);
    ASSERT_TRUE(a && b);
    EXPECT_GT(sum(a->frame.clean), 0.0);
    EXPECT_TRUE(same_bits(a->frame.echo, b->frame.echo));
    EXPECT_TRUE(same_bits(a->frame.clean, b->frame.clean));
}

// ---- host effects: speckle, ambient noise, TVG ----------------------------------------------------

// A wide target that fills many cells: a 24 x 6 m quad at 15 m.
Scene wide_target() {
    Scene scene;
    add_quad(scene, 15.0, 0.0, 0.0, 24.0, 6.0);
    return scene;
}

TEST_P(EffectsTest, SpeckleIsExponentialWithTheMeanPreserved) {
    const Scene scene = wide_target();
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.speckle = EffectMode::on;
    ASSERT_EQ(on.speckle, SpeckleModel::rayleigh);
    off.effects.speckle = EffectMode::off;
    auto a = render_once(GetParam(), on, scene, {}, SaveFlags::none, 7);
    auto b = render_once(GetParam(), off, scene, {}, SaveFlags::none, 7);
    ASSERT_TRUE(a && b);
    EXPECT_TRUE(same_bits(a->frame.clean, b->frame.clean)); // speckle is a host stage after the scan
    const double source = std::pow(10.0, on.source_level_db / 10.0);
    double n = 0, mean = 0, m2 = 0, below_one = 0;
    for (std::size_t i = 0; i < a->frame.clean.size(); ++i) {
        const double clean = a->frame.clean[i];
        const double expected_off = source * clean;
        // Off: intensity = SL x clean, rounded to float once (relative 6e-8).
        ASSERT_NEAR(b->frame.intensity[i], expected_off, 1.2e-7 * expected_off) << "cell " << i;
        if (!(clean > 0.0) || expected_off < 1e-30) continue;
        const double s = a->frame.intensity[i] / expected_off; // the speckle multiplier of this cell
        n += 1;
        const double delta = s - mean;
        mean += delta / n;
        m2 += delta * (s - mean);
        below_one += s < 1.0;
    }
    ASSERT_GT(n, 3000.0); // ~300 beams x ~15 bins that the quad feeds
    const double variance = m2 / (n - 1);
    // Fully developed speckle: intensity x Exp(1): mean 1 (the echo level is preserved), variance 1,
    // P(s < 1) = 1 - 1/e. Tolerances are 5 standard errors over n independent cells: sd(mean) = 1/sqrt(n),
    // sd(sample variance) = sqrt((mu4 - 1) / n) = sqrt(8 / n), sd(fraction) = sqrt(p (1 - p) / n).
    EXPECT_NEAR(mean, 1.0, 5.0 / std::sqrt(n));
    EXPECT_NEAR(variance, 1.0, 5.0 * std::sqrt(8.0 / n));
    const double p = 1.0 - std::exp(-1.0);
    EXPECT_NEAR(below_one / n, p, 5.0 * std::sqrt(p * (1 - p) / n));
}

TEST_P(EffectsTest, SpeckleOffIsAUnitMultiplier) {
    // Never considered = the legacy gaussian speckle |N(1, sigma)| with sigma = 0: every multiplier is 1.
    const Scene scene = wide_target();
    SonarConfig off = clean_config(), unit = clean_config();
    off.effects.speckle = EffectMode::off;
    unit.effects.speckle = EffectMode::on;
    unit.speckle = SpeckleModel::gaussian;
    unit.speckle_gaussian_sigma = 0.0;
    auto a = render_once(GetParam(), off, scene);
    auto b = render_once(GetParam(), unit, scene);
    ASSERT_TRUE(a && b);
    EXPECT_GT(sum(a->frame.intensity), 0.0);
    EXPECT_TRUE(same_bits(a->frame.intensity, b->frame.intensity));
    EXPECT_TRUE(same_bits(a->frame.display, b->frame.display));
}

TEST_P(EffectsTest, AmbientNoiseRaisesEmptyBinsToTheNoiseLevel) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 4.0, 4.0); // everything beyond ~11 m is empty
    SonarConfig on = clean_config(), off = clean_config();
    on.effects.ambient_noise = EffectMode::on;
    off.effects.ambient_noise = EffectMode::off;
    auto a = render_once(GetParam(), on, scene, {}, SaveFlags::none, 3);
    auto b = render_once(GetParam(), off, scene, {}, SaveFlags::none, 3);
    ASSERT_TRUE(a && b);
    EXPECT_TRUE(same_bits(a->frame.clean, b->frame.clean));
    // The default sonar is a line array: a beam steered to theta is a cone 1 / cos(theta) wider in sine
    // space and hears that much more of the sea, DI_j = DI + 10 log10(cos theta_j).
    const NoiseTerms terms = on.noise_terms();
    const std::uint32_t beams = a->frame.beams;
    ASSERT_EQ(a->frame.beam_angles_rad.size(), beams);
    double n = 0, total = 0, below = 0, signal_cells = 0;
    for (std::size_t i = 0; i < a->frame.clean.size(); ++i) {
        const double di = terms.directivity_index_db + 10.0 * std::log10(std::cos(a->frame.beam_angles_rad[i % beams]));
        const double noise = std::pow(10.0, (terms.noise_level_db - di) / 10.0);
        if (a->frame.clean[i] == 0.0f) {
            EXPECT_EQ(b->frame.intensity[i], 0.0f) << "off: an empty cell stays exactly 0";
            ASSERT_GT(a->frame.intensity[i], 0.0f);
            n += 1;
            total += a->frame.intensity[i] / noise;
            below += a->frame.intensity[i] < noise;
        } else {
            // Noise is added power: never lowers a cell (float rounding is monotonic).
            ASSERT_GE(a->frame.intensity[i], b->frame.intensity[i]);
            signal_cells += 1;
        }
    }
    ASSERT_GT(n, 100000.0);
    ASSERT_GT(signal_cells, 100.0);
    // Ambient noise power N_j = 10^((NL - DI_j)/10) times Exp(1): mean N_j, P(below N_j) = 1 - 1/e.
    // 5 standard errors: sd(mean) = 1/sqrt(n), sd(fraction) = sqrt(p (1 - p) / n).
    EXPECT_NEAR(total / n, 1.0, 5.0 / std::sqrt(n));
    const double p = 1.0 - std::exp(-1.0);
    EXPECT_NEAR(below / n, p, 5.0 * std::sqrt(p * (1 - p) / n));
    // The display shows the floor: NL - DI_j = 50-54 dB is below db_min = 60 dB, so off and on both map
    // empty cells to 0 there; the floor is in the intensity, which is what polar.npy holds.
}

TEST_P(EffectsTest, TvgAddsItsDbPerDecadePlusTwoAlphaR) {
    const Scene scene = wide_target();
    for (const bool absorption : {true, false}) {
        for (const double k : {20.0, 40.0}) {
            SonarConfig on = clean_config(), off = clean_config();
            on.effects.absorption = off.effects.absorption = absorption ? EffectMode::on : EffectMode::off;
            on.effects.tvg = EffectMode::on;
            on.tvg_db_per_decade = k;
            off.effects.tvg = EffectMode::off;
            auto a = render_once(GetParam(), on, scene);
            auto b = render_once(GetParam(), off, scene);
            ASSERT_TRUE(a && b);
            EXPECT_TRUE(same_bits(a->frame.clean, b->frame.clean));
            const Plan& plan = renderer_plan(a->renderer);
            // TVG = k log10 r + 2 alpha r at the bin centre r; it compensates the absorption only when
            // the absorption effect is on (otherwise there is none to compensate).
            const double alpha = absorption ? on.absorption_db_per_m : 0.0;
            std::size_t checked = 0;
            for (std::uint32_t bin = 0; bin < plan.bins; ++bin) {
                const double r = on.range_min_m + (bin + 0.5) * (on.range_max_m - on.range_min_m) / on.bins;
                const double expected_db = k * std::log10(r) + 2.0 * alpha * r;
                for (std::uint32_t j = 0; j < plan.beams; ++j) {
                    const std::size_t i = std::size_t(bin) * plan.beams + j;
                    if (!(b->frame.intensity[i] > 0.0f)) {
                        EXPECT_EQ(a->frame.intensity[i], 0.0f);
                        continue;
                    }
                    // Both are one float rounding of a double product (6e-8 relative each): 1e-5 dB.
                    ASSERT_NEAR(to_db(double(a->frame.intensity[i]) / double(b->frame.intensity[i])), expected_db, 1e-5)
                        << "bin " << bin << " (r = " << r << " m), absorption " << absorption << ", k = " << k;
                    ++checked;
                }
            }
            EXPECT_GT(checked, 1000u);
        }
    }
}

TEST_P(EffectsTest, TvgOffIsZeroGain) {
    // Never considered = TVG on with 0 dB/decade and nothing to compensate (absorption off).
    const Scene scene = wide_target();
    SonarConfig off = clean_config(), zero = clean_config();
    off.effects.absorption = zero.effects.absorption = EffectMode::off;
    off.effects.tvg = EffectMode::off;
    zero.effects.tvg = EffectMode::on;
    zero.tvg_db_per_decade = 0.0;
    auto a = render_once(GetParam(), off, scene);
    auto b = render_once(GetParam(), zero, scene);
    ASSERT_TRUE(a && b);
    EXPECT_GT(sum(a->frame.intensity), 0.0);
    EXPECT_TRUE(same_bits(a->frame.intensity, b->frame.intensity));
}

INSTANTIATE_TEST_SUITE_P(Effects, EffectsTest, ::testing::Values(Backend::vulkan, Backend::cpu), backend_param_name);

// ---- auto resolution (the plan alone) ---------------------------------------------------------------

Plan plan_of(const SonarConfig& config, const Scene& scene) {
    auto plan = make_plan(config, scene_data(scene));
    EXPECT_TRUE(plan.ok()) << (plan.ok() ? "" : plan.error().message);
    return plan.ok() ? plan.value() : Plan{};
}

const EffectState* state_of(const Plan& plan, const std::string& name) {
    for (const auto& e : plan.effects.states)
        if (e.name == name) return &e;
    return nullptr;
}

TEST(EffectsAuto, EveryEffectReportsItsStateAndWhy) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    SonarConfig config = load_preset("default").value();
    config.effects.speckle = EffectMode::off;
    const Plan plan = plan_of(config, scene);
    const std::vector<std::string> names = {"incidence",
                                            "vertical_pattern",
                                            "vertical_sidelobes",
                                            "horizontal_pattern",
                                            "spreading",
                                            "absorption",
                                            "speckle",
                                            "ambient_noise",
                                            "tvg"};
    ASSERT_EQ(plan.effects.states.size(), names.size());
    for (std::size_t i = 0; i < names.size(); ++i) {
        EXPECT_EQ(plan.effects.states[i].name, names[i]);
        EXPECT_FALSE(plan.effects.states[i].why.empty()) << names[i];
    }
    EXPECT_EQ(state_of(plan, "speckle")->why, "off in config");
    EXPECT_FALSE(plan.effects.speckle);
    // The preset's defaults: auto everywhere; all on except TVG (raw received levels).
    EXPECT_TRUE(plan.effects.incidence && plan.effects.vertical_pattern && plan.effects.horizontal_pattern &&
                plan.effects.spreading && plan.effects.absorption && plan.effects.ambient_noise);
    EXPECT_FALSE(plan.effects.tvg);
    EXPECT_EQ(state_of(plan, "tvg")->why.rfind("auto: ", 0), 0u);
    // The vertical side lobes say from where the tier views take over: the 20-degree sinc's first null,
    // asin(pi / k) with k from its half-power point (vertical_coverage x vfov / 2 = 20 deg is less); with
    // them off, the vertical pattern says that it stops there.
    EXPECT_TRUE(plan.effects.vertical_sidelobes);
    const double k = sinc_half_power_x() / std::sin(10.0 * kDeg);
    char beyond[64], within[64];
    std::snprintf(beyond, sizeof beyond, "beyond +-%.1f deg", std::asin(kPi / k) / kDeg);
    std::snprintf(within, sizeof within, "within +-%.1f deg", std::asin(kPi / k) / kDeg);
    EXPECT_NE(state_of(plan, "vertical_sidelobes")->why.find(beyond), std::string::npos)
        << state_of(plan, "vertical_sidelobes")->why << " (expected " << beyond << ")";
    config.effects.vertical_sidelobes = EffectMode::off;
    const Plan main_band = plan_of(config, scene);
    EXPECT_FALSE(main_band.effects.vertical_sidelobes);
    EXPECT_EQ(main_band.views, main_band.slices);
    EXPECT_NE(state_of(main_band, "vertical_pattern")->why.find(within), std::string::npos)
        << state_of(main_band, "vertical_pattern")->why << " (expected " << within << ")";
}

TEST(EffectsAuto, AbsorptionIsOffBelowATenthOfADbOverTheRangeWindow) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    SonarConfig config = load_preset("default").value();
    config.range_max_m = 40.0;
    config.absorption_db_per_m = 0.0012; // 2 alpha range_max = 0.096 dB: invisible
    Plan plan = plan_of(config, scene);
    EXPECT_FALSE(plan.effects.absorption);
    EXPECT_NE(state_of(plan, "absorption")->why.find("0.096"), std::string::npos) << state_of(plan, "absorption")->why;
    config.absorption_db_per_m = 0.0013; // 0.104 dB
    EXPECT_TRUE(plan_of(config, scene).effects.absorption);
    // Francois-Garrison at 750 kHz in 10 C sea water is ~0.2 dB/m: on over 40 m.
    config.absorption_db_per_m = -1.0;
    plan = plan_of(config, scene);
    EXPECT_TRUE(plan.effects.absorption);
    EXPECT_GT(plan.alpha_db_per_m, 0.1);
    EXPECT_LT(plan.alpha_db_per_m, 0.4);
    // An explicit mode wins over the rule.
    config.absorption_db_per_m = 0.0012;
    config.effects.absorption = EffectMode::on;
    EXPECT_TRUE(plan_of(config, scene).effects.absorption);
}

TEST(EffectsAuto, OffEffectsSetNoShaderFlagsAndNoSidelobeKernel) {
    Scene scene;
    add_quad(scene, 10.0, 0.0, 0.0, 1.0, 1.0);
    SonarConfig config = load_preset("default").value();
    for (EffectMode* mode : {&config.effects.incidence, &config.effects.vertical_pattern,
                             &config.effects.horizontal_pattern, &config.effects.spreading, &config.effects.absorption})
        *mode = EffectMode::off;
    const Plan plan = plan_of(config, scene);
    EXPECT_EQ(plan.effects.shader_flags(), 0u);
    EXPECT_EQ(plan.params.effect_flags, 0u);
    EXPECT_EQ(plan.sidelobe_taps, 1u);
    // Nothing to compensate: TVG's 2 alpha r uses the absorption actually applied.
    EXPECT_EQ(plan.alpha_db_per_m, 0.0);

    // Auto horizontal pattern: off when the side-lobe kernel does not reach the next beam.
    config.effects.horizontal_pattern = EffectMode::automatic;
    config.sidelobe_kernel_beamwidths = 0.0;
    const Plan narrow = plan_of(config, scene);
    EXPECT_FALSE(narrow.effects.horizontal_pattern);
    EXPECT_EQ(narrow.sidelobe_taps, 1u);
}

} // namespace
} // namespace vksonar::testing
