// SonarConfig loading, overrides, serialization, presets and validate().
#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "config/config_keys.h"
#include "core/json_depth.h"
#include "vksonar/config.h"
#include "vksonar/result.h"

namespace vksonar {
namespace {

SonarConfig apply_json(const SonarConfig& base, const std::string& json) {
    auto result = apply_config_json(base, json, "test.json");
    EXPECT_TRUE(result.ok()) << result.error().message;
    return result.ok() ? result.value() : base;
}

// The first problem of a JSON config: its parse's, else validate()'s; "" where it validates.
std::string json_problem(const std::string& json) {
    auto c = apply_config_json(SonarConfig{}, json, "test.json");
    if (!c.ok()) return c.error().message;
    auto v = c->validate();
    return v.ok() ? std::string() : v.error().message;
}

std::string apply_error(const std::string& json) {
    auto result = apply_config_json(SonarConfig{}, json, "test.json");
    EXPECT_FALSE(result.ok()) << json;
    return result.ok() ? std::string() : result.error().message;
}

std::string override_error(const std::string& text) {
    auto result = apply_config_override(SonarConfig{}, text);
    EXPECT_FALSE(result.ok()) << text;
    return result.ok() ? std::string() : result.error().message;
}

TEST(Config, DefaultsAreValid) {
    EXPECT_TRUE(SonarConfig{}.validate().ok());
}

// An enum field holding a value none of its names has (a C++ caller's static_cast) is refused by
// validate(), naming the key, instead of being read past the end of the names (an audit's).
TEST(Config, AnEnumValueWithoutANameIsRefused) {
    SonarConfig c;
    c.horizontal_pattern = static_cast<BeamPattern>(99);
    auto r = c.validate();
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "horizontal_pattern = 99: must be one of box|sinc|hann|gaussian|chebyshev");
    SonarConfig e;
    e.effects.speckle = static_cast<EffectMode>(7);
    ASSERT_FALSE(e.validate());
    EXPECT_NE(e.validate().error().message.find("effects.speckle = 7"), std::string::npos);
}

// One key spelled dotted and nested in one file: the later value would win in silence (stop 54's sweep).
TEST(Config, AKeyDottedAndNestedInOneFileIsRefused) {
    auto r = apply_config_json(SonarConfig{}, R"({"display.db_min": 50, "display": {"db_min": 70}})", "f.json");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message,
              "f.json: key 'display.db_min' is given twice (dotted and nested: one value would be lost)");
    auto ok = apply_config_json(SonarConfig{}, R"({"display.db_min": 50, "display": {"db_max": 150}})", "f.json");
    ASSERT_TRUE(ok) << ok.error().message;
    EXPECT_EQ(ok->db_min, 50.0);
    EXPECT_EQ(ok->db_max, 150.0);
}

// A file of many thousands of keys is no config: refused during the parse at the key past kMaxConfigKeys
// (an outside audit's 2-million-key file ran for hours: the ordered objects' inserts are quadratic), in
// one object or spread over many; at the limit the parse goes on to the keys' own check.
TEST(Config, AFileOfManyThousandKeysIsRefusedWhileParsing) {
    const auto keys_json = [](std::size_t objects, std::size_t keys_each) {
        std::string text = "{";
        for (std::size_t o = 0; o < objects; ++o) {
            text += (o ? ",\"o" : "\"o") + std::to_string(o) + "\": {";
            for (std::size_t k = 0; k < keys_each; ++k)
                text += (k ? ",\"k" : "\"k") + std::to_string(k) + "\": 1";
            text += "}";
        }
        return text + "}";
    };
    for (const auto& [objects, keys_each] : {std::pair<std::size_t, std::size_t>{1, 200000}, {500, 400}}) {
        const auto r = apply_config_json(SonarConfig{}, keys_json(objects, keys_each), "k.json");
        ASSERT_FALSE(r);
        EXPECT_EQ(r.error().message,
                  "k.json: more than " + std::to_string(kMaxConfigKeys) + " keys (a config has a few hundred)");
    }
    const auto at_limit = apply_config_json(SonarConfig{}, keys_json(1, kMaxConfigKeys - 1), "k.json");
    ASSERT_FALSE(at_limit);
    EXPECT_EQ(at_limit.error().message.rfind("k.json: unknown key 'o0'", 0), 0u) << at_limit.error().message;
}

