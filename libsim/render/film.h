#pragma once
// Per-pixel spectral and XYZ accumulation. Each pixel is written by one work item at a time, in
// sample order, so the image is bit-identical for any thread count. The elastic and fluorescent
// parts of each sample are accumulated apart; the main image is their sum, and with
// `separateComponents` the image also carries them as "elastic" and "fluorescent" layers.
#include <array>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <string_view>
#include <vector>

#include "io/image_io.h"
#include "render/path_tracer.h"
#include "spectral/color.h"
#include "spectral/sampled_wavelengths.h"

namespace fluorosim {

class Film {
public:
    // Throws ConfigError for a bad size, or one whose memory (estimatedBytes) exceeds the memory cap.
    Film(int width, int height, double lambdaMin, double lambdaMax, double binWidth, ColorMatchingFunctions cmf,
         bool separateComponents = false);
    // Spectral bins for a range and bin width: the last bin ends at lambdaMax.
    static int binCount(double lambdaMin, double lambdaMax, double binWidth);
    // Memory a render holds for a film of this size: the accumulators, the copy of the rows of a pass in
    // progress (render() stages them), and the float image written out; about 44 bytes per pixel and bin.
    static double estimatedBytes(int width, int height, int bins);
    int width() const { return width_; }
    int height() const { return height_; }
    int binCount() const { return static_cast<int>(binCenters_.size()); }
    const std::vector<double>& binCenters() const { return binCenters_; }

    // Adds one path's radiance estimate; non-finite estimates are counted and dropped.
    void addSample(int x, int y, const PathRadiance& L, const SampledWavelengths& wl);
    // Mean over `samplesPerPixel`: spectral radiance per bin (per nm) and XYZ (Y = luminance-weighted
    // radiance normalized so a flat spectrum of 1 gives Y = 1).
    ExrImage image(int samplesPerPixel) const;
    uint64_t nonFiniteSamples() const;
    double meanLuminance(int samplesPerPixel) const;

    // One row's samples of a pass, staged: render() traces a pass into rows and commits them when the
    // whole pass is done, so a pass cancelled half way leaves the film at its last finished pass.
    // Committing replays the samples in order, so the sums are bit-identical to addSample(x, y, ...).
    // A row holds only its pass's samples (not a copy of the row's sums), and reset() keeps its
    // storage, so a pass costs no allocation or copy in proportion to the width times the bins.
    struct Row {
        struct Sample {
            int x;
            SampledSpectrum elastic, fluorescent;
            SampledWavelengths wl;
        };
        int y = -1;
        std::vector<Sample> samples;
        void reset(int row) {
            y = row;
            samples.clear();
        }
    };
    void addSample(Row& row, int x, const PathRadiance& L, const SampledWavelengths& wl) const;
    void commit(const Row& row);
    // A light-traced contribution to pixel (x, y)'s fluorescent or elastic layer (render/light_tracer.h):
    // spectral radiance integrated over wavelength at `lambdaNm`, already divided by the photons traced per
    // sample, so that image() averages it with the camera samples. Outside the spectral range it adds nothing.
    void addSplat(int x, int y, double lambdaNm, double value, bool fluorescent);

    // The accumulators, bit for bit, for render checkpoints (render/checkpoint.h). readState throws
    // IoError for a short stream and ConfigError for a state of another size.
    void writeState(std::ostream& out) const;
    void readState(std::istream& in);

    // An empty film like this one (width, bins, layers) with `rows` rows: a band of the image.
    Film band(int rows) const;
    // A band of this image rendered elsewhere (RenderOptions::firstRow): `band` has this film's width
    // and bins, and its sums become rows [firstRow, firstRow + band.height()) here, exactly.
    void placeRows(int firstRow, const Film& band);
    // The film's sums as bytes and back (same dimensions), so that a band can travel between processes.
    std::string sums() const;
    void setSums(std::string_view bytes);  // throws Error when the size does not match

private:
    enum Component { kElastic = 0, kFluorescent = 1 };
    void accumulate(double* xyz, double* spectral, const SampledSpectrum& L, const SampledWavelengths& wl) const;
    void addSpectra(int x, int y, const SampledSpectrum& elastic, const SampledSpectrum& fluorescent, const SampledWavelengths& wl);

    int width_, height_;
    double lambdaMin_, lambdaMax_, binWidth_;
    bool separate_;
    std::vector<double> binCenters_, binWidths_;
    ColorMatchingFunctions cmf_;
    double yIntegral_;
    std::array<std::vector<double>, 2> xyz_;       // 3 per pixel, per component
    std::array<std::vector<double>, 2> spectral_;  // bins per pixel, per component
    std::vector<uint32_t> nonFinite_;
};

}  // namespace fluorosim
