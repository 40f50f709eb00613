// Samples whose refractive index differs from the immersion medium's: a block of index n_s under a water
// bath and a water objective, its top surface some tens of µm above the focus. Before the light's way to
// the objective bent at that surface, such a sample imaged nothing: the computed part's cone rays stopped
// at the surface (computed_electrons_fraction 0), and camera paths aimed at the focal point through it
// were refracted past the focus.
//  - Energy: a thin dye layer in the focal plane against the closed-form chain, with the collection cone
//    in the sample (asin(NA/n_s)) and the Fresnel transmittance of the top surface, for both estimators.
//  - The image: a sub-resolution bead's stack against an independent Gibson–Lanni computation.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>

#include "materials/fresnel.h"
#include "optics/acquisition.h"
#include "optics/imaging.h"
#include "optics/light_sheet.h"
#include "render/path_tracer.h"
#include "support/dye_layer.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

constexpr double kWater = 1.33;

// A water bath with a block of `sampleIndex` in it, its top `depthMm` above the focal plane (z = 0); the
// sheet is in the block. Returns the block's medium index, for dyed shapes inside it.
int addMismatchedBlock(Scene& scene, double sampleIndex, double depthMm) {
    scene.media.emplace_back("water", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, kWater);
    scene.media.emplace_back("block", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, sampleIndex);
    addMediumBox(scene, Vec3(-0.15, -0.15, -0.15), Vec3(0.15, 0.15, depthMm), 1);
    scene.shapes.back().outsideMedium = 0;
    if (sampleIndex != kWater) {
        scene.shapes.back().material = static_cast<int>(scene.materials.size());
        scene.materials.push_back(makeDielectric(0.0));
        scene.materialNames.push_back("block surface");
    }
    addBath(scene, 0.4, 0);
    scene.camera.medium = 0;
    return 1;
}

optics::ObjectiveOptions waterObjective() {
    optics::ObjectiveOptions objective;
    objective.na = 0.8;
    objective.magnification = 16;
    objective.immersionIndex = kWater;
    objective.workingDistanceMm = 0.2;
    return objective;
}

// (1/4π) ∫ over the sample's collection cone of the Fresnel transmittance into water, dω (midpoint rule).
double collectionFraction(double sampleIndex, double na) {
    const double sinMax = na / sampleIndex, cosMax = std::sqrt(1 - sinMax * sinMax);
    const int n = 20000;
    double sum = 0;
    for (int i = 0; i < n; ++i) {
        const double cosT = 1 - (i + 0.5) / n * (1 - cosMax);
        sum += (1 - fresnelDielectric(cosT, kWater / sampleIndex)) * (1 - cosMax) / n;
    }
    return 0.5 * sum;
}

class MismatchedLayer : public ::testing::TestWithParam<double> {};

TEST_P(MismatchedLayer, KeepsThePhotonBudgetWithTheSampleConeAndFresnel) {
    const double sampleIndex = GetParam();
    const DyeLayer layer{separatedBandDye(70000, 0.9), 1e-4, 0.001, 0.05};
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 750;
    const int block = addMismatchedBlock(scene, sampleIndex, 0.02);  // the top 20 µm above the focus
    addDyeLayer(scene, layer, block, 0.0, 0.0, 0.0, sampleIndex);
    const auto sheet = addLayerSheet(scene, sampleIndex);
    scene.finalize();

    const optics::ObjectiveOptions objective = waterObjective();
    optics::DetectorOptions detector;
    detector.exposureS = 0.01;
    optics::BandPassOptions band;
    band.centreNm = 650;
    band.fwhmNm = 60;
    const optics::Filter filter = optics::Filter::bandPass(band);

    const double collection = collectionFraction(sampleIndex, objective.na);
    const int size = 12;
    double expected = layerElectrons(layer, *sheet, 488.0, filter, LayerCamera{6.5e-3 / 16, size, 0.01, 0.8, collection}, true);
    // The layer is uniform over the field and its margin: only the PSF tail of the dye beyond the computed
    // region is missing (layerImageKept, from the aberrated PSF's own Parseval-normalised table).
    optics::AcquireOptions o;
    o.psf.vCut = 60;
    optics::FocalPlane focus;
    const PathTracer tracer(scene);
    const double enclosed = layerImageKept(optics::setUpChannelImaging(scene, tracer.lights(), objective, focus, filter, detector, size, size, o), layer,
                                           650, LayerCamera{6.5e-3 / 16, size, 0.01, 0.8, collection});
    expected *= enclosed;

    for (optics::Estimator estimator : {optics::Estimator::Split, optics::Estimator::Path}) {
        o.estimator = estimator;
        o.spp = estimator == optics::Estimator::Split ? 16 : 256;
        o.seed = 7;
        const optics::PlaneImage r = optics::renderPlane(scene, objective, focus, filter, detector, size, size, o);
        double measured = 0, var = 0;
        for (size_t i = 0; i < r.electrons.size(); ++i) {
            measured += r.electrons[i];
            var += sqr(r.stderrElectrons[i]);
        }
        const double se = std::sqrt(var);
        std::printf("  n_s %.2f %s: %.6g +- %.2g e-, closed form %.6g (collection %.5f, the region keeps %.5f), ratio %.5f\n", sampleIndex,
                    optics::estimatorName(estimator), measured, se, expected, collection, enclosed, measured / expected);
        EXPECT_LT(se, 0.01 * expected) << optics::estimatorName(estimator);
        // The computed part's quadrature bound (0.5 %, docs/model.md) and 4 standard errors.
        EXPECT_NEAR(measured / expected, 1.0, 0.005 + 4 * se / expected) << optics::estimatorName(estimator);
        if (estimator == optics::Estimator::Split) {
            EXPECT_GT(r.computedElectrons, 0.99 * measured);
        }
    }
}

