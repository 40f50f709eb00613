// Point and spot lights with spectral lines against the closed form for a Lambertian plane:
// radiance leaving the plane under a point source of intensity I at height h is rho I cos^3 / (pi h^2)
// at horizontal offset x (cos = h / sqrt(h^2 + x^2)), all of it inside the line's spectral bin.
#include <gtest/gtest.h>

#include <cmath>
#include <utility>
#include <vector>

#include "core/math.h"
#include "render/path_tracer.h"
#include "render/renderer.h"
#include "support/test_scenes.h"
#include "spectral/color.h"

namespace fluorosim {
namespace {

constexpr double kRho = 0.6, kPower = 5.0, kHeight = 2.0, kLine = 532.0;
// Heights are in mm; radiance is per m^2.
constexpr double kHeightM2 = kHeight * kHeight * 1e-6;

Scene planeScene(Light light) {
    Scene scene;
    scene.spectral.lambdaMin = 400;
    scene.spectral.lambdaMax = 700;
    scene.materials.push_back(makeDiffuse(Spectrum::constant(kRho)));
    scene.geometry.addMesh(TriangleMesh{{Vec3(-50, 0, -50), Vec3(50, 0, -50), Vec3(50, 0, 50), Vec3(-50, 0, 50)}, {0, 1, 2, 0, 2, 3}});
    ShapeInfo plane;
    plane.material = 0;
    scene.shapes.push_back(plane);
    scene.lights.push_back(std::move(light));
    // A one-pixel camera with a tiny field of view looking straight down at the origin.
    scene.camera.position = Vec3(0, 1, 0);
    scene.camera.frame = Frame{Vec3(1, 0, 0), Vec3(0, 0, 1), Vec3(0, -1, 0)};
    scene.camera.width = 1;
    scene.camera.height = 1;
    scene.camera.tanHalfFovY = 1e-4;
    scene.finalize();
    return scene;
}

ColorMatchingFunctions flat() {
    const TabulatedSpectrum one({360, 830}, {1, 1});
    return {one, one, one};
}

double binValue(const Scene& scene, double lambda, int spp) {
    Film film(1, 1, 400, 700, 10, flat());
    RenderOptions opt;
    opt.spp = spp;
    render(scene, film, opt);
    const ExrImage img = film.image(spp);
    double total = 0;
    for (size_t b = 0; b < img.spectral[0].wavelengthsNm.size(); ++b) {
        const double c = img.spectral[0].wavelengthsNm[b];
        const double v = img.spectral[0].values[b] * 10.0;  // per nm -> integrated over the bin
        if (std::abs(c - lambda) < 5) total += v;
        else EXPECT_EQ(v, 0.0) << "energy outside the line's bin at " << c << " nm";
    }
    return total;
}

TEST(Lights, PointLightLineOnLambertianPlane) {
    const Scene scene = planeScene(PointLight{Vec3(0, kHeight, 0), Spectrum::lines({{kLine, kPower}})});
    // Direct lighting only (one bounce back to the camera); indirect light escapes to infinity.
    const double expected = kRho * kPower / (kPi * kHeightM2);
    EXPECT_NEAR(binValue(scene, kLine, 64), expected, 1e-6 * expected);
}

TEST(Lights, SphereLightOverLambertianPlane) {
    // A sphere of radiance L and radius r whose centre is D above the plane gives the irradiance
    // E = pi L (r / D)^2 directly below it, so the plane's radiance is rho L (r / D)^2. NEE samples
    // the visible cone; BSDF-sampled hits are weighted by MIS.
    const double L = 3.0, r = 0.5, D = 2.0;
    Scene scene;
    scene.materials.push_back(makeDiffuse(Spectrum::constant(kRho)));
    scene.geometry.addMesh(TriangleMesh{{Vec3(-50, 0, -50), Vec3(50, 0, -50), Vec3(50, 0, 50), Vec3(-50, 0, 50)}, {0, 1, 2, 0, 2, 3}});
    ShapeInfo plane;
    plane.material = 0;
    scene.shapes.push_back(plane);
    const uint32_t bulb = scene.geometry.addSphere(Vec3(0, D, 0), r);
    scene.shapes.push_back(ShapeInfo{"bulb"});
    scene.addAreaLight(bulb, AreaEmission{Spectrum::constant(L), false});
    scene.finalize();
    const PathTracer tracer(scene);
    PathStats stats;
    const auto [mean, se] = testing::meanOf(100000, [&](int i) {
        Rng rng = Rng::forKey(8, static_cast<uint64_t>(i), 2);
        const SampledWavelengths wl = SampledWavelengths::sampleUniform(rng.uniform(), 400, 700);
        return tracer.radiance(Ray{Vec3(0, 0.2, 0), Vec3(0, -1, 0)}, kNone, wl, rng, stats).total().average();
    });
    EXPECT_NEAR(mean, kRho * L * (r / D) * (r / D), 4 * se) << "stderr " << se;
    EXPECT_LT(se, 0.01 * mean);
}

TEST(Lights, MaxDepthOneStillGivesDirectLighting) {
    // max_depth counts scattering vertices: 1 allows the plane's vertex and its next-event estimate.
    Scene scene = planeScene(PointLight{Vec3(0, kHeight, 0), Spectrum::lines({{kLine, kPower}})});
    scene.render.maxDepth = 1;
    const double expected = kRho * kPower / (kPi * kHeightM2);
    EXPECT_NEAR(binValue(scene, kLine, 16), expected, 1e-6 * expected);
}

TEST(Lights, SpotLightFalloffAndCone) {
    // Light at (x0, h, 0) aimed at (x0, 0, 0); the origin lies at angle atan(x0 / h) off axis.
    const double x0 = 1.0, angle = std::atan(x0 / kHeight) * 180 / kPi;  // 26.6 deg
    auto spot = [&](double cone, double start) {
        return SpotLight{Vec3(x0, kHeight, 0), Vec3(0, -1, 0), Spectrum::lines({{kLine, kPower}}), std::cos(cone * kPi / 180),
                         std::cos(start * kPi / 180)};
    };
    const double cos3 = std::pow(kHeight / std::hypot(kHeight, x0), 3);
    const double full = kRho * kPower * cos3 / (kPi * kHeightM2);
    // The pixel footprint (1e-4 mm) times the off-axis gradient of the closed form (< 1 /mm) bounds
    // the deviation at 1e-4 relative.
    const double tol = 1e-4 * full;
    EXPECT_NEAR(binValue(planeScene(spot(40, 30)), kLine, 16), full, tol);  // inside the full-power cone
    EXPECT_EQ(binValue(planeScene(spot(20, 10)), kLine, 16), 0.0);                  // outside the cone
    // In the falloff band: pbrt's smoothstep in cos(theta).
    const double c = std::cos(angle * kPi / 180), c0 = std::cos(35 * kPi / 180), c1 = std::cos(15 * kPi / 180);
    const double t = (c - c0) / (c1 - c0), smooth = t * t * (3 - 2 * t);
    EXPECT_NEAR(binValue(planeScene(spot(35, 15)), kLine, 16), full * smooth, tol);
}

TEST(Lights, ContinuousAndLineEmittersTogether) {
    // A continuous flat spectrum plus a line: every bin gets the continuous part, the line's bin
    // also gets the line; the mixture wavelength sampler must weight both correctly. The tolerance
    // is 4 standard errors, estimated from 20 independent renders (seeds 1..20) of 4000 spp each.
    const double flatIntensity = 0.02;  // W sr^-1 nm^-1
    Scene mixed = planeScene(PointLight{Vec3(0, kHeight, 0), Spectrum::lines({{kLine, kPower}})});
    mixed.lights.push_back(PointLight{Vec3(0, kHeight, 0), Spectrum::constant(flatIntensity)});
    constexpr int kBatches = 20;
    std::vector<double> lineBins, otherMeans;
    for (int batch = 0; batch < kBatches; ++batch) {
        Film film(1, 1, 400, 700, 10, flat());
        RenderOptions opt;
        opt.spp = 4000;
        opt.seed = static_cast<uint64_t>(batch + 1);
        render(mixed, film, opt);
        const ExrImage img = film.image(opt.spp);
        double lineBin = 0, otherMean = 0;
        int others = 0;
        for (size_t b = 0; b < img.spectral[0].wavelengthsNm.size(); ++b) {
            const double v = img.spectral[0].values[b];
            if (std::abs(img.spectral[0].wavelengthsNm[b] - kLine) < 5) lineBin = v;
            else {
                otherMean += v;
                ++others;
            }
        }
        lineBins.push_back(lineBin);
        otherMeans.push_back(otherMean / others);
    }
    // Mean of the batches and its standard error from their spread.
    auto estimate = [](const std::vector<double>& x) {
        double m = 0, v = 0;
        for (double a : x) m += a / static_cast<double>(x.size());
        for (double a : x) v += (a - m) * (a - m) / static_cast<double>(x.size() - 1);
        return std::pair{m, std::sqrt(v / static_cast<double>(x.size()))};
    };
    const double geom = kRho / (kPi * kHeightM2);
    const double wantOther = geom * flatIntensity, wantLine = geom * (flatIntensity + kPower / 10.0);
    const auto [other, otherSe] = estimate(otherMeans);
    const auto [line, lineSe] = estimate(lineBins);
    EXPECT_NEAR(other, wantOther, 4 * otherSe) << "stderr " << otherSe;
    EXPECT_NEAR(line, wantLine, 4 * lineSe) << "stderr " << lineSe;
    // The test has power: each standard error is a small fraction of the value it checks.
    EXPECT_LT(otherSe, 0.01 * wantOther);
    EXPECT_LT(lineSe, 0.01 * wantLine);
}

}  // namespace
}  // namespace fluorosim
