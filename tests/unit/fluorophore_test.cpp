// Dye absorption: mu_a = ln(10) epsilon(lambda) c, its derivative with respect to concentration on a
// dual-number scalar (the property later fitting needs), concentration units and bad input.
#include <gtest/gtest.h>

#include <cmath>

#include "core/errors.h"
#include "core/units.h"
#include "database.h"
#include "media/medium.h"
#include "render/path_tracer.h"
#include "support/test_scenes.h"

namespace fluorosim {
namespace {

// Minimal forward-mode dual number: value and derivative with respect to one parameter.
struct Dual {
    double v = 0, d = 0;
    Dual() = default;
    explicit Dual(double value, double derivative = 0) : v(value), d(derivative) {}
    Dual operator+(const Dual& o) const { return Dual(v + o.v, d + o.d); }
    Dual operator*(double s) const { return Dual(v * s, d * s); }
};

const spectra::Database& db() {
    static const spectra::Database instance;
    return instance;
}

TEST(Fluorophore, AbsorptionIsLn10TimesExtinctionTimesConcentration) {
    const Fluorophore af488 = db().fluorophore("AF488");
    EXPECT_EQ(af488.extinctionPeak(), 73000.0);
    EXPECT_EQ(af488.quantumYield(), 0.92);
    // At the excitation peak (499 nm), 10 uM: ln(10) * 73000 /M/cm * 1e-5 M = 1.6809 /cm = 0.16809 /mm.
    EXPECT_NEAR(dyeAbsorption(af488, 499.0, 1e-5), std::log(10.0) * 73000 * 1e-5 / 10, 1e-12);
    EXPECT_NEAR(af488.molarExtinction(499.0), 73000.0, 1e-9);
    EXPECT_NEAR(af488.emission().integral(), 1.0, 1e-12);
}

TEST(Fluorophore, CoefficientsDifferentiateOnAScalarType) {
    // Two dyes in water; derivative of sigma_a with respect to the first concentration.
    const std::vector<DyeComponent> dyes = {{db().fluorophore("AF488"), 2e-6}, {db().fluorophore("AF568"), 5e-6}};
    const Spectrum water = Spectrum::tabulated(db().solventAbsorption("water"));
    const std::vector<Dual> c = {Dual(2e-6, 1.0), Dual(5e-6, 0.0)};
    for (double lambda : {450.0, 499.0, 578.0, 650.0}) {
        const Dual s = absorptionCoefficient<Dual>(water, dyes, c, lambda);
        const std::vector<double> plain = {2e-6, 5e-6};
        EXPECT_DOUBLE_EQ(s.v, absorptionCoefficient<double>(water, dyes, plain, lambda));
        const double expected = std::log(10.0) * dyes[0].dye.molarExtinction(lambda) / 10;
        EXPECT_NEAR(s.d, expected, 1e-14 * expected) << lambda;
    }
}

TEST(Fluorophore, DyeSolutionFollowsBeerLambert) {
    // Transmittance through d mm of 10 uM AF488 at 499 nm is 10^(-epsilon c d[cm]).
    Scene scene;
    testing::addEnclosure(scene, 20, 1.0);
    scene.media.emplace_back("af488", Spectrum::constant(0), Spectrum::constant(0), 0.0, 1.0,
                             std::vector<DyeComponent>{{db().fluorophore("AF488"), 1e-5}});
    testing::addInterfaceSphere(scene, Vec3(0, 0, 0), 2.0, 0, kNone);
    scene.finalize();
    const PathTracer tracer(scene);
    SampledWavelengths wl = SampledWavelengths::atLine(499.0, 1.0);
    Rng exactRng;  // unused: homogeneous transmittance is exact
    const SampledSpectrum T = tracer.transmittance(Vec3(-5, 0, 0), Vec3(5, 0, 0), kNone, wl, exactRng);
    EXPECT_NEAR(T[0], std::pow(10.0, -73000 * 1e-5 * 0.4), 1e-9);  // 4 mm = 0.4 cm
}

TEST(Fluorophore, ConcentrationUnits) {
    EXPECT_DOUBLE_EQ(parseQuantity("10 uM", Dimension::MolarConcentration, "c"), 1e-5);
    EXPECT_DOUBLE_EQ(parseQuantity("1 mM", Dimension::MolarConcentration, "c"), 1e-3);
    EXPECT_DOUBLE_EQ(parseQuantity("5 nM", Dimension::MolarConcentration, "c"), 5e-9);
    EXPECT_DOUBLE_EQ(parseQuantity("2 µM", Dimension::MolarConcentration, "c"), 2e-6);
    EXPECT_DOUBLE_EQ(parseQuantity("0.1 g/L", Dimension::MassConcentration, "c"), 0.1);
    EXPECT_DOUBLE_EQ(parseQuantity("643.4 g/mol", Dimension::MolarMass, "m"), 643.4);
    EXPECT_THROW(parseQuantity("10 mm", Dimension::MolarConcentration, "c"), ConfigError);
}

TEST(Fluorophore, BadInput) {
    EXPECT_THROW(db().fluorophore("alexa_fluor_350"), ConfigError);                 // no sourced extinction or QY
    EXPECT_NO_THROW(db().fluorophore("alexa_fluor_350", 19000.0, 0.5));             // given explicitly
    EXPECT_THROW(db().fluorophore("AF488", std::nullopt, 1.5), ConfigError);         // QY outside [0, 1]
    EXPECT_THROW(db().fluorophore("AF488", -5.0, std::nullopt), ConfigError);        // negative extinction
    try {
        db().fluorophore("AF489");
        FAIL();
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("alexa_fluor_488"), std::string::npos) << e.what();
    }
    EXPECT_THROW(Medium("m", Spectrum::constant(0), Spectrum::constant(0), 0, 1,
                                   std::vector<DyeComponent>{{db().fluorophore("AF488"), -1e-6}}),
                 ConfigError);
}

}  // namespace
}  // namespace fluorosim
