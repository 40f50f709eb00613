// Photon budget of the simulated microscope: a thin uniform dye layer in the focal plane, lit in its
// own plane by a known static light sheet, must give the expected photoelectrons of the closed-form
// chain: absorbed photons (σa E / (hc/λx), with the sheet's Beer–Lambert loss from where it entered
// the layer) × Φ × collection fraction Ω/4π × ∫ f(λ) T(λ) QE(λ) dλ × object pixel area × exposure.
// Tolerance: the computed image's stated quadrature bound (0.5 %) and 4 standard errors of the paths'
// part, with the standard error below 0.3 %.
// This test found a bias: rays leaving a surface used to start a small offset away from it, so every
// crossing skipped about 20 nm of medium (a 1 µm layer read 2.2 % low, a 0.2 µm one 10 %).
// The dye absorbs only at 440-500 nm and emits only at 600-700 nm: with AF488 the layer re-absorbs
// part of its own emission (emission travelling inside the layer), which adds secondary fluorescence
// that the chain leaves out and makes the estimate heavy-tailed (one path in 10^5 carried 5000 times
// the mean: a sub-path at a re-absorbed wavelength grazing along the 1 µm layer).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "optics/acquisition.h"
#include "optics/light_sheet.h"
#include "render/path_tracer.h"
#include "support/dye_layer.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim {
namespace {

using namespace testing;

TEST(PhotonBudget, ThinDyeLayerUnderKnownSheetMatchesTheClosedFormChain) {
    const DyeLayer layer{separatedBandDye(70000, 0.9), 1e-4, 0.001, 0.05};  // 100 µM, 1 µm thick, 0.1 mm wide
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 750;
    scene.media.emplace_back("water", Spectrum::constant(0.0), Spectrum::constant(0.0), 0.0, 1.33);
    addDyeLayer(scene, layer, 0, 0.0, 0.0, 0.0, 1.33);
    addBath(scene, 0.4, 0);
    const auto sheet = addLayerSheet(scene, 1.33);
    scene.camera.medium = 0;
    scene.finalize();

    optics::ObjectiveOptions objective;
    objective.na = 0.8;
    objective.magnification = 16;
    objective.workingDistanceMm = 0.2;
    optics::DetectorOptions detector;
    detector.qe = Spectrum::constant(0.8);
    detector.exposureS = 0.01;
    optics::BandPassOptions band;
    band.centreNm = 650;
    band.fwhmNm = 60;
    const optics::Filter filter = optics::Filter::bandPass(band);
    optics::AcquireOptions o;
    o.spp = 1000;
    o.seed = 5;
    o.psf.vCut = 60;  // a small field: the PSF cut sets the margin (what the tail leaves out enters the closed form below)
    const optics::PlaneImage r = optics::renderPlane(scene, objective, optics::FocalPlane{}, filter, detector, 16, 16, o);

    const double collection = (1 - std::cos(objective.collectionHalfAngle())) / 2;
    const LayerCamera camera{6.5e-3 / 16, 16, 0.01, 0.8, collection};
    double expected = layerElectrons(layer, *sheet, 488.0, filter, camera, true);
    double measured = 0, var = 0;
    for (size_t i = 0; i < r.electrons.size(); ++i) {
        measured += r.electrons[i];
        var += r.stderrElectrons[i] * r.stderrElectrons[i];
    }
    // The layer is uniform over the field and its margin, so what leaves the field through the PSF comes
    // back from beyond it; only the PSF tail of the dye beyond the computed region is missing.
    const PathTracer tracer(scene);
    const double kept = layerImageKept(optics::setUpChannelImaging(scene, tracer.lights(), objective, optics::FocalPlane{}, filter, detector, 16, 16, o),
                                       layer, 650, camera);
    expected *= kept;
    const double se = std::sqrt(var);
    std::printf("  expected photoelectrons over 16x16 pixels: simulated %.6g +- %.2g, closed form %.6g (the region keeps %.5f), ratio %.5f (%.1f s), largest sample %.3g, mean sample %.3g\n",
                measured, se, expected, kept, measured / expected, r.seconds, r.largestSample, measured / (r.width * r.height));
    EXPECT_LT(se, 0.003 * expected) << "the check must resolve well below 1 %";
    // The image is nearly all computed (no variance), so the check is the computed part's quadrature
    // bound, 0.5 % (docs/model.md); it reads 1.0020 here, a residual not yet traced to its quadrature.
    EXPECT_NEAR(measured / expected, 1.0, 0.005 + 4 * se / expected);
}

}  // namespace
}  // namespace fluorosim
