#include "optics/detector.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"

namespace fluorosim::optics {
namespace {

// Shortest text that reads back as the same double, so a message shows exactly the value given.
std::string num(double v) {
    char buf[64];
    const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
    return ec == std::errc() ? std::string(buf, end) : std::string("?");
}

[[noreturn]] void reject(const char* field, const std::string& value, const char* rule) {
    throw ConfigError(std::string("detector.") + field + " = " + value + ": " + rule);
}

void requirePositive(const char* field, double v, const char* rule) {
    if (!(v > 0) || !std::isfinite(v)) reject(field, num(v), rule);
}

void requireNonNegative(const char* field, double v, const char* rule) {
    if (!(v >= 0) || !std::isfinite(v)) reject(field, num(v), rule);
}

// A detector's inputs are computed images; a negative or NaN count is a bug upstream, not user input.
void checkCounts(const std::vector<double>& values, const char* what) {
    for (size_t i = 0; i < values.size(); ++i)
        if (!(values[i] >= 0) || !std::isfinite(values[i]))
            throw NumericError(std::string("detector: ") + what + " at pixel " + std::to_string(i) + " is " + num(values[i]) +
                               " (must be finite and >= 0)");
}

// log Gamma(x) for x >= 1 by Stirling's series with the argument shifted to >= 7 (as in numpy's
// random_loggam); std::lgamma writes the global signgam and so is not safe to call from threads.
double logGamma(double x) {
    static constexpr double a[10] = {8.333333333333333e-02, -2.777777777777778e-03, 7.936507936507937e-04,
                                     -5.952380952380952e-04, 8.417508417508418e-04,  -1.917526917526918e-03,
                                     6.410256410256410e-03,  -2.955065359477124e-02, 1.796443723688307e-01,
                                     -1.39243221690590e+00};
    if (x == 1.0 || x == 2.0) return 0.0;
    const int shift = x < 7.0 ? static_cast<int>(7.0 - x) : 0;
    double x0 = x + shift;
    const double x2 = 1.0 / (x0 * x0);
    double series = a[9];
    for (int k = 8; k >= 0; --k) series = series * x2 + a[k];
    double lg = series / x0 + 0.5 * std::log(2.0 * kPi) + (x0 - 0.5) * std::log(x0) - x0;
    for (int k = 0; k < shift; ++k) {
        x0 -= 1.0;
        lg -= std::log(x0);
    }
    return lg;
}

// Sequential-search inversion of the CDF; for mean < 10 this takes about mean + 1 steps.
double poissonInversion(double mean, Rng& rng) {
    const double u = rng.uniform();
    double p = std::exp(-mean), cdf = p;
    double k = 0;
    // The cap only matters when rounding keeps the summed CDF just below u (u within 1e-16 of 1);
    // P(k > 200) for mean < 10 is below 1e-200.
    while (u > cdf && k < 200) {
        k += 1;
        p *= mean / k;
        cdf += p;
    }
    return k;
}

// PTRS: Hörmann, "The transformed rejection method for generating Poisson random variables",
// Insurance: Mathematics and Economics 12 (1993) 39-45. Exact for mean >= 10.
double poissonPtrs(double mean, Rng& rng) {
    const double slam = std::sqrt(mean), logMean = std::log(mean);
    const double b = 0.931 + 2.53 * slam;
    const double a = -0.059 + 0.02483 * b;
    const double invAlpha = 1.1239 + 1.1328 / (b - 3.4);
    const double vr = 0.9277 - 3.6224 / (b - 2.0);
    for (;;) {
        const double u = rng.uniform() - 0.5;
        const double v = rng.uniform();
        const double us = 0.5 - std::abs(u);
        // us == 0 gives k = -inf, rejected below.
        const double k = std::floor((2.0 * a / us + b) * u + mean + 0.43);
        if (us >= 0.07 && v <= vr) return k;
        if (k < 0 || (us < 0.013 && v > us)) continue;
        if (std::log(v) + std::log(invAlpha) - std::log(a / (us * us) + b) <= -mean + k * logMean - logGamma(k + 1.0))
            return k;
    }
}

}  // namespace

const char* sensorTypeName(SensorType t) { return t == SensorType::SCmos ? "sCMOS" : "EMCCD"; }

double sampleStandardNormal(Rng& rng) {
    const double u1 = 1.0 - rng.uniform();  // (0, 1]: log is finite
    const double u2 = rng.uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPi * u2);
}

