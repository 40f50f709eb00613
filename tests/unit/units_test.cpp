// parseQuantity / unitScale: quantities with explicit units into internal units (mm, 1/mm, nm).
#include <gtest/gtest.h>

#include <optional>
#include <string>
#include <string_view>

#include "core/errors.h"
#include "core/units.h"

namespace fluorosim {
namespace {

// Expects ConfigError whose message names both `what` and the offending text.
void expectRejected(std::string_view text, Dimension dim, std::optional<std::string_view> bareUnit = std::nullopt) {
    SCOPED_TRACE("text \"" + std::string(text) + "\"");
    try {
        const double v = parseQuantity(text, dim, "--the-option", bareUnit);
        ADD_FAILURE() << "accepted, returned " << v;
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("--the-option"), std::string::npos) << msg;
        EXPECT_NE(msg.find(std::string(text)), std::string::npos) << msg;
    }
}

TEST(Units, LengthsInMillimetres) {
    EXPECT_DOUBLE_EQ(parseQuantity("5 mm", Dimension::Length, "x"), 5.0);
    EXPECT_DOUBLE_EQ(parseQuantity("0.2mm", Dimension::Length, "x"), 0.2);
    EXPECT_DOUBLE_EQ(parseQuantity("2 cm", Dimension::Length, "x"), 20.0);
    EXPECT_DOUBLE_EQ(parseQuantity("1.5 m", Dimension::Length, "x"), 1500.0);
    EXPECT_DOUBLE_EQ(parseQuantity("1.5um", Dimension::Length, "x"), 1.5e-3);
    EXPECT_DOUBLE_EQ(parseQuantity("1 µm", Dimension::Length, "x"), 1e-3);
    EXPECT_DOUBLE_EQ(parseQuantity("3 micron", Dimension::Length, "x"), 3e-3);
    // nm is a length too, so "5 nm" is a valid (tiny) Length.
    EXPECT_DOUBLE_EQ(parseQuantity("5 nm", Dimension::Length, "x"), 5e-6);
    EXPECT_DOUBLE_EQ(parseQuantity("  7 mm  ", Dimension::Length, "x"), 7.0);
    EXPECT_DOUBLE_EQ(parseQuantity("+7 mm", Dimension::Length, "x"), 7.0);
    EXPECT_DOUBLE_EQ(parseQuantity("1e-3 m", Dimension::Length, "x"), 1.0);
}

TEST(Units, InverseLengthsInPerMillimetre) {
    EXPECT_DOUBLE_EQ(parseQuantity("90 /cm", Dimension::InverseLength, "x"), 9.0);
    EXPECT_DOUBLE_EQ(parseQuantity("9/mm", Dimension::InverseLength, "x"), 9.0);
    EXPECT_DOUBLE_EQ(parseQuantity("90 cm^-1", Dimension::InverseLength, "x"), 9.0);
    EXPECT_DOUBLE_EQ(parseQuantity("0.5 1/mm", Dimension::InverseLength, "x"), 0.5);
    EXPECT_DOUBLE_EQ(parseQuantity("20 /m", Dimension::InverseLength, "x"), 0.02);
    EXPECT_DOUBLE_EQ(parseQuantity("2 /um", Dimension::InverseLength, "x"), 2000.0);
    EXPECT_DOUBLE_EQ(parseQuantity("0.9/mm", Dimension::InverseLength, "x"), 0.9);
}

TEST(Units, WavelengthsInNanometres) {
    EXPECT_DOUBLE_EQ(parseQuantity("550 nm", Dimension::Wavelength, "x"), 550.0);
    EXPECT_DOUBLE_EQ(parseQuantity("550nm", Dimension::Wavelength, "x"), 550.0);
    EXPECT_DOUBLE_EQ(parseQuantity("1.5um", Dimension::Wavelength, "x"), 1500.0);
    EXPECT_DOUBLE_EQ(parseQuantity("1 µm", Dimension::Wavelength, "x"), 1000.0);
}

TEST(Units, MicroMayBeWrittenWithTheGreekMu) {
    // U+03BC (Greek mu), which keyboards and papers give as often as U+00B5 (micro sign).
    EXPECT_DOUBLE_EQ(parseQuantity("5 \xCE\xBCm", Dimension::Length, "x"), 5e-3);
    EXPECT_DOUBLE_EQ(parseQuantity("5 \xC2\xB5m", Dimension::Length, "x"), 5e-3);
    EXPECT_DOUBLE_EQ(parseQuantity("10 \xCE\xBCM", Dimension::MolarConcentration, "x"), 1e-5);
    EXPECT_DOUBLE_EQ(parseQuantity("0.5 \xCE\xBCm", Dimension::Wavelength, "x"), 500.0);
}

TEST(Units, TimesInSecondsAndPowersInMilliwatts) {
    EXPECT_DOUBLE_EQ(parseQuantity("50 ms", Dimension::Time, "x"), 0.05);
    EXPECT_DOUBLE_EQ(parseQuantity("2 s", Dimension::Time, "x"), 2.0);
    EXPECT_DOUBLE_EQ(parseQuantity("100 us", Dimension::Time, "x"), 1e-4);
    EXPECT_DOUBLE_EQ(parseQuantity("1 min", Dimension::Time, "x"), 60.0);
    EXPECT_DOUBLE_EQ(parseQuantity("3 mW", Dimension::Power, "x"), 3.0);
    EXPECT_DOUBLE_EQ(parseQuantity("0.5 W", Dimension::Power, "x"), 500.0);
    EXPECT_DOUBLE_EQ(parseQuantity("20 \xCE\xBCW", Dimension::Power, "x"), 0.02);
    EXPECT_DOUBLE_EQ(parseQuantity("0.05", Dimension::Time, "exposure_s", "s"), 0.05);
    expectRejected("50 mm", Dimension::Time);
    expectRejected("3 mJ", Dimension::Power);
}

TEST(Units, AnUnknownUnitListsTheAcceptedOnes) {
    try {
        parseQuantity("5 uu", Dimension::Length, "x");
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("units: m, cm, mm, um, nm"), std::string::npos) << e.what();
    }
}

