// SonarConfig <-> JSON (files, --set overrides, meta.json) and SonarConfig::validate().
// Every key goes through the table in config_keys.cpp.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "config/config_keys.h"
#include "core/json_depth.h"
#include "core/json_member_names.h"
#include "core/plan.h" // resolves_to_line_array
#include "vksonar/config.h"

namespace vksonar {
namespace {

using config_keys::Json;

std::string unknown_key_message(const std::string& name) {
    return "unknown key '" + name + "' (did you mean '" + config_keys::closest(name) + "'?)";
}

// Applies the members of `object` (whose keys are relative to `prefix`) to `config`. `applied`: the
// dotted names set so far in this file: one key spelled dotted and nested ("display.db_min" beside
// "display": {"db_min"}) would leave the later in silence, as a key twice in one object would.
// Returns an empty string or the first problem, naming the dotted key.
std::string apply_object(SonarConfig& config, const Json& object, const std::string& prefix,
                         std::set<std::string>& applied) {
    for (auto it = object.begin(); it != object.end(); ++it) {
        const std::string name = prefix + it.key();
        if (const auto* key = config_keys::find(name)) {
            if (!applied.insert(name).second)
                return "key '" + name + "' is given twice (dotted and nested: one value would be lost)";
            std::string problem = key->set(config, it.value());
            if (!problem.empty()) return "key '" + name + "': " + problem;
            continue;
        }
        if (config_keys::is_group(name)) {
            if (!it.value().is_object())
                return "key '" + name + "': expected an object of " + name + ".* keys, got " + it.value().dump();
            std::string problem = apply_object(config, it.value(), name + ".", applied);
            if (!problem.empty()) return problem;
            continue;
        }
        return unknown_key_message(name);
    }
    return {};
}

std::string format_number(double value) {
    std::ostringstream out;
    out.precision(10);
    out << value;
    return out.str();
}

// The range window over the resolution c / 2B, rounded: as a double, so that validate() can name a
// count too large for the integer.
double bins_from_bandwidth(const SonarConfig& c) {
    return std::round((c.range_max_m - c.range_min_m) * 2.0 * c.bandwidth_hz / c.sound_speed_mps);
}

// Helpers for validate(): each returns true when the check fails and fills `problem`.
struct Checker {
    std::string problem;

