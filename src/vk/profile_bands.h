// The rows profile.comp walks per dispatch. Lavapipe (Mesa's llvmpipe) ends an invocation's loops after
// 65535 loop iterations in all, counted over every loop of the shader (gallivm's loop limiter), and says
// nothing: the rows past that point are never added. One invocation walks a (cone) column's every row,
// which at `--quality accurate` on a line array came to about 80k iterations and left beams near
// broadside up to 99 % short in the nadir rows. So the host splits the rows into bands, one dispatch
// each, every band's loop count within a budget; each band adds to the profiles after the one before,
// so every cell's additions keep their order and the frame is the same bits for any banding.
#pragma once
#include <cstdint>
#include <vector>

#include "core/plan.h"
#include "sonar_shared.h"
#include "stages/stage_table.h"

namespace vksonar::vk {

// The loop iterations one band may cost by profile_row_cost's estimate: half lavapipe's limit, which
// leaves room for pixels whose range footprints span more bins than the estimate allows.
constexpr double kProfileBandBudget = 32768.0;
// The range bins a lit pixel's footprint is taken to span in the estimate (profile_footprint_bins): at
// least 6 (the default scene averages about 2 of its 7.7 cm bins; a grazing seabed's far rows a few more),
// and at least what a footprint's length in metres spans, as that is the geometry's, not the bins':
// kProfileFootprintM, and kProfileFootprintGrazing x range_max x the larger pixel side (a pixel's
// footprint on a surface at 30 deg grazing). 8192 bins over 20 m (2.4 mm) put 80 and more bins under a
// seabed pixel, and pixels 2.8 deg wide (accuracy.pixels_per_beam 0.09) their width in range across
// the row: with 6 bins every frame of either ran out of loops.
constexpr double kProfileFootprintBins = 6.0;
constexpr double kProfileFootprintM = 0.45; // 6 bins of the default's 7.7 cm, so its bands stay as they were
constexpr double kProfileFootprintGrazing = 2.0;
[[nodiscard]] double profile_footprint_bins(const Plan& plan);

// ProfileRowBand::loop_check: the turns of profile.comp's last loop, which the device cuts short where it
// has ended the invocation's loops (loops_ran_out: the host then refuses the frame).
constexpr std::uint32_t kLoopCheckTurns = 2;

// An upper estimate of the loop iterations row `row` adds to the costliest profile.comp invocation in the
// layout that walks rows one by one (DeviceShape::gather_rows off): its pixels in each view's window (the
// pixel column's own, or a run of cone columns' with the tier views' reach), each with its bins.
[[nodiscard]] double profile_row_cost(const Plan& plan, const DeviceShape& shape, std::uint32_t row);

// The bands, in order, covering rows [0, plan.rows): one band where the walk takes rows in blocks
// (`block_rows`: profile.comp kGatherRows) or where every row fits one budget.
[[nodiscard]] std::vector<shared::ProfileRowBand> profile_row_bands(const Plan& plan, const DeviceShape& shape,
                                                                    bool block_rows);

} // namespace vksonar::vk
