// meta.json's "effects", "validity" and "noise" as JSON values, shared by meta.json (files.cpp) and the HDF5
// dataset's attributes (src/cli/render_cmd.cpp), so both say the same thing the same way.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/angles.h"
#include "core/plan.h"
#include "host/host_stages.h"
#include "vksonar/frame.h"
#include "vksonar/scene.h"
#include "vksonar/validity.h"

namespace vksonar::host {

// run_record.cpp: vksonar's version ("0.1.0"), and the scene's content as FNV-1a 64 in 16 hex digits:
// its vertex and index arrays, meshes, draws (transforms, materials, objects), materials, objects,
// classes and effect requests: a scene file changed in any of these (or an external buffer it names)
// hashes differently; one only re-saved with the same content does not. Every output records both
// (meta.json, the .h5 attributes).
const char* vksonar_version();
std::string scene_fnv1a64(const Scene& scene);

// {"name": {"on": bool, "why": "..."}, ...} in the plan's effect order.
inline nlohmann::ordered_json effects_json(const std::vector<EffectState>& states) {
    nlohmann::ordered_json effects = nlohmann::ordered_json::object();
    for (const EffectState& e : states)
        effects[e.name] = {{"on", e.on}, {"why", e.why}};
    return effects;
}

// Where the numbers are a model's and where they are its extrapolation (validity.h).
inline nlohmann::ordered_json validity_json(const std::vector<ModelValidity>& models) {
    nlohmann::ordered_json validity = nlohmann::ordered_json::array();
    for (const ModelValidity& v : models)
        validity.push_back({{"model", v.model},
                            {"ok", v.ok},
                            {"key", v.key},
                            {"value", v.value},
                            {"domain", v.domain},
                            {"action", v.action}});
    return validity;
}

// Beam j's horizontal -3 dB width in angle: the configured width, or for a line array's beam steered to
// theta, whose width is constant in sine, asin(sin theta + s) - asin(sin theta - s) with s = sin(bw / 2)
// (about bw / cos theta; 2.4 times the broadside width at 65 deg). meta.json's and the bag's
// rx_beamwidths.
inline double rx_beamwidth_rad(const Plan& plan, std::size_t j) {
    const double bw = plan.config.horizontal_beamwidth_deg * kDegToRad;
    if (!plan.line_array || j >= plan.beam_angle_rad.size()) return bw;
    const double s = std::sin(0.5 * bw), u = std::sin(plan.beam_angle_rad[j]);
    return std::asin(std::min(u + s, 1.0)) - std::asin(std::max(u - s, -1.0));
}

// The noise terms as used ("auto" resolved) and each beam's floor NL - DI_j (a line array's steered
// beams hear more of the sea; with element_width, plus the element pattern's power at the beam; the floor is added only
// where effects.ambient_noise is on). In every mode: the legacy modes' polar scan is the physical chain's too (their
// own images keep their constants).
inline nlohmann::ordered_json noise_json(const Plan& plan) {
    const SonarConfig& cfg = plan.config;
    nlohmann::ordered_json floors = nlohmann::ordered_json::array();
    for (std::size_t j = 0; j < plan.beams && j < plan.beam_floor_db.size(); ++j)
        floors.push_back(plan.beam_floor_db[j]);
    // the grain across beams (plan_grain.cpp): what it applies to (what the noise stage draws in rows), or
    // why every cell is drawn alone; the grid's step and taps only where something is grained
    const RowDraws rows = row_draws_of(plan);
    const bool grained_speckle = plan.grain.taps > 0 && rows.speckle, grained_noise = plan.grain.taps > 0 && rows.noise;
    // why speckle that is on goes without the grain
    std::string per_cell_speckle;
    if (plan.effects.speckle && !grained_speckle) {
        if (cfg.speckle == SpeckleModel::gaussian) per_cell_speckle = "the gaussian speckle model is drawn per cell";
        if (cfg.speckle == SpeckleModel::gamma)
            per_cell_speckle = "gamma speckle of " + nlohmann::json(cfg.speckle_looks).dump() +
                               " looks is drawn per cell: the grain averages a whole number of looks, at most " +
                               std::to_string(kGrainMaxLooks);
    }
    std::string grain = plan.grain.why;
    if (grained_speckle || grained_noise) {
        const std::string speckle = rows.speckle_looks > 1 ? "gamma speckle (the mean of " +
                                                                 std::to_string(rows.speckle_looks) + " grained looks)"
                                                           : "speckle";
        grain = (grained_speckle && grained_noise ? speckle + " and ambient noise"
                 : grained_speckle                ? speckle
                                                  : std::string("ambient noise")) +
                " correlated across beams as the receive pattern overlaps them";
        if (!per_cell_speckle.empty()) grain += " (" + per_cell_speckle + ")";
    } else if (plan.grain.taps > 0) {
        grain = per_cell_speckle.empty() ? "nothing grained: speckle and ambient noise are off"
                                         : "nothing grained: " + per_cell_speckle + ", and ambient noise is off";
    }
    const bool grained = grained_speckle || grained_noise;
    return {{"beam_correlation", cfg.beam_correlation == BeamCorrelation::pattern ? "pattern" : "none"},
            {"grain", grain},
            {"grain_grid_step", grained ? plan.grain.step : 0.0},
            {"grain_grid_step_unit", plan.line_array ? "sine" : "rad"},
            {"grain_taps", grained ? plan.grain.taps : 0u},
            {"noise_level_db", plan.noise.noise_level_db},
            {"noise_level", cfg.noise_level_db < 0.0 ? "auto: the sea's spectrum over the band" : "config"},
            {"band_hz", plan.noise.band_hz},
            {"directivity_index_db", plan.noise.directivity_index_db},
            {"directivity_index", cfg.directivity_index_db < 0.0 ? "auto: from the beam patterns" : "config"},
            {"floor_db_by_beam", std::move(floors)}};
}

// The scene's objects and classes (SceneInstance): {"instances": [{"id", "node", "mesh", "class",
// "class_id"}, ...], "classes": [{"id", "name"}, ...]}; id 0 is no object and no class.
inline nlohmann::ordered_json objects_json(const Scene& scene) {
    nlohmann::ordered_json instances = nlohmann::ordered_json::array(), classes = nlohmann::ordered_json::array();
    for (const SceneInstance& i : scene.instances())
        instances.push_back(
            {{"id", i.id}, {"node", i.node}, {"mesh", i.mesh}, {"class", i.class_name}, {"class_id", i.class_id}});
    for (std::size_t c = 0; c < scene.classes().size(); ++c)
        classes.push_back({{"id", c + 1}, {"name", scene.classes()[c]}});
    return {{"instances", std::move(instances)}, {"classes", std::move(classes)}};
}

} // namespace vksonar::host
