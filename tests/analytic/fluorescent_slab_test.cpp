// The slab validator with a grey fluorescent dye. Exact checks this case allows:
// - with quantum yield 1 and no other absorption, every photon leaves: Rd + Tt + Rf + Tf + Rsp = 1;
// - with isotropic scattering and identical bands, re-emission is indistinguishable from isotropic
//   scattering, so Rd + Rf and Tt + Tf equal the published values of a plain slab with
//   mus' = mus + QY mua_dye and mua' = mua + (1 - QY) mua_dye;
// - with quantum yield 0 there is no fluorescence at all;
// - with a transparent emission band and matched boundaries, re-emitted photons leave up or down with
//   equal probability: Rf = Tf.
#include <gtest/gtest.h>

#include <cmath>

#include "render/slab_transport.h"

namespace fluorosim {
namespace {

// Standard error of Rx + Ry when each photon contributes to at most one of them.
double sumStderr(double x, double sx, double y, double sy, double n) { return std::sqrt(std::max(0.0, sx * sx + sy * sy - 2 * x * y / (n - 1))); }

SlabOptions prahlSplit(double muaDye, double qy) {
    // Prahl's adding-doubling case (tests/data/slab_references.json, prahl_ad_a080_b1_g0):
    // mua = 2 /cm, mus = 8 /cm, g = 0, d = 0.1 cm: Rd = 0.21085, Tt = 0.54140 (accuracy 1e-5).
    SlabOptions o;
    o.muaDye = muaDye;
    o.quantumYield = qy;
    o.mus = 0.8 - qy * muaDye;
    o.mua = 0.2 - (1 - qy) * muaDye;
    o.thickness = 1.0;
    o.photons = 1000000;
    o.seed = 77;
    return o;
}

TEST(FluorescentSlab, QuantumYieldOneConservesPhotons) {
    for (double n : {1.0, 1.4}) {
        SlabOptions o;
        o.mus = 3.0;
        o.muaDye = 2.0;
        o.quantumYield = 1.0;
        o.g = 0.8;
        o.thickness = 1.5;
        o.n = n;
        o.photons = 200000;
        const SlabResult r = simulateSlab(o);
        EXPECT_NEAR(r.Rd + r.Tt + r.Rf + r.Tf + r.Rsp, 1.0, 1e-12) << "n = " << n;
        EXPECT_GT(r.Rf, 0.05);
        EXPECT_GT(r.Tf, 0.05);
    }
}

class FluorescenceAsScattering : public ::testing::TestWithParam<std::pair<double, double>> {};

TEST_P(FluorescenceAsScattering, MatchesPublishedPlainSlab) {
    const auto [muaDye, qy] = GetParam();
    const SlabOptions o = prahlSplit(muaDye, qy);
    const SlabResult r = simulateSlab(o);
    const double n = static_cast<double>(o.photons);
    const double R = r.Rd + r.Rf, T = r.Tt + r.Tf;
    const double sR = sumStderr(r.Rd, r.RdStderr, r.Rf, r.RfStderr, n), sT = sumStderr(r.Tt, r.TtStderr, r.Tf, r.TfStderr, n);
    EXPECT_NEAR(R, 0.21085, 4 * sR + 1e-5) << "stderr " << sR;
    EXPECT_NEAR(T, 0.54140, 4 * sT + 1e-5) << "stderr " << sT;
    EXPECT_GT(r.Rf + r.Tf, 0.02);  // fluorescence is really there
}

INSTANTIATE_TEST_SUITE_P(Splits, FluorescenceAsScattering,
                         ::testing::Values(std::pair{0.3, 1.0}, std::pair{0.4, 0.5}, std::pair{0.2, 0.25}));

TEST(FluorescentSlab, QuantumYieldZeroGivesNoFluorescence) {
    const SlabOptions o = prahlSplit(0.1, 0.0);  // mua = 0.1 + dye 0.1 /mm
    const SlabResult r = simulateSlab(o);
    EXPECT_EQ(r.Rf, 0.0);
    EXPECT_EQ(r.Tf, 0.0);
    EXPECT_NEAR(r.Rd, 0.21085, 4 * r.RdStderr + 1e-5);
    EXPECT_NEAR(r.Tt, 0.54140, 4 * r.TtStderr + 1e-5);
}

TEST(FluorescentSlab, TransparentEmissionBandEmitsSymmetrically) {
    SlabOptions o;
    o.mus = 5.0;
    o.g = 0.9;
    o.muaDye = 1.0;
    o.quantumYield = 0.7;
    o.thickness = 1.0;
    o.emission = SlabBand{0.0, 0.0, 0.0, 0.0};
    o.photons = 1000000;
    const SlabResult r = simulateSlab(o);
    EXPECT_NEAR(r.Rf, r.Tf, 4 * std::hypot(r.RfStderr, r.TfStderr));
    EXPECT_GT(r.Rf, 0.1);
}

TEST(FluorescentSlab, AbsorbingEmissionBandQuenchesEscape) {
    SlabOptions o;
    o.mus = 5.0;
    o.muaDye = 1.0;
    o.quantumYield = 1.0;
    o.thickness = 1.0;
    o.photons = 200000;
    const SlabResult clear = simulateSlab(o);
    o.emission = SlabBand{20.0, 5.0, 0.0, 0.0};  // strong non-fluorescent absorption at emission wavelengths
    const SlabResult dark = simulateSlab(o);
    EXPECT_LT(dark.Rf + dark.Tf, 0.5 * (clear.Rf + clear.Tf));
    // The excitation band is untouched: elastic reflectance agrees within statistics.
    EXPECT_NEAR(dark.Rd, clear.Rd, 4 * std::hypot(dark.RdStderr, clear.RdStderr));
}

TEST(FluorescentSlab, RejectsBadQuantumYield) {
    SlabOptions o;
    o.thickness = 1;
    o.quantumYield = 1.5;
    EXPECT_THROW(o.validate(), std::exception);
}

// A transparent emission band inside n = 1.4 traps re-emitted photons by total internal reflection
// forever; they must be tallied as guided, not loop (found in review).
TEST(FluorescentSlab, GuidedPhotonsTerminate) {
    SlabOptions o;
    o.mus = 1.0;
    o.muaDye = 0.5;
    o.quantumYield = 1.0;
    o.thickness = 1.0;
    o.n = 1.4;
    o.emission = SlabBand{0.0, 0.0, 0.0, 0.0};
    o.photons = 100000;
    const SlabResult r = simulateSlab(o);
    EXPECT_GT(r.guided, 0.05);
    EXPECT_NEAR(r.Rd + r.Tt + r.Rf + r.Tf + r.guided + r.Rsp, 1.0, 1e-12);
    EXPECT_NEAR(r.Ta, 0.0, 1e-12);
}

}  // namespace
}  // namespace fluorosim
