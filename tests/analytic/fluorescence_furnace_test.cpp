// The fluorescence furnace: an optically thin, non-scattering dyed ball (index 1, null boundary) at the
// centre of a large sphere that emits a uniform line radiance Le inwards, seen along a diameter by a
// camera inside the enclosure. Its fluorescent radiance follows from the transfer equation:
//   J(r)   = (Le/2) ∫_{-1}^{1} exp(-σx s(r, μ)) dμ,  s(r, μ) = -rμ + sqrt(a² - r²(1 - μ²))
// is the mean radiance at radius r (the uniform field attenuated along the way in), and the primary
// fluorescence leaving the ball along the diameter, integrated over a band [λ1, λ2], is
//   L = Φ σa,dye(λx) ∫ dλ f(λ) λx/λ ∫_{-a}^{a} J(|x|) exp(-σa(λ) (a - x)) dx,
// with re-absorption on the way out. Only secondary fluorescence is left out: a fraction at most
// Φ 2a ∫ f(λ) σa(λ) dλ of the primary (the longest chord times the emission-weighted absorption), which
// the test checks is far below its standard error.
//
// Camera paths reach the dye at depth 0 (through a null boundary), so their excitation sub-paths start
// before any surface bounce; a sub-path whose sampled direction hits the enclosure must weigh that hit
// against next-event estimation. Without that weight the ball read about 1.5x this value.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "support/fluorescent_scenes.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

constexpr double kBallRadius = 0.5, kEnclosureRadius = 10, kLe = 1.0;

// Gauss-Legendre nodes and weights on [-1, 1] (Newton on the Legendre recurrence).
std::vector<std::pair<double, double>> gaussLegendre(int n) {
    std::vector<std::pair<double, double>> nodes;
    for (int i = 1; i <= n; ++i) {
        double x = std::cos(kPi * (i - 0.25) / (n + 0.5)), dp = 0;
        for (int iter = 0; iter < 100; ++iter) {
            double p0 = 1, p1 = x;
            for (int k = 2; k <= n; ++k) {
                const double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
                p0 = p1;
                p1 = p2;
            }
            dp = n * (x * p1 - p0) / (x * x - 1);
            const double dx = p1 / dp;
            x -= dx;
            if (std::abs(dx) < 1e-15) break;
        }
        nodes.emplace_back(x, 2 / ((1 - x * x) * dp * dp));
    }
    return nodes;
}

double meanRadianceInBall(double r, double sigmaX, const std::vector<std::pair<double, double>>& gl) {
    const double a = kBallRadius;
    double sum = 0;
    for (const auto& [mu, w] : gl) sum += w * std::exp(-sigmaX * (-r * mu + std::sqrt(a * a - r * r * (1 - mu * mu))));
    return 0.5 * kLe * sum;
}

double furnaceReference(const Fluorophore& dye, double molar, double lambdaX, double l1, double l2) {
    const auto gl = gaussLegendre(64);
    const double a = kBallRadius, sigmaX = dyeAbsorption(dye, lambdaX, molar);
    double total = 0;
    for (const auto& [ul, wl] : gl) {
        const double lambda = 0.5 * (l1 + l2) + 0.5 * (l2 - l1) * ul;
        const double sigmaL = dyeAbsorption(dye, lambda, molar);
        double chord = 0;
        for (const auto& [ux, wx] : gl) {
            const double x = a * ux;
            chord += wx * a * meanRadianceInBall(std::abs(x), sigmaX, gl) * std::exp(-sigmaL * (a - x));
        }
        total += wl * 0.5 * (l2 - l1) * dye.emissionPdf(lambda) * lambdaX / lambda * chord;
    }
    return dye.quantumYield() * sigmaX * total;
}

struct FurnaceCase {
    const char* dye;
    double lambdaX, molar, bandLo, bandHi;
};

class FluorescenceFurnace : public ::testing::TestWithParam<FurnaceCase> {};

