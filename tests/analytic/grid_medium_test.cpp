// Heterogeneous (grid) media against closed forms and independent estimators:
// - ratio-tracking transmittance through a linear ramp and a Gaussian blob (closed-form optical depth),
//   also with a grid 100 mm (10^5 µm) from the origin, 50 nm voxels, a one-voxel sheet at a grazing
//   angle and a 10^6 concentration contrast;
// - a constant grid gives the homogeneous medium's fluorescence;
// - three majorant resolutions (fine, automatic, one global cell) give the same mean, and the forward
//   photon tracer (analog delta tracking, an independent estimator) agrees;
// - an all-zero grid and optical depth 10^4: no NaN, bounded cost, exact zeros where they must be.
// Tolerances: 4 standard errors of the estimate (fixed seeds).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "render/flux_sensor.h"
#include "render/photon_tracer.h"
#include "support/fluorescent_scenes.h"
#include "support/test_scenes.h"
#include "volume/volume_fields.h"

namespace fluorosim {
namespace {

using namespace testing;

Affine voxelsAt(double size, const Vec3& origin) { return Affine::scaling(size).then(Affine::translation(origin)); }

// A medium whose absorption is sigma (1/mm) times the grid, at every wavelength, inside an
// axis-aligned box.
struct GridBox {
    Scene scene;
    int medium = kNone;
};

GridBox absorbingGridBox(const DensityGrid& grid, double sigma, const Vec3& lo, const Vec3& hi, int cellVoxels = 0) {
    GridBox b;
    std::vector<VolumeChannel> ch(2);
    ch[kSolventChannel].grid = grid;
    ch[kScatteringChannel].offset = 1;
    auto volume = std::make_shared<const VolumeFields>(std::move(ch), Affine(), Interpolation::Trilinear, MajorantGridOptions{cellVoxels});
    b.scene.media.emplace_back("grid", Spectrum::constant(sigma), Spectrum::constant(0), 0, 1, std::vector<DyeComponent>{}, volume);
    b.medium = 0;
    addMediumBox(b.scene, lo, hi, 0);
    b.scene.finalize();
    return b;
}

Estimate meanTransmittance(const Scene& scene, const Vec3& p0, const Vec3& p1, int medium, int n, uint64_t seed) {
    const PathTracer tracer(scene);
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.4, 400, 700);
    return meanOf(n, [&](int i) {
        Rng rng = Rng::forKey(seed, static_cast<uint64_t>(i), 3);
        const SampledSpectrum T = tracer.transmittance(p0, p1, medium, wl, rng);
        EXPECT_TRUE(std::isfinite(T[0]) && T[0] >= 0);
        return T[0];
    });
}

void expectTransmittance(const Estimate& e, double expected, const char* what) {
    const double z = (e.mean - expected) / e.stderr_;
    std::printf("  %-44s T = %.6f +- %.1e, closed form %.6f, z = %+.2f\n", what, e.mean, e.stderr_, expected, z);
    EXPECT_LT(std::abs(z), 4.0) << what;
    EXPECT_LT(e.stderr_, 0.01 * expected) << what << ": the check must be sharp";
}

// A linear ramp in x is reproduced exactly by trilinear interpolation, so the optical depth along any
// chord is the ramp's integral. Checked at a grid 100 mm from the origin and with 50 nm voxels too.
TEST(GridMedium, RatioTrackingThroughLinearRamp) {
    struct Case {
        double voxel;
        Vec3 origin;
        const char* name;
        uint64_t seed;
    };
    // (With one seed the three cases give identical numbers: the process is invariant under scaling
    // and translation, which is itself a check. Different seeds make them independent.)
    for (const Case& c : {Case{0.01, Vec3(), "ramp, 10 um voxels", 10}, Case{5e-4, Vec3(100, 100, -100), "ramp, 0.5 um voxels at 100 mm", 20},
                          Case{5e-5, Vec3(), "ramp, 50 nm voxels", 30}}) {
        const int n = 64;
        const double len = (n - 1) * c.voxel;
        // sigma(x) = s0 (1 + 2 x/len) over [0, len], the grid value being 1 + 2 i/(n-1).
        const double s0 = 0.5 / len;  // optical depth 2 s0 len = 1 along x
        const DensityGrid g = DensityGrid::fromVoxels("ramp", {{0, 0, 0}, {n - 1, 15, 15}}, voxelsAt(c.voxel, c.origin),
                                                      [&](int i, int, int) { return 1.0 + 2.0 * i / (n - 1); });
        const Vec3 lo = c.origin, hi = c.origin + Vec3(len, 15 * c.voxel, 15 * c.voxel);
        const GridBox box = absorbingGridBox(g, s0, lo, hi);
        // Along x through the whole box, from outside.
        const Vec3 y = Vec3(0, 7.5 * c.voxel, 7.3 * c.voxel);
        const double tauX = s0 * 2 * len;
        expectTransmittance(meanTransmittance(box.scene, c.origin + y - Vec3(len, 0, 0), c.origin + y + Vec3(2 * len, 0, 0), kNone, 20000, c.seed),
                            std::exp(-tauX), c.name);
        // From a point inside, exactly on a voxel (and majorant cell) boundary x = 16 voxels, obliquely.
        const Vec3 p0 = c.origin + Vec3(16 * c.voxel, 4 * c.voxel, 4 * c.voxel);
        const Vec3 p1 = c.origin + Vec3(48 * c.voxel, 12 * c.voxel, 10 * c.voxel);
        const double x0 = 16.0 / (n - 1), x1 = 48.0 / (n - 1);  // as fractions of len
        const double tau = s0 * length(p1 - p0) * (1 + (x0 + x1));  // mean of 1 + 2x along the chord
        expectTransmittance(meanTransmittance(box.scene, p0, p1, box.medium, 20000, c.seed + 1), std::exp(-tau), c.name);
    }
}

// A Gaussian blob A exp(-r²/(2w²)) with w = 16 voxels: along a line at distance b from its centre the
// optical depth is A w sqrt(2π) exp(-b²/(2w²)). (Trilinear interpolation changes it by about
// h²/(8w²) = 5e-4 relative, ten times below the test's resolution.)
TEST(GridMedium, RatioTrackingThroughGaussianBlob) {
    const double h = 0.01, w = 16 * h, A = 4.0;
    const DensityGrid g = DensityGrid::fromVoxels("blob", {{-80, -12, -4}, {80, 12, 4}}, voxelsAt(h, Vec3()), [&](int i, int j, int k) {
        return std::exp(-(i * i + j * j + k * k) * h * h / (2 * w * w));
    });
    for (int cell : {-1, 0, 2}) {
        const GridBox box = absorbingGridBox(g, A, Vec3(-0.9, -0.13, -0.05), Vec3(0.9, 0.13, 0.05), cell);
        for (double b : {0.0, 0.05}) {
            const double tau = A * w * std::sqrt(2 * kPi) * std::exp(-b * b / (2 * w * w));
            char name[64];
            std::snprintf(name, sizeof name, "blob, b = %.2f mm, majorant cell %d", b, cell);
            expectTransmittance(meanTransmittance(box.scene, Vec3(-2, b, 0), Vec3(2, b, 0), kNone, 50000, static_cast<uint64_t>(30 + cell + 100 * b)), std::exp(-tau), name);
        }
    }
}

// A thin blob (A = 0.25 /mm, optical depth 0.1 through its centre): its largest value over the 1.8 mm the
// line spends in the box expects 8 × 0.25 × 1.8 = 3.6 collisions at the residual's raised majorant, so
// ratio tracking takes the line in one segment at that value instead of the majorant grid's cells
// (Medium::majorants' fewCollisions). The optical depth is the same closed form as above.
TEST(GridMedium, RatioTrackingThroughAThinBlobInOneSegment) {
    const double h = 0.01, w = 16 * h, A = 0.25;
    const DensityGrid g = DensityGrid::fromVoxels("blob", {{-80, -12, -4}, {80, 12, 4}}, voxelsAt(h, Vec3()), [&](int i, int j, int k) {
        return std::exp(-(i * i + j * j + k * k) * h * h / (2 * w * w));
    });
    const GridBox box = absorbingGridBox(g, A, Vec3(-0.9, -0.13, -0.05), Vec3(0.9, 0.13, 0.05));
    for (double b : {0.0, 0.05}) {
        const double tau = A * w * std::sqrt(2 * kPi) * std::exp(-b * b / (2 * w * w));
        char name[64];
        std::snprintf(name, sizeof name, "thin blob, b = %.2f mm, one segment", b);
        expectTransmittance(meanTransmittance(box.scene, Vec3(-2, b, 0), Vec3(2, b, 0), kNone, 50000, static_cast<uint64_t>(60 + 100 * b)), std::exp(-tau), name);
    }
}

// A one-voxel sheet (value v at k = 0) is a tent of half-width h in z, so a ray at angle θ to it sees
// optical depth sigma v h / sin θ, however grazing, as long as it crosses the sheet inside its extent.
TEST(GridMedium, OneVoxelSheetAtGrazingAngles) {
    const double h = 0.001;
    const DensityGrid g = DensityGrid::fromVoxels("sheet", {{-400, -20, 0}, {400, 20, 0}}, voxelsAt(h, Vec3()),
                                                  [](int, int, int) { return 1.0; });
    for (double deg : {90.0, 10.0, 1.0}) {
        const double theta = deg * kPi / 180;
        const double sigma = 0.7 * std::sin(theta) / h;  // optical depth 0.7
        for (int cell : {-1, 0}) {
            const GridBox box = absorbingGridBox(g, sigma, Vec3(-0.45, -0.03, -0.003), Vec3(0.45, 0.03, 0.003), cell);
            const Vec3 d(std::cos(theta), 0, std::sin(theta));
            char name[64];
            std::snprintf(name, sizeof name, "sheet at %.0f deg, majorant cell %d", deg, cell);
            expectTransmittance(meanTransmittance(box.scene, d * -0.3 + Vec3(0, 0.001, 0), d * 0.3 + Vec3(0, 0.001, 0), kNone, 20000, static_cast<uint64_t>(deg * 10 + cell)),
                                std::exp(-0.7), name);
        }
    }
}

// Values 1 and 1e-6 in one grid, under the one global majorant: the dim half costs about 10^6 null
// collisions per unit of optical depth, and ratio tracking still returns exp(-tau) on both sides.
TEST(GridMedium, ContrastOfAMillionInOneGrid) {
    const double h = 0.01;
    const DensityGrid g = DensityGrid::fromVoxels("contrast", {{-50, -5, -5}, {50, 5, 5}}, voxelsAt(h, Vec3()),
                                                  [](int i, int, int) { return i < 0 ? 1.0 : 1e-6; });
    const GridBox box = absorbingGridBox(g, 100.0, Vec3(-0.5, -0.05, -0.05), Vec3(0.5, 0.05, 0.05), -1);
    // Dim side: 0.4 mm at 1e-4 /mm.
    expectTransmittance(meanTransmittance(box.scene, Vec3(0.05, 0, 0), Vec3(0.45, 0, 0), box.medium, 2000, 5), std::exp(-100 * 1e-6 * 0.4),
                        "dim side (1e-6)");
    // Bright side: 0.02 mm at 100 /mm.
    expectTransmittance(meanTransmittance(box.scene, Vec3(-0.45, 0, 0), Vec3(-0.43, 0, 0), box.medium, 80000, 6), std::exp(-2.0),
                        "bright side (1)");
}

// --- Radiance through the path tracer ---

Scene dyedBallScene(std::shared_ptr<const VolumeFields> volume, double molar, double sigmaS) {
    Scene scene;
    scene.spectral.lambdaMin = 380;
    scene.spectral.lambdaMax = 780;
    const Fluorophore dye = databaseDye("AF488");
    scene.media.emplace_back("dyed", Spectrum::constant(0.0), Spectrum::constant(sigmaS), 0.3, 1.0,
                             std::vector<DyeComponent>{{dye, volume ? 0.0 : molar}}, volume);
    addDyedBall(scene, 1.0, 0, false);
    addPointLight(scene, Vec3(0, 0, 6), Spectrum::lines({{488, 1.0}}));
    scene.finalize();
    return scene;
}

// Grid covering the unit ball, value(i, j, k) in µM (voxel 0.05 mm).
std::shared_ptr<const VolumeFields> dyeVolume(const std::function<double(int, int, int)>& micromolar, int cellVoxels) {
    const DensityGrid g = DensityGrid::fromVoxels("AF488", {{-21, -21, -21}, {21, 21, 21}}, voxelsAt(0.05, Vec3()), micromolar);
    std::vector<VolumeChannel> ch(3);
    ch[kSolventChannel].offset = 1;
    ch[kScatteringChannel].offset = 1;
    ch[kFirstDyeChannel].grid = g;
    ch[kFirstDyeChannel].scale = 1e-6;
    return std::make_shared<const VolumeFields>(std::move(ch), Affine(), Interpolation::Trilinear, MajorantGridOptions{cellVoxels});
}

FluxSensorResult ballFlux(const Scene& scene, uint64_t paths, uint64_t seed) {
    FluxSensorOptions s;
    s.radius = 1.0001;
    s.paths = paths;
    s.seed = seed;
    return measureExitantFlux(scene, s);
}

void expectSame(const TallyValue& a, const TallyValue& b, const char* what) {
    const double sigma = std::hypot(a.stderr_, b.stderr_);
    const double z = (a.mean - b.mean) / sigma;
    std::printf("  %-40s %.6g +- %.2g vs %.6g +- %.2g, z = %+.2f\n", what, a.mean, a.stderr_, b.mean, b.stderr_, z);
    EXPECT_LT(std::abs(z), 4.0) << what;
    EXPECT_LT(sigma, 0.05 * std::abs(b.mean)) << what << ": the check must be sharp";
}

TEST(GridMedium, ConstantGridMatchesHomogeneousMedium) {
    const Scene homogeneous = dyedBallScene(nullptr, 5e-6, 2.0);
    const Scene grid = dyedBallScene(dyeVolume([](int, int, int) { return 5.0; }, 0), 0, 2.0);
    // The grid medium branches about 4 times per voxel length, so it needs fewer paths for the same error.
    const FluxSensorResult a = ballFlux(homogeneous, 60000, 21), b = ballFlux(grid, 20000, 22);
    expectSame(b.fluorescentPower, a.fluorescentPower, "fluorescent power, grid vs homogeneous");
    expectSame(b.fluorescentPowerTimesLambda, a.fluorescentPowerTimesLambda, "power x lambda, grid vs homogeneous");
}

// A blob of dye (peak 40 µM, w = 0.3 mm) in a scattering ball.
double blob(int i, int j, int k) { return 40.0 * std::exp(-(i * i + j * j + k * k) * 0.0025 / (2 * 0.09)); }

TEST(GridMedium, MajorantResolutionsGiveTheSameMeanAndAgreeWithForwardTracer) {
    std::vector<FluxSensorResult> r;
    for (int cell : {2, 0, -1}) r.push_back(ballFlux(dyedBallScene(dyeVolume(blob, cell), 0, 2.0), 60000, 30));
    std::printf("  tentative collisions per path: cell 2: %.1f, automatic: %.1f, global: %.1f\n",
                double(r[0].stats.tentativeCollisions) / r[0].stats.paths, double(r[1].stats.tentativeCollisions) / r[1].stats.paths,
                double(r[2].stats.tentativeCollisions) / r[2].stats.paths);
    EXPECT_LT(r[0].stats.tentativeCollisions, r[2].stats.tentativeCollisions);
    // The same seed, different majorants: the estimates are correlated only through the seed; compare
    // each with the forward tracer, the independent estimator.
    ForwardPhotonOptions f;
    f.aimRadius = 1.0001;
    f.photons = 1000000;
    f.seed = 31;
    const ForwardPhotonResult forward = traceForwardPhotons(dyedBallScene(dyeVolume(blob, 0), 0, 2.0), f);
    const char* names[] = {"cell 2 voxels vs forward", "automatic cells vs forward", "one global cell vs forward"};
    for (size_t i = 0; i < r.size(); ++i) expectSame(r[i].fluorescentPower, forward.fluorescentPower, names[i]);
}

TEST(GridMedium, AllZeroGridIsExactlyClear) {
    const Scene scene = dyedBallScene(dyeVolume([](int, int, int) { return 0.0; }, 0), 0, 0.0);
    EXPECT_TRUE(scene.media[0].isVacuumLike());
    const FluxSensorResult r = ballFlux(scene, 2000, 40);
    EXPECT_EQ(r.fluorescentPower.mean, 0.0);
    EXPECT_EQ(r.stats.fluorescenceBranches, 0u);
    Rng rng(1, 0);
    const PathTracer tracer(scene);
    EXPECT_EQ(tracer.transmittance(Vec3(-2, 0, 0), Vec3(2, 0, 0), kNone, SampledWavelengths::sampleUniform(0.5, 400, 700), rng)[0], 1.0);
}

// Optical depth 10^4 across a 1 mm box, albedo 0.99, lit and seen from below: every path ends (by
// absorption or by leaving),
// no value is NaN or infinite, and the cost per path stays bounded (about 1/(1 - albedo) collisions).
TEST(GridMedium, OpticalDepthTenThousandTerminatesWithBoundedCost) {
    const double h = 0.02;
    const DensityGrid g = DensityGrid::fromVoxels("dense", {{0, 0, 0}, {50, 50, 50}}, voxelsAt(h, Vec3()), [](int, int, int) { return 1.0; });
    std::vector<VolumeChannel> ch(2);
    ch[kSolventChannel].grid = g;
    ch[kScatteringChannel].grid = g;
    Scene scene;
    scene.media.emplace_back("dense", Spectrum::constant(100.0), Spectrum::constant(9900.0), 0.0, 1.0, std::vector<DyeComponent>{},
                             std::make_shared<const VolumeFields>(std::move(ch), Affine(), Interpolation::Trilinear));
    addMediumBox(scene, Vec3(0, 0, 0), Vec3(1, 1, 1), 0);
    scene.lights.push_back(PointLight{Vec3(0.5, 0.5, -3), Spectrum::constant(1.0)});  // on the camera's side
    scene.finalize();
    const PathTracer tracer(scene);
    PathStats stats;
    const WavelengthSampler ws(400, 700, {}, true);
    const Estimate e = meanOf(4000, [&](int i) {
        Rng rng = Rng::forKey(50, static_cast<uint64_t>(i), 0);
        const SampledWavelengths wl = ws.sample(rng.uniform(), rng.uniform());
        const double L = tracer.radiance(Ray{Vec3(0.5, 0.5, -2), normalize(Vec3(rng.uniform() - 0.5, rng.uniform() - 0.5, 4))}, kNone, wl, rng, stats)
                             .total()
                             .average();
        EXPECT_TRUE(std::isfinite(L) && L >= 0);
        return L;
    });
    const double perPath = double(stats.tentativeCollisions) / double(stats.paths);
    std::printf("  optical depth 1e4: radiance %.3g +- %.1g, %.1f tentative collisions per path, %llu truncated\n", e.mean, e.stderr_, perPath,
                static_cast<unsigned long long>(stats.truncated));
    EXPECT_EQ(stats.truncated, 0u);
    EXPECT_LT(perPath, 1000.0);
    EXPECT_GT(e.mean, 0.0);  // light diffusely reflected by the dense box reaches the camera side
    // Transmittance through it is zero to any precision, without NaN.
    Rng rng(2, 0);
    const double T = tracer.transmittance(Vec3(0.5, 0.5, -1), Vec3(0.5, 0.5, 2), kNone, SampledWavelengths::sampleUniform(0.5, 400, 700), rng)[0];
    EXPECT_TRUE(std::isfinite(T));
    EXPECT_LT(T, 1e-100);
}

}  // namespace
}  // namespace fluorosim
