#include "viewer/spectral_image.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <regex>

#include "core/errors.h"
#include "io/image_io.h"

namespace fluorosim::viewer {
namespace {

// Linear RGB of a layer, computed from its bands when it has no RGB channels.
std::vector<float> layerRgb(const SpectralImage& image, const SpectralLayerImage& layer, const ColorMatchingFunctions& cmf) {
    if (!layer.rgb.empty()) return layer.rgb;
    const size_t n = size_t(image.width) * image.height;
    std::vector<float> rgb(n * 3, 0.f);
    for (size_t b = 0; b < layer.bands.size(); ++b) {
        const double lo = b ? 0.5 * (layer.bands[b - 1].lambdaNm + layer.bands[b].lambdaNm) : layer.bands[b].lambdaNm;
        const double hi = b + 1 < layer.bands.size() ? 0.5 * (layer.bands[b].lambdaNm + layer.bands[b + 1].lambdaNm) : layer.bands[b].lambdaNm;
        const double width = layer.bands.size() > 1 ? hi - lo : 1.0;
        const double l = layer.bands[b].lambdaNm;
        const Rgb w = xyzToLinearSrgb({cmf.x(l) * width, cmf.y(l) * width, cmf.z(l) * width});
        for (size_t i = 0; i < n; ++i)
            for (int c = 0; c < 3; ++c) rgb[i * 3 + size_t(c)] += static_cast<float>(w[size_t(c)] * layer.bands[b].values[i]);
    }
    return rgb;
}

double percentile(std::vector<float> v, double p) {
    if (v.empty()) return 0;
    const auto k = static_cast<size_t>(std::clamp(p / 100.0, 0.0, 1.0) * double(v.size() - 1));
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
    return v[k];
}

}  // namespace

double spectralChannelWavelength(const std::string& channelName) {
    static const std::regex kBand(R"((?:.*\.)?S0\.(\d+),(\d+)nm)");
    std::smatch m;
    if (!std::regex_match(channelName, m, kBand)) return -1;
    return std::stod(m[1].str() + "." + m[2].str());
}

SpectralImage loadSpectralImage(const std::filesystem::path& file) {
    const ExrChannels exr = readExr(file.string());
    SpectralImage image;
    image.width = exr.width;
    image.height = exr.height;
    std::map<std::string, SpectralLayerImage> layers;
    for (const auto& [name, values] : exr.channels) {
        const double lambda = spectralChannelWavelength(name);
        if (lambda >= 0) {
            const size_t s = name.rfind("S0.");
            const std::string prefix = s > 0 ? name.substr(0, s - 1) : "";
            layers[prefix].prefix = prefix;
            layers[prefix].bands.push_back({lambda, values});
            continue;
        }
        const size_t dot = name.rfind('.');
        const std::string prefix = dot == std::string::npos ? "" : name.substr(0, dot);
        const std::string base = dot == std::string::npos ? name : name.substr(dot + 1);
        if (base != "R" && base != "G" && base != "B") continue;
        SpectralLayerImage& layer = layers[prefix];
        layer.prefix = prefix;
        if (layer.rgb.empty()) layer.rgb.assign(values.size() * 3, 0.f);
        const size_t c = base == "R" ? 0 : base == "G" ? 1 : 2;
        for (size_t i = 0; i < values.size(); ++i) layer.rgb[i * 3 + c] = values[i];
    }
    for (auto& [prefix, layer] : layers) {
        std::sort(layer.bands.begin(), layer.bands.end(), [](const SpectralBand& a, const SpectralBand& b) { return a.lambdaNm < b.lambdaNm; });
        if (prefix.empty()) image.layers.insert(image.layers.begin(), std::move(layer));
        else image.layers.push_back(std::move(layer));
    }
    if (image.layers.empty()) throw ConfigError(file.string() + ": the image has neither R, G, B nor spectral channels");
    return image;
}

std::vector<uint8_t> spectralImageRgb8(const SpectralImage& image, size_t layerIndex, int band, double exposure,
                                       const ColorMatchingFunctions& cmf) {
    const SpectralLayerImage& layer = image.layers.at(layerIndex);
    const size_t w = size_t(image.width), h = size_t(image.height);
    std::vector<float> rgb;
    if (band < 0) {
        rgb = layerRgb(image, layer, cmf);
    } else {
        const SpectralBand& b = layer.bands.at(size_t(band));
        const Colour tint = wavelengthColour(b.lambdaNm, cmf);
        rgb.resize(w * h * 3);
        for (size_t i = 0; i < w * h; ++i)
            for (size_t c = 0; c < 3; ++c) rgb[i * 3 + c] = static_cast<float>(b.values[i] * tint[c]);
    }
    std::vector<uint8_t> out(w * h * 3);
    for (size_t y = 0; y < h; ++y)
        for (size_t x = 0; x < w; ++x)
            for (size_t c = 0; c < 3; ++c) {
                const double v = std::clamp(exposure * rgb[(y * w + x) * 3 + c], 0.0, 1.0);
                out[((h - 1 - y) * w + x) * 3 + c] = static_cast<uint8_t>(std::lround(srgbEncode(v) * 255.0));
            }
    return out;
}

double autoExposure(const SpectralImage& image, size_t layerIndex, int band) {
    const SpectralLayerImage& layer = image.layers.at(layerIndex);
    std::vector<float> v;
    if (band >= 0) {
        v = layer.bands.at(size_t(band)).values;
    } else if (!layer.rgb.empty()) {
        v.resize(layer.rgb.size() / 3);
        for (size_t i = 0; i < v.size(); ++i)
            v[i] = 0.2126f * layer.rgb[i * 3] + 0.7152f * layer.rgb[i * 3 + 1] + 0.0722f * layer.rgb[i * 3 + 2];
    } else {
        v.assign(size_t(image.width) * image.height, 0.f);
        for (const SpectralBand& b : layer.bands)
            for (size_t i = 0; i < v.size(); ++i) v[i] += b.values[i];
    }
    const double p = percentile(std::move(v), 99.5);
    return p > 0 ? 1.0 / p : 1.0;
}

}  // namespace fluorosim::viewer
