#pragma once
// Camera detector: photons -> photoelectrons (QE) -> electrons with dark current -> shot noise,
// full-well saturation, EM gain, read noise -> ADU with offset, rounding and ADC clipping.
//
// Units: electrons (e-) and ADU; exposure in s; wavelengths in nm; pixel pitch in µm (the sensor
// plane, not the sample: divide by the magnification for the sample's pixel size).
//
// The pipeline, per pixel, with e = expected electrons = QE-weighted photons + dark current * exposure:
//   n  ~ Poisson(e)                      shot noise on signal and dark current together
//   n  = min(n, fullWell)                pixel saturation (photo- and dark electrons share the well)
//   n' ~ Gamma(shape n, scale M)         EMCCD only, M = emGain > 1 (see below); n' = n otherwise
//   x  = n' + Normal(0, readNoise)       read noise, in electrons at the output amplifier
//   ADU = clamp(round(x / gain + offset), 0, 2^bitDepth - 1)
//
// EM gain model: the multiplication register is modelled as a gamma distribution of shape n and
// scale M (Basden, Haniff & Mackay 2003, their high-gain limit). Its output has mean M n and
// variance M^2 n, so with Poisson input the output variance is 2 M^2 e: excess noise factor
// F = sqrt(2) for every M > 1 (the real register has F^2 = 2 - 1/M + O(stages^-1), i.e. sqrt(2)
// for the gains > 10 at which EMCCDs are run). M = 1 means no register (F = 1), a step at M = 1.
// Clock-induced charge and the register's own full well are not modelled; the read noise is the
// output amplifier's, before the EM gain is divided out.
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/rng.h"
#include "spectral/spectrum.h"

namespace fluorosim::optics {

enum class SensorType { SCmos, Emccd };

const char* sensorTypeName(SensorType t);

// Defaults: a typical scientific CMOS camera (Hamamatsu ORCA-Flash4.0-class: 6.5 µm pixels,
// 0.46 e-/ADU, 100 ADU offset, 1.4 e- rms read noise, 30000 e- full well, 16-bit output). The QE
// defaults to a flat 0.8, not a measured curve: pass Spectrum::tabulated(...) for a real camera.
struct DetectorOptions {
    SensorType type = SensorType::SCmos;
    double pixelPitchUm = 6.5;
    Spectrum qe = Spectrum::constant(0.8);  // quantum efficiency, in [0, 1] at every wavelength
    double exposureS = 0.1;
    double gainElectronsPerAdu = 0.46;  // conversion gain: electrons per ADU (after the EM gain)
    double offsetAdu = 100;             // the ADU of zero electrons (the bias)
    double readNoiseElectrons = 1.4;    // rms
    double darkCurrentElectronsPerS = 0.5;
    double fullWellElectrons = 30000;
    int bitDepth = 16;  // 8..16; ADU values are clipped to [0, 2^bitDepth - 1]
    double emGain = 1;  // EMCCD multiplication gain M >= 1 (must be 1 for sCMOS)

    // sCMOS pixels are not alike. Per-pixel calibration maps, row-major from the top over the sensor's
    // `sensorWidth` columns, as cameras ship them (offset in ADU, conversion gain in e-/ADU, read noise in
    // e- rms, dark current in e-/s); an empty map is the scalar above for every pixel.
    std::vector<double> offsetMapAdu, gainMapElectronsPerAdu, readNoiseMapElectrons, darkCurrentMapElectronsPerS;
    int sensorWidth = 0;               // columns (needed by the maps and the row noise)
    double rowNoiseElectrons = 0;      // rms of an offset shared by the pixels of a row in each frame
    // Hot pixels: this fraction of pixels, a fixed pattern chosen by `hotPixelSeed`, have the dark current
    // `hotPixelDarkCurrentElectronsPerS` instead of their own.
    double hotPixelFraction = 0;
    double hotPixelDarkCurrentElectronsPerS = 0;
    uint64_t hotPixelSeed = 1;

