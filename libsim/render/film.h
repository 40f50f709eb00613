#pragma once
// Per-pixel spectral and XYZ accumulation. Each pixel is written by one work item at a time, in
// sample order, so the image is bit-identical for any thread count. The elastic and fluorescent
// parts of each sample are accumulated apart; the main image is their sum, and with
// `separateComponents` the image also carries them as "elastic" and "fluorescent" layers.
#include <array>
#include <cstdint>
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
    Film(int width, int height, double lambdaMin, double lambdaMax, double binWidth, ColorMatchingFunctions cmf,
         bool separateComponents = false);
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
    void accumulate(size_t pixel, Component c, const SampledSpectrum& L, const SampledWavelengths& wl);

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
