#include "vk/resample_walk.h"

#include <algorithm>
#include <vector>

#include "core/sonar_math.hpp"

namespace vksonar::vk {
namespace {

// Which share of a column's profile a beam adds: none, column_weight, or 1 - column_weight.
enum class Share : std::uint8_t { none, weight, rest };

struct Term {
    std::uint32_t column;
    Share share;
    bool operator==(const Term& other) const { return column == other.column && share == other.share; }
};

// w(c, j) of docs/pipeline.md §4, by the rule resample.comp's gather() and the CPU reference use.
Share gathered_share(const Plan& plan, std::uint32_t column, std::uint32_t beam) {
    const std::uint32_t share = math_f32::resample_share(plan.column_beam[column], beam, plan.beams, plan.circular);
    return share == 1 ? Share::weight : (share == 2 ? Share::rest : Share::none);
}

} // namespace

bool resample_can_walk(const Plan& plan, std::uint32_t beams_per_run) {
    if (beams_per_run == 0 || plan.beam_column_begin.size() != plan.beams ||
        plan.beam_column_end.size() != plan.beams || plan.column_beam.size() != plan.profile_columns)
        return false;
    std::vector<Term> gathered, walked, carry;
    for (std::uint32_t first = 0; first < plan.beams; first += beams_per_run) {
        const std::uint32_t last = std::min(first + beams_per_run, plan.beams);
        // The terms resample.comp's walk() adds, step by step as it adds them.
        std::uint32_t c = plan.beam_column_begin[first];
        carry.clear();
        for (std::uint32_t j = first; j < last; ++j) {
            const std::uint32_t end = std::min(plan.beam_column_end[j], plan.profile_columns);
            walked = carry;
            carry.clear();
            for (; c < end; ++c) {
                const bool own = plan.column_beam[c] == j;
                walked.push_back({c, own ? Share::weight : Share::rest});
                if (own) carry.push_back({c, Share::rest});
            }
            gathered.clear();
            for (std::uint32_t g = plan.beam_column_begin[j]; g < end; ++g)
                gathered.push_back({g, gathered_share(plan, g, j)});
            if (walked != gathered) return false;
        }
    }
    return true;
}

} // namespace vksonar::vk
