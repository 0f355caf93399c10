// Physical ranges of every key (validate() refuses a value just outside, naming the key) and the
// validity domains of the models a frame uses (model_validity: just inside ok, just outside not).
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "config/config_keys.h"
#include "core/plan.h"
#include "scene/scene_data.h"
#include "vksonar/config.h"
#include "vksonar/validity.h"

namespace vksonar {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180.0;

std::string number_text(double x, bool count) {
    if (count) return std::to_string(static_cast<long long>(x));
    char text[64];
    std::snprintf(text, sizeof text, "%.17g", x);
    return text;
}

// The problem of `name=value` on the default config: the setter's or validate()'s, or empty.
std::string problem_of(const std::string& name, const std::string& value) {
    auto set = apply_config_override(SonarConfig{}, name + "=" + value);
    if (!set) return set.error().message;
    const auto valid = set->validate();
    return valid ? std::string() : valid.error().message;
}

// For every bounded key: a value just outside each finite bound is refused with the key's name and
// the range; the bound itself (closed) or a value just inside (open) passes the key's own range check.
TEST(KeyRanges, EveryKeyJustOutsideItsRangeIsRefusedByName) {
    std::size_t checked = 0;
    for (const auto& key : config_keys::all()) {
        if (!key.range.bounded()) continue;
        const bool count = key.type == config_keys::KeyType::count;
        const config_keys::KeyRange& r = key.range;
        const auto step = [count](double x) { return count ? 1.0 : std::max(std::abs(x) * 1e-6, 1e-6); };
        for (const bool low : {true, false}) {
            const double bound = low ? r.min : r.max;
            if (!std::isfinite(bound)) continue;
            const bool open = low ? r.min_open : r.max_open;
            const double outside = open ? bound : (low ? bound - step(bound) : bound + step(bound));
            if (count && outside < 0) continue; // a negative count is refused by the setter's type check
            const std::string text = number_text(outside, count);
            const std::string problem = problem_of(key.name, text);
            ASSERT_FALSE(problem.empty()) << key.name << " = " << text << " was accepted";
            EXPECT_NE(problem.find(key.name), std::string::npos) << problem;
            // validate()'s message names the value and the range (the setter's, for absorption < 0,
            // names the value).
            if (problem.rfind("--set", 0) != 0) {
                EXPECT_EQ(problem.rfind(std::string(key.name) + " = ", 0), 0u) << problem;
                EXPECT_NE(problem.find(config_keys::range_text(r)), std::string::npos) << problem;
            }
            const double inside = open ? (low ? bound + step(bound) : bound - step(bound)) : bound;
            const std::string inside_problem = problem_of(key.name, number_text(inside, count));
            EXPECT_EQ(inside_problem.find("must be in"), std::string::npos)
                << key.name << " = " << inside << ": " << inside_problem;
            ++checked;
        }
        EXPECT_NE(std::string(r.reason), "") << key.name << " has a range without a reason";
    }
    EXPECT_GE(checked, 60u); // about two bounds for each of the 31 numeric keys
}

TEST(KeyRanges, TheIssueExamplesAndTheCrossKeyRules) {
    EXPECT_EQ(problem_of("source_level", "400"), "source_level = 400: must be in [100, 260] dB re 1 uPa at 1 m");
    EXPECT_EQ(problem_of("sound_speed", "1e9"), "sound_speed = 1000000000: must be in [1400, 1650] m/s");
    EXPECT_EQ(problem_of("bandwidth", "1600000"),
              "bandwidth = 1600000: must be at most twice the frequency (1500000 Hz): the band f +- B/2 would reach "
              "below 0 Hz");
    EXPECT_EQ(problem_of("bandwidth", "1500000").find("twice the frequency"), std::string::npos);
    EXPECT_EQ(problem_of("horizontal_beamwidth", "131"),
              "horizontal_beamwidth = 131: must be at most hfov (130 degrees): a beam wider than the whole fan");
    EXPECT_EQ(problem_of("horizontal_beamwidth", "130"), "");
    EXPECT_NE(problem_of("display.db_min", "140").find("display.db_max = 140: must be greater than display.db_min"),
              std::string::npos);
}

// A depth pass whose range-profile buffer no Vulkan device can bind is refused by make_plan, before
// anything is allocated, with its size.
TEST(KeyRanges, ADepthPassPastTheBufferLimitIsRefusedWithItsSize) {
    SonarConfig c;
    c.beam_geometry = BeamGeometry::planar; // profile columns = pixel columns, which fit the column limit
    c.bins = 65536;
    c.pixels_per_beam = 32; // 32 x 512 = 16384 columns: 65536 x 16384 floats = 4.3 GB
    ASSERT_TRUE(c.validate().ok());
    SceneData scene;
    auto plan = make_plan(c, scene);
    ASSERT_FALSE(plan.ok());
    EXPECT_NE(
        plan.error().message.find("range-profile buffer would hold 4.29549 GB (65536 bins x 16386 profile columns)"),
        std::string::npos)
        << plan.error().message;
    c.bins = 4096; // 268 MB: fine
    EXPECT_TRUE(make_plan(c, scene).ok());
}

// A copy: the lists are temporaries.
std::optional<ModelValidity> find_model(const std::vector<ModelValidity>& list, const std::string& model) {
    for (const auto& v : list)
        if (v.model == model) return v;
    return std::nullopt;
}

// A config inside every domain: the default with range_min past the far-field distance.
SonarConfig inside_config() {
    SonarConfig c;
    c.range_min_m = 6.0; // L^2 / lambda = 5.15 m for 1 deg at 750 kHz
    return c;
}

TEST(Validity, InsideEveryDomainEveryEntryIsOk) {
    const auto list = model_validity(inside_config());
    ASSERT_EQ(list.size(), 3u); // francois_garrison, far_field_beam_pattern, beam_sampling
    for (const auto& v : list) {
        EXPECT_TRUE(v.ok) << v.warning();
        EXPECT_EQ(v.action, "none");
        EXPECT_FALSE(v.domain.empty());
    }
}

// Beams further apart than a beamwidth: with the horizontal pattern on the near kernel weighs each column by
// the pattern at its own direction, so a target between two beams reads what the pattern says (ok); with
// the pattern off, or a kernel shorter than the beam spacing (K = 0), the scan is the tent between beam
// centres, which holds only while adjacent beams are at most a beamwidth apart (in sine for a line array).
// 120 beams over 130 deg: 1.08 deg apart for a 1 deg beam.
TEST(Validity, SparseBeamsNeedThePatternPerColumn) {
    SonarConfig c = inside_config();
    EXPECT_TRUE(find_model(model_validity(c), "beam_sampling")->ok);
    for (const BeamGeometry geometry : {BeamGeometry::planar, BeamGeometry::line_array}) {
        c.beam_geometry = geometry;
        c.beams = 120;
        c.effects.horizontal_pattern = EffectMode::automatic;
        EXPECT_TRUE(find_model(model_validity(c), "beam_sampling")->ok) << "the near kernel runs";
        c.effects.horizontal_pattern = EffectMode::off;
        const auto v = find_model(model_validity(c), "beam_sampling");
        EXPECT_FALSE(v->ok);
        EXPECT_EQ(v->key, "beams");
        EXPECT_EQ(v->value, 120.0);
        EXPECT_NE(v->warning().find("interpolates"), std::string::npos) << v->warning();
        c.beams = 130; // 1 deg apart (in sine only at broadside for the line array: 0.99998 deg)
        EXPECT_TRUE(find_model(model_validity(c), "beam_sampling")->ok);
        // A kernel shorter than the beam spacing (0.4 beamwidths against 1.08 deg apart; a line array's
        // beams, 0.46 deg apart in sine at its edges, too): K = 0, the tent.
        c.beams = 120;
        c.effects.horizontal_pattern = EffectMode::automatic;
        c.sidelobe_kernel_beamwidths = 0.4;
        const auto tent = find_model(model_validity(c), "beam_sampling");
        EXPECT_FALSE(tent->ok);
        EXPECT_NE(tent->warning().find("interpolates"), std::string::npos) << tent->warning();
        if (geometry == BeamGeometry::line_array) {
            // 0.5 beamwidths reaches the edge beams' neighbours (K = 1) but not a target midway between
            // two broadside beams (0.54 deg out): past the kernel's reach.
            c.sidelobe_kernel_beamwidths = 0.5;
            const auto short_kernel = find_model(model_validity(c), "beam_sampling");
            EXPECT_FALSE(short_kernel->ok);
            EXPECT_NE(short_kernel->warning().find("sidelobe_kernel_beamwidths"), std::string::npos)
                << short_kernel->warning();
        }
        c.sidelobe_kernel_beamwidths = 3.0;
    }
    // The plan's own answer: the same config planned, with the pattern on and off.
    SceneData scene;
    c.beam_geometry = BeamGeometry::planar;
    c.beams = 65; // 2 deg apart
    auto on = make_plan(c, scene);
    ASSERT_TRUE(on.ok()) << on.error().message;
    EXPECT_TRUE(find_model(on.value().validity, "beam_sampling")->ok);
    c.effects.horizontal_pattern = EffectMode::off;
    auto off = make_plan(c, scene);
    ASSERT_TRUE(off.ok()) << off.error().message;
    EXPECT_FALSE(find_model(off.value().validity, "beam_sampling")->ok);
}

TEST(Validity, FrancoisGarrisonFrequencyAndWater) {
    SonarConfig c = inside_config();
    c.frequency_hz = 1e6;
    EXPECT_TRUE(find_model(model_validity(c), "francois_garrison")->ok);
    c.frequency_hz = 1.001e6;
    auto v = find_model(model_validity(c), "francois_garrison");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
    EXPECT_EQ(v->key, "frequency");
    EXPECT_EQ(v->value, 1.001e6);
    EXPECT_NE(v->action.find("extrapolates"), std::string::npos);
    const std::string warning = v->warning();
    EXPECT_EQ(warning.find('\n'), std::string::npos);
    EXPECT_NE(warning.find("francois_garrison: frequency = 1.001e+06"), std::string::npos) << warning;
    EXPECT_NE(warning.find("[200, 1e+06] Hz"), std::string::npos) << warning;

    // Up to 500 kHz the MgSO4 limits hold: 22 degC inside, 22.5 outside; 30 ppt inside, 29.9 outside.
    c.frequency_hz = 300e3;
    c.temperature_c = 22.0;
    EXPECT_TRUE(find_model(model_validity(c), "francois_garrison")->ok);
    c.temperature_c = 22.5;
    EXPECT_EQ(find_model(model_validity(c), "francois_garrison")->key, "temperature");
    EXPECT_FALSE(find_model(model_validity(c), "francois_garrison")->ok);
    c.temperature_c = 10.0;
    c.salinity_ppt = 29.9;
    EXPECT_EQ(find_model(model_validity(c), "francois_garrison")->key, "salinity");
    // Above 500 kHz the pure-water limits: 29.9 ppt is inside.
    c.frequency_hz = 600e3;
    EXPECT_TRUE(find_model(model_validity(c), "francois_garrison")->ok);
    // An explicit absorption uses no model.
    c.absorption_db_per_m = 0.1;
    EXPECT_FALSE(find_model(model_validity(c), "francois_garrison").has_value());
}

TEST(Validity, FarFieldDistanceOfTheImpliedAperture) {
    SonarConfig c = inside_config();
    const double lambda = c.sound_speed_mps / c.frequency_hz;
    const double aperture = 0.886 * lambda / (c.horizontal_beamwidth_deg * kDeg);
    const double distance = aperture * aperture / lambda;
    EXPECT_NEAR(distance, 5.154, 0.001);
    c.range_min_m = distance * 1.001;
    EXPECT_TRUE(find_model(model_validity(c), "far_field_beam_pattern")->ok);
    c.range_min_m = distance * 0.999;
    auto v = find_model(model_validity(c), "far_field_beam_pattern");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
    EXPECT_EQ(v->key, "range_min");
    EXPECT_NE(v->domain.find("5.154 m"), std::string::npos) << v->domain;
    EXPECT_NE(v->action.find("beam_focus"), std::string::npos) << v->action;
    // Out of focus (beam_focus none or fixed) the horizontal pattern is the aperture's at each range: only
    // the vertical aperture is left, 0.886 lambda / 20 deg = 5.1 mm, far field from 13 mm.
    for (BeamFocus focus : {BeamFocus::none, BeamFocus::fixed}) {
        c.beam_focus = focus;
        v = find_model(model_validity(c), "far_field_beam_pattern");
        ASSERT_TRUE(v);
        EXPECT_TRUE(v->ok) << v->domain;
        EXPECT_NE(v->domain.find("vfov"), std::string::npos) << v->domain;
    }
    // ... but where no near kernel applies the focus (the horizontal pattern resolved off, one beam, the
    // tent) the plan keeps the far-field pattern, and the warning stays.
    c.beam_focus = BeamFocus::none;
    v = find_model(model_validity(c, {}, false, 0.0), "far_field_beam_pattern");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
    EXPECT_TRUE(find_model(model_validity(c, {}, true, 0.05), "far_field_beam_pattern")->ok);
    // The remedy is named only where it applies: not for a chebyshev pattern, nor in a legacy mode.
    c.beam_focus = BeamFocus::dynamic;
    c.horizontal_pattern = BeamPattern::chebyshev;
    EXPECT_EQ(find_model(model_validity(c), "far_field_beam_pattern")->action.find("beam_focus"), std::string::npos);
    c.horizontal_pattern = BeamPattern::sinc;
    // Without beam patterns the model is not used.
    c.effects.horizontal_pattern = EffectMode::off;
    c.effects.vertical_pattern = EffectMode::off;
    EXPECT_FALSE(find_model(model_validity(c), "far_field_beam_pattern").has_value());
}

TEST(Validity, ChebyshevNeedsEnoughElements) {
    SonarConfig c = inside_config();
    c.vertical_pattern = BeamPattern::chebyshev; // -30 dB: A = acosh(31.6) = 4.15, N >= 9.29
    const double a = std::acosh(std::pow(10.0, 30.0 / 20.0));
    const double limit_deg = 1.772 / (1.0 + 2.0 * a) / kDeg; // 10.9 deg
    c.vfov_deg = limit_deg * 0.999;
    auto v = find_model(model_validity(c), "chebyshev_large_array");
    ASSERT_TRUE(v);
    EXPECT_TRUE(v->ok) << v->warning();
    c.vfov_deg = limit_deg * 1.001;
    v = find_model(model_validity(c), "chebyshev_large_array");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
    EXPECT_EQ(v->key, "vfov");
    c.vertical_pattern = BeamPattern::sinc;
    EXPECT_FALSE(find_model(model_validity(c), "chebyshev_large_array").has_value());
}

TEST(Validity, RoughFacetSlope) {
    AcousticMaterial rough;
    rough.name = "rock";
    rough.model = AcousticMaterial::Model::rough;
    rough.rms_slope = 0.5;
    AcousticMaterial lambert; // no facet term: no entry
    const SonarConfig c = inside_config();
    auto list = model_validity(c, {lambert, rough});
    auto v = find_model(list, "rough_facet");
    ASSERT_TRUE(v);
    EXPECT_TRUE(v->ok);
    rough.rms_slope = 0.51;
    list = model_validity(c, {lambert, rough});
    v = find_model(list, "rough_facet");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
    EXPECT_EQ(v->key, "material 1 'rock' rms_slope");
    EXPECT_EQ(v->value, 0.51);
}

// make_plan records the list the CLI prints and meta.json writes.
TEST(Validity, ThePlanCarriesTheList) {
    SceneData scene;
    SonarConfig c = inside_config();
    c.frequency_hz = 2e6;
    auto plan = make_plan(c, scene);
    ASSERT_TRUE(plan.ok()) << plan.error().message;
    auto v = find_model(plan->validity, "francois_garrison");
    ASSERT_TRUE(v);
    EXPECT_FALSE(v->ok);
}

} // namespace
} // namespace vksonar