    bool fail(const std::string& key, double value, const std::string& rule) {
        if (problem.empty()) problem = key + " = " + format_number(value) + ": " + rule;
        return true;
    }
    void check(bool ok, const std::string& key, double value, const std::string& rule) {
        if (!ok) fail(key, value, rule);
    }
};

} // namespace

Result<SonarConfig> apply_config_json(const SonarConfig& base, const std::string& json_text,
                                      const std::string& origin) {
    if (json_nests_too_deep(json_text))
        return make_error(ErrorCode::parse,
                          origin + ": invalid JSON: nests deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    // A key twice in one object would leave the last in silence: refused, naming it (MemberNames). A config
    // has a few hundred keys; an object of many thousands is no config, and the ordered object's inserts (a
    // search each) would take time quadratic in them (80000 keys: 4.5 s, 2 million: hours): refused at the
    // key past the limit, during the parse.
    struct TooManyKeys {};
    MemberNames names;
    const Json::parser_callback_t keys_once = [&](int, Json::parse_event_t event, Json& parsed) {
        names.on(event, parsed);
        if (names.keys() > kMaxConfigKeys) throw TooManyKeys{};
        return true;
    };
    Json root;
    try {
        root = Json::parse(json_text, keys_once, /*allow_exceptions=*/true, /*ignore_comments=*/true);
    } catch (const TooManyKeys&) {
        return make_error(ErrorCode::parse, origin + ": more than " + std::to_string(kMaxConfigKeys) +
                                                " keys (a config has a few hundred)");
    } catch (const nlohmann::json::parse_error& e) {
        // nlohmann's message starts with "[json.exception.parse_error.101] parse error at line 3, column 5: ...".
        std::string what = e.what();
        const auto pos = what.find("] ");
        if (pos != std::string::npos) what = what.substr(pos + 2);
        return make_error(ErrorCode::parse, origin + ": invalid JSON: " + what);
    } catch (const nlohmann::json::exception& e) {
        // Not a syntax error but a value the parser cannot hold, e.g. "range_max": 1e999 (out_of_range.406).
        std::string what = e.what();
        const auto pos = what.find("] ");
        if (pos != std::string::npos) what = what.substr(pos + 2);
        return make_error(ErrorCode::parse, origin + ": invalid JSON: " + what);
    }
    if (!names.twice().empty())
        return make_error(ErrorCode::parse, origin + ": key '" + names.twice() + "' is given twice in one object");
    if (!root.is_object())
        return make_error(ErrorCode::parse,
                          origin + ": expected a JSON object of config keys, got " + std::string(root.type_name()));
    SonarConfig config = base;
    std::set<std::string> applied;
    std::string problem = apply_object(config, root, "", applied);
    if (!problem.empty()) return make_error(ErrorCode::invalid_argument, origin + ": " + problem);
    return config;
}

Result<SonarConfig> apply_config_file(const SonarConfig& base, const std::string& path) {
    std::ifstream file(path, std::ios::binary);
    if (!file) return make_error(ErrorCode::io, path + ": cannot open config file");
    std::ostringstream text;
    text << file.rdbuf();
    if (file.bad()) return make_error(ErrorCode::io, path + ": cannot read config file");
    return apply_config_json(base, text.str(), path);
}

Result<SonarConfig> apply_config_override(const SonarConfig& base, const std::string& key_equals_value) {
    // Keys and values end up in JSON (meta.json, error messages), which must be UTF-8: reject other
    // bytes here with a clear error instead of a serializer exception later (found by fuzz_config).
    try {
        (void)Json(key_equals_value).dump();
    } catch (const nlohmann::json::type_error&) {
        return make_error(ErrorCode::invalid_argument,
                          "--set " + Json(key_equals_value).dump(-1, ' ', false, Json::error_handler_t::replace) +
                              ": not valid UTF-8 text");
    }
    const auto equals = key_equals_value.find('=');
    if (equals == std::string::npos || equals == 0)
        return make_error(ErrorCode::invalid_argument,
                          "--set " + key_equals_value + ": expected key=value (e.g. --set effects.speckle=off)");
    const std::string name = key_equals_value.substr(0, equals);
    const std::string value = key_equals_value.substr(equals + 1);
    const auto* key = config_keys::find(name);
    if (!key)
        return make_error(ErrorCode::invalid_argument, "--set " + key_equals_value + ": " + unknown_key_message(name));
    SonarConfig config = base;
    std::string problem = key->set(config, config_keys::parse_override_value(*key, value));
    if (!problem.empty())
        return make_error(ErrorCode::invalid_argument,
                          "--set " + key_equals_value + ": key '" + name + "': " + problem);
    return config;
}

std::string config_to_json(const SonarConfig& config) {
    Json root = Json::object();
    for (const auto& key : config_keys::all()) {
        Json* node = &root;
        std::string name = key.name;
        std::size_t dot;
        while ((dot = name.find('.')) != std::string::npos) {
            node = &(*node)[name.substr(0, dot)];
            name = name.substr(dot + 1);
        }
        (*node)[name] = key.get(config);
    }
    // A text key may hold bytes that are not UTF-8 (scene.asset_root from a Latin-1 folder name, via
    // --asset-root): replaced by U+FFFD, as dump() would otherwise throw (nothing here may throw).
    return root.dump(2, ' ', false, Json::error_handler_t::replace);
}

std::uint32_t SonarConfig::range_bins() const {
    if (!(bandwidth_hz > 0)) return bins;
    return static_cast<std::uint32_t>(std::clamp(bins_from_bandwidth(*this), 1.0, 65536.0));
}

Result<void> SonarConfig::validate() const {
    // The first problem in words, or empty.
    const std::string first_problem = [this]() -> std::string {
        Checker c;

        // Every number in the table must be finite (NaN/Inf arrive through --set or a hand-written file).
        for (const auto& key : config_keys::all()) {
            const Json value = key.get(*this);
            if (value.is_number_float() && !std::isfinite(value.get<double>()))
                return std::string(key.name) + " = " + format_number(value.get<double>()) + ": must be a finite number";
            // An enum field set to a value no name has (static_cast in C++) reads as its number.
            if (key.type == config_keys::KeyType::choice && !value.is_string())
                return std::string(key.name) + " = " + value.dump() + ": must be one of " + key.choices;
        }
        for (std::size_t i = 0; i < beam_angles_deg.size(); ++i)
            if (!std::isfinite(beam_angles_deg[i]))
                return "beam_angles[" + std::to_string(i) + "] = " + format_number(beam_angles_deg[i]) +
                       ": must be a finite number";

        // Every numeric key within its physical range (the table in config_keys.cpp: one place per key,
        // with its reason), then the rules that tie keys together.
        if (std::string problem = config_keys::check_ranges(*this); !problem.empty()) return problem;

        c.check(horizontal_beamwidth_deg <= hfov_deg, "horizontal_beamwidth", horizontal_beamwidth_deg,
                "must be at most hfov (" + format_number(hfov_deg) + " degrees): a beam wider than the whole fan");
        c.check(range_max_m > range_min_m, "range_max", range_max_m,
                "must be greater than range_min (" + format_number(range_min_m) + " m)");
        if (c.problem.empty())
            c.check(range_max_m / range_min_m <= 1e6, "range_max", range_max_m,
                    "range_max / range_min must be at most 1e6 (range_min = " + format_number(range_min_m) +
                        " m); raise range_min");
        // A real pulse's band f +- B/2 cannot reach below 0 Hz.
        c.check(bandwidth_hz <= 2.0 * frequency_hz, "bandwidth", bandwidth_hz,
                "must be at most twice the frequency (" + format_number(2.0 * frequency_hz) +
                    " Hz): the band f +- B/2 would reach below 0 Hz");
        c.check(db_max > db_min, "display.db_max", db_max,
                "must be greater than display.db_min (" + format_number(db_min) + " dB)");
        if (c.problem.empty() && bandwidth_hz > 0) {
            const double resolution_m = sound_speed_mps / (2.0 * bandwidth_hz);
            const double derived = bins_from_bandwidth(*this);
            c.check(derived <= 65536, "bandwidth", bandwidth_hz,
                    "gives " + format_number(derived) + " range bins of c / 2B = " + format_number(resolution_m) +
                        " m over the range window; at most 65536");
        }
        if (!c.problem.empty()) return c.problem;

        if (!beam_angles_deg.empty()) {
            if (beam_angles_deg.size() != beams)
                return "beams = " + std::to_string(beams) + ": does not match beam_angles (" +
                       std::to_string(beam_angles_deg.size()) + " entries); set one or clear beam_angles";
            const double half = hfov_deg / 2 + 1e-9;
            for (std::size_t i = 0; i < beam_angles_deg.size(); ++i) {
                if (std::abs(beam_angles_deg[i]) > half)
                    return "beam_angles[" + std::to_string(i) + "] = " + format_number(beam_angles_deg[i]) +
                           ": outside +-hfov/2 (" + format_number(hfov_deg / 2) + " degrees)";
                if (i > 0 && !(beam_angles_deg[i] < beam_angles_deg[i - 1]))
                    return "beam_angles[" + std::to_string(i) + "] = " + format_number(beam_angles_deg[i]) +
                           ": the table must be strictly decreasing (port first), but beam_angles[" +
                           std::to_string(i - 1) + "] = " + format_number(beam_angles_deg[i - 1]);
            }
        }

        // A focus other than dynamic defocuses the aperture (plan_focus.cpp): it needs the aperture's
        // weighting, which sinc (uniform) and hann have; chebyshev's ideal line source ends in impulses, and
        // box and gaussian are no aperture. The legacy modes reproduce their plugins, which have no focus.
        // A choice key's value as its name (the key table's own).
        auto name_of = [this](const char* key) { return config_keys::find(key)->get(*this).get<std::string>(); };
        if (c.problem.empty() && beam_focus != BeamFocus::dynamic) {
            const std::string focus = "beam_focus = " + name_of("beam_focus");
            if (mode != SonarMode::physical)
                c.problem = focus + ": needs mode physical (the legacy modes reproduce their plugins' images)";
            else if (horizontal_pattern != BeamPattern::sinc && horizontal_pattern != BeamPattern::hann)
                c.problem = focus +
                            ": needs horizontal_pattern sinc or hann (an aperture whose weighting vksonar "
                            "knows), not " +
                            name_of("horizontal_pattern");
        }
        // The element pattern is a line array's: its elements lie along one axis (a planar beam's aperture
        // faces along the beam, and the legacy modes reproduce their plugins).
        if (c.problem.empty() && element_width > 0.0 && !resolves_to_line_array(*this, nullptr))
            c.fail("element_width", element_width,
                   "needs a line array (beam_geometry line_array, mode physical, hfov < 180): the elements lie "
                   "along its axis");
        // The uuv plugin projects one pinhole depth image; a sliced depth pass has no single focal length.
        if (c.problem.empty() && mode == SonarMode::uuv_legacy)
            c.check(
                hfov_deg <= max_slice_deg && hfov_deg < 180, "hfov", hfov_deg,
                "mode uuv-legacy needs one perspective depth image: hfov must be < 180 and <= accuracy.max_slice (" +
                    format_number(max_slice_deg) + " degrees)");
        return c.problem;
    }();
    if (first_problem.empty()) return {};
    return make_error(ErrorCode::invalid_argument, first_problem);
}

} // namespace vksonar
