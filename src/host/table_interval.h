// The fan image's lookup search (images.cpp), apart so that the tests can hold it to a plain search.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace vksonar::host {

// Interval of a sorted table containing x: returns i0 and t with x = table[i0] + t (table[i0+1] - table[i0]),
// clamped to the ends (t = 0 at either end). `decreasing` selects the order of the table. `hint`: where the
// search starts, and where the interval found is left for the next one.
inline void locate_in_table(const std::vector<double>& table, std::size_t n, double x, bool decreasing,
                            std::int32_t& i0, float& t, std::int32_t& hint) {
    if (n <= 1) {
        i0 = 0;
        t = 0.0f;
        return;
    }
    auto before = [decreasing](double a, double b) { return decreasing ? a > b : a < b; };
    if (!before(table[0], x)) { // x at or before the first entry
        i0 = 0;
        t = 0.0f;
        return;
    }
    if (!before(x, table[n - 1])) { // x at or past the last entry
        i0 = static_cast<std::int32_t>(n - 1);
        t = 0.0f;
        return;
    }
    // The one lo with table[lo] before x and x not after table[lo + 1] (the table is monotonic, so "before x"
    // holds for a run of entries from the first on): walked to from `hint`, the previous pixel's, which a
    // neighbouring pixel's lies within a step or two of (a binary search from scratch found the same lo, at
    // a mispredicted branch a halving).
    std::size_t lo = std::min<std::size_t>(static_cast<std::size_t>(std::max(hint, 0)), n - 2);
    while (lo > 0 && !before(table[lo], x))
        --lo;
    while (lo + 2 < n && before(table[lo + 1], x))
        ++lo;
    hint = static_cast<std::int32_t>(lo);
    const std::size_t hi = lo + 1;
    const double span = table[hi] - table[lo];
    i0 = static_cast<std::int32_t>(lo);
    t = span != 0.0 ? static_cast<float>(std::clamp((x - table[lo]) / span, 0.0, 1.0)) : 0.0f;
}

} // namespace vksonar::host
