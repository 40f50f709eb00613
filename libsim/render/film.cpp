#include "render/film.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "core/errors.h"

namespace fluorosim {

Film::Film(int width, int height, double lambdaMin, double lambdaMax, double binWidth, ColorMatchingFunctions cmf)
    : width_(width), height_(height), lambdaMin_(lambdaMin), binWidth_(binWidth), cmf_(std::move(cmf)) {
    if (width <= 0 || height <= 0 || static_cast<int64_t>(width) * height > (int64_t(1) << 26))
        throw ConfigError("film resolution must be positive and at most 2^26 pixels, got " + std::to_string(width) + "x" +
                          std::to_string(height));
    if (!(binWidth > 0) || (lambdaMax - lambdaMin) / binWidth > 4000)
        throw ConfigError("spectral bin width must be positive and give at most 4000 bins, got " + std::to_string(binWidth) + " nm");
    const int bins = std::max(1, static_cast<int>(std::ceil((lambdaMax - lambdaMin) / binWidth - 1e-9)));
    // The last bin ends at lambdaMax even when the range is not a multiple of the bin width.
    for (int b = 0; b < bins; ++b) {
        const double lo = lambdaMin + b * binWidth, hi = std::min(lambdaMax, lo + binWidth);
        binCenters_.push_back(0.5 * (lo + hi));
        binWidths_.push_back(hi - lo);
    }
    yIntegral_ = cmf_.y.integral();
    if (!(yIntegral_ > 0)) throw ConfigError("colour matching function y has zero integral");
    const size_t pixels = static_cast<size_t>(width) * static_cast<size_t>(height);
    xyz_.assign(3 * pixels, 0.0);
    spectral_.assign(static_cast<size_t>(bins) * pixels, 0.0);
    nonFinite_.assign(pixels, 0);
}

void Film::addSample(int x, int y, const SampledSpectrum& L, const SampledWavelengths& wl) {
    const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
    if (!L.isFinite()) {
        ++nonFinite_[pixel];
        return;
    }
    const int bins = binCount();
    for (int i = 0; i < kNumWavelengths; ++i) {
        if (wl.pdf[i] == 0 || L[i] == 0) continue;
        const double c = L[i] / wl.pdf[i] / kNumWavelengths;
        const double l = wl.lambda[i];
        xyz_[3 * pixel + 0] += c * cmf_.x(l) / yIntegral_;
        xyz_[3 * pixel + 1] += c * cmf_.y(l) / yIntegral_;
        xyz_[3 * pixel + 2] += c * cmf_.z(l) / yIntegral_;
        // A line exactly at the range maximum belongs to the last bin.
        const int b = std::min(bins - 1, static_cast<int>(std::floor((l - lambdaMin_) / binWidth_)));
        if (b >= 0 && b < bins) spectral_[pixel * static_cast<size_t>(bins) + static_cast<size_t>(b)] += c / binWidths_[static_cast<size_t>(b)];
    }
}

ExrImage Film::image(int spp) const {
    ExrImage img;
    img.width = width_;
    img.height = height_;
    const size_t pixels = static_cast<size_t>(width_) * static_cast<size_t>(height_);
    const double inv = spp > 0 ? 1.0 / spp : 0.0;
    img.rgb.resize(3 * pixels);
    for (size_t p = 0; p < pixels; ++p) {
        const Rgb rgb = xyzToLinearSrgb({xyz_[3 * p] * inv, xyz_[3 * p + 1] * inv, xyz_[3 * p + 2] * inv});
        for (int c = 0; c < 3; ++c) img.rgb[3 * p + static_cast<size_t>(c)] = static_cast<float>(rgb[static_cast<size_t>(c)]);
    }
    SpectralLayer layer;
    layer.wavelengthsNm = binCenters_;
    const size_t bins = binCenters_.size();
    layer.values.resize(bins * pixels);
    for (size_t p = 0; p < pixels; ++p)
        for (size_t b = 0; b < bins; ++b) layer.values[b * pixels + p] = static_cast<float>(spectral_[p * bins + b] * inv);
    img.spectral.push_back(std::move(layer));
    return img;
}

uint64_t Film::nonFiniteSamples() const { return std::accumulate(nonFinite_.begin(), nonFinite_.end(), uint64_t(0)); }

double Film::meanLuminance(int spp) const {
    double sum = 0;
    for (size_t p = 1; p < xyz_.size(); p += 3) sum += xyz_[p];
    return spp > 0 ? sum / spp / (static_cast<double>(width_) * height_) : 0.0;
}

}  // namespace fluorosim
