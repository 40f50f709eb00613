// The diffraction PSF: the Airy sampler against its closed-form encircled energy, and the image of a
// sub-resolution bead (0.08 µm) in focus against the diffraction model (the Airy pattern convolved
// with the bead's projected thickness and averaged over the pixel), at two wavelengths and two NAs.
// Tolerance for the bead: FWHM within 5 % (the goal).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "core/rng.h"
#include "optics/acquisition.h"
#include "optics/light_sheet.h"
#include "optics/psf.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

TEST(AiryPattern, SamplesFollowTheEncircledEnergy) {
    const optics::AiryPattern airy;
    // EE(v) = 1 - J0(v)² - J1(v)², renormalised to the truncation at v = 60.
    auto ee = [](double v) { return 1 - std::pow(std::cyl_bessel_j(0.0, v), 2) - std::pow(std::cyl_bessel_j(1.0, v), 2); };
    const double lambda = 550, na = 0.9, k = 2 * kPi * na / (lambda * 1e-6);
    const int n = 400000;
    for (double v : {1.0, 1.6163, 3.8317, 7.0156, 20.0}) {
        int inside = 0;
        Rng rng(3, static_cast<uint64_t>(v * 1000));
        for (int i = 0; i < n; ++i) inside += airy.sampleRadiusMm(rng.uniform(), lambda, na) * k < v;
        const double p = ee(v) / ee(60.0), se = std::sqrt(p * (1 - p) / n);
        EXPECT_NEAR(double(inside) / n, p, 4 * se) << "v = " << v;
    }
    EXPECT_NEAR(optics::AiryPattern::intensity(1.6163), 0.5, 1e-4);  // the half maximum sets the FWHM
    // The density integrates to one.
    double sum = 0;
    const double rMax = 60 / k, dr = rMax / 20000;
    for (int i = 0; i < 20000; ++i) sum += airy.densityPerMm2((i + 0.5) * dr, lambda, na) * 2 * kPi * (i + 0.5) * dr * dr;
    EXPECT_NEAR(sum, 1.0, 1e-4);
}

// Half-maximum width of a symmetric profile sampled at pixel centres (linear interpolation).
double fwhm(const std::vector<double>& p, double pixel) {
    const int c = static_cast<int>(p.size()) / 2;
    const double half = 0.5 * p[static_cast<size_t>(c)];
    auto crossing = [&](int dir) {
        for (int i = c; i + dir >= 0 && i + dir < static_cast<int>(p.size()); i += dir) {
            const double a = p[static_cast<size_t>(i)], b = p[static_cast<size_t>(i + dir)];
            if (b < half) return (i - c + dir * (a - half) / (a - b)) * pixel;
        }
        return 0.0;
    };
    return crossing(1) - crossing(-1);
}

