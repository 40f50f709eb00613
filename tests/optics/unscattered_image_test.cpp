// The computed unscattered image (optics/unscattered_image.h): no variance, and every quadrature it
// uses converges as its resolution is refined, to below the stated bound at the defaults.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>

#include "core/errors.h"
#include "optics/acquisition.h"
#include "optics/imaging.h"
#include "optics/unscattered_image.h"
#include "support/fluorescent_scenes.h"
#include "support/sheet_scenes.h"
#include "volume/volume_fields.h"

namespace fluorosim {
namespace {

using namespace testing;

// AF594 on 0.5 µm voxels (or `voxel`): a dendrite-like filament along x through the sheet, one crossing it at 45°,
// and a blob off the focal plane, in weakly scattering tissue (σs 1/mm) inside a water bath.
Scene neuriteScene(double sigmaS, double voxel = 0.0005) {
    const DensityGrid g = DensityGrid::fromVoxels("AF594", {{-24, -24, -12}, {24, 24, 12}}, Affine::scaling(voxel), [](int i, int j, int k) {
        const double along = std::exp(-(sqr(j - 2) + sqr(k)) / 1.2);
        const double diagonal = std::exp(-(sqr(i - j) / 2.0 + sqr(k + 1)) / 1.5);
        const double blob = std::exp(-(sqr(i - 8) + sqr(j + 10) + sqr(k - 6)) / 4.0);
        const double v = 10.0 * along + 6.0 * diagonal + 8.0 * blob;
        return v > 0.05 ? v : 0.0;
    });
    Scene scene = af594Tissue(g, sigmaS);
    addSheetAndFinalize(scene, 0.002, 0.1);
    return scene;
}

struct Microscope {
    optics::ObjectiveOptions objective;
    optics::DetectorOptions detector;
    optics::Filter filter = optics::Filter::open();
    int size = 40;
    Microscope() {
        objective.na = 0.8;
        objective.magnification = 16;
        objective.workingDistanceMm = 0.2;
        optics::BandPassOptions band;
        band.centreNm = 630;
        band.fwhmNm = 60;
        filter = optics::Filter::bandPass(band);
    }
};

optics::UnscatteredPlane computedPlane(const Scene& scene, const Microscope& s, const optics::UnscatteredOptions& u, int threads = 0) {
    optics::AcquireOptions o;
    o.unscattered = u;
    const optics::ChannelImaging channel =
        optics::setUpChannelImaging(scene, scene.lights, s.objective, optics::FocalPlane{}, s.filter, s.detector, s.size, s.size, o);
    const optics::Imaging imaging(s.objective, optics::FocalPlane{}, s.detector, s.size, s.size, channel.psf);
    return optics::computeUnscatteredImage(scene, scene.lights, imaging, *channel.unscattered, threads);
}

std::vector<double> computed(const Scene& scene, const Microscope& s, const optics::UnscatteredOptions& u, int threads = 0) {
    return computedPlane(scene, s, u, threads).electrons;
}

double relativeL2(const std::vector<double>& a, const std::vector<double>& b) {
    double d = 0, n = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        d += sqr(a[i] - b[i]);
        n += sqr(b[i]);
    }
    return std::sqrt(d / n);
}

TEST(UnscatteredImage, EachQuadratureConvergesAsItIsRefined) {
    const Scene scene = neuriteScene(1.0);
    const Microscope s;
    const optics::UnscatteredOptions defaults;
    const std::vector<double> base = computed(scene, s, defaults);
    double sum = 0;
    for (double e : base) sum += e;
    std::printf("  default image: %.6g e- in all\n", sum);
    EXPECT_GT(sum, 0.0);
    struct Knob {
        const char* name;
        std::function<void(optics::UnscatteredOptions&, int)> refine;  // level 1, 2: finer and finer
    };
    const std::vector<Knob> knobs = {
        {"lateral samples", [](optics::UnscatteredOptions& u, int l) { u.lateralSamples = 2 << l, u.kernelPhases = 4 * (2 << l); }},
        {"axial step", [](optics::UnscatteredOptions& u, int l) { u.axialStepUm = 0.25 / (2 << (l - 1)); }},
        {"transmittance lattice", [](optics::UnscatteredOptions& u, int l) { u.transmittanceStepUm = 2.0 / (2 << (l - 1)); }},
        {"transmittance quadrature", [](optics::UnscatteredOptions& u, int l) { u.transmittanceQuadratureVoxels = 4.0 / (2 << (l - 1)); }},
        {"cone directions", [](optics::UnscatteredOptions& u, int l) { u.coneRings = 3 << l, u.coneAzimuths = 4 << l; }},
        {"spectral nodes", [](optics::UnscatteredOptions& u, int l) { u.spectralNodes = 8 << l; }},
        {"pixel quadrature", [](optics::UnscatteredOptions& u, int l) { u.pixelQuadrature = 3 << l; }},
        {"far bins", [](optics::UnscatteredOptions& u, int l) { u.farBinUm = 2.0 / (2 << (l - 1)); }},
        {"near kernel", [](optics::UnscatteredOptions& u, int l) { u.nearPixels = 2 << l, u.nearTaperPixels = 3 << l; }},
        {"faintest points left out", [](optics::UnscatteredOptions& u, int l) { u.dropPointsBelow = l == 1 ? 1e-5 : 0.0; }},
    };
    for (const Knob& k : knobs) {
        optics::UnscatteredOptions fine = defaults, finer = defaults;
        k.refine(fine, 1);
        k.refine(finer, 2);
        const std::vector<double> a = computed(scene, s, fine), b = computed(scene, s, finer);
        const double errorDefault = relativeL2(base, b), errorFine = relativeL2(a, b);
        std::printf("  %-26s default vs finest %.2e, finer vs finest %.2e\n", k.name, errorDefault, errorFine);
        EXPECT_LT(errorDefault, 0.01) << k.name;
    }
}

// The faintest points (the sheet's flanks) are left out of the projection within a budget of the
// photoelectrons the points send: the image loses at most that share, and nothing when the budget is 0.
TEST(UnscatteredImage, TheFaintestPointsLeftOutStayWithinTheirBudget) {
    const Scene scene = neuriteScene(1.0);
    const Microscope s;
    optics::UnscatteredOptions all, some;
    all.dropPointsBelow = 0;
    some.dropPointsBelow = 1e-3;
    const optics::UnscatteredPlane a = computedPlane(scene, s, all), b = computedPlane(scene, s, some);
    EXPECT_EQ(a.droppedPoints, 0u);
    EXPECT_EQ(a.droppedFraction, 0.0);
    EXPECT_EQ(a.points, b.points);
    double sumA = 0, sumB = 0, largest = 0;
    for (double e : a.electrons) largest = std::max(largest, e);
    for (size_t i = 0; i < a.electrons.size(); ++i) {
        sumA += a.electrons[i];
        sumB += b.electrons[i];
        ASSERT_LE(b.electrons[i], a.electrons[i] + 1e-12 * largest) << "pixel " << i;  // emissions only removed (FFT round-off)
    }
    std::printf("  left out %llu of %llu points, %.3g of their photoelectrons; image %.6g -> %.6g e-\n",
                static_cast<unsigned long long>(b.droppedPoints), static_cast<unsigned long long>(b.points), b.droppedFraction, sumA, sumB);
    EXPECT_GT(b.droppedPoints, 0u);
    EXPECT_GT(b.droppedFraction, 0.0);
    EXPECT_LE(b.droppedFraction, 1e-3);
    // The camera sees part of what the points send, so it loses at most about the same share.
    EXPECT_LE(1 - sumB / sumA, 1e-3 * 1.5);
}

TEST(UnscatteredImage, ABadFaintPointBudgetIsRefusedByName) {
    for (double bad : {-1e-4, 0.5, std::nan("")}) {
        optics::UnscatteredOptions u;
        u.dropPointsBelow = bad;
        try {
            u.validate();
            ADD_FAILURE() << "no error for " << bad;
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find("dropPointsBelow must lie in [0, 0.01]"), std::string::npos) << e.what();
        }
    }
}

