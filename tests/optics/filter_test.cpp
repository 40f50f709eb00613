// Filters (optics/filter.h): parametric band-pass and edge filters measured back from their
// tabulated curves (centre, FWHM, edge width, blocking), dichroic R + T = 1, filter-set paths,
// vendor curves from the spectral database, the emission-blocking warning and bad input messages.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "database.h"
#include "optics/filter.h"

namespace fluorosim::optics {
namespace {

const spectra::Database& db() {
    static const spectra::Database database(std::filesystem::path(FLUOROSIM_SOURCE_DIR) / "spectra" / "data");
    return database;
}

// A GFP-like cube: 470/40 excitation, 495 nm long-pass dichroic, Semrock 525/45 emission.
FilterSet gfpSet() {
    FilterSet set;
    set.name = "GFP";
    set.excitation = Filter::bandPass({.centreNm = 470, .fwhmNm = 40});
    set.dichroic = Filter::longPass({.edgeNm = 495});
    set.emission = Filter::fromDatabase(db(), "semrock_FF01-525-45");
    return set;
}

// First wavelength at which the curve, walked from `from` towards `to` on a 0.001 nm grid, reaches `level`.
double firstCrossing(const Filter& f, double from, double to, double level) {
    const double step = to > from ? 1e-3 : -1e-3;
    double prev = f(from);
    for (double l = from + step; (step > 0) == (l < to); l += step) {
        const double v = f(l);
        if ((prev - level) * (v - level) <= 0) return l - step * (v - level) / (v - prev);
        prev = v;
    }
    return NAN;
}

TEST(Filter, MeasurePassBandOfAHandTrapezoid) {
    const PassBand band = measurePassBand(TabulatedSpectrum({500, 510, 540, 550}, {0, 0.8, 0.8, 0}));
    EXPECT_DOUBLE_EQ(band.lowNm, 505);
    EXPECT_DOUBLE_EQ(band.highNm, 545);
    EXPECT_DOUBLE_EQ(band.centreNm(), 525);
    EXPECT_DOUBLE_EQ(band.fwhmNm(), 40);
    EXPECT_DOUBLE_EQ(band.peakTransmission, 0.8);
}

TEST(Filter, BandPassCentreAndFwhmRecoveredFromTheCurve) {
    struct Case {
        double centre, fwhm, edge, tolerance;
    };
    // Edges on grid points or half-way between them are exact by the symmetry of the logistic; an
    // edge elsewhere sees the 1 nm linear interpolation (measured below 0.02 nm for a 3 nm edge).
    for (const Case& c : std::vector<Case>{{525, 45, 3, 1e-4}, {561, 30, 2, 1e-4}, {600.3, 37.4, 3, 0.02}, {700, 75, 8, 0.02}}) {
        SCOPED_TRACE("band-pass " + std::to_string(c.centre) + "/" + std::to_string(c.fwhm));
        const Filter f = Filter::bandPass({.centreNm = c.centre, .fwhmNm = c.fwhm, .edgeWidthNm = c.edge});
        EXPECT_EQ(f.curve().minLambda(), 300);
        EXPECT_EQ(f.curve().maxLambda(), 900);
        EXPECT_EQ(f.curve().wavelengths().size(), 601u);
        const PassBand band = measurePassBand(f.curve());
        EXPECT_NEAR(band.centreNm(), c.centre, c.tolerance);
        EXPECT_NEAR(band.fwhmNm(), c.fwhm, 2 * c.tolerance);
        EXPECT_NEAR(band.peakTransmission, 0.95, 1e-4);
    }
}

TEST(Filter, EdgeWidthIsTheTenToNinetyPercentRise) {
    // On a 0.01 nm grid, so that the measured rise is the model's, not the interpolation's.
    const Filter f = Filter::bandPass({.centreNm = 525, .fwhmNm = 45, .peakTransmission = 0.9, .edgeWidthNm = 4},
                                      {.minNm = 450, .maxNm = 600, .stepNm = 0.01});
    const double rise = firstCrossing(f, 480, 525, 0.9 * 0.9) - firstCrossing(f, 480, 525, 0.1 * 0.9);
    EXPECT_NEAR(rise, 4.0, 1e-3);
    const double fall = firstCrossing(f, 570, 525, 0.1 * 0.9) - firstCrossing(f, 570, 525, 0.9 * 0.9);
    EXPECT_NEAR(fall, 4.0, 1e-3);
}

TEST(Filter, OutOfBandTransmissionIsTheOdBlockingLevel) {
    for (double od : {2.0, 4.0, 6.0, 8.0}) {
        const Filter f = Filter::bandPass({.centreNm = 525, .fwhmNm = 45, .blockingOd = od});
        // Ten edge widths away from the band the logistic is below e^-40, so T is 10^-OD.
        double lowest = 1;
        for (double l = 300; l <= 900; l += 1)
            if (std::abs(l - 525) > 22.5 + 30) lowest = std::min(lowest, f(l));
        EXPECT_NEAR(-std::log10(lowest), od, 1e-9) << "OD " << od;
        EXPECT_NEAR(-std::log10(f(400)), od, 1e-9);
        EXPECT_NEAR(-std::log10(f(800)), od, 1e-9);
    }
}

TEST(Filter, DichroicReflectionPlusTransmissionIsOne) {
    const Filter lp = Filter::longPass({.edgeNm = 495, .edgeWidthNm = 5, .peakTransmission = 0.96, .blockingOd = 2});
    const Filter sp = Filter::shortPass({.edgeNm = 495, .edgeWidthNm = 5, .peakTransmission = 0.96, .blockingOd = 2});
    for (double l = 300; l <= 900; l += 0.7) {
        EXPECT_DOUBLE_EQ(lp.reflection(l) + lp.transmission(l), 1.0);
        EXPECT_DOUBLE_EQ(sp.reflection(l) + sp.transmission(l), 1.0);
    }
    // At the edge T = (Tp + Tb)/2; well past it the pass band and the blocking level.
    EXPECT_NEAR(lp(495), (0.96 + 0.01) / 2, 1e-12);
    EXPECT_NEAR(sp(495), (0.96 + 0.01) / 2, 1e-12);
    EXPECT_NEAR(lp(560), 0.96, 1e-9);
    EXPECT_NEAR(lp(430), 0.01, 1e-9);
    EXPECT_NEAR(lp.reflection(430), 0.99, 1e-9);
    EXPECT_NEAR(sp(430), 0.96, 1e-9);
    EXPECT_NEAR(sp.reflection(560), 0.99, 1e-9);
    // Beyond its table a filter blocks, so a dichroic reflects.
    EXPECT_EQ(lp(950), 0.0);
    EXPECT_EQ(lp.reflection(950), 1.0);
}

TEST(Filter, FilterSetPaths) {
    const FilterSet set = gfpSet();
    for (double l : {450.0, 470.0, 495.0, 510.0, 525.0, 600.0}) {
        EXPECT_DOUBLE_EQ(set.emissionPath(l), set.dichroic->transmission(l) * set.emission(l));
        EXPECT_DOUBLE_EQ(set.excitationPath(l), set.excitation(l) * (1 - set.dichroic->transmission(l)));
    }
    // The cube sends 470 nm to the sample and 525 nm to the camera, and not the other way round.
    EXPECT_GT(set.excitationPath(470), 0.9);
    EXPECT_GT(set.emissionPath(525), 0.9);
    EXPECT_LT(set.emissionPath(470), 1e-5);
    EXPECT_LT(set.excitationPath(525), 1e-5);
    const TabulatedSpectrum curve = set.emissionPathCurve();
    EXPECT_DOUBLE_EQ(curve(525), set.emissionPath(525));

    // A light-sheet detection arm: no dichroic, so only the filters count.
    FilterSet arm = set;
    arm.dichroic.reset();
    EXPECT_DOUBLE_EQ(arm.emissionPath(525), arm.emission(525));
    EXPECT_DOUBLE_EQ(arm.excitationPath(470), arm.excitation(470));
    EXPECT_EQ(Filter::open()(488), 1.0);
}

TEST(Filter, DatabaseFiltersMeasuredFromTheirCurves) {
    // Semrock quotes a guaranteed minimum bandwidth of 45 nm; the measured FWHM of the typical curve
    // is wider (SOURCES.md: 500–551 nm).
    const PassBand semrock = measurePassBand(Filter::fromDatabase(db(), "semrock_FF01-525-45").curve());
    EXPECT_NEAR(semrock.centreNm(), 525, 1.5);
    EXPECT_GE(semrock.fwhmNm(), 45);
    EXPECT_LE(semrock.fwhmNm(), 52);
    EXPECT_NEAR(semrock.lowNm, 500, 1);
    EXPECT_NEAR(semrock.highNm, 551, 1);
    EXPECT_GT(semrock.peakTransmission, 0.95);
    // Chroma ET filters are named by their FWHM: 525/36 (SOURCES.md: 508–543.5 nm).
    const PassBand chroma = measurePassBand(Filter::fromDatabase(db(), "chroma_ET525-36m").curve());
    EXPECT_NEAR(chroma.centreNm(), 525, 1.5);
    EXPECT_NEAR(chroma.fwhmNm(), 36, 1);
    try {
        Filter::fromDatabase(db(), "semrock_FF01-525-46");
        ADD_FAILURE() << "accepted an unknown filter";
    } catch (const ConfigError& e) {
        EXPECT_NE(std::string(e.what()).find("semrock_FF01-525-45"), std::string::npos) << e.what();
    }
}

TEST(Filter, EmissionBlockingWarning) {
    const FilterSet set = gfpSet();
    const TabulatedSpectrum af647 = db().dye("AF647").emission;
    const TabulatedSpectrum af488 = db().dye("AF488").emission;
    // AF647 emits at 630–800 nm, where the 525/45 filter blocks at its OD floor.
    const double blocked = emissionPathEfficiency(set, af647);
    EXPECT_LT(blocked, 1e-5);
    const auto warning = emissionBlockingWarning(set, af647, "AF647");
    ASSERT_TRUE(warning.has_value());
    for (const char* part : {"GFP", "AF647", "semrock_FF01-525-45", "long-pass 495"})
        EXPECT_NE(warning->find(part), std::string::npos) << "missing \"" << part << "\" in: " << *warning;
    // AF488 is what the cube is for.
    const double passed = emissionPathEfficiency(set, af488);
    EXPECT_GT(passed, 0.4);
    EXPECT_LT(passed, 0.8);
    EXPECT_FALSE(emissionBlockingWarning(set, af488, "AF488").has_value());
    std::printf("emission path efficiency of the GFP cube: AF488 %.4f, AF647 %.3g\n", passed, blocked);
    EXPECT_THROW(emissionPathEfficiency(set, TabulatedSpectrum({500, 600}, {0, 0})), ConfigError);
}

// Expects ConfigError from `make` whose message contains every one of `parts`.
void expectRejected(const std::function<void()>& make, const std::vector<std::string>& parts) {
    try {
        make();
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        for (const std::string& part : parts) EXPECT_NE(msg.find(part), std::string::npos) << "missing \"" << part << "\" in: " << msg;
    }
}

TEST(Filter, BadInputNamesFieldAndValue) {
    expectRejected([] { Filter::bandPass({.fwhmNm = 0}); }, {"fwhmNm", "got 0"});
    expectRejected([] { Filter::bandPass({.fwhmNm = -5}); }, {"fwhmNm", "-5"});
    expectRejected([] { Filter::bandPass({.peakTransmission = 1.2}); }, {"peakTransmission", "(0, 1]", "1.2"});
    expectRejected([] { Filter::bandPass({.peakTransmission = -0.1}); }, {"peakTransmission", "-0.1"});
    expectRejected([] { Filter::bandPass({.edgeWidthNm = 0}); }, {"edgeWidthNm", "got 0"});
    expectRejected([] { Filter::bandPass({.fwhmNm = 10, .edgeWidthNm = 6}); }, {"edgeWidthNm", "half of fwhmNm", "6"});
    expectRejected([] { Filter::bandPass({.blockingOd = 0}); }, {"blockingOd", "(0, 12]", "0"});
    expectRejected([] { Filter::bandPass({.blockingOd = 0.01}); }, {"blockingOd", "below the peak transmission"});
    expectRejected([] { Filter::longPass({.edgeNm = -495}); }, {"edgeNm", "-495"});
    expectRejected([] { Filter::shortPass({.peakTransmission = 2}); }, {"peakTransmission", "2"});
    expectRejected([] { Filter::bandPass({}, {.minNm = 900, .maxNm = 300}); }, {"maxNm", "300"});
    expectRejected([] { Filter("measured", TabulatedSpectrum({500, 510}, {0.5, 1.5})); }, {"measured", "1.5", "510 nm"});
}

}  // namespace
}  // namespace fluorosim::optics
