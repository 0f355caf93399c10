// π and the degree/radian factors, defined once for the library (tests keep their own: their
// references are computed independently of the code under test).
#pragma once

namespace vksonar {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
constexpr double kRadToDeg = 180.0 / kPi;

} // namespace vksonar