INSTANTIATE_TEST_SUITE_P(IndexMismatch, MismatchedLayer, ::testing::Values(1.33, 1.36, 1.45, 1.56));

// The Gibson–Lanni image of a point at depth d_b below the step, for an objective whose nominal focus
// lies z_f deep (Gibson and Lanni 1991, without a coverslip): U(r) = ∫ sqrt(a(ρ) / cos θ_s) exp(i k [d_b n_s
// cos θ_s − z_f n_i cos θ_i]) J0(k NA r ρ) ρ dρ, with a the Fresnel transmittance of the step relative to the
// axis and 1/cos θ_s the aplanatic objective's pupil intensity for an isotropic emitter.
// The plane of focus is the least-squares best focus (docs/optics.md): z_f = D Var(n_s cos θ_s) /
// Cov(n_s cos θ_s, n_i cos θ_i) over the pupil weighted by ρ a(ρ) / cos θ_s, for a plane of focus D deep.
// Written from the formula with Simpson's rule, apart from the model's tables.
struct GibsonLanni {
    double na, ni, ns, lambdaMm;
    static constexpr int kNodes = 2000;  // Simpson intervals over ρ
    double cosS(double rho) const { return std::sqrt(1 - sqr(na * rho / ns)); }
    double cosI(double rho) const { return std::sqrt(1 - sqr(na * rho / ni)); }
    double pupilIntensity(double rho) const {
        return (1 - fresnelDielectric(cosS(rho), ni / ns)) / (1 - fresnelDielectric(1.0, ni / ns)) / cosS(rho);
    }
    template <class F>
    auto simpson(F&& f) const {
        auto sum = f(0.0) + f(1.0);
        for (int i = 1; i < kNodes; ++i) sum += f(static_cast<double>(i) / kNodes) * (i % 2 ? 4.0 : 2.0);
        return sum / (3.0 * kNodes);
    }
    double nominalFocus(double planeDepth) const {
        auto w = [&](double r) { return r * pupilIntensity(r); };
        const double W = simpson(w);
        const double ms = simpson([&](double r) { return w(r) * ns * cosS(r); }) / W, mi = simpson([&](double r) { return w(r) * ni * cosI(r); }) / W;
        const double vs = simpson([&](double r) { return w(r) * sqr(ns * cosS(r) - ms); });
        const double cv = simpson([&](double r) { return w(r) * (ns * cosS(r) - ms) * (ni * cosI(r) - mi); });
        return planeDepth * vs / cv;
    }
    // |U(r)|² on r = i dr (i < nr) for a point at pointDepth and the nominal focus at focusDepth; J0 tabulated
    // once per radius and pupil node (`j0`, from besselTable).
    std::vector<double> besselTable(double dr, int nr) const {
        const double k = 2 * kPi / lambdaMm;
        std::vector<double> j0(static_cast<size_t>(nr) * (kNodes + 1));
        for (int i = 0; i < nr; ++i)
            for (int n = 0; n <= kNodes; ++n) j0[static_cast<size_t>(i) * (kNodes + 1) + n] = std::cyl_bessel_j(0.0, k * na * i * dr * n / kNodes);
        return j0;
    }
    std::vector<double> profile(const std::vector<double>& j0, int nr, double pointDepth, double focusDepth) const {
        const double k = 2 * kPi / lambdaMm;
        std::vector<std::complex<double>> pupil(kNodes + 1);
        for (int n = 0; n <= kNodes; ++n) {
            const double rho = static_cast<double>(n) / kNodes, simpsonWeight = (n == 0 || n == kNodes ? 1.0 : n % 2 ? 4.0 : 2.0) / (3.0 * kNodes);
            const double phase = k * (pointDepth * ns * cosS(rho) - focusDepth * ni * cosI(rho));
            pupil[static_cast<size_t>(n)] = simpsonWeight * std::sqrt(pupilIntensity(rho)) * rho * std::exp(std::complex<double>(0, phase));
        }
        std::vector<double> out(static_cast<size_t>(nr));
        for (int i = 0; i < nr; ++i) {
            std::complex<double> u = 0;
            for (int n = 0; n <= kNodes; ++n) u += pupil[static_cast<size_t>(n)] * j0[static_cast<size_t>(i) * (kNodes + 1) + n];
            out[static_cast<size_t>(i)] = std::norm(u);
        }
        return out;
    }
};

