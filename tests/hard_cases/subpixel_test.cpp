// Hard cases of issue 17 item 6, "small and thin things keep their energy": an object smaller than a pixel
// returns what its area and material say, not zero and not a pixel's worth (docs/pipeline.md "Sub-pixel
// objects"). At the default (`balanced`) quality on both backends, with every effect that is not part of
// the closed form off (noise, speckle, absorption, both beam patterns).
//
// Energies are relative to the source level: the clean polar scan holds E / 10^(SL/10) (echo_energy,
// shaders/sonar_math.h, leaves SL out; the host adds it in dB with the noise), so the closed forms
// below, 10^(SL/10) mu (...), are compared without their 10^(SL/10).
//
// A Lambert sphere of radius a at range R (a << R): each surface element dA at incidence theta returns
// mu cos^2(theta) dA / R^4 (one cos from Lambert's f, one from the projected solid angle), and over the
// visible half, dA = 2 pi a^2 sin(theta) dtheta, integral cos^2 sin dtheta over [0, pi/2] = 1/3:
//   E = mu 2 pi a^2 / (3 R^4).
// A Lambert cylinder of radius a whose axis makes angle psi with the ray: a strip of its surface at angle
// phi around the axis from the ray's side has cos(theta) = cos(phi) sin(psi), so per unit length
//   dE/dl = mu a sin^2(psi) / r^4 * integral cos^2(phi) dphi over [-pi/2, pi/2] = mu a (pi / 2) sin^2(psi) / r^4.
// For a cable along y at x = X, z = 0 (the sonar at the origin), a point at steering angle theta has
// y = X tan(theta), r = X / cos(theta), sin(psi) = cos(theta), dl = X dtheta / cos^2(theta): per radian
// of steering angle dE/dtheta = mu a (pi / 2) X cos^4(theta) / X^4 = mu a (pi / 2) cos^4(theta) / X^3.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "core/renderer_access.h"
#include "hard_support.h"