    double offsetAt(size_t pixel) const { return offsetMapAdu.empty() ? offsetAdu : offsetMapAdu[pixel]; }
    double gainAt(size_t pixel) const { return gainMapElectronsPerAdu.empty() ? gainElectronsPerAdu : gainMapElectronsPerAdu[pixel]; }
    double readNoiseAt(size_t pixel) const { return readNoiseMapElectrons.empty() ? readNoiseElectrons : readNoiseMapElectrons[pixel]; }
    bool hotPixel(size_t pixel) const;
    double darkCurrentAt(size_t pixel) const;
    // The maps' pixel count (0 without maps); ConfigError unless every map has it.
    size_t mapPixels() const;

    // Throws ConfigError naming the field and its value for: non-positive or non-finite pixel pitch,
    // exposure, gain or full well; a bit depth outside 8..16; negative read noise or dark current;
    // an offset outside [0, 2^bitDepth - 1]; a QE outside [0, 1] or with spectral lines; emGain < 1,
    // or emGain != 1 on an sCMOS sensor; maps of unequal sizes, not whole rows of `sensorWidth`, or with
    // a value the scalar would refuse; row noise without `sensorWidth`; a hot-pixel fraction outside [0, 1].
    void validate() const;
    double adcMax() const { return std::ldexp(1.0, bitDepth) - 1.0; }  // 2^bitDepth - 1
};

class Detector {
public:
    explicit Detector(DetectorOptions options);  // validates
    const DetectorOptions& options() const { return options_; }

    double quantumEfficiency(double lambdaNm) const { return options_.qe(lambdaNm); }

    // Mean photoelectrons per pixel from mean photon counts at one wavelength (photons * QE(λ)).
    // For a spectrum of photons, call it per wavelength band and sum the results.
    std::vector<double> photoelectrons(const std::vector<double>& photonsPerPixel, double lambdaNm) const;

    // Mean electrons per pixel collected in one exposure: the photoelectrons (already QE-weighted)
    // plus dark current * exposure. This is the input of readOut and expectedAdu.
    std::vector<double> expectedElectrons(const std::vector<double>& photoelectronsPerPixel) const;

    // One noisy frame. Each pixel draws from Rng::forKey(seed, pixel, frame), and each row's offset from
    // its own key, so the result depends only on (seed, frame, pixel) and not on threading; use the frame
    // index for a stack taken with one seed. Throws NumericError for a negative or non-finite expected
    // count (naming the pixel), ConfigError for an image of another size than the maps'.
    std::vector<uint16_t> readOut(const std::vector<double>& expectedElectrons, uint64_t seed, uint64_t frame = 0) const;

    // The noise-free image in ADU, not rounded: min(e, fullWell) * M / gain + offset, clipped to the
    // ADC range. Away from saturation this is the mean of readOut (up to the < 0.5 ADU of rounding);
    // within a few noise sigmas of full well or of the ADC limits the mean of readOut is lower,
    // because there the noise is clipped.
    std::vector<double> expectedAdu(const std::vector<double>& expectedElectrons) const;

private:
    void checkMapSize(size_t pixels) const;
    DetectorOptions options_;
};

// Samplers used by readOut, exposed for the statistical tests.
// Poisson: inversion for mean < 10, Hörmann's PTRS (transformed rejection) up to 1e7, and a rounded
// normal above (its skewness 1/sqrt(mean) < 3e-4 there, and PTRS's log-density acceptance test
// starts losing digits to cancellation). Returns an integer-valued double; mean must be >= 0.
double samplePoisson(double mean, Rng& rng);
// Gamma(shape, scale) for shape >= 1 (Marsaglia & Tsang 2000).
double sampleGamma(double shape, double scale, Rng& rng);
// Standard normal (Box-Muller, one value per call so the stream use is fixed per sample).
double sampleStandardNormal(Rng& rng);

// The median of a chi-square of one degree of freedom. A squared half difference is its pixel's variance times
// such a chi-square, so a median over pixels reads that variance at this fraction, where slots' variance of 15
// degrees of freedom reads nearly all of it: the adaptive mode divides the field's by it to weigh both alike.
constexpr double kMedianOfChiSquare1 = 0.45493642;

// The median, over the pixels at or above the `quantile` of `signal` (e⁻), of variance / (signal + dark +
// read²): a Monte Carlo part's noise against the camera's, as the adaptive mode judges its field and photons.
double medianVarianceOverCamera(const std::vector<double>& variance, const std::vector<double>& signal, double quantile, double darkElectrons,
                                double readNoiseElectrons);

}  // namespace fluorosim::optics