// A PSF narrower than a pixel (NA 0.5 at 1.5 µm object pixels: 2.4 cycles of its band per pixel)
// must be integrated over the pixel wherever the point lies in it. With 3 x 3 Gauss–Legendre points per
// pixel the image of this scene was 21 % too bright with lattice points at pixel centres and 16 % too dark
// with points at quarter pixels; the node count now follows the PSF's band.
TEST(UnscatteredImage, APsfNarrowerThanAPixelKeepsItsEnergyWhereverThePointLies) {
    const Scene scene = neuriteScene(0.0, 0.002);  // 2 µm voxels: the lattice resolves the field at every spacing below
    Microscope s;
    s.objective.na = 0.5;
    s.objective.magnification = 6.5 / 1.5;
    s.size = 16;
    auto total = [&](int lateral, int phases) {
        optics::UnscatteredOptions u;
        u.lateralSamples = lateral;
        u.kernelPhases = phases;
        double sum = 0;
        for (double e : computed(scene, s, u)) sum += e;
        return sum;
    };
    const double centres = total(1, 8), quarters = total(2, 8), sixths = total(3, 12), eighths = total(4, 8);
    std::printf("  lattice points at pixel centres %.6g, quarters %.6g, sixths %.6g, eighths %.6g e-\n", centres, quarters, sixths, eighths);
    EXPECT_NEAR(quarters / eighths, 1.0, 0.005);
    EXPECT_NEAR(sixths / eighths, 1.0, 0.005);
    EXPECT_NEAR(centres / eighths, 1.0, 0.01);  // one point per pixel also samples the trilinear field coarsely
}

}  // namespace
}  // namespace fluorosim
