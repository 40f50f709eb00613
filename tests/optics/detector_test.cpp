// Camera detector: photon-transfer calibration recovers gain and read noise, saturation and ADC
// clipping, the Poisson/gamma/normal samplers' statistics, and rejection of bad options.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "core/errors.h"
#include "core/math.h"
#include "core/rng.h"
#include "optics/detector.h"
#include "optics/photon_transfer.h"
#include "statistical/chi2.h"

namespace fluorosim::optics {
namespace {

struct LevelRun {
    std::vector<PhotonTransferPoint> points;
    std::vector<double> expectedAduMean;  // the detector's noise-free ADU per level
};

// Flat fields of `pixels` pixels at each photoelectron level, `frames` frames per level, one seed.
LevelRun runFlatFields(const Detector& det, const std::vector<double>& levels, size_t pixels, int frames, uint64_t seed) {
    LevelRun run;
    for (size_t l = 0; l < levels.size(); ++l) {
        const std::vector<double> e = det.expectedElectrons(std::vector<double>(pixels, levels[l]));
        std::vector<std::vector<uint16_t>> stack;
        for (int f = 0; f < frames; ++f) stack.push_back(det.readOut(e, seed, l * 1000 + static_cast<uint64_t>(f)));
        run.points.push_back(measurePhotonTransferPoint(stack));
        run.expectedAduMean.push_back(det.expectedAdu({e[0]})[0]);
    }
    return run;
}

// Photon transfer on the default sCMOS (g = 0.46 e-/ADU, read noise 1.4 e-, offset 100, dark
// 0.05 e- per exposure): 6 flat-field levels of 256 x 256 pixels, 4 frames each, so each level's
// variance has dof = 65536 * 3 = 196608 and a relative standard error sqrt(2 / dof) = 0.32%.
// Propagating these through the weighted fit (the same covariance fitPhotonTransfer reports) gives
// standard errors of 0.14% on the gain (the four bright levels each pin the slope) and 0.23% on the
// read noise (set by the dark level's variance, 9.58 ADU^2, and the gain). The 2% acceptance is
// therefore 14 and 8.6 standard errors; the test also requires the fit's own standard errors to
// be <= 0.5%, so that 2% is >= 4 of them. The fit includes the 1/12 ADU^2 of rounding: leaving it
// out would bias the read noise by +0.45% (about 2 standard errors).
TEST(Detector, PhotonTransferRecoversGainAndReadNoise) {
    const DetectorOptions o;  // the sCMOS defaults
    const Detector det(o);
    const std::vector<double> levels = {0, 100, 500, 2000, 8000, 20000};
    const LevelRun run = runFlatFields(det, levels, 256 * 256, 4, 20240611);
    const PhotonTransferFit fit = fitPhotonTransfer(run.points, o.offsetAdu);

    std::printf("[ sCMOS PTC ] gain %.5f +- %.5f e-/ADU (configured %.5f, error %+.3f%%), read noise %.5f +- %.5f e- "
                "(configured %.5f, error %+.3f%%), chi2 %.2f / %d dof\n",
                fit.gainElectronsPerAdu, fit.gainStdErr, o.gainElectronsPerAdu,
                100 * (fit.gainElectronsPerAdu / o.gainElectronsPerAdu - 1), fit.readNoiseElectrons, fit.readNoiseStdErr,
                o.readNoiseElectrons, 100 * (fit.readNoiseElectrons / o.readNoiseElectrons - 1), fit.chi2, fit.dof);

    EXPECT_LE(fit.gainStdErr, 0.005 * o.gainElectronsPerAdu);
    EXPECT_LE(fit.readNoiseStdErr, 0.005 * o.readNoiseElectrons);
    EXPECT_NEAR(fit.gainElectronsPerAdu, o.gainElectronsPerAdu, 0.02 * o.gainElectronsPerAdu);
    EXPECT_NEAR(fit.readNoiseElectrons, o.readNoiseElectrons, 0.02 * o.readNoiseElectrons);
    // The model (shot + read + rounding noise) fits all levels: chi-square with 4 dof below its
    // 1e-4 quantile, 23.51.
    EXPECT_EQ(fit.dof, 4);
    EXPECT_LT(fit.chi2, 23.51);

    // Each level's mean is the noise-free ADU: rounding adds nothing on average once the noise is a
    // few ADU wide, and the mean's standard error is sqrt(var / samples).
    for (size_t l = 0; l < levels.size(); ++l) {
        const PhotonTransferPoint& p = run.points[l];
        EXPECT_NEAR(p.meanAdu, run.expectedAduMean[l], 5 * std::sqrt(p.varianceAdu2 / p.samples)) << "level " << levels[l];
    }
}

// EMCCD (M = 100, excess noise factor sqrt(2)): the photon-transfer slope is F^2 M / g, so the fit
// returns g / (2 M) and read noise / (2 M). Reported, not required: the gamma-distributed output is
// far from Gaussian at low light, so the fit's error model does not hold there.
TEST(Detector, EmccdPhotonTransferReport) {
    DetectorOptions o;
    o.type = SensorType::Emccd;
    o.emGain = 100;
    o.gainElectronsPerAdu = 10;
    o.readNoiseElectrons = 40;
    o.fullWellElectrons = 80000;
    const Detector det(o);
    const LevelRun run = runFlatFields(det, {0, 5, 20, 50, 100, 200}, 256 * 256, 4, 7);
    const PhotonTransferFit fit = fitPhotonTransfer(run.points, o.offsetAdu);
    const double f2m = 2.0 * o.emGain;
    std::printf("[ EMCCD PTC ] apparent gain %.6f e-/ADU -> g = %.4f (configured %.4f), apparent read noise %.5f e- -> %.3f "
                "(configured %.3f), chi2 %.1f / %d dof\n",
                fit.gainElectronsPerAdu, fit.gainElectronsPerAdu * f2m, o.gainElectronsPerAdu, fit.readNoiseElectrons,
                fit.readNoiseElectrons * f2m, o.readNoiseElectrons, fit.chi2, fit.dof);
    // Sanity only (25%): the excess noise doubles the slope, so the fit is near g / (2 M), not g / M.
    EXPECT_NEAR(fit.gainElectronsPerAdu * f2m, o.gainElectronsPerAdu, 0.25 * o.gainElectronsPerAdu);
}

TEST(Detector, FullWellSaturates) {
    DetectorOptions o;
    o.readNoiseElectrons = 0;
    o.darkCurrentElectronsPerS = 0;
    o.fullWellElectrons = 10000;
    const Detector det(o);
    // 10000 / 0.46 + 100 = 21839.13 ADU, below the 16-bit ADC limit: the well saturates first.
    const double saturated = 10000 / 0.46 + 100;
    const std::vector<double> e(1000, 1e6);
    const std::vector<uint16_t> frame = det.readOut(e, 1);
    for (uint16_t v : frame) ASSERT_EQ(v, 21839);
    EXPECT_DOUBLE_EQ(det.expectedAdu({1e6})[0], saturated);
    EXPECT_DOUBLE_EQ(det.expectedAdu({10000})[0], saturated);
    EXPECT_DOUBLE_EQ(det.expectedAdu({5000})[0], 5000 / 0.46 + 100);
    // Just below the well the signal still varies (shot noise), and never exceeds the well.
    const std::vector<uint16_t> near = det.readOut(std::vector<double>(1000, 9950), 2);
    const auto [lo, hi] = std::minmax_element(near.begin(), near.end());
    EXPECT_LT(*lo, 21839);
    EXPECT_EQ(*hi, 21839);
}

TEST(Detector, AdcClipsAtItsMaximum) {
    DetectorOptions o;
    o.gainElectronsPerAdu = 0.2;  // 30000 e- full well = 150100 ADU: the ADC saturates first
    const Detector det16(o);
    for (uint16_t v : det16.readOut(std::vector<double>(500, 20000), 3)) ASSERT_EQ(v, 65535);
    EXPECT_DOUBLE_EQ(det16.expectedAdu({20000})[0], 65535);

    o.bitDepth = 12;
    const Detector det12(o);
    for (uint16_t v : det12.readOut(std::vector<double>(500, 20000), 3)) ASSERT_EQ(v, 4095);
    EXPECT_DOUBLE_EQ(det12.expectedAdu({20000})[0], 4095);
    // Below saturation the 12-bit ADC gives the same counts as the 16-bit one.
    EXPECT_EQ(det12.readOut({300}, 9), det16.readOut({300}, 9));
}

TEST(Detector, NegativeValuesClipToZeroInsteadOfWrapping) {
    DetectorOptions o;
    o.offsetAdu = 0;
    o.gainElectronsPerAdu = 1;
    o.readNoiseElectrons = 20;
    o.darkCurrentElectronsPerS = 0;
    const Detector det(o);
    const size_t n = 100000;
    const std::vector<uint16_t> frame = det.readOut(std::vector<double>(n, 0.0), 4);
    EXPECT_LT(*std::max_element(frame.begin(), frame.end()), 200);  // 10 sigma; a wrapped value would be ~65535
    // ADU = 0 when the read noise is below 0.5 e-: probability Phi(0.5 / 20) = 0.509973.
    const double zeros = static_cast<double>(std::count(frame.begin(), frame.end(), 0)) / n;
    EXPECT_NEAR(zeros, 0.509973, 5 * std::sqrt(0.25 / n));
}

TEST(Detector, ReadOutIsKeyedPerPixelAndFrame) {
    const Detector det{DetectorOptions{}};
    const std::vector<double> big = det.expectedElectrons(std::vector<double>(70000, 300));
    const std::vector<uint16_t> a = det.readOut(big, 11), b = det.readOut(big, 11), c = det.readOut(big, 11, 1);
    EXPECT_EQ(a, b);
    EXPECT_NE(a, c);
    // A pixel's value does not depend on the image size (nor on how the pixels are split among threads).
    const std::vector<uint16_t> small = det.readOut(std::vector<double>(big.begin(), big.begin() + 100), 11);
    EXPECT_TRUE(std::equal(small.begin(), small.end(), a.begin()));
    EXPECT_THROW(det.readOut({1.0, -1.0}, 1), NumericError);
    EXPECT_THROW(det.readOut({NAN}, 1), NumericError);
}

TEST(Detector, QuantumEfficiencyAndDarkCurrent) {
    DetectorOptions o;
    o.qe = Spectrum::tabulated(TabulatedSpectrum({400, 500, 600, 700}, {0.5, 0.8, 0.9, 0.6}));
    const Detector det(o);
    EXPECT_DOUBLE_EQ(det.quantumEfficiency(550), 0.85);
    const std::vector<double> pe = det.photoelectrons({100, 1000}, 550);
    EXPECT_DOUBLE_EQ(pe[0], 85);
    EXPECT_DOUBLE_EQ(pe[1], 850);
    // Dark current 0.5 e-/s for 0.1 s.
    EXPECT_DOUBLE_EQ(det.expectedElectrons(pe)[0], 85.05);
    EXPECT_DOUBLE_EQ(Detector{DetectorOptions{}}.quantumEfficiency(480), 0.8);  // the flat default
}

// Expects ConfigError whose message names the field and the value.
void expectRejected(const std::function<void(DetectorOptions&)>& change, const std::string& field, const std::string& value) {
    DetectorOptions o;
    change(o);
    SCOPED_TRACE(field + " = " + value);
    try {
        o.validate();
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(field), std::string::npos) << msg;
        EXPECT_NE(msg.find(value), std::string::npos) << msg;
    }
    EXPECT_THROW(Detector{o}, ConfigError);
}

// sCMOS pixels as cameras calibrate them: per-pixel offset, gain and read noise (mean and variance of
// each pixel over many frames against its own values, 4 standard errors), hot pixels as a fixed
// pattern, and row noise shared by a row's pixels.
TEST(Detector, CalibrationMapsHotPixelsAndRowNoise) {
    DetectorOptions o;
    o.sensorWidth = 8;
    o.darkCurrentElectronsPerS = 0;
    for (int i = 0; i < 32; ++i) {
        o.offsetMapAdu.push_back(100 + i);
        o.gainMapElectronsPerAdu.push_back(0.4 + 0.01 * i);
        o.readNoiseMapElectrons.push_back(1.0 + 0.1 * i);
    }
    const Detector camera(o);
    const int frames = 4000;
    for (double e : {0.0, 50.0}) {
        std::vector<double> sum(32, 0.0), sumSq(32, 0.0);
        for (int f = 0; f < frames; ++f) {
            const std::vector<uint16_t> adu = camera.readOut(std::vector<double>(32, e), 7, static_cast<uint64_t>(f));
            for (int i = 0; i < 32; ++i) {
                sum[i] += adu[i];
                sumSq[i] += double(adu[i]) * adu[i];
            }
        }
        double worstMean = 0, worstVar = 0;
        for (int i = 0; i < 32; ++i) {
            const double g = o.gainMapElectronsPerAdu[i], rn = o.readNoiseMapElectrons[i];
            const double mean = sum[i] / frames, var = sumSq[i] / frames - mean * mean;
            const double expectedVar = (e + rn * rn) / (g * g) + 1.0 / 12;  // shot and read noise, and rounding
            worstMean = std::max(worstMean, std::abs(mean - (e / g + o.offsetMapAdu[i])) / std::sqrt(expectedVar / frames));
            worstVar = std::max(worstVar, std::abs(var - expectedVar) / (expectedVar * std::sqrt(2.0 / frames)));
        }
        std::printf("  %g e-: per-pixel mean and variance against their maps, largest |z| %.2f and %.2f\n", e, worstMean, worstVar);
        EXPECT_LT(worstMean, 4.5);
        EXPECT_LT(worstVar, 4.5);
    }
    EXPECT_THROW(camera.readOut(std::vector<double>(16, 0.0), 1), ConfigError);  // not the maps' size

    // Hot pixels: a fixed pattern of the asked fraction, with their own dark current.
    DetectorOptions hot;
    hot.sensorWidth = 100;
    hot.hotPixelFraction = 0.05;
    hot.hotPixelDarkCurrentElectronsPerS = 200;
    hot.exposureS = 0.1;
    const std::vector<double> dark = Detector(hot).expectedElectrons(std::vector<double>(10000, 0.0));
    size_t count = 0;
    for (size_t i = 0; i < dark.size(); ++i) {
        const bool isHot = hot.hotPixel(i);
        count += isHot;
        EXPECT_DOUBLE_EQ(dark[i], (isHot ? 200 : hot.darkCurrentElectronsPerS) * 0.1);
    }
    EXPECT_NEAR(double(count), 500, 4 * std::sqrt(10000 * 0.05 * 0.95));
    DetectorOptions other = hot;
    other.hotPixelSeed = 2;
    size_t same = 0;
    for (size_t i = 0; i < 10000; ++i) same += hot.hotPixel(i) && other.hotPixel(i);
    EXPECT_LT(same, 60u);  // another camera, another pattern (25 expected by chance)

    // Row noise: an offset per row and frame, the same for the row's pixels.
    DetectorOptions rows;
    rows.sensorWidth = 64;
    rows.readNoiseElectrons = 0;
    rows.darkCurrentElectronsPerS = 0;
    rows.rowNoiseElectrons = 3;
    rows.gainElectronsPerAdu = 0.25;
    double withinRow = 0, rowMeans = 0, rowMeansSq = 0;
    const int rowCount = 64 * 50;
    for (int f = 0; f < 50; ++f) {
        const std::vector<uint16_t> adu = Detector(rows).readOut(std::vector<double>(64 * 64, 0.0), 3, static_cast<uint64_t>(f));
        for (int r = 0; r < 64; ++r) {
            double m = 0;
            for (int x = 0; x < 64; ++x) m += adu[static_cast<size_t>(r * 64 + x)];
            m /= 64;
            for (int x = 0; x < 64; ++x) withinRow = std::max(withinRow, std::abs(adu[static_cast<size_t>(r * 64 + x)] - m));
            rowMeans += m;
            rowMeansSq += m * m;
        }
    }
    const double rowVar = rowMeansSq / rowCount - sqr(rowMeans / rowCount), expected = sqr(3 / 0.25);
    std::printf("  row noise 3 e-: variance of row means %.1f ADU^2 (expected %.1f), largest spread within a row %.1f ADU\n", rowVar, expected,
                withinRow);
    EXPECT_NEAR(rowVar, expected, 4 * expected * std::sqrt(2.0 / rowCount) + 1.0 / 12);
    EXPECT_LE(withinRow, 1.0);  // only the rounding of one value
    rows.sensorWidth = 0;
    EXPECT_THROW(rows.validate(), ConfigError);
}

TEST(Detector, RejectsBadOptions) {
    EXPECT_NO_THROW(DetectorOptions{}.validate());
    expectRejected([](auto& o) { o.exposureS = 0; }, "exposureS", "0");
    expectRejected([](auto& o) { o.exposureS = -0.25; }, "exposureS", "-0.25");
    expectRejected([](auto& o) { o.exposureS = INFINITY; }, "exposureS", "inf");
    expectRejected([](auto& o) { o.bitDepth = 7; }, "bitDepth", "7");
    expectRejected([](auto& o) { o.bitDepth = 17; }, "bitDepth", "17");
    expectRejected([](auto& o) { o.readNoiseElectrons = -1.5; }, "readNoiseElectrons", "-1.5");
    expectRejected([](auto& o) { o.darkCurrentElectronsPerS = -0.125; }, "darkCurrentElectronsPerS", "-0.125");
    expectRejected([](auto& o) { o.gainElectronsPerAdu = 0; }, "gainElectronsPerAdu", "0");
    expectRejected([](auto& o) { o.gainElectronsPerAdu = -2.5; }, "gainElectronsPerAdu", "-2.5");
    expectRejected([](auto& o) { o.fullWellElectrons = 0; }, "fullWellElectrons", "0");
    expectRejected([](auto& o) { o.fullWellElectrons = -30000; }, "fullWellElectrons", "-30000");
    expectRejected([](auto& o) { o.offsetAdu = -1; }, "offsetAdu", "-1");
    expectRejected([](auto& o) { o.offsetAdu = 65536; }, "offsetAdu", "65536");
    expectRejected([](auto& o) { o.bitDepth = 8; o.offsetAdu = 300; }, "offsetAdu", "300");
    expectRejected([](auto& o) { o.qe = Spectrum::constant(1.25); }, "qe", "1.25");
    expectRejected([](auto& o) { o.qe = Spectrum::constant(-0.5); }, "qe", "-0.5");
    expectRejected([](auto& o) { o.qe = Spectrum::tabulated(TabulatedSpectrum({400, 700}, {0.5, 0.75}), 2.0); }, "qe", "1.5");
    expectRejected([](auto& o) { o.qe = Spectrum::lines({{500, 0.5}}); }, "qe", "lines");
    expectRejected([](auto& o) { o.pixelPitchUm = 0; }, "pixelPitchUm", "0");
    expectRejected([](auto& o) { o.emGain = 50; }, "emGain", "50");  // sCMOS
    expectRejected([](auto& o) { o.type = SensorType::Emccd; o.emGain = 0.5; }, "emGain", "0.5");
    // The limits themselves are valid.
    DetectorOptions edge;
    edge.bitDepth = 8;
    edge.offsetAdu = 255;
    edge.readNoiseElectrons = 0;
    edge.darkCurrentElectronsPerS = 0;
    edge.qe = Spectrum::constant(1.0);
    EXPECT_NO_THROW(edge.validate());
}

// Moments of n draws of Poisson(mean), one stream per mean. The sample mean has standard error
// sqrt(mean / n) and the sample variance sqrt((mean + 2 mean^2) / n) (fourth central moment
// mean + 3 mean^2). Tolerance 5 standard errors: over the 24 checks a correct sampler fails one with
// probability about 24 * 5.7e-7 = 1.4e-5. The means cover inversion (< 10), PTRS (10 ... 1e7) and
// the normal approximation (>= 1e7) on both sides of each switch.
TEST(Detector, PoissonSamplerMoments) {
    const size_t n = 1'000'000;
    const std::vector<double> means = {0.05, 0.7, 3, 9.99, 10, 25, 300, 1e4, 9.99e6, 1e7, 3e8, 1e12};
    for (size_t m = 0; m < means.size(); ++m) {
        const double mu = means[m];
        Rng rng(99, m);
        double sum = 0, sumSq = 0;
        bool integer = true;
        for (size_t i = 0; i < n; ++i) {
            const double k = samplePoisson(mu, rng);
            integer = integer && k >= 0 && k == std::floor(k);
            const double d = k - mu;  // centred on the true mean: no cancellation at 1e12
            sum += d;
            sumSq += d * d;
        }
        const double meanErr = sum / n;
        const double var = (sumSq - sum * sum / n) / (n - 1);
        const double seMean = std::sqrt(mu / n), seVar = std::sqrt((mu + 2 * mu * mu) / n);
        std::printf("[ Poisson ] mean %-8g: sample mean - mean = %+.3e (%+.2f se), variance / mean - 1 = %+.3e (%+.2f se)\n", mu,
                    meanErr, meanErr / seMean, var / mu - 1, (var - mu) / seVar);
        EXPECT_TRUE(integer) << mu;
        EXPECT_LE(std::abs(meanErr), 5 * seMean) << mu;
        EXPECT_LE(std::abs(var - mu), 5 * seVar) << mu;
    }
    Rng rng(1, 2);
    EXPECT_EQ(samplePoisson(0, rng), 0);
}

// Pearson chi-square of the sampled distribution against the exact pmf (cells with expected count
// < 5 pooled), at means on both sides of the inversion/PTRS switch and deep in PTRS.
TEST(Detector, PoissonSamplerChiSquare) {
    const std::vector<double> means = {0.7, 4.5, 9.99, 10, 37.2, 1000, 1e5};
    const double alpha = chi2::sidak(chi2::kFamilyAlpha, static_cast<int>(means.size()));
    const size_t n = 1'000'000;
    for (size_t m = 0; m < means.size(); ++m) {
        const double mu = means[m];
        const double lo = std::max(0.0, std::floor(mu - 8 * std::sqrt(mu) - 10)), hi = std::ceil(mu + 8 * std::sqrt(mu) + 10);
        const size_t cells = static_cast<size_t>(hi - lo) + 1;
        std::vector<double> observed(cells + 1, 0.0), expected(cells + 1, 0.0);  // last cell: outside [lo, hi]
        double inside = 0;
        for (size_t c = 0; c < cells; ++c) {
            const double k = lo + static_cast<double>(c);
            const double p = std::exp(k * std::log(mu) - mu - std::lgamma(k + 1));
            expected[c] = n * p;
            inside += p;
        }
        expected[cells] = n * std::max(0.0, 1 - inside);
        Rng rng(4242, m);
        for (size_t i = 0; i < n; ++i) {
            const double k = samplePoisson(mu, rng);
            observed[k >= lo && k <= hi ? static_cast<size_t>(k - lo) : cells] += 1;
        }
        const chi2::Chi2Result r = chi2::chiSquare(observed, expected);
        std::printf("[ Poisson chi2 ] mean %-6g: %s\n", mu, r.summary().c_str());
        EXPECT_TRUE(r.accept(alpha)) << "mean " << mu << ": " << r.summary();
    }
}

// Gamma(k, theta): mean k theta, variance k theta^2; the sample variance has standard error
// sqrt((2 k^2 + 6 k) / n) theta^2. The normal sampler: mean 0 (se 1/sqrt(n)), variance 1 (se sqrt(2/n)).
TEST(Detector, GammaAndNormalSamplerMoments) {
    const size_t n = 1'000'000;
    const double theta = 2.5;
    for (double k : {1.0, 3.0, 47.0, 30000.0}) {
        Rng rng(5, static_cast<uint64_t>(k));
        double sum = 0, sumSq = 0;
        const double mu = k * theta;
        for (size_t i = 0; i < n; ++i) {
            const double d = sampleGamma(k, theta, rng) - mu;
            sum += d;
            sumSq += d * d;
        }
        const double var = (sumSq - sum * sum / n) / (n - 1);
        EXPECT_LE(std::abs(sum / n), 5 * std::sqrt(k / n) * theta) << k;
        EXPECT_LE(std::abs(var - k * theta * theta), 5 * std::sqrt((2 * k * k + 6 * k) / n) * theta * theta) << k;
    }
    Rng rng(6, 0);
    double sum = 0, sumSq = 0;
    for (size_t i = 0; i < n; ++i) {
        const double z = sampleStandardNormal(rng);
        sum += z;
        sumSq += z * z;
    }
    EXPECT_LE(std::abs(sum / n), 5 / std::sqrt(double(n)));
    EXPECT_LE(std::abs((sumSq - sum * sum / n) / (n - 1) - 1), 5 * std::sqrt(2.0 / n));
}

// The adaptive mode weighs two kinds of variance estimate alike: the field's squared half difference (one
// degree of freedom) over kMedianOfChiSquare1, and the photons' slots' variance (15 degrees of freedom). On
// Gaussian noise of a known variance (a fifth of the camera's), the median over 20 000 pixels reads 1 for the
// first and the median of chi-square(15) / 15, 0.956, for the second (4 standard errors of the median).
TEST(Detector, OneAndFifteenDegreesOfFreedomReadTheVarianceAlike) {
    constexpr size_t kPixels = 20000;
    constexpr double kShare = 0.2, kRead = 1.4;
    std::vector<double> signal(kPixels), fromHalves(kPixels), fromSlots(kPixels);
    Rng rng(9, 0);
    for (size_t i = 0; i < kPixels; ++i) {
        signal[i] = 100.0 + static_cast<double>(i % 997);
        const double variance = kShare * (signal[i] + kRead * kRead);
        fromHalves[i] = sqr(std::sqrt(variance) * sampleStandardNormal(rng)) / kMedianOfChiSquare1;  // a half difference, squared
        // 16 slots, each an estimate with 16 times the mean's variance; the mean's variance from their spread.
        std::array<double, 16> x{};
        double mean = 0;
        for (double& v : x) mean += (v = std::sqrt(16 * variance) * sampleStandardNormal(rng)) / 16;
        for (double v : x) fromSlots[i] += sqr(v - mean) / (16 * 15);
    }
    // Standard errors of the medians: sqrt(1/4 / n) over the density at the median, chi-square(1) at 0.455
    // (0.471, then scaled by 1/0.455) and chi-square(15)/15 at 0.956 (1.119).
    const double se1 = 0.5 / std::sqrt(double(kPixels)) / 0.4711 / kMedianOfChiSquare1, se15 = 0.5 / std::sqrt(double(kPixels)) / 1.119;
    EXPECT_NEAR(medianVarianceOverCamera(fromHalves, signal, 0.0, 0.0, kRead) / kShare, 1.0, 4 * se1);
    EXPECT_NEAR(medianVarianceOverCamera(fromSlots, signal, 0.0, 0.0, kRead) / kShare, 0.9559, 4 * se15);
}

}  // namespace
}  // namespace fluorosim::optics