TEST(Units, BareNumbersUseTheBareUnit) {
    EXPECT_DOUBLE_EQ(parseQuantity("0.02", Dimension::Length, "--thickness", "cm"), 0.2);
    EXPECT_DOUBLE_EQ(parseQuantity("90", Dimension::InverseLength, "--mua", "/cm"), 9.0);
    EXPECT_DOUBLE_EQ(parseQuantity("9", Dimension::InverseLength, "--mus", "/cm"), 0.9);
    EXPECT_DOUBLE_EQ(parseQuantity("550", Dimension::Wavelength, "x", "nm"), 550.0);
    // An explicit unit wins over the bare unit.
    EXPECT_DOUBLE_EQ(parseQuantity("9/mm", Dimension::InverseLength, "--mua", "/cm"), 9.0);
    EXPECT_DOUBLE_EQ(parseQuantity("0.2mm", Dimension::Length, "--thickness", "cm"), 0.2);
    // MCML-style bare numbers and explicit units give bit-identical internal values.
    EXPECT_EQ(parseQuantity("90", Dimension::InverseLength, "--mua", "/cm"),
              parseQuantity("9/mm", Dimension::InverseLength, "--mua", "/cm"));
    EXPECT_EQ(parseQuantity("0.02", Dimension::Length, "--thickness", "cm"),
              parseQuantity("0.2mm", Dimension::Length, "--thickness", "cm"));
}

TEST(Units, DimensionlessNumbersNeedNoUnit) {
    EXPECT_DOUBLE_EQ(parseQuantity("1.33", Dimension::Dimensionless, "--n"), 1.33);
    EXPECT_DOUBLE_EQ(parseQuantity(" 2 ", Dimension::Dimensionless, "--n"), 2.0);
    expectRejected("1.33 mm", Dimension::Dimensionless);
}

TEST(Units, BareNumberWithoutBareUnitIsAnError) {
    expectRejected("5", Dimension::Length);
    expectRejected("90", Dimension::InverseLength);
    expectRejected("550", Dimension::Wavelength);
    try {
        parseQuantity("5", Dimension::Length, "thickness");
        FAIL() << "accepted a bare number";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("missing unit"), std::string::npos) << e.what();
    }
}

