// Light sheet and widefield illumination (optics/light_sheet.h): Gaussian-beam closed forms against
// hand values, the exact normalisation (irradiance integrated over planes normal to the beam equals
// the power), the 1/e² width of the profile, NA <-> waist, and messages for bad options.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/math.h"
#include "optics/light_sheet.h"

namespace fluorosim::optics {
namespace {

// Hand values for λ = 488 nm, n = 1.33, w0 = 2 µm:
// zR = π (0.002 mm)² 1.33 / 488e-6 mm = 0.0342485 mm.
constexpr double kLambda = 488, kIndex = 1.33, kWaist = 0.002, kRayleigh = 0.034248510076019874;
constexpr double kPowerMw = 10, kHeight = 0.1;

// A sheet tilted off every axis and off the origin, so the tests exercise the frame, not just x, y, z.
LightSheetOptions tiltedOptions(SheetMode mode, SheetSides sides) {
    LightSheetOptions o;
    o.wavelengthNm = kLambda;
    o.powerMw = kPowerMw;
    o.propagation = {1, 1, 0};
    o.normal = {-1, 1, 1};
    o.centreMm = {0.3, -0.2, 1.5};
    o.waistMm = kWaist;
    o.heightMm = kHeight;
    o.refractiveIndex = kIndex;
    o.mode = mode;
    o.sides = sides;
    return o;
}

// The frame as documented (h = n × u), built here independently of the class.
struct Axes {
    Vec3 u, h, n, c;
};
Axes axesOf(const LightSheetOptions& o) {
    const Vec3 u = normalize(o.propagation), n = normalize(o.normal);
    return {u, cross(n, u), n, o.centreMm};
}

// ∫∫ E dy dz over the plane x = const, normal to the beam. Along z (and y for smooth profiles) the
// trapezoid rule with step h = w/4 over ±8w: by Poisson summation its relative error for a
// Gaussian of 1/e² half-width w is about 2 exp(−π² w²/(2h²)) = 2 e^{−8π²} ≈ 1e-34, and the cut
// tails are erfc(8√2) ≈ 1e-57 of the integral; the DSLM height profile is a top-hat convolved with
// the same Gaussian, so its transform decays at least as fast. The top-hat height is integrated by
// the midpoint rule over [−H, H] with ±H/2 on cell boundaries, exact for a piecewise constant.
// What remains is rounding, ~1e-15 per sample sum, so the tests allow 1e-12 relative.
double planeIntegral(const std::function<double(const Vec3&)>& e, const LightSheet& sheet, double x, double lambdaNm) {
    const Axes a = axesOf(sheet.options());
    const double w = sheet.waistAt(x, lambdaNm);
    const double hz = w / 4;
    std::vector<std::pair<double, double>> ys;  // (position, weight)
    const double height = sheet.options().heightMm;
    if (sheet.options().mode == SheetMode::Scanned) {
        const double span = height / 2 + 8 * w;
        const int n = static_cast<int>(std::ceil(span / hz));
        for (int i = -n; i <= n; ++i) ys.emplace_back(i * hz, hz);
    } else if (sheet.options().heightProfile == HeightProfile::Gaussian) {
        const double wy = height / 2, hy = wy / 4;
        for (int i = -32; i <= 32; ++i) ys.emplace_back(i * hy, hy);
    } else {
        const int cells = 400;
        const double dy = 2 * height / cells;
        for (int i = 0; i < cells; ++i) ys.emplace_back(-height + (i + 0.5) * dy, dy);
    }
    double sum = 0;
    for (const auto& [y, wy] : ys)
        for (int k = -32; k <= 32; ++k) sum += wy * hz * e(a.c + a.u * x + a.h * y + a.n * (k * hz));
    return sum;
}

TEST(LightSheet, RayleighRangeAndWaistMatchHandValues) {
    const LightSheet sheet(tiltedOptions(SheetMode::Static, SheetSides::Single));
    EXPECT_NEAR(sheet.rayleighRangeMm(kLambda), kRayleigh, 1e-15);
    EXPECT_NEAR(rayleighRangeMm(kWaist, kLambda, kIndex), kRayleigh, 1e-15);
    EXPECT_DOUBLE_EQ(sheet.waistAt(0, kLambda), kWaist);
    // w(zR) = √2 w0 and w(3 zR) = √10 w0, on both sides of the focus.
    EXPECT_NEAR(sheet.waistAt(kRayleigh, kLambda), std::sqrt(2.0) * kWaist, 1e-15);
    EXPECT_NEAR(sheet.waistAt(-kRayleigh, kLambda), std::sqrt(2.0) * kWaist, 1e-15);
    EXPECT_NEAR(sheet.waistAt(3 * kRayleigh, kLambda), std::sqrt(10.0) * kWaist, 1e-15);
    EXPECT_NEAR(beamRadiusMm(kWaist, 3 * kRayleigh, kLambda, kIndex), std::sqrt(10.0) * kWaist, 1e-15);
    // A given waist holds at every wavelength, so zR ∝ 1/λ.
    EXPECT_NEAR(sheet.rayleighRangeMm(2 * kLambda), kRayleigh / 2, 1e-15);
}

TEST(LightSheet, NaAndWaistRoundTrip) {
    // Hand value: θ = asin(0.1/1.33) = 0.075258, w0 = 488e-6 mm / (π · 1.33 · θ) = 1.55189 µm.
    EXPECT_NEAR(waistFromNa(0.1, kLambda, kIndex), 0.0015518863169944382, 1e-15);
    for (double na : {0.01, 0.05, 0.1, 0.3, 0.8, 1.2}) {
        const double w0 = waistFromNa(na, kLambda, kIndex);
        EXPECT_NEAR(naFromWaist(w0, kLambda, kIndex), na, 1e-13 * na) << "NA " << na;
    }
    for (double w0 : {0.0005, 0.001, 0.002, 0.01}) EXPECT_NEAR(waistFromNa(naFromWaist(w0, kLambda, kIndex), kLambda, kIndex), w0, 1e-13 * w0);

    // A sheet given by its NA: w0 ∝ λ, so zR = λ/(π n θ²) ∝ λ as well.
    LightSheetOptions o = tiltedOptions(SheetMode::Static, SheetSides::Single);
    o.waistMm = std::nullopt;
    o.illuminationNa = 0.1;
    const LightSheet sheet(o);
    EXPECT_NEAR(sheet.waistMm(kLambda), 0.0015518863169944382, 1e-15);
    EXPECT_NEAR(sheet.waistMm(2 * kLambda), 2 * 0.0015518863169944382, 1e-15);
    EXPECT_NEAR(sheet.rayleighRangeMm(2 * kLambda), 2 * sheet.rayleighRangeMm(kLambda), 1e-15);
}

TEST(LightSheet, PeakIrradianceHandValue) {
    // Static, single: P sqrt(2/π) / (w0 H) = 0.01 W · 0.797885 / (0.002 mm · 0.1 mm) = 39.8942 W/mm².
    const LightSheet sheet(tiltedOptions(SheetMode::Static, SheetSides::Single));
    EXPECT_NEAR(sheet.irradiance(sheet.centre(), 0, kLambda), 39.89422804014327, 1e-12);
    // Dual: each side carries half, and the two add up to the single-sided value.
    const LightSheet dual(tiltedOptions(SheetMode::Static, SheetSides::Dual));
    EXPECT_NEAR(dual.irradiance(dual.centre(), 1, kLambda), 39.89422804014327 / 2, 1e-12);
    EXPECT_NEAR(dual.totalIrradiance(dual.centre(), kLambda), 39.89422804014327, 1e-12);
    // The scanned sheet at the middle of its scan range: the erf bracket is 2 − 2 erfc(√2 H/(2 w0)) = 2.
    const LightSheet scanned(tiltedOptions(SheetMode::Scanned, SheetSides::Single));
    EXPECT_NEAR(scanned.irradiance(scanned.centre(), 0, kLambda), 39.89422804014327, 1e-12);
}

TEST(LightSheet, IrradianceIntegratesToPowerOverPlanesNormalToTheBeam) {
    const double powerW = kPowerMw * 1e-3;
    for (SheetMode mode : {SheetMode::Static, SheetMode::Scanned})
        for (SheetSides sides : {SheetSides::Single, SheetSides::Dual}) {
            const LightSheet sheet(tiltedOptions(mode, sides));
            for (double x : {0.0, kRayleigh, 3 * kRayleigh, -3 * kRayleigh}) {
                SCOPED_TRACE(std::string(sheetModeName(mode)) + ", " + sheetSidesName(sides) + ", x = " + std::to_string(x));
                double total = 0;
                for (int side = 0; side < sheet.sides(); ++side) {
                    const double sidePower = planeIntegral([&](const Vec3& p) { return sheet.irradiance(p, side, kLambda); },
                                                           sheet, x, kLambda);
                    EXPECT_NEAR(sidePower, powerW / sheet.sides(), 1e-12 * powerW);
                    total += sidePower;
                }
                EXPECT_NEAR(total, powerW, 1e-12 * powerW);
            }
        }
}

TEST(LightSheet, GaussianHeightProfileIntegratesToPower) {
    LightSheetOptions o = tiltedOptions(SheetMode::Static, SheetSides::Single);
    o.heightProfile = HeightProfile::Gaussian;
    const LightSheet sheet(o);
    for (double x : {0.0, kRayleigh, 3 * kRayleigh})
        EXPECT_NEAR(planeIntegral([&](const Vec3& p) { return sheet.irradiance(p, 0, kLambda); }, sheet, x, kLambda), 0.01,
                    1e-14);
    // H is the 1/e² full height: at y = H/2 the value is e^-2 of the centre.
    const Axes a = axesOf(o);
    EXPECT_NEAR(sheet.irradiance(a.c + a.h * (kHeight / 2), 0, kLambda) / sheet.irradiance(a.c, 0, kLambda), std::exp(-2.0),
                1e-14);
}

// Bisection for the z > 0 at which the profile across the sheet falls to e^-2 of its peak.
double measuredHalfWidth(const LightSheet& sheet, double x) {
    const Axes a = axesOf(sheet.options());
    const auto e = [&](double z) { return sheet.totalIrradiance(a.c + a.u * x + a.n * z, kLambda); };
    const double target = std::exp(-2.0) * e(0);
    double lo = 0, hi = 10 * sheet.waistAt(x, kLambda);
    for (int i = 0; i < 200 && hi - lo > 1e-16; ++i) {
        const double mid = 0.5 * (lo + hi);
        (e(mid) > target ? lo : hi) = mid;
    }
    return 0.5 * (lo + hi);
}

TEST(LightSheet, ProfileAcrossTheSheetFallsToEMinus2AtTheWaist) {
    for (SheetMode mode : {SheetMode::Static, SheetMode::Scanned})
        for (SheetSides sides : {SheetSides::Single, SheetSides::Dual}) {
            const LightSheet sheet(tiltedOptions(mode, sides));
            for (double x : {0.0, kRayleigh, 3 * kRayleigh}) {
                SCOPED_TRACE(std::string(sheetModeName(mode)) + ", " + sheetSidesName(sides) + ", x = " + std::to_string(x));
                EXPECT_NEAR(measuredHalfWidth(sheet, x), sheet.waistAt(x, kLambda), 1e-12);
            }
        }
}

TEST(LightSheet, ScannedSheetHasSoftEdgesAtTheScanRange) {
    const LightSheet scanned(tiltedOptions(SheetMode::Scanned, SheetSides::Single));
    const LightSheet stat(tiltedOptions(SheetMode::Static, SheetSides::Single));
    const Axes a = axesOf(scanned.options());
    const Vec3 inside = a.c + a.h * (0.3 * kHeight) + a.n * 0.001;
    EXPECT_NEAR(scanned.irradiance(inside, 0, kLambda), stat.irradiance(inside, 0, kLambda), 1e-12);
    // At the end of the scan range half of the beam's time-averaged footprint remains (erf(0) = 0).
    const Vec3 edge = a.c + a.h * (kHeight / 2);
    EXPECT_NEAR(scanned.irradiance(edge, 0, kLambda), 0.5 * stat.irradiance(a.c, 0, kLambda), 1e-13 * 39.9);
    // Beyond it the scanned sheet falls off like the beam's Gaussian; the static top-hat is 0.
    const Vec3 beyond = a.c + a.h * (kHeight / 2 + kWaist);
    EXPECT_GT(scanned.irradiance(beyond, 0, kLambda), 0.0);
    EXPECT_LT(scanned.irradiance(beyond, 0, kLambda), 0.03 * stat.irradiance(a.c, 0, kLambda));
    EXPECT_EQ(stat.irradiance(beyond, 0, kLambda), 0.0);
    // Far out the erfc form does not cancel to zero or go negative.
    const double far = scanned.irradiance(a.c + a.h * (kHeight / 2 + 10 * kWaist), 0, kLambda);
    EXPECT_GT(far, 0.0);
    EXPECT_LT(far, 1e-80);
}

TEST(LightSheet, DirectionsAndFrame) {
    LightSheet sheet(tiltedOptions(SheetMode::Static, SheetSides::Dual));
    const Axes a = axesOf(sheet.options());
    ASSERT_EQ(sheet.sides(), 2);
    const Vec3 d0 = sheet.direction(0), d1 = sheet.direction(1);
    EXPECT_NEAR(length(d0 - a.u), 0, 1e-15);
    EXPECT_NEAR(length(d1 + a.u), 0, 1e-15);
    EXPECT_NEAR(std::abs(dot(sheet.heightAxis(), a.h)), 1, 1e-15);
    EXPECT_NEAR(dot(sheet.heightAxis(), sheet.normalAxis()), 0, 1e-15);
    EXPECT_NEAR(length(sheet.towardSource(a.c, 1).d - a.u), 0, 1e-15);  // side 1 comes from +u
    EXPECT_NEAR(sheet.local(a.c).z, 0, 1e-15);
    EXPECT_NEAR(sheet.totalIrradiance(a.c, kLambda), 39.89422804014327, 1e-12);

    const LightSheet single(tiltedOptions(SheetMode::Static, SheetSides::Single));
    EXPECT_EQ(single.sides(), 1);
    EXPECT_THROW(single.direction(1), ConfigError);
}

TEST(LightSheet, SpectrumIsNormalisedToUnitWeight) {
    LightSheetOptions o = tiltedOptions(SheetMode::Static, SheetSides::Single);
    o.wavelengthNm = std::nullopt;
    o.spectrum = Spectrum::lines({{488, 2}, {561, 6}});
    const LightSheet lines(o);
    ASSERT_EQ(lines.spectrum().spectralLines().size(), 2u);
    EXPECT_DOUBLE_EQ(lines.spectrum().spectralLines()[0].power, 0.25);
    EXPECT_DOUBLE_EQ(lines.spectrum().spectralLines()[1].power, 0.75);

    o.spectrum = Spectrum::tabulated(TabulatedSpectrum({480, 490, 500}, {0, 3, 0}), 7.0);
    const LightSheet band(o);
    EXPECT_NEAR(band.spectrum().integral(0, 1000), 1.0, 1e-15);
    EXPECT_NEAR(band.spectrum()(490), 0.1, 1e-15);  // peak of a triangle of base 20 nm and area 1

    // A single laser line has weight 1, so irradiance() is directly W/mm².
    const LightSheet line(tiltedOptions(SheetMode::Static, SheetSides::Single));
    ASSERT_EQ(line.spectrum().spectralLines().size(), 1u);
    EXPECT_EQ(line.spectrum().spectralLines()[0].power, 1.0);
}

// Expects ConfigError from building the sheet whose message contains every one of `parts`.
template <class Model, class Options>
void expectRejected(const Options& o, const std::vector<std::string>& parts) {
    try {
        const Model model(o);
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        for (const std::string& part : parts) EXPECT_NE(msg.find(part), std::string::npos) << "missing \"" << part << "\" in: " << msg;
    }
}

TEST(LightSheet, BadOptionsNameFieldAndValue) {
    const auto with = [](const std::function<void(LightSheetOptions&)>& change) {
        LightSheetOptions o = tiltedOptions(SheetMode::Static, SheetSides::Single);
        change(o);
        return o;
    };
    expectRejected<LightSheet>(with([](auto& o) { o.powerMw = 0; }), {"powerMw", "0 mW"});
    expectRejected<LightSheet>(with([](auto& o) { o.powerMw = -3; }), {"powerMw", "-3"});
    expectRejected<LightSheet>(with([](auto& o) { o.propagation = {0, 0, 0}; }), {"propagation", "(0, 0, 0)"});
    expectRejected<LightSheet>(with([](auto& o) { o.normal = {1, 0, 0}; }), {"normal", "orthogonal", "(1, 0, 0)"});
    expectRejected<LightSheet>(with([](auto& o) { o.waistMm = -0.001; }), {"waistMm", "-0.001"});
    expectRejected<LightSheet>(with([](auto& o) { o.waistMm = 1e-9; }), {"waistMm", "1e-09", "far below the wavelength"});
    expectRejected<LightSheet>(with([](auto& o) { o.illuminationNa = 0.1; }), {"waistMm", "illuminationNa", "not both"});
    expectRejected<LightSheet>(with([](auto& o) { o.waistMm = std::nullopt; }), {"waistMm or illuminationNa"});
    expectRejected<LightSheet>(with([](auto& o) {
                                   o.waistMm = std::nullopt;
                                   o.illuminationNa = 1.5;
                               }),
                               {"illuminationNa", "1.5", "1.33"});
    expectRejected<LightSheet>(with([](auto& o) { o.heightMm = 0; }), {"heightMm", "0 mm"});
    expectRejected<LightSheet>(with([](auto& o) { o.refractiveIndex = 0.9; }), {"refractiveIndex", "0.9"});
    expectRejected<LightSheet>(with([](auto& o) { o.wavelengthNm = -488; }), {"wavelengthNm", "-488"});
    expectRejected<LightSheet>(with([](auto& o) { o.spectrum = Spectrum::lines({{561, 1}}); }), {"wavelengthNm", "spectrum", "not both"});
    expectRejected<LightSheet>(with([](auto& o) {
                                   o.wavelengthNm = std::nullopt;
                                   o.spectrum = Spectrum::constant(1);
                               }),
                               {"constant spectrum"});
    expectRejected<LightSheet>(with([](auto& o) {
                                   o.wavelengthNm = std::nullopt;
                                   o.spectrum = Spectrum::lines({{561, 0}});
                               }),
                               {"no power"});
    expectRejected<LightSheet>(with([](auto& o) {
                                   o.mode = SheetMode::Scanned;
                                   o.heightProfile = HeightProfile::Gaussian;
                               }),
                               {"heightProfile", "static sheet only"});
    // A bad side is a programming error, reported the same way.
    const LightSheet sheet(tiltedOptions(SheetMode::Static, SheetSides::Single));
    try {
        sheet.irradiance({0, 0, 0}, 2, kLambda);
        ADD_FAILURE() << "accepted side 2";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("got 2"), std::string::npos) << e.what();
    }
    EXPECT_THROW(waistFromNa(1.4, kLambda, kIndex), ConfigError);
    EXPECT_THROW(naFromWaist(0, kLambda, kIndex), ConfigError);
}

TEST(Widefield, UniformOverTheFieldAndIntegratesToPower) {
    WidefieldOptions o;
    o.powerMw = 2;
    o.axis = {0.2, -0.3, -1};
    o.centreMm = {0.1, 0.2, 0.3};
    o.fieldDiameterMm = 0.4;
    const WidefieldIllumination light(o);
    const Vec3 axis = normalize(o.axis);
    EXPECT_NEAR(length(light.direction(0) - axis), 0, 1e-15);
    // P / (π R²) = 0.002 W / (π 0.04 mm²) = 0.0159155 W/mm², the same at any depth along the axis.
    EXPECT_NEAR(light.irradiance(o.centreMm, 0, 488), 0.015915494309189534, 1e-15);
    EXPECT_NEAR(light.irradiance(o.centreMm + axis * 5.0, 0, 600), 0.015915494309189534, 1e-15);

    // Polar midpoint rule over [0, 2R] with R on a cell boundary: exact for a piecewise constant
    // times r (linear), so only rounding remains.
    const Frame f = Frame::fromNormal(axis);
    const double r0 = o.fieldDiameterMm / 2;
    const int nr = 64, nphi = 64;
    double sum = 0;
    for (int i = 0; i < nr; ++i)
        for (int j = 0; j < nphi; ++j) {
            const double r = (i + 0.5) * 2 * r0 / nr, phi = (j + 0.5) * 2 * kPi / nphi;
            const Vec3 p = o.centreMm + axis * 0.7 + f.s * (r * std::cos(phi)) + f.t * (r * std::sin(phi));
            sum += light.irradiance(p, 0, 488) * r * (2 * r0 / nr) * (2 * kPi / nphi);
        }
    EXPECT_NEAR(sum, 0.002, 1e-15);
}

TEST(Widefield, BadOptionsNameFieldAndValue) {
    WidefieldOptions o;
    o.fieldDiameterMm = -1;
    expectRejected<WidefieldIllumination>(o, {"fieldDiameterMm", "-1"});
    o = {};
    o.powerMw = 0;
    expectRejected<WidefieldIllumination>(o, {"widefield powerMw", "0 mW"});
    o = {};
    o.axis = {0, 0, 0};
    expectRejected<WidefieldIllumination>(o, {"axis", "(0, 0, 0)"});
}

}  // namespace
}  // namespace fluorosim::optics