// A stack's planes share a PSF while their pupils agree within the tolerance: under a mismatch the
// depth changes the Gibson–Lanni phase and planes split into groups; matched, they share one.
TEST(IndexMismatch, StackPlanesShareAPsfWithinTheDepthTolerance) {
    std::vector<double> offsets;
    for (int k = -6; k <= 6; ++k) offsets.push_back(k * 5e-4);
    optics::FocalPlane focus;  // small tables: only the grouping is tested
    focus.centreMm = Vec3(0, 0, 0);
    focus.towardObjective = Vec3(0, 0, 1);
    struct Case {
        double sampleIndex, tolerance;
    };
    for (const Case c : {Case{kWater, 0.0025}, Case{1.52, 0.0025}, Case{1.52, 0.01}}) {
        Scene scene;
        scene.spectral.lambdaMin = 450;
        scene.spectral.lambdaMax = 700;
        addMismatchedBlock(scene, c.sampleIndex, 0.03);
        scene.finalize();
        optics::PsfTableOptions table;
        table.vCut = 20;
        table.wMax = 20;
        table.depthTolerance = c.tolerance;
        const auto psfs = optics::makePlanePsfs(scene, waterObjective(), focus, offsets, 520, table);
        ASSERT_EQ(psfs.size(), offsets.size());
        std::vector<const optics::WidefieldPsf*> distinct;
        double worst = 0;
        for (size_t i = 0; i < psfs.size(); ++i) {
            if (std::find(distinct.begin(), distinct.end(), psfs[i].get()) == distinct.end()) distinct.push_back(psfs[i].get());
            optics::FocalPlane plane = focus;
            plane.centreMm = Vec3(0, 0, offsets[i]);
            const double distance = optics::pupilDistance(psfs[i]->pupil(), optics::pupilAt(scene, waterObjective(), plane, 520), 520);
            worst = std::max(worst, distance);
            EXPECT_LE(distance, c.tolerance) << "plane " << i;
        }
        std::printf("  n_s %.2f, 13 planes over +-3 um, 30 um deep, tolerance %.4f: %zu PSFs, largest pupil distance to a plane's own %.4f\n",
                    c.sampleIndex, c.tolerance, distinct.size(), worst);
        if (c.sampleIndex == kWater) EXPECT_EQ(distinct.size(), 1u);
        else if (c.tolerance > 0.005) EXPECT_LT(distinct.size(), offsets.size());
        else EXPECT_GT(distinct.size(), 1u);
    }
}

class MismatchedBead : public ::testing::TestWithParam<double> {};

