// Column-major 4 x 4 matrices in double (m[col * 4 + row]): the scene's node transforms, the depth
// pass's composition and the sub-pixel returns' facing all use these, so each is written once.
#pragma once

#include <array>

namespace vksonar {

using Mat4 = std::array<double, 16>;

inline Mat4 identity4() {
    return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
}

// a b, summed in k order so every caller rounds the same way.
inline Mat4 multiply(const Mat4& a, const Mat4& b) {
    Mat4 c{};
    for (int col = 0; col < 4; ++col)
        for (int row = 0; row < 4; ++row) {
            double s = 0;
            for (int k = 0; k < 4; ++k)
                s += a[k * 4 + row] * b[col * 4 + k];
            c[col * 4 + row] = s;
        }
    return c;
}

// The determinant of the upper-left 3 x 3 (the linear part): its sign says whether the transform mirrors
// (a triangle's winding flips), zero that it flattens its meshes.
inline double determinant3(const Mat4& m) {
    return m[0] * (m[5] * m[10] - m[9] * m[6]) - m[4] * (m[1] * m[10] - m[9] * m[2]) +
           m[8] * (m[1] * m[6] - m[5] * m[2]);
}

} // namespace vksonar