TEST(Config, TableKeysAreUniqueAndRoundTrip) {
    std::set<std::string> names;
    for (const auto& key : config_keys::all()) {
        EXPECT_TRUE(names.insert(key.name).second) << key.name;
        EXPECT_EQ(config_keys::find(key.name), &key);
        // Every key's getter output is accepted by its setter.
        SonarConfig config;
        EXPECT_EQ(key.set(config, key.get(SonarConfig{})), "") << key.name;
    }
}

TEST(Config, FlatAndNestedKeys) {
    const auto config = apply_json(SonarConfig{}, R"({
        // comments are allowed
        "hfov": 90, "beams": 256, "bins": 300, "range_min": 1, "range_max": 25.5,
        "beam_spacing": "equisine", "absorption": 0.2, "vertical_pattern": "hann",
        "display": {"db_min": 50, "db_max": 120, "colormap": "viridis", "fan_width": 800},
        "accuracy": {"pixels_per_beam": 3, "rows_per_vfov": 32, "max_slice": 45, "normal_method": "sobel5",
                     "range_kernel": "nearest"},
        "cpu": {"precision": "double"},
        "effects": {"speckle": "off", "tvg": "on", "absorption": false},
        "name": "x", "description": "y", "source": "z"
    })");
    EXPECT_EQ(config.hfov_deg, 90);
    EXPECT_EQ(config.beams, 256u);
    EXPECT_EQ(config.bins, 300u);
    EXPECT_EQ(config.range_max_m, 25.5);
    EXPECT_EQ(config.beam_spacing, BeamSpacing::equisine);
    EXPECT_EQ(config.absorption_db_per_m, 0.2);
    EXPECT_EQ(config.vertical_pattern, BeamPattern::hann);
    EXPECT_EQ(config.db_min, 50);
    EXPECT_EQ(config.db_max, 120);
    EXPECT_EQ(config.colormap, Colormap::viridis);
    EXPECT_EQ(config.fan_width_px, 800u);
    EXPECT_EQ(config.pixels_per_beam, 3);
    EXPECT_EQ(config.rows_per_vfov, 32u);
    EXPECT_EQ(config.max_slice_deg, 45);
    EXPECT_EQ(config.normal_method, NormalMethod::sobel5);
    EXPECT_EQ(config.range_kernel, RangeKernel::nearest);
    EXPECT_EQ(config.cpu_precision, Precision::f64);
    EXPECT_EQ(config.effects.speckle, EffectMode::off);
    EXPECT_EQ(config.effects.tvg, EffectMode::on);
    EXPECT_EQ(config.effects.absorption, EffectMode::off);
    EXPECT_EQ(config.effects.incidence, EffectMode::automatic);
    EXPECT_EQ(config.name, "x");
    EXPECT_TRUE(config.validate().ok());

    // Dotted keys are accepted in files too.
    EXPECT_EQ(apply_json(SonarConfig{}, R"({"display.db_min": 42})").db_min, 42);
}

TEST(Config, UnknownKeySuggestsClosest) {
    EXPECT_EQ(apply_error(R"({"hfvo": 90})"), "test.json: unknown key 'hfvo' (did you mean 'hfov'?)");
    EXPECT_NE(apply_error(R"({"display": {"db_mni": 1}})").find("did you mean 'display.db_min'"), std::string::npos);
    EXPECT_NE(apply_error(R"({"db_min": 1})").find("did you mean 'display.db_min'"), std::string::npos);
    EXPECT_NE(apply_error(R"({"effects": {"specle": "on"}})").find("'effects.speckle'"), std::string::npos);
    EXPECT_NE(override_error("rnage_max=3").find("did you mean 'range_max'"), std::string::npos);
}

// A key is echoed in the message; one holding a newline (JSON "\n") must not break the message into
// two lines, so control characters come out escaped.
TEST(Config, ControlCharactersInAKeyAreEscaped) {
    EXPECT_EQ(apply_error(R"({"hf\nov\u0001": 90})").rfind("test.json: unknown key 'hf\\nov\\x01'", 0), 0u);
    EXPECT_EQ(override_error("hf\tov=3").rfind("--set hf\\tov=3: unknown key 'hf\\tov'", 0), 0u);
}

