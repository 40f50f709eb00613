#pragma once
// Spectral OpenEXR images as `fluorosim render` writes them (libsim/io/image_io.h): linear sRGB in
// R, G, B and one channel per spectral bin in the layout of Fichet et al. 2021 ("S0.555,000000nm",
// with a layer prefix such as "fluorescent."). The viewer shows the sRGB composite, or one band
// tinted with its wavelength's colour; both are scaled by an exposure and sRGB-encoded.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "viewer/colour.h"

namespace fluorosim::viewer {

struct SpectralBand {
    double lambdaNm = 0;
    std::vector<float> values;  // row-major from the top
};

struct SpectralLayerImage {
    std::string prefix;  // "" for the main layer
    std::vector<float> rgb;  // interleaved linear sRGB, empty when the layer has none
    std::vector<SpectralBand> bands;  // by wavelength
};

struct SpectralImage {
    int width = 0, height = 0;
    std::vector<SpectralLayerImage> layers;  // the main layer first
};

// Throws IoError for an unreadable file, ConfigError for an image with neither RGB nor spectral
// channels.
SpectralImage loadSpectralImage(const std::filesystem::path& file);

// Parses a spectral channel name ("S0.555,000000nm", possibly after "prefix."): the wavelength, or a
// negative value when the name is not one.
double spectralChannelWavelength(const std::string& channelName);

// The view: band -1 is the sRGB composite (from R, G, B, or from the bands through the CIE matching
// functions when the layer has no RGB), band b ≥ 0 that band alone in its wavelength's colour.
// Exposure multiplies linear values before sRGB encoding. Output rows run from the bottom (VTK order).
std::vector<uint8_t> spectralImageRgb8(const SpectralImage& image, size_t layer, int band, double exposure,
                                       const ColorMatchingFunctions& cmf);
// 1 / (the 99.5th percentile of the luminance, or of the band): maps most of the image below white.
double autoExposure(const SpectralImage& image, size_t layer, int band);

}  // namespace fluorosim::viewer