double samplePoisson(double mean, Rng& rng) {
    if (!(mean > 0)) return 0.0;
    if (mean < 10.0) return poissonInversion(mean, rng);
    if (mean < 1e7) return poissonPtrs(mean, rng);
    return std::max(0.0, std::floor(mean + std::sqrt(mean) * sampleStandardNormal(rng) + 0.5));
}

double sampleGamma(double shape, double scale, Rng& rng) {
    const double d = shape - 1.0 / 3.0, c = 1.0 / std::sqrt(9.0 * d);
    for (;;) {
        const double x = sampleStandardNormal(rng);
        const double t = 1.0 + c * x;
        if (t <= 0) continue;
        const double v = t * t * t;
        const double u = rng.uniform();
        if (u < 1.0 - 0.0331 * x * x * x * x) return d * v * scale;
        if (u > 0 && std::log(u) < 0.5 * x * x + d * (1.0 - v + std::log(v))) return d * v * scale;
    }
}

void DetectorOptions::validate() const {
    if (type != SensorType::SCmos && type != SensorType::Emccd)
        reject("type", std::to_string(static_cast<int>(type)), "unknown sensor type");
    requirePositive("pixelPitchUm", pixelPitchUm, "must be > 0 µm");
    requirePositive("exposureS", exposureS, "must be > 0 s");
    requirePositive("gainElectronsPerAdu", gainElectronsPerAdu, "must be > 0 e-/ADU");
    requireNonNegative("readNoiseElectrons", readNoiseElectrons, "must be >= 0 e-");
    requireNonNegative("darkCurrentElectronsPerS", darkCurrentElectronsPerS, "must be >= 0 e-/s");
    requirePositive("fullWellElectrons", fullWellElectrons, "must be > 0 e-");
    if (bitDepth < 8 || bitDepth > 16) reject("bitDepth", std::to_string(bitDepth), "must be in 8..16");
    if (!(offsetAdu >= 0 && offsetAdu <= adcMax()))
        reject("offsetAdu", num(offsetAdu),
               ("must lie in the ADC range [0, " + num(adcMax()) + "] of the " + std::to_string(bitDepth) + "-bit ADC").c_str());
    if (!(emGain >= 1) || !std::isfinite(emGain)) reject("emGain", num(emGain), "must be >= 1");
    if (type == SensorType::SCmos && emGain != 1) reject("emGain", num(emGain), "must be 1 for an sCMOS sensor (EM gain needs type Emccd)");
    if (!qe.spectralLines().empty()) reject("qe", "spectral lines", "a quantum efficiency must be a constant or tabulated curve");
    // A tabulated spectrum is non-negative and piecewise linear, so its extreme values are the table's
    // (times the scale): maxValue() < 0 means a negative scale, > 1 a QE above 1 somewhere.
    const double qeMax = qe.maxValue();
    if (!(qeMax >= 0 && qeMax <= 1)) reject("qe", "max " + num(qeMax), "quantum efficiency must lie in [0, 1]");
    const size_t pixels = mapPixels();
    if (pixels > 0 && (sensorWidth <= 0 || pixels % static_cast<size_t>(sensorWidth) != 0))
        reject("sensorWidth", std::to_string(sensorWidth), ("the maps' " + std::to_string(pixels) + " pixels are not whole rows of it").c_str());
    for (size_t i = 0; i < offsetMapAdu.size(); ++i)
        if (!(offsetMapAdu[i] >= 0 && offsetMapAdu[i] <= adcMax())) reject("offsetMapAdu", "pixel " + std::to_string(i) + " = " + num(offsetMapAdu[i]), "must lie in the ADC range");
    for (size_t i = 0; i < gainMapElectronsPerAdu.size(); ++i)
        if (!(gainMapElectronsPerAdu[i] > 0) || !std::isfinite(gainMapElectronsPerAdu[i]))
            reject("gainMapElectronsPerAdu", "pixel " + std::to_string(i) + " = " + num(gainMapElectronsPerAdu[i]), "must be > 0 e-/ADU");
    for (size_t i = 0; i < readNoiseMapElectrons.size(); ++i)
        if (!(readNoiseMapElectrons[i] >= 0) || !std::isfinite(readNoiseMapElectrons[i]))
            reject("readNoiseMapElectrons", "pixel " + std::to_string(i) + " = " + num(readNoiseMapElectrons[i]), "must be >= 0 e-");
    for (size_t i = 0; i < darkCurrentMapElectronsPerS.size(); ++i)
        if (!(darkCurrentMapElectronsPerS[i] >= 0) || !std::isfinite(darkCurrentMapElectronsPerS[i]))
            reject("darkCurrentMapElectronsPerS", "pixel " + std::to_string(i) + " = " + num(darkCurrentMapElectronsPerS[i]), "must be >= 0 e-/s");
    requireNonNegative("rowNoiseElectrons", rowNoiseElectrons, "must be >= 0 e-");
    if (rowNoiseElectrons > 0 && sensorWidth <= 0) reject("rowNoiseElectrons", num(rowNoiseElectrons), "needs the sensor's width (sensorWidth)");
    if (!(hotPixelFraction >= 0 && hotPixelFraction <= 1)) reject("hotPixelFraction", num(hotPixelFraction), "must lie in [0, 1]");
    requireNonNegative("hotPixelDarkCurrentElectronsPerS", hotPixelDarkCurrentElectronsPerS, "must be >= 0 e-/s");
}