TEST(AiryPattern, BeadInFocusHasTheDiffractionLimitedWidth) {
    const optics::AiryPattern airy;
    for (double emission : {520.0, 640.0})
        for (double na : {0.5, 1.0}) {
            // Sub-resolution beads: 0.16 µm at NA 0.5, 0.08 µm at NA 1 (where the bead's depth would
            // otherwise add geometric blur across the wide cone). Hits per pixel scale with (R NA)², so
            // NA 0.5 also gets twice the samples. The tolerance is 4 standard errors of the width.
            const double radius = na < 0.7 ? 8e-5 : 4e-5;
            const Fluorophore dye("narrow", TabulatedSpectrum({440, 450, 500, 510}, {0, 1, 1, 0}), 70000,
                                  TabulatedSpectrum({emission - 3, emission, emission + 3}, {0, 1, 0}), 0.9);
            Scene scene;
            scene.spectral.lambdaMin = 450;
            scene.spectral.lambdaMax = 700;
            scene.media.emplace_back("water", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, 1.33);
            scene.media.emplace_back("bead", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, 1.33, std::vector<DyeComponent>{{dye, 1e-3}});
            const uint32_t id = scene.geometry.addSphere(Vec3(0, 0, 0), radius);
            ShapeInfo bead;
            bead.isInterface = true;
            bead.insideMedium = 1;
            bead.outsideMedium = 0;
            scene.shapes.push_back(bead);
            (void)id;
            LightSheetSpec spec;
            spec.wavelengthNm = 488;
            spec.waistMm = 0.002;
            spec.heightMm = 0.1;
            scene.lights.push_back(BeamLight{optics::makeLightSheet(spec), spec});
            scene.camera.medium = 0;
            scene.finalize();

            const double model = optics::AiryPattern::fwhmMm(emission, na);
            const double pixel = model / 8;
            optics::ObjectiveOptions objective;
            objective.na = na;
            objective.magnification = 6.5e-3 / pixel;
            objective.workingDistanceMm = 0.05;
            optics::DetectorOptions detector;
            // The split estimator (the default) sees the bead through its direct part, so its samples
            // carry the budget; the path part sees nothing here but checks that it adds nothing.
            optics::AcquireOptions o;
            o.directSpp = na < 0.7 ? 240000 : 120000;
            o.spp = 16;
            o.seed = 9;
            const optics::PlaneImage r = optics::renderPlane(scene, objective, optics::FocalPlane{}, optics::Filter::open(), detector, 25, 1, o);
            auto symmetric = [](const std::vector<double>& v) {
                std::vector<double> s(25);
                for (int x = 0; x < 25; ++x) s[static_cast<size_t>(x)] = 0.5 * (v[static_cast<size_t>(x)] + v[static_cast<size_t>(24 - x)]);
                return s;
            };
            const std::vector<double> row = symmetric(r.electrons);

            // The model row: Airy ⊗ projected thickness, averaged over each pixel (4 x 4 points).
            std::vector<double> expected(25, 0.0);
            const int m = 24;
            for (int x = 0; x < 25; ++x)
                for (int sx = 0; sx < 4; ++sx)
                    for (int sy = 0; sy < 4; ++sy) {
                        const double px = (x - 12 + (sx + 0.5) / 4 - 0.5) * pixel, py = ((sy + 0.5) / 4 - 0.5) * pixel;
                        for (int i = -m; i <= m; ++i)
                            for (int j = -m; j <= m; ++j) {
                                const double bx = i * radius / m, by = j * radius / m, b2 = bx * bx + by * by;
                                if (b2 >= radius * radius) continue;
                                expected[static_cast<size_t>(x)] +=
                                    2 * std::sqrt(radius * radius - b2) * airy.densityPerMm2(std::hypot(px - bx, py - by), emission, na);
                            }
                    }
            const double measured = fwhm(row, pixel), predicted = fwhm(expected, pixel);
            // The width's standard error by the delta method: its derivative with respect to each
            // pixel (finite differences through the symmetrization) times the pixel's standard error.
            // The direct part's standard errors treat its Owen-scrambled Sobol' points as independent,
            // so they overstate the error (replicas at an eighth of the points each read about 5x
            // less); the bound is conservative.
            double variance = 0;
            for (size_t x = 0; x < 25; ++x) {
                std::vector<double> moved = r.electrons;
                const double h = 1e-3 * r.stderrElectrons[x] + 1e-12;
                moved[x] += h;
                variance += std::pow((fwhm(symmetric(moved), pixel) - measured) / h * r.stderrElectrons[x], 2);
            }
            const double stderrRatio = std::sqrt(variance) / predicted;
            std::printf("  emission %.0f nm, NA %.1f: bead FWHM %.4f um, model %.4f um (Airy alone %.4f um), ratio %.4f +- %.4f (%.1f s)\n",
                        emission, na, measured * 1e3, predicted * 1e3, model * 1e3, measured / predicted, stderrRatio, r.seconds);
            EXPECT_LT(stderrRatio, 0.02) << "the check must be sharp";
            EXPECT_NEAR(measured / predicted, 1.0, 4 * stderrRatio);
        }
}