namespace vksonar::testing::hard {
namespace {

SonarConfig closed_form_config() {
    SonarConfig c = quiet_config(); // the default preset at the default (balanced) quality, noise off
    c.effects.horizontal_pattern = EffectMode::off;
    c.effects.vertical_pattern = EffectMode::off;
    c.effects.absorption = EffectMode::off;
    c.effects.incidence = EffectMode::on;
    c.effects.spreading = EffectMode::on;
    return c;
}

AcousticMaterial lambert(double backscatter_db) {
    AcousticMaterial m;
    m.name = "lambert";
    m.backscatter_db = backscatter_db;
    m.model = AcousticMaterial::Model::lambert;
    return m;
}

// A closed UV sphere (one vertex per pole, counter-clockwise seen from outside) of radius r centred at c.
void add_closed_sphere(Scene& scene, double r, const std::array<double, 3>& c, std::uint32_t segments,
                       std::uint32_t rings, const AcousticMaterial& material) {
    std::vector<float> p{0.0f, 0.0f, static_cast<float>(r)}; // north pole: vertex 0
    for (std::uint32_t i = 1; i < rings; ++i) {
        const double theta = kPi * i / rings;
        for (std::uint32_t j = 0; j < segments; ++j) {
            const double phi = 2 * kPi * j / segments;
            p.push_back(static_cast<float>(r * std::sin(theta) * std::cos(phi)));
            p.push_back(static_cast<float>(r * std::sin(theta) * std::sin(phi)));
            p.push_back(static_cast<float>(r * std::cos(theta)));
        }
    }
    const auto south = static_cast<std::uint32_t>(p.size() / 3);
    p.insert(p.end(), {0.0f, 0.0f, static_cast<float>(-r)});
    auto ring = [&](std::uint32_t i, std::uint32_t j) { return 1 + (i - 1) * segments + j % segments; };
    std::vector<std::uint32_t> idx;
    for (std::uint32_t j = 0; j < segments; ++j) {
        idx.insert(idx.end(), {0, ring(1, j), ring(1, j + 1)});
        for (std::uint32_t i = 1; i + 1 < rings; ++i)
            idx.insert(idx.end(), {ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j), ring(i + 1, j + 1),
                                   ring(i, j + 1)});
        idx.insert(idx.end(), {ring(rings - 1, j), south, ring(rings - 1, j + 1)});
    }
    add_mesh_draw(scene, p, idx, translation(c[0], c[1], c[2]), material);
}

// A closed cylinder (capped) of radius r along y from -half to +half, centred at c, `sides` around and
// `segments` along.
void add_cable(Scene& scene, double r, double half, const std::array<double, 3>& c, std::uint32_t sides,
               std::uint32_t segments, const AcousticMaterial& material) {
    std::vector<float> p;
    for (std::uint32_t s = 0; s <= segments; ++s) {
        const double y = -half + 2 * half * s / segments;
        for (std::uint32_t k = 0; k < sides; ++k) {
            const double phi = 2 * kPi * k / sides;
            p.insert(p.end(), {static_cast<float>(r * std::cos(phi)), static_cast<float>(y),
                               static_cast<float>(r * std::sin(phi))});
        }
    }
    const auto cap0 = static_cast<std::uint32_t>(p.size() / 3);
    p.insert(p.end(), {0.0f, static_cast<float>(-half), 0.0f, 0.0f, static_cast<float>(half), 0.0f});
    auto at = [&](std::uint32_t s, std::uint32_t k) { return s * sides + k % sides; };
    std::vector<std::uint32_t> idx;
    for (std::uint32_t s = 0; s < segments; ++s)
        for (std::uint32_t k = 0; k < sides; ++k)
            idx.insert(idx.end(), {at(s, k), at(s + 1, k), at(s + 1, k + 1), at(s, k), at(s + 1, k + 1), at(s, k + 1)});
    for (std::uint32_t k = 0; k < sides; ++k) {
        idx.insert(idx.end(), {cap0, at(0, k), at(0, k + 1)});
        idx.insert(idx.end(), {cap0 + 1, at(segments, k + 1), at(segments, k)});
    }
    add_mesh_draw(scene, p, idx, translation(c[0], c[1], c[2]), material);
}

double db(double x) {
    return 10.0 * std::log10(x);
}

class Subpixel : public HardCase {};

// Lambert spheres of 2 to 40 cm diameter at 15 m: the scan's total energy within 1 dB of 2 pi a^2 mu /
// (3 R^4). Their size against the pixel grid: the default's pixels are ~0.25 deg wide and ~0.3 deg tall,
// 6.6 and 7.9 cm at 15 m, so the spheres span 0.3 to 6 pixels: the small ones go through the sub-pixel
// returns, the large ones through the raster.
TEST_P(Subpixel, SpheresKeepTheEnergyOfTheirAreaAtEverySize) {
    const SonarConfig config = closed_form_config();
    const double range = 15.0, mu = std::pow(10.0, -20.0 / 10.0);
    for (double diameter_cm : {2.0, 4.0, 6.0, 10.0, 20.0, 40.0}) {
        SCOPED_TRACE(diameter_cm);
        const double a = 0.005 * diameter_cm;
        Scene scene;
        add_closed_sphere(scene, a, {range, 0.0, 0.0}, 48, 24, lambert(-20.0));
        auto rendered = render_checked(GetParam(), config, scene);
        ASSERT_TRUE(rendered);
        const double got = total(rendered->frame.clean);
        const double expected = mu * 2 * kPi * a * a / (3 * std::pow(range, 4));
        const double error_db = got > 0 ? db(got / expected) : -999.0;
        std::printf("[subpixel] %s sphere %4.0f cm at %.0f m: %.4e vs %.4e, %+.2f dB\n",
                    GetParam() == Backend::vulkan ? "vulkan" : "cpu", diameter_cm, range, got, expected, error_db);
        EXPECT_LT(std::abs(error_db), 1.0);
    }
}

// A 1 cm cable across the fan at 10 m (y from -5 to 5 m, 26.6 degrees either side): a continuous line,
// every beam it crosses at the level of mu a (pi / 2) cos^4(theta) / X^3 per radian of steering angle,
// times the beam's width in steering angle.
TEST_P(Subpixel, ThinCableGivesAContinuousLineAtItsLevel) {
    const SonarConfig config = closed_form_config();
    const double x = 10.0, half = 5.0, a = 0.005, mu = std::pow(10.0, -20.0 / 10.0);
    Scene scene;
    add_cable(scene, a, half, {x, 0.0, 0.0}, 12, 100, lambert(-20.0));
    auto rendered = render_checked(GetParam(), config, scene);
    ASSERT_TRUE(rendered);
    const Frame& f = rendered->frame;
    const Plan& plan = renderer_plan(rendered->renderer);
    const double edge = std::atan(half / x);
    double worst = 0, got_total = 0, expected_total = 0;
    std::uint32_t compared = 0;
    for (std::uint32_t j = 1; j + 1 < f.beams; ++j) {
        const double theta = plan.beam_angle_rad[j];
        // Beams a degree and more inside the cable's ends: a beam's cone reaches a beam width either side.
        if (std::abs(theta) > edge - 1.0 * kDeg) continue;
        const double width = 0.5 * std::abs(plan.beam_angle_rad[j - 1] - plan.beam_angle_rad[j + 1]);
        const double expected = mu * a * 0.5 * kPi * std::pow(std::cos(theta), 4) / std::pow(x, 3) * width;
        const double got = beam_energy(f, j);
        got_total += got;
        expected_total += expected;
        const double error_db = got > 0 ? db(got / expected) : -999.0;
        worst = std::max(worst, std::abs(error_db));
        ++compared;
        EXPECT_GT(got, 0.0) << "beam " << j << " at " << theta / kDeg << " deg: a gap in the line";
    }
    std::printf("[subpixel] %s cable 1 cm at %.0f m: %u beams, worst beam %+.2f dB, total %+.2f dB\n",
                GetParam() == Backend::vulkan ? "vulkan" : "cpu", x, compared, worst, db(got_total / expected_total));
    EXPECT_GT(compared, 100u);
    EXPECT_LT(worst, 1.0);
    EXPECT_LT(std::abs(db(got_total / expected_total)), 0.5);
}

INSTANTIATE_TEST_SUITE_P(Backends, Subpixel, ::testing::Values(Backend::cpu, Backend::vulkan), backend_name);

} // namespace
} // namespace vksonar::testing::hard
