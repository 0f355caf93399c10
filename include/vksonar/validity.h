// Validity domains of the models a frame uses: where vksonar's numbers are the model's and where they
// are an extrapolation. validate() refuses the physically impossible; this says, for a config that
// validates, which fitted or approximate model it takes outside the domain where that model holds.
#pragma once

#include <string>
#include <vector>

#include "vksonar/config.h"
#include "vksonar/scene.h"

namespace vksonar {

// One model the frame uses and whether the config keeps it inside its domain.
// Thread-safety: a plain value: safe to read from many threads at once, to write from one.
struct ModelValidity {
    std::string model;  // "francois_garrison", "far_field_beam_pattern", "beam_sampling", "chebyshev_large_array",
                        // "rough_facet"
    bool ok = true;     // the config lies inside the model's domain
    std::string key;    // the key that decides (the first one outside the domain when !ok)
    double value = 0.0; // its value
    std::string domain; // the domain in words, with the figures ("frequency in [200, 1e+06] Hz")
    std::string action; // what vksonar does outside it ("extrapolates the fit"); "none" when ok

    // The entry as the one line the CLI prints for !ok: "francois_garrison: frequency = 3e+06 is outside
    // the model's domain (frequency in [200, 1e+06] Hz, ...); vksonar extrapolates ...". Pure.
    std::string warning() const;
};

// The models a config (and the scene's materials) uses, each checked against its domain, in a fixed
// order: francois_garrison (absorption auto), far_field_beam_pattern (a beam pattern effect not off),
// beam_sampling (the physical mode, more than one beam; judged from the config's side-lobe kernel reach:
// the plan's own entry also knows when the main-lobe-only rule shortens it), chebyshev_large_array (per
// chebyshev pattern), rough_facet (per rough material, incidence not off).
// Meaningful for a config that validates. Pure: returns a new vector, may be called from any thread.
[[nodiscard]] std::vector<ModelValidity> model_validity(const SonarConfig& config,
                                                        const std::vector<AcousticMaterial>& materials = {});

} // namespace vksonar