// Bytes that are not UTF-8 (a Latin-1 or UTF-16 file's, echoed by the JSON parser's "last read") come out
// as \xNN, so that a message is one line of UTF-8 (an audit's grep took such a line for binary); well-formed
// UTF-8 in any script is kept. Overlong forms, surrogates and cut-off sequences are not well-formed.
TEST(Config, BytesThatAreNotUtf8AreEscapedInMessages) {
    using vksonar::detail::escape_control_chars;
    EXPECT_EQ(escape_control_chars("caf\xe9"), "caf\\xe9");                      // Latin-1
    EXPECT_EQ(escape_control_chars("\xff\xfe{"), "\\xff\\xfe{");                 // a UTF-16 BOM
    EXPECT_EQ(escape_control_chars("caf\xc3\xa9 \xe4\xb8\xad \xf0\x9f\x98\x80"), // é, 中, an emoji: kept
              "caf\xc3\xa9 \xe4\xb8\xad \xf0\x9f\x98\x80");
    EXPECT_EQ(escape_control_chars("\xc0\xaf"), "\\xc0\\xaf");                   // overlong '/'
    EXPECT_EQ(escape_control_chars("\xed\xa0\x80"), "\\xed\\xa0\\x80");          // a surrogate
    EXPECT_EQ(escape_control_chars("a\xe4\xb8"), "a\\xe4\\xb8");                 // cut off at the end
    EXPECT_EQ(escape_control_chars("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80"); // past U+10FFFF
    // well-formed, but breaking or reordering a line (a reviewer's: Python's splitlines() split at U+2028)
    EXPECT_EQ(escape_control_chars("a\xc2\x85"
                                   "b\xe2\x80\xa8"
                                   "c\xe2\x80\xa9"
                                   "d\xe2\x80\xae"
                                   "e\xe2\x81\xa6"
                                   "f"),
              "a\\u0085b\\u2028c\\u2029d\\u202ee\\u2066f");
    EXPECT_EQ(escape_control_chars("\xc2\xa0\xe2\x80\xa7\xe2\x80\xaf"), "\xc2\xa0\xe2\x80\xa7\xe2\x80\xaf"); // kept
    const std::string latin1 = apply_error("{\"name\": \"caf\xe9\"}");
    EXPECT_NE(latin1.find("\\xe9"), std::string::npos) << latin1;
    EXPECT_EQ(latin1.find('\xe9'), std::string::npos) << latin1;
}

TEST(Config, WrongTypesNameKeyAndValue) {
    const auto beams = apply_error(R"({"beams": "many"})");
    EXPECT_NE(beams.find("test.json"), std::string::npos) << beams;
    EXPECT_NE(beams.find("beams"), std::string::npos) << beams;
    EXPECT_NE(beams.find("\"many\""), std::string::npos) << beams;
    EXPECT_NE(apply_error(R"({"beams": -3})").find("beams"), std::string::npos);
    EXPECT_NE(apply_error(R"({"beams": 2.5})").find("beams"), std::string::npos);
    EXPECT_NE(apply_error(R"({"hfov": "wide"})").find("hfov"), std::string::npos);
    EXPECT_NE(apply_error(R"({"speckle": "pink"})").find("rayleigh|gamma|gaussian"), std::string::npos);
    EXPECT_NE(apply_error(R"({"display": 3})").find("display"), std::string::npos);
    EXPECT_NE(apply_error(R"({"beam_angles": [1, "x"]})").find("beam_angles"), std::string::npos);
    EXPECT_NE(apply_error(R"({"absorption": -1})").find("absorption"), std::string::npos);
    EXPECT_NE(apply_error(R"([1, 2])").find("expected a JSON object"), std::string::npos);
    EXPECT_NE(apply_error(R"({"hfov": )").find("invalid JSON"), std::string::npos);
}

TEST(Config, Overrides) {
    auto result = apply_config_override(SonarConfig{}, "effects.speckle=off");
    ASSERT_TRUE(result.ok()) << result.error().message;
    EXPECT_EQ(result->effects.speckle, EffectMode::off);
    result = apply_config_override(*result, "display.db_min=50");
    ASSERT_TRUE(result.ok());
    EXPECT_EQ(result->db_min, 50);
    result = apply_config_override(*result, "absorption=auto");
    ASSERT_TRUE(result.ok());
    EXPECT_LT(result->absorption_db_per_m, 0);
    result = apply_config_override(*result, "beam_angles=[10, 0, -10]");
    ASSERT_TRUE(result.ok()) << result.error().message;
    EXPECT_EQ(result->beam_angles_deg, (std::vector<double>{10, 0, -10}));
    EXPECT_EQ(result->beams, 3u);
    result = apply_config_override(*result, "beam_angles=");
    ASSERT_TRUE(result.ok());
    EXPECT_TRUE(result->beam_angles_deg.empty());
    result = apply_config_override(*result, "description=a = b");
    ASSERT_TRUE(result.ok());
    EXPECT_EQ(result->description, "a = b");

    EXPECT_NE(override_error("beams=many").find("beams"), std::string::npos);
    EXPECT_NE(override_error("hfov").find("key=value"), std::string::npos);
    auto nan = apply_config_override(SonarConfig{}, "hfov=nan");
    ASSERT_TRUE(nan.ok()); // parses; validate() rejects it
    const auto refused = nan->validate();
    ASSERT_FALSE(refused.ok());
    EXPECT_EQ(refused.error().code, ErrorCode::invalid_argument);
    EXPECT_NE(refused.error().message.find("hfov"), std::string::npos);
}

TEST(Config, PrecedenceIsOrderOfApplication) {
    auto preset = load_preset("oculus_m750d_lf");
    ASSERT_TRUE(preset.ok()) << preset.error().message;
    const auto file = apply_json(*preset, R"({"range_max": 50, "bins": 600})");
    auto set = apply_config_override(file, "bins=700");
    ASSERT_TRUE(set.ok());
    EXPECT_EQ(set->frequency_hz, 750e3); // preset
    EXPECT_EQ(set->range_max_m, 50);     // file over preset
    EXPECT_EQ(set->bins, 700u);          // --set over file
}

TEST(Config, JsonRoundTrip) {
    for (const auto& name : preset_names()) {
        auto preset = load_preset(name);
        ASSERT_TRUE(preset.ok()) << preset.error().message;
        const std::string text = config_to_json(*preset);
        const auto back = apply_json(SonarConfig{}, text);
        EXPECT_EQ(config_to_json(back), text) << name;
    }
    SonarConfig config;
    config.absorption_db_per_m = 0.05;
    config.effects.tvg = EffectMode::on;
    const auto json = nlohmann::json::parse(config_to_json(config));
    EXPECT_EQ(json["absorption"], 0.05);
    EXPECT_EQ(json["effects"]["tvg"], "on");
    EXPECT_EQ(json["display"]["colormap"], "sonar");
    EXPECT_EQ(nlohmann::json::parse(config_to_json(SonarConfig{}))["absorption"], "auto");
}

// A text key with bytes that are not UTF-8 (a Latin-1 folder name from --asset-root): config_to_json
// must not throw (nlohmann's dump() throws type_error 316 on them); the bad byte becomes U+FFFD.
TEST(Config, JsonOfNonUtf8TextDoesNotThrow) {
    SonarConfig config;
    config.scene_asset_root = "/data/caf\xe9/assets";
    std::string text;
    ASSERT_NO_THROW(text = config_to_json(config));
    const auto json = nlohmann::json::parse(text);
    EXPECT_EQ(json["scene"]["asset_root"], "/data/caf\xef\xbf\xbd/assets");
}

TEST(Presets, AllLoadValidateAndCiteASource) {
    const auto names = preset_names();
    for (const char* expected :
         {"default", "oculus_m750d_lf", "oculus_m750d_hf", "oculus_m1200d_lf", "oculus_m1200d_hf", "gemini_720is",
          "blueview_m900_90", "blueview_p900_130", "aris_explorer_3000"})
        EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
    for (const auto& name : names) {
        auto preset = load_preset(name);
        ASSERT_TRUE(preset.ok()) << preset.error().message;
        EXPECT_TRUE(preset->validate().ok()) << name;
        EXPECT_EQ(preset->name, name);
        EXPECT_FALSE(preset->description.empty()) << name;
        EXPECT_FALSE(preset->source.empty()) << name;
        EXPECT_LE(preset->bins, 1024u) << name;
    }
    auto aris = load_preset("aris_explorer_3000");
    ASSERT_TRUE(aris.ok());
    EXPECT_EQ(aris->beam_angles_deg.size(), 128u);
    EXPECT_EQ(aris->beams, 128u);
    EXPECT_EQ(aris->frequency_hz, 3e6);

    auto fallback = load_preset("default");
    ASSERT_TRUE(fallback.ok());
    EXPECT_EQ(fallback->bins, 512u);
    EXPECT_EQ(fallback->range_max_m, 40);
    EXPECT_EQ(fallback->frequency_hz, 750e3);
}

TEST(Presets, UnknownPresetListsValidOnes) {
    auto result = load_preset("oculus_m9000");
    ASSERT_FALSE(result.ok());
    EXPECT_NE(result.error().message.find("oculus_m9000"), std::string::npos);
    EXPECT_NE(result.error().message.find("gemini_720is"), std::string::npos);
}

std::string invalid(const std::string& override_text) {
    auto result = apply_config_override(SonarConfig{}, override_text);
    EXPECT_TRUE(result.ok()) << override_text;
    if (!result.ok()) return {};
    const auto valid = result->validate();
    EXPECT_FALSE(valid.ok()) << override_text;
    return valid ? std::string() : valid.error().message;
}

TEST(Validate, NamesFieldAndValue) {
    EXPECT_EQ(invalid("beams=0"), "beams = 0: must be in [1, 16384]");
    EXPECT_EQ(invalid("bins=0"), "bins = 0: must be in [1, 65536]");
    EXPECT_NE(invalid("range_min=-1").find("range_min = -1"), std::string::npos);
    EXPECT_NE(invalid("range_max=0.2").find("range_max = 0.2"), std::string::npos); // below range_min 0.5
    EXPECT_NE(invalid("hfov=400").find("hfov = 400"), std::string::npos);
    EXPECT_NE(invalid("hfov=0").find("hfov = 0"), std::string::npos);
    EXPECT_NE(invalid("vfov=180").find("vfov = 180"), std::string::npos);
    EXPECT_NE(invalid("vfov=-1").find("vfov"), std::string::npos);
    EXPECT_NE(invalid("sound_speed=0").find("sound_speed"), std::string::npos);
    EXPECT_NE(invalid("frequency=-5").find("frequency"), std::string::npos);
    EXPECT_NE(invalid("display.db_max=10").find("display.db_max"), std::string::npos);
    EXPECT_NE(invalid("accuracy.pixels_per_beam=0").find("pixels_per_beam"), std::string::npos);
    EXPECT_NE(invalid("accuracy.rows_per_vfov=0").find("rows_per_vfov"), std::string::npos);
    EXPECT_NE(invalid("accuracy.max_slice=121").find("max_slice"), std::string::npos);
    EXPECT_NE(invalid("accuracy.max_slice=0").find("max_slice"), std::string::npos);
    EXPECT_NE(invalid("speckle_looks=0").find("speckle_looks"), std::string::npos);
    EXPECT_NE(invalid("source_level=inf").find("source_level"), std::string::npos);
    EXPECT_NE(invalid("range_min=1e-5").find("range_max / range_min"), std::string::npos);
    EXPECT_NE(invalid("beam_angles=10,10,-10").find("strictly decreasing"), std::string::npos);
    EXPECT_NE(invalid("beam_angles=-10,0,10").find("strictly decreasing"), std::string::npos);
    EXPECT_NE(invalid("beam_angles=80,0,-10").find("outside"), std::string::npos);

    // The hard cases of docs/hard_cases.md stay valid.
    SonarConfig wide;
    wide.hfov_deg = 360;
    wide.beams = 4096;
    EXPECT_TRUE(wide.validate().ok());
    SonarConfig narrow;
    narrow.hfov_deg = 1;
    narrow.beams = 1;
    narrow.range_min_m = 0.01;
    narrow.range_max_m = 100; // ratio 1e4
    EXPECT_TRUE(narrow.validate().ok());

    // A table contradicted by a later `beams` is reported.
    auto table = apply_json(SonarConfig{}, R"({"beam_angles": [10, 0, -10]})");
    EXPECT_TRUE(table.validate().ok());
    table.beams = 4;
    EXPECT_NE(table.validate().error().message.find("does not match beam_angles"), std::string::npos);
}

// docs/pipeline.md, "Frames and grids": bins derived from the bandwidth, delta r = c / 2B (0.2-60 m at 30 kHz: 2.5 cm,
// 2392 bins).
// beam_focus fixed or none defocuses the aperture (src/core/plan_focus.cpp): sinc and hann have an aperture
// weighting to defocus, the other shapes none; the legacy modes have no horizontal pattern.
TEST(Validate, BeamFocusNeedsAKnownApertureAndThePhysicalMode) {
    const auto problem = json_problem;
    EXPECT_EQ(problem(R"({"beam_focus": "fixed", "horizontal_pattern": "chebyshev"})"),
              "beam_focus = fixed: needs horizontal_pattern sinc or hann (an aperture whose weighting vksonar knows), "
              "not chebyshev");
    EXPECT_EQ(problem(R"({"beam_focus": "none", "horizontal_pattern": "gaussian"})"),
              "beam_focus = none: needs horizontal_pattern sinc or hann (an aperture whose weighting vksonar knows), "
              "not gaussian");
    EXPECT_EQ(problem(R"({"beam_focus": "none", "mode": "uuv-legacy"})"),
              "beam_focus = none: needs mode physical (the legacy modes reproduce their plugins' images)");
    EXPECT_NE(problem(R"({"focus_range": 0})").find("focus_range = 0: must be in (0, 100000] m"), std::string::npos);
    EXPECT_NE(problem(R"({"beam_focus": "sharp"})").find("beam_focus"), std::string::npos);
    EXPECT_EQ(problem(R"({"beam_focus": "fixed", "horizontal_pattern": "hann", "focus_range": 3})"), "");
    EXPECT_EQ(problem(R"({"beam_focus": "dynamic", "horizontal_pattern": "box"})"), "");
}

// element_width is a line array's: refused where the beams resolve planar, and outside [0, 2].
TEST(Validate, ElementWidthNeedsALineArray) {
    const auto problem = json_problem;
    const std::string rule = ": needs a line array (beam_geometry line_array, mode physical, hfov < 180): the "
                             "elements lie along its axis";
    EXPECT_EQ(problem(R"({"element_width": 0.5, "beam_geometry": "planar"})"), "element_width = 0.5" + rule);
    EXPECT_EQ(problem(R"({"element_width": 0.5, "hfov": 200})"), "element_width = 0.5" + rule);
    EXPECT_EQ(problem(R"({"element_width": 0.5, "mode": "gtri-legacy"})"), "element_width = 0.5" + rule);
    EXPECT_NE(problem(R"({"element_width": 3})").find("element_width = 3: must be in [0, 2]"), std::string::npos);
    EXPECT_EQ(problem(R"({"element_width": 0.5})"), "");
    EXPECT_EQ(problem(R"({"element_width": 0, "beam_geometry": "planar"})"), "");
}

TEST(Validate, BandwidthDerivesTheRangeBins) {
    SonarConfig c;
    c.range_min_m = 0.2;
    c.range_max_m = 60.0;
    c.sound_speed_mps = 1500.0;
    c.bins = 1024;
    EXPECT_EQ(c.range_bins(), 1024u) << "bandwidth 0: bins as given";
    c.bandwidth_hz = 30e3;
    EXPECT_TRUE(c.validate().ok());
    EXPECT_EQ(c.range_bins(), 2392u); // 59.8 m / 0.025 m
    c.bandwidth_hz = 1.0;             // c / 2B = 750 m, far wider than the window: one bin
    EXPECT_EQ(c.range_bins(), 1u);
    c.sound_speed_mps = 1480.0;
    c.bandwidth_hz = 20e3; // 59.8 / 0.037 = 1616.2 -> 1616
    EXPECT_EQ(c.range_bins(), 1616u);
    EXPECT_EQ(invalid("bandwidth=-1"), "bandwidth = -1: must be in [0, 20000000] Hz");
    // Chebyshev side-lobe levels: the -3 dB beamwidth needs them below -3 dB; -10 dB keeps margin.
    EXPECT_EQ(invalid("horizontal_sidelobe_db=-5"), "horizontal_sidelobe_db = -5: must be in [-100, -10] dB");
    EXPECT_EQ(invalid("vertical_sidelobe_db=-120"), "vertical_sidelobe_db = -120: must be in [-100, -10] dB");
    EXPECT_NE(invalid("bandwidth=nan").find("bandwidth"), std::string::npos);
    // 39.5 m at c / 2B = 0.54 mm: 73.7k bins, over the limit; the message gives the count and c / 2B.
    const std::string too_many = invalid("bandwidth=1.4e6");
    EXPECT_NE(too_many.find("bandwidth = 1400000: gives 73733 range bins of c / 2B = 0.0005357142857 m"),
              std::string::npos)
        << too_many;
}

TEST(Reference, DocsConfigMdIsInSyncWithTheTable) {
    const std::string table = config_keys::reference_markdown();
    for (const auto& key : config_keys::all())
        EXPECT_NE(table.find(std::string("`") + key.name + "`"), std::string::npos) << key.name;
#ifdef VKSONAR_ASSET_DIR
    std::ifstream file(std::string(VKSONAR_ASSET_DIR) + "/../docs/config.md");
    ASSERT_TRUE(file) << "docs/config.md is missing";
    std::stringstream text;
    text << file.rdbuf();
    EXPECT_NE(text.str().find(table), std::string::npos)
        << "docs/config.md is out of date: regenerate its table with `vksonar presets --keys`";
#endif
}

} // namespace
} // namespace vksonar