size_t DetectorOptions::mapPixels() const {
    size_t n = 0;
    for (const std::vector<double>* map : {&offsetMapAdu, &gainMapElectronsPerAdu, &readNoiseMapElectrons, &darkCurrentMapElectronsPerS}) {
        if (map->empty()) continue;
        if (n != 0 && map->size() != n)
            throw ConfigError("detector: the calibration maps differ in size (" + std::to_string(n) + " and " + std::to_string(map->size()) + " pixels)");
        n = map->size();
    }
    return n;
}

bool DetectorOptions::hotPixel(size_t pixel) const {
    if (!(hotPixelFraction > 0)) return false;
    Rng rng = Rng::forKey(hotPixelSeed, pixel, 0x686f74ULL);  // a fixed pattern: the same in every frame and run
    return rng.uniform() < hotPixelFraction;
}

double DetectorOptions::darkCurrentAt(size_t pixel) const {
    if (hotPixel(pixel)) return hotPixelDarkCurrentElectronsPerS;
    return darkCurrentMapElectronsPerS.empty() ? darkCurrentElectronsPerS : darkCurrentMapElectronsPerS[pixel];
}

Detector::Detector(DetectorOptions options) : options_(std::move(options)) { options_.validate(); }

void Detector::checkMapSize(size_t pixels) const {
    const size_t maps = options_.mapPixels();
    if (maps != 0 && maps != pixels)
        throw ConfigError("detector: an image of " + std::to_string(pixels) + " pixels on calibration maps of " + std::to_string(maps));
}

std::vector<double> Detector::photoelectrons(const std::vector<double>& photonsPerPixel, double lambdaNm) const {
    if (!std::isfinite(lambdaNm) || !(lambdaNm > 0))
        throw ConfigError("detector: wavelength = " + num(lambdaNm) + " nm: must be > 0");
    checkCounts(photonsPerPixel, "photon count");
    const double q = quantumEfficiency(lambdaNm);
    std::vector<double> out(photonsPerPixel.size());
    for (size_t i = 0; i < out.size(); ++i) out[i] = photonsPerPixel[i] * q;
    return out;
}

std::vector<double> Detector::expectedElectrons(const std::vector<double>& photoelectronsPerPixel) const {
    checkCounts(photoelectronsPerPixel, "photoelectron count");
    checkMapSize(photoelectronsPerPixel.size());
    std::vector<double> out(photoelectronsPerPixel.size());
    for (size_t i = 0; i < out.size(); ++i) out[i] = photoelectronsPerPixel[i] + options_.darkCurrentAt(i) * options_.exposureS;
    return out;
}