// The PSF displacement is drawn at the hero wavelength and the path's other sampling decisions are
// spectral too; both enter one spectral-MIS weight. A small emitter at 455 and 680 nm (two 10 nm boxes,
// 3/4 of the sampled range apart, so that one camera path carries both) is seen through a layer whose
// absorption rises from 0 at 455 nm to 1.5 at 680 nm: the PSF is tighter where the path pdf is higher.
// The same emitter with two spectral lines (no spectral MIS: all four slots at one line) is the
// reference: the centre pixel, the sum of the edge pixels and the sum of the corners. (Over 10 nm the
// PSF and the transmittance bend by less than 1e-3 of the line values.) Multiplying a PSF-only MIS
// weight into the tracer's path-only weight, as acquisition once did, read the centre 10 % high.
TEST(AiryPattern, PsfAndPathWeightsShareOneSpectralMisWeight) {
    auto render = [](bool lines, uint64_t seed) {
        Scene scene;
        scene.spectral.lambdaMin = 450;
        scene.spectral.lambdaMax = 750;
        const double h = 0.4;  // layer thickness, mm
        const TabulatedSpectrum absorption({450, 750}, {0.0, 1.5 / h * 300 / 225});
        scene.media.emplace_back("absorber", Spectrum::tabulated(absorption), Spectrum::constant(0.0), 0.0, 1.0);
        addMediumBox(scene, Vec3(-1, -1, 0.01), Vec3(1, 1, 0.01 + h), 0);
        TriangleMesh square;  // 0.3 µm emitting square in the focal plane, facing the objective
        const double e = 1.5e-4;
        square.positions = {Vec3(-e, -e, 0), Vec3(e, -e, 0), Vec3(e, e, 0), Vec3(-e, e, 0)};
        square.indices = {0, 1, 2, 0, 2, 3};
        const uint32_t id = scene.geometry.addMesh(square);
        scene.shapes.push_back(ShapeInfo{"emitter"});
        const Spectrum emission = lines ? Spectrum::lines({{455, 5.0}, {680, 5.0}})
                                        : Spectrum::tabulated(TabulatedSpectrum({450, 450.0001, 460, 460.0001, 675, 675.0001, 685, 685.0001},
                                                                                {0, 0.5, 0.5, 0, 0, 0.5, 0.5, 0}));
        scene.addAreaLight(id, AreaEmission{emission, false});
        scene.finalize();
        optics::ObjectiveOptions objective;
        objective.na = 0.8;
        objective.magnification = 16;
        objective.immersionIndex = 1.0 / 0.9;  // a wide cone in air-like immersion
        optics::DetectorOptions detector;
        optics::AcquireOptions o;
        o.spp = lines ? 200000 : 800000;
        o.seed = seed;
        return optics::renderPlane(scene, objective, optics::FocalPlane{}, optics::Filter::open(), detector, 3, 3, o);
    };
    const optics::PlaneImage mis = render(false, 3), reference = render(true, 4);
    const std::vector<std::pair<const char*, std::vector<int>>> groups{{"centre", {4}}, {"edges", {1, 3, 5, 7}}, {"corners", {0, 2, 6, 8}}};
    for (const auto& [name, pixels] : groups) {
        double a = 0, b = 0, va = 0, vb = 0;
        for (int p : pixels) {
            a += mis.electrons[p];
            b += reference.electrons[p];
            va += sqr(mis.stderrElectrons[p]);
            vb += sqr(reference.stderrElectrons[p]);
        }
        const double se = std::sqrt(va + vb);
        std::printf("  %s: continuous %.5g +- %.2g, lines %.5g +- %.2g, ratio %.4f, z = %+.2f\n", name, a, std::sqrt(va), b, std::sqrt(vb),
                    a / b, (a - b) / se);
        if (pixels.size() == 1) {
            EXPECT_LT(se, 0.015 * b) << "the centre must resolve the 10 % bias it guards against";
        }
        EXPECT_LT(std::abs(a - b), 4 * se) << name;
    }
}

}  // namespace
}  // namespace fluorosim