TEST(Units, WrongDimensionIsAnError) {
    expectRejected("5 nm", Dimension::InverseLength);
    expectRejected("5 mm", Dimension::InverseLength);
    expectRejected("5 mm", Dimension::Wavelength);
    expectRejected("5 cm", Dimension::Wavelength);
    expectRejected("90 /cm", Dimension::Length);
    expectRejected("90 /cm", Dimension::Wavelength);
    expectRejected("5 furlongs", Dimension::Length);
    expectRejected("5 /furlong", Dimension::InverseLength);
    expectRejected("5 mm extra", Dimension::Length);
}

TEST(Units, MalformedNumbersAreErrors) {
    expectRejected("abc", Dimension::Length);
    expectRejected("", Dimension::Length);
    expectRejected("mm", Dimension::Length);
    expectRejected("nan mm", Dimension::Length);
    expectRejected("NaN /mm", Dimension::InverseLength);
    expectRejected("inf mm", Dimension::Length);
    expectRejected("-inf nm", Dimension::Wavelength);
    expectRejected("1e999 mm", Dimension::Length);
    expectRejected("1e999", Dimension::Length, "cm");
    expectRejected("nan", Dimension::InverseLength, "/cm");
    expectRejected("nan", Dimension::Dimensionless);
    expectRejected("--5 mm", Dimension::Length);
}

TEST(Units, ErrorMessageNamesExpectedDimension) {
    try {
        parseQuantity("5 nm", Dimension::InverseLength, "sigma_a");
        FAIL() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find("sigma_a"), std::string::npos) << msg;
        EXPECT_NE(msg.find("5 nm"), std::string::npos) << msg;
        EXPECT_NE(msg.find(dimensionName(Dimension::InverseLength)), std::string::npos) << msg;
    }
}

TEST(Units, BareUnitThatDoesNotFitTheDimensionThrows) {
    // A programming error, but it must not dereference an empty optional (undefined behaviour).
    EXPECT_ANY_THROW(parseQuantity("5", Dimension::Length, "x", "/cm"));
    EXPECT_ANY_THROW(parseQuantity("5", Dimension::InverseLength, "x", "cm"));
}

TEST(Units, UnitScale) {
    EXPECT_EQ(unitScale("cm", Dimension::Length), std::optional<double>(10.0));
    EXPECT_EQ(unitScale("mm", Dimension::Length), std::optional<double>(1.0));
    EXPECT_EQ(unitScale("nm", Dimension::Wavelength), std::optional<double>(1.0));
    EXPECT_EQ(unitScale("um", Dimension::Wavelength), std::optional<double>(1000.0));
    EXPECT_EQ(unitScale("/cm", Dimension::InverseLength), std::optional<double>(0.1));
    EXPECT_EQ(unitScale("cm^-1", Dimension::InverseLength), std::optional<double>(0.1));
    EXPECT_EQ(unitScale("1/mm", Dimension::InverseLength), std::optional<double>(1.0));
    EXPECT_FALSE(unitScale("mm", Dimension::Wavelength).has_value());
    EXPECT_FALSE(unitScale("cm", Dimension::InverseLength).has_value());
    EXPECT_FALSE(unitScale("/nm/", Dimension::InverseLength).has_value());
    EXPECT_FALSE(unitScale("", Dimension::Length).has_value());
    EXPECT_FALSE(unitScale("parsec", Dimension::Length).has_value());
}

TEST(Units, ProductBeyondDoubleIsRejected) {
    // 1e308 is finite in metres but not in millimetres; it used to come back as inf.
    expectRejected("1e308 m", Dimension::Length);
    expectRejected("1e306 /nm", Dimension::InverseLength);
    expectRejected("1e400 mm", Dimension::Length);
    expectRejected("1e308", Dimension::Length, "m");
    EXPECT_DOUBLE_EQ(parseQuantity("1e300 m", Dimension::Length, "x"), 1e303);
}

TEST(Units, HugeTextIsEchoedAsAnExcerpt) {
    const std::string unit(50 << 20, 'x');
    try {
        parseQuantity("1 " + unit, Dimension::Length, "--the-option");
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_LT(msg.size(), 400u);
        EXPECT_NE(msg.find("--the-option"), std::string::npos) << msg;
        EXPECT_NE(msg.find("(52428802 characters)"), std::string::npos) << msg;
    }
}

}  // namespace
}  // namespace fluorosim