TEST_P(MismatchedBead, StackMatchesAnIndependentGibsonLanniComputation) {
    const double sampleIndex = GetParam(), depth = 0.03, emission = 520, radius = 2e-5;
    const Fluorophore dye("narrow", TabulatedSpectrum({440, 450, 500, 510}, {0, 1, 1, 0}), 70000,
                          TabulatedSpectrum({emission - 1, emission, emission + 1}, {0, 1, 0}), 0.9);
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 700;
    const int block = addMismatchedBlock(scene, sampleIndex, depth);
    scene.media.emplace_back("bead", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, sampleIndex, std::vector<DyeComponent>{{dye, 1e-3}});
    scene.geometry.addSphere(Vec3(0, 0, 0), radius);
    ShapeInfo bead;
    bead.isInterface = true;
    bead.insideMedium = static_cast<int>(scene.media.size()) - 1;
    bead.outsideMedium = block;
    scene.shapes.push_back(bead);
    LightSheetSpec spec;
    spec.wavelengthNm = 488;
    spec.waistMm = 0.01;
    spec.heightMm = 0.1;
    spec.refractiveIndex = sampleIndex;
    scene.lights.push_back(BeamLight{optics::makeLightSheet(spec), spec});
    scene.finalize();

    optics::Microscope m;
    m.objective = waterObjective();
    m.detector.darkCurrentElectronsPerS = 0;
    m.width = m.height = 31;  // the bead at the middle of the centre pixel
    optics::MicroscopeChannel channel;
    channel.name = "narrow";
    channel.lights = {0};
    m.channels = {channel};
    m.stack.planes = 13;  // ±3 µm
    m.stack.stepMm = 0.0005;
    optics::Stack stack = optics::emptyStack(m, {0});
    optics::AcquireOptions o;
    o.spp = 1;
    ASSERT_TRUE(optics::acquireStack(scene, m, stack, o));

    const GibsonLanni gl{m.objective.na, kWater, sampleIndex, emission * 1e-6};
    const double pixel = m.pixelSizeMm();
    constexpr int kSub = 16;
    // The radial profile at steps of pixel / 64, linear between them, out to the field's corner.
    const double dr = pixel / 64;
    const int nr = static_cast<int>(std::ceil(std::hypot(m.width, m.height) * 0.5 * pixel / dr)) + 2;
    const std::vector<double> j0 = gl.besselTable(dr, nr);
    double worst = 0;
    for (int k = 0; k < m.stack.planes; ++k) {
        const double offset = m.planeOffsetMm(k);  // of the plane of focus toward the objective from the bead
        const std::vector<double> radial = gl.profile(j0, nr, depth, gl.nominalFocus(depth - offset));
        auto intensity = [&](double r) {
            const double u = r / dr;
            const size_t i = std::min(static_cast<size_t>(u), static_cast<size_t>(nr - 2));
            return radial[i] + (u - static_cast<double>(i)) * (radial[i + 1] - radial[i]);
        };
        std::vector<double> model(static_cast<size_t>(m.width * m.height)), image(model.size());
        double modelSum = 0, imageSum = 0;
        for (int y = 0; y < m.height; ++y)
            for (int x = 0; x < m.width; ++x) {
                const size_t i = static_cast<size_t>(y * m.width + x);
                double v = 0;
                for (int a = 0; a < kSub; ++a)
                    for (int b = 0; b < kSub; ++b) {
                        const double px = (x - m.width / 2 + (a + 0.5) / kSub - 0.5) * pixel, py = (y - m.height / 2 + (b + 0.5) / kSub - 0.5) * pixel;
                        v += intensity(std::hypot(px, py));
                    }
                model[i] = v;
                image[i] = stack.expected[stack.pixelOffset(0, k) + i];
                modelSum += model[i];
                imageSum += image[i];
            }
        double diff = 0, norm = 0;
        for (size_t i = 0; i < model.size(); ++i) {
            diff += sqr(image[i] / imageSum - model[i] / modelSum);
            norm += sqr(model[i] / modelSum);
        }
        const double rel = std::sqrt(diff / norm);
        worst = std::max(worst, rel);
        std::printf("  n_s %.2f plane %+.1f um: relative L2 %.4f, peak pixel %.4f (Gibson-Lanni %.4f)\n", sampleIndex, offset * 1e3, rel,
                    image[static_cast<size_t>((m.height / 2) * m.width + m.width / 2)] / imageSum,
                    model[static_cast<size_t>((m.height / 2) * m.width + m.width / 2)] / modelSum);
        EXPECT_LT(rel, 0.10) << "plane " << k;  // the goal
        // Each plane images with its own depth's PSF (makePlanePsfs); with the middle plane's PSF for all,
        // n 1.52 read 2.9 % at ±3 µm.
        EXPECT_LT(rel, 0.02) << "plane " << k;
    }
    std::printf("  n_s %.2f: worst relative L2 over +-3 um %.4f\n", sampleIndex, worst);
}

INSTANTIATE_TEST_SUITE_P(IndexMismatch, MismatchedBead, ::testing::Values(1.33, 1.36, 1.45, 1.52));

}  // namespace
}  // namespace fluorosim
