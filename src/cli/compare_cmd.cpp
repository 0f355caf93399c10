// `vksonar compare A.npy B.npy`: how far two scans are apart, in linear and dB terms.
// A is the reference (PSNR uses its peak). Exit 1 when the max dB difference exceeds --tol.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/commands.h"
#include "cli/npy_read.h"

namespace vksonar::cli {
namespace {

std::string shape_text(const std::vector<std::size_t>& shape) {
    std::string text = "(";
    for (std::size_t i = 0; i < shape.size(); ++i)
        text += (i ? ", " : "") + std::to_string(shape[i]);
    return text + (shape.size() == 1 ? ",)" : ")");
}

// 10 log10 of an intensity; zero and negative intensities sit at the bottom of the dB scale.
double to_db(double intensity) {
    return 10.0 * std::log10(std::max(intensity, 1e-300));
}

} // namespace

int run_compare(const std::vector<std::string>& argv) {
    const Args args =
        parse_args(argv, {{"--tol", true, false}, {"--floor", true, false}, {"--help", false, false}}, "compare");
    if (args.has("--help")) {
        std::printf("usage: vksonar compare A.npy B.npy [--tol DB] [--floor DB]\n"
                    "  A is the reference. Prints max abs difference, RMSE, the max dB difference over elements\n"
                    "  where either scan is above the floor, and PSNR (peak of A). Exits 1 if the max dB\n"
                    "  difference exceeds --tol (default 1 dB). --floor defaults to the peak minus 60 dB.\n");
        return 0;
    }
    if (args.positional.size() != 2)
        throw BadInput("compare: needs two .npy files (A.npy B.npy), got " + std::to_string(args.positional.size()));
    const double tolerance_db = args.has("--tol") ? parse_double(args.value("--tol"), "compare: --tol") : 1.0;
    if (tolerance_db < 0) throw BadInput("compare: --tol " + args.value("--tol") + " must be >= 0 dB");

    const NpyArray a = read_npy(args.positional[0]);
    const NpyArray b = read_npy(args.positional[1]);
    if (a.shape != b.shape)
        throw BadInput("compare: shapes differ: " + args.positional[0] + " is " + shape_text(a.shape) + ", " +
                       args.positional[1] + " is " + shape_text(b.shape));
    const std::size_t n = a.values.size();

    std::size_t non_finite = 0;
    double peak = 0;
    for (std::size_t i = 0; i < n; ++i) {
        if (!std::isfinite(a.values[i]) || !std::isfinite(b.values[i])) {
            ++non_finite;
            continue;
        }
        peak = std::max({peak, std::abs(a.values[i]), std::abs(b.values[i])});
    }
    const double floor_db = args.has("--floor") ? parse_double(args.value("--floor"), "compare: --floor")
                                                : (peak > 0 ? to_db(peak) - 60.0 : 0.0);

    double max_abs = 0, sum_sq = 0, max_db = 0, peak_a = 0;
    std::size_t above_floor = 0, max_db_index = 0;
    for (std::size_t i = 0; i < n; ++i) {
        const double x = a.values[i], y = b.values[i];
        if (!std::isfinite(x) || !std::isfinite(y)) continue;
        const double d = x - y;
        max_abs = std::max(max_abs, std::abs(d));
        sum_sq += d * d;
        peak_a = std::max(peak_a, std::abs(x));
        const double dx = to_db(x), dy = to_db(y);
        if (std::max(dx, dy) < floor_db) continue;
        ++above_floor;
        // Below the floor both count as the floor, so a value vanishing into the noise costs at most
        // its height above the floor.
        const double diff = std::abs(std::max(dx, floor_db) - std::max(dy, floor_db));
        if (diff > max_db) {
            max_db = diff;
            max_db_index = i;
        }
    }
    const std::size_t finite = n - non_finite;
    const double rmse = finite ? std::sqrt(sum_sq / static_cast<double>(finite)) : 0.0;

    std::printf("shape:        %s (%zu elements)\n", shape_text(a.shape).c_str(), n);
    std::printf("max_abs:      %.6g\n", max_abs);
    std::printf("rmse:         %.6g\n", rmse);
    std::printf("max_db_diff:  %.4f dB (floor %.2f dB, %zu elements above it", max_db, floor_db, above_floor);
    if (max_db > 0) std::printf(", worst at flat index %zu", max_db_index);
    std::printf(")\n");
    if (rmse > 0 && peak_a > 0)
        std::printf("psnr:         %.2f dB\n", 20.0 * std::log10(peak_a / rmse));
    else
        std::printf("psnr:         inf\n");
    if (non_finite) std::printf("non_finite:   %zu elements (NaN/Inf in either file)\n", non_finite);

    const bool pass = non_finite == 0 && max_db <= tolerance_db;
    std::printf("result:       %s (tolerance %.4g dB)\n", pass ? "PASS" : "FAIL", tolerance_db);
    return pass ? 0 : 1;
}

} // namespace vksonar::cli