std::vector<uint16_t> Detector::readOut(const std::vector<double>& expectedElectrons, uint64_t seed, uint64_t frame) const {
    checkCounts(expectedElectrons, "expected electron count");
    checkMapSize(expectedElectrons.size());
    const DetectorOptions& o = options_;
    const bool em = o.type == SensorType::Emccd && o.emGain > 1;
    const double adcMax = o.adcMax();
    std::vector<uint16_t> out(expectedElectrons.size());
    // Row noise: one offset per row and frame, from the row's own stream (keys beyond any pixel's).
    std::vector<double> rowOffset;
    if (o.rowNoiseElectrons > 0) {
        const size_t rows = (out.size() + static_cast<size_t>(o.sensorWidth) - 1) / static_cast<size_t>(o.sensorWidth);
        rowOffset.resize(rows);
        for (size_t r = 0; r < rows; ++r) {
            Rng rng = Rng::forKey(seed, (uint64_t(1) << 62) + r, frame);
            rowOffset[r] = o.rowNoiseElectrons * sampleStandardNormal(rng);
        }
    }
    // Blocks of pixels run in parallel; each pixel has its own keyed stream, so the blocking and the
    // thread count do not change the result.
    constexpr size_t kBlock = 1 << 14;
    const size_t blocks = (out.size() + kBlock - 1) / kBlock;
    parallelFor(blocks, 0, [&](size_t block) {
        const size_t end = std::min(out.size(), (block + 1) * kBlock);
        for (size_t i = block * kBlock; i < end; ++i) {
            Rng rng = Rng::forKey(seed, i, frame);
            double electrons = std::min(samplePoisson(expectedElectrons[i], rng), o.fullWellElectrons);
            if (em && electrons > 0) electrons = sampleGamma(electrons, o.emGain, rng);
            if (const double read = o.readNoiseAt(i); read > 0) electrons += read * sampleStandardNormal(rng);
            if (!rowOffset.empty()) electrons += rowOffset[i / static_cast<size_t>(o.sensorWidth)];
            const double adu = std::clamp(std::floor(electrons / o.gainAt(i) + o.offsetAt(i) + 0.5), 0.0, adcMax);
            out[i] = static_cast<uint16_t>(adu);
        }
    });
    return out;
}

std::vector<double> Detector::expectedAdu(const std::vector<double>& expectedElectrons) const {
    checkCounts(expectedElectrons, "expected electron count");
    checkMapSize(expectedElectrons.size());
    const DetectorOptions& o = options_;
    const double m = o.type == SensorType::Emccd ? o.emGain : 1.0;
    std::vector<double> out(expectedElectrons.size());
    for (size_t i = 0; i < out.size(); ++i)
        out[i] = std::clamp(std::min(expectedElectrons[i], o.fullWellElectrons) * m / o.gainAt(i) + o.offsetAt(i), 0.0, o.adcMax());
    return out;
}

double medianVarianceOverCamera(const std::vector<double>& variance, const std::vector<double>& signal, double quantile, double darkElectrons,
                                double readNoiseElectrons) {
    if (variance.size() != signal.size() || signal.empty()) return 0.0;
    std::vector<double> sorted = signal;
    std::sort(sorted.begin(), sorted.end());
    const double cut = sorted[static_cast<size_t>(std::clamp(quantile, 0.0, 1.0) * static_cast<double>(sorted.size() - 1))];
    std::vector<double> ratio;
    for (size_t i = 0; i < signal.size(); ++i)
        if (signal[i] >= cut) ratio.push_back(variance[i] / (std::max(0.0, signal[i]) + darkElectrons + readNoiseElectrons * readNoiseElectrons));
    std::nth_element(ratio.begin(), ratio.begin() + static_cast<std::ptrdiff_t>(ratio.size() / 2), ratio.end());
    return ratio[ratio.size() / 2];
}

}  // namespace fluorosim::optics