TEST_P(FluorescenceFurnace, MatchesTransferEquation) {
    const FurnaceCase c = GetParam();
    const Fluorophore dye = databaseDye(c.dye);
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 800;
    const int m = addDyedMedium(scene, "dyed", 0, 0, 0, 1, {{dye, c.molar}});
    addDyedBall(scene, kBallRadius, m, false);
    const uint32_t enclosure = scene.geometry.addSphere(Vec3(0, 0, 0), kEnclosureRadius);
    scene.shapes.push_back(ShapeInfo{"enclosure"});
    scene.addAreaLight(enclosure, AreaEmission{Spectrum::lines({{c.lambdaX, kLe}}), true});
    scene.finalize();

    // Secondary fluorescence, left out of the reference, is below this fraction of it.
    const auto [emLo, emHi] = dye.emissionSupport();
    double reabsorption = 0;  // ∫ f(λ) σa(λ) dλ, 1/mm
    for (double l = emLo; l < emHi; l += 0.1) reabsorption += dye.emissionPdf(l + 0.05) * dyeAbsorption(dye, l + 0.05, c.molar) * 0.1;
    const double secondaryBound = dye.quantumYield() * reabsorption * 2 * kBallRadius;

    const PathTracer tracer(scene);
    const WavelengthSampler ws(c.bandLo, c.bandHi, {}, true);
    PathStats stats;
    const Estimate e = meanOf(400000, [&](int i) {
        Rng rng = Rng::forKey(17, static_cast<uint64_t>(i), 3);
        const SampledWavelengths wl = ws.sample(rng.uniform(), rng.uniform());
        const PathRadiance L = tracer.radiance(Ray{Vec3(5, 0, 0), Vec3(-1, 0, 0)}, kNone, wl, rng, stats);
        double v = 0;
        for (int k = 0; k < kNumWavelengths; ++k) v += L.fluorescent[k] / wl.pdf[k] / kNumWavelengths;
        return v;
    });
    const double ref = furnaceReference(dye, c.molar, c.lambdaX, c.bandLo, c.bandHi);
    const double z = (e.mean - ref) / e.stderr_;
    std::printf("  %s at %.0f nm: %.6g +- %.2g, transfer equation %.6g (ratio %.4f), z = %+.2f; secondary below %.2g of it\n", c.dye,
                c.lambdaX, e.mean, e.stderr_, ref, e.mean / ref, z, secondaryBound);
    EXPECT_GT(stats.fluorescenceBranches, 100000u);
    EXPECT_LT(secondaryBound * ref, 0.25 * e.stderr_) << "the reference leaves out more than the test resolves";
    EXPECT_LT(e.stderr_, 0.01 * ref) << "the check must be sharp";
    EXPECT_LT(std::abs(z), 4.0);
}

// Optical depth 0.001-0.003 across the ball at the excitation line: thin enough that secondary
// fluorescence is negligible, with attenuation still in the reference.
INSTANTIATE_TEST_SUITE_P(Dyes, FluorescenceFurnace,
                         ::testing::Values(FurnaceCase{"AF488", 488, 1e-7, 500, 650}, FurnaceCase{"AF594", 561, 1e-7, 580, 750},
                                           FurnaceCase{"AF647", 633, 5e-8, 640, 800}),
                         [](const ::testing::TestParamInfo<FurnaceCase>& p) { return std::string(p.param.dye); });

// Mean radiance (1/4π)∫L dω at a point in vacuum near a sphere light of radiance Le is Le Ω/(4π), with
// Ω = 2π(1 - sqrt(1 - r²/d²)). meanRadiance starts a path as a re-emission point does (next-event
// estimation first, then an isotropic direction), so both strategies must share the light by MIS.
TEST(MeanRadiance, NearSphereLightIsSolidAngleFraction) {
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 700;
    const double r = 1.0, d = 1.5;
    const uint32_t bulb = scene.geometry.addSphere(Vec3(0, 0, d), r);
    scene.shapes.push_back(ShapeInfo{"bulb"});
    scene.addAreaLight(bulb, AreaEmission{Spectrum::constant(kLe), false});
    scene.finalize();
    const PathTracer tracer(scene);
    const WavelengthSampler ws(400, 700, {}, true);
    PathStats stats;
    const Estimate e = meanOf(200000, [&](int i) {
        Rng rng = Rng::forKey(29, static_cast<uint64_t>(i), 1);
        const SampledWavelengths wl = ws.sample(rng.uniform(), rng.uniform());
        return tracer.meanRadiance(Vec3(0, 0, 0), kNone, wl, rng, stats).total().average();
    });
    const double ref = kLe * 2 * kPi * (1 - std::sqrt(1 - r * r / (d * d))) * kInv4Pi;
    const double z = (e.mean - ref) / e.stderr_;
    std::printf("  mean radiance %.6g +- %.2g, closed form %.6g (ratio %.5f), z = %+.2f\n", e.mean, e.stderr_, ref, e.mean / ref, z);
    EXPECT_LT(e.stderr_, 0.005 * ref);
    EXPECT_LT(std::abs(z), 4.0);
}

}  // namespace
}  // namespace fluorosim
