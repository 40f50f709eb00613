#include "render/film.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <array>
#include <istream>
#include <ostream>
#include <string>

#include "core/errors.h"
#include "core/memory_cap.h"

namespace fluorosim {

Film::Film(int width, int height, double lambdaMin, double lambdaMax, double binWidth, ColorMatchingFunctions cmf,
           bool separateComponents)
    : width_(width), height_(height), lambdaMin_(lambdaMin), lambdaMax_(lambdaMax), binWidth_(binWidth), separate_(separateComponents), cmf_(std::move(cmf)) {
    if (width <= 0 || height <= 0 || static_cast<int64_t>(width) * height > (int64_t(1) << 26))
        throw ConfigError("film resolution must be positive and at most 2^26 pixels, got " + std::to_string(width) + "x" +
                          std::to_string(height));
    if (!(binWidth > 0) || (lambdaMax - lambdaMin) / binWidth > 4000)
        throw ConfigError("spectral bin width must be positive and give at most 4000 bins, got " + std::to_string(binWidth) + " nm");
    const int bins = binCount(lambdaMin, lambdaMax, binWidth);
    requireMemory(estimatedBytes(width, height, bins),
                  "film of " + std::to_string(width) + "x" + std::to_string(height) + " pixels with " + std::to_string(bins) + " spectral bins");
    // The last bin ends at lambdaMax even when the range is not a multiple of the bin width.
    for (int b = 0; b < bins; ++b) {
        const double lo = lambdaMin + b * binWidth, hi = std::min(lambdaMax, lo + binWidth);
        binCenters_.push_back(0.5 * (lo + hi));
        binWidths_.push_back(hi - lo);
    }
    yIntegral_ = cmf_.y.integral();
    if (!(yIntegral_ > 0)) throw ConfigError("colour matching function y has zero integral");
    const size_t pixels = static_cast<size_t>(width) * static_cast<size_t>(height);
    for (int c = 0; c < 2; ++c) {
        xyz_[c].assign(3 * pixels, 0.0);
        spectral_[c].assign(static_cast<size_t>(bins) * pixels, 0.0);
    }
    nonFinite_.assign(pixels, 0);
}

int Film::binCount(double lambdaMin, double lambdaMax, double binWidth) {
    return std::max(1, static_cast<int>(std::ceil((lambdaMax - lambdaMin) / binWidth - 1e-9)));
}

double Film::estimatedBytes(int width, int height, int bins) {
    const double pixels = static_cast<double>(width) * static_cast<double>(height);
    const double perPixelAndChannel = 2 * 8    // elastic and fluorescent sums, double
                                      + 3 * 4;  // total, elastic and fluorescent layers as floats in the EXR image
    // + non-finite counts, and a pass's staged samples (one per pixel and sample of the pass).
    return pixels * ((3.0 + bins) * perPixelAndChannel + 4 + static_cast<double>(sizeof(Row::Sample)));
}

void Film::addSample(int x, int y, const PathRadiance& L, const SampledWavelengths& wl) { addSpectra(x, y, L.elastic, L.fluorescent, wl); }

void Film::addSpectra(int x, int y, const SampledSpectrum& elastic, const SampledSpectrum& fluorescent, const SampledWavelengths& wl) {
    const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
    if (!elastic.isFinite() || !fluorescent.isFinite()) {
        ++nonFinite_[pixel];
        return;
    }
    const size_t bins = static_cast<size_t>(binCount());
    for (int c = 0; c < 2; ++c) accumulate(&xyz_[c][3 * pixel], &spectral_[c][pixel * bins], c == kElastic ? elastic : fluorescent, wl);
}

void Film::addSample(Row& row, int x, const PathRadiance& L, const SampledWavelengths& wl) const {
    row.samples.push_back(Row::Sample{x, L.elastic, L.fluorescent, wl});
}

// One pixel of one component: `xyz` holds its 3 sums, `spectral` its bins.
void Film::accumulate(double* xyz, double* spectral, const SampledSpectrum& L, const SampledWavelengths& wl) const {
    const int bins = binCount();
    for (int i = 0; i < kNumWavelengths; ++i) {
        if (wl.pdf[i] == 0 || L[i] == 0) continue;
        const double c = L[i] / wl.pdf[i] / kNumWavelengths;
        const double l = wl.lambda[i];
        xyz[0] += c * cmf_.x(l) / yIntegral_;
        xyz[1] += c * cmf_.y(l) / yIntegral_;
        xyz[2] += c * cmf_.z(l) / yIntegral_;
        // A line exactly at the range maximum belongs to the last bin.
        const int b = std::min(bins - 1, static_cast<int>(std::floor((l - lambdaMin_) / binWidth_)));
        if (b >= 0 && b < bins) spectral[b] += c / binWidths_[static_cast<size_t>(b)];
    }
}

void Film::addSplat(int x, int y, double lambdaNm, double value, bool fluorescent) {
    const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
    if (!std::isfinite(value)) {
        ++nonFinite_[pixel];
        return;
    }
    if (lambdaNm < lambdaMin_ || lambdaNm > lambdaMax_) return;
    const int c = fluorescent ? kFluorescent : kElastic;
    double* xyz = &xyz_[c][3 * pixel];
    xyz[0] += value * cmf_.x(lambdaNm) / yIntegral_;
    xyz[1] += value * cmf_.y(lambdaNm) / yIntegral_;
    xyz[2] += value * cmf_.z(lambdaNm) / yIntegral_;
    const int bins = binCount();
    const int b = std::min(bins - 1, static_cast<int>(std::floor((lambdaNm - lambdaMin_) / binWidth_)));
    spectral_[c][pixel * static_cast<size_t>(bins) + static_cast<size_t>(b)] += value / binWidths_[static_cast<size_t>(b)];
}

void Film::commit(const Row& r) {
    for (const Row::Sample& s : r.samples) addSpectra(s.x, r.y, s.elastic, s.fluorescent, s.wl);
}

namespace {

template <class T>
void writeArray(std::ostream& out, const std::vector<T>& v) {
    const uint64_t n = v.size();
    out.write(reinterpret_cast<const char*>(&n), sizeof n);
    out.write(reinterpret_cast<const char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
}

template <class T>
void readArray(std::istream& in, std::vector<T>& v, const char* what) {
    uint64_t n = 0;
    in.read(reinterpret_cast<char*>(&n), sizeof n);
    if (!in) throw IoError(std::string("film state: truncated before ") + what);
    if (n != v.size())
        throw ConfigError(std::string("film state: ") + what + " holds " + std::to_string(n) + " values, this film " + std::to_string(v.size()));
    in.read(reinterpret_cast<char*>(v.data()), static_cast<std::streamsize>(n * sizeof(T)));
    if (!in) throw IoError(std::string("film state: truncated in ") + what);
}

}  // namespace

void Film::writeState(std::ostream& out) const {
    const int32_t dims[4] = {width_, height_, binCount(), separate_ ? 1 : 0};
    out.write(reinterpret_cast<const char*>(dims), sizeof dims);
    for (int c = 0; c < 2; ++c) {
        writeArray(out, xyz_[c]);
        writeArray(out, spectral_[c]);
    }
    writeArray(out, nonFinite_);
}

void Film::readState(std::istream& in) {
    int32_t dims[4] = {};
    in.read(reinterpret_cast<char*>(dims), sizeof dims);
    if (!in) throw IoError("film state: truncated");
    if (dims[0] != width_ || dims[1] != height_ || dims[2] != binCount() || dims[3] != (separate_ ? 1 : 0))
        throw ConfigError("film state: " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + " pixels, " + std::to_string(dims[2]) +
                          " bins" + (dims[3] ? " with" : " without") + " fluorescent layers; this render has " + std::to_string(width_) + "x" +
                          std::to_string(height_) + ", " + std::to_string(binCount()) + (separate_ ? " with" : " without"));
    for (int c = 0; c < 2; ++c) {
        readArray(in, xyz_[c], "XYZ sums");
        readArray(in, spectral_[c], "spectral sums");
    }
    readArray(in, nonFinite_, "non-finite counts");
}

ExrImage Film::image(int spp) const {
    ExrImage img;
    img.width = width_;
    img.height = height_;
    const size_t pixels = static_cast<size_t>(width_) * static_cast<size_t>(height_);
    const size_t bins = binCenters_.size();
    const double inv = spp > 0 ? 1.0 / spp : 0.0;
    // weights[c]: how much of each component goes into the layer.
    auto rgbOf = [&](std::array<double, 2> weights) {
        std::vector<float> rgb(3 * pixels);
        for (size_t p = 0; p < pixels; ++p) {
            std::array<double, 3> xyz{};
            for (int c = 0; c < 2; ++c)
                for (int k = 0; k < 3; ++k) xyz[static_cast<size_t>(k)] += weights[static_cast<size_t>(c)] * xyz_[c][3 * p + static_cast<size_t>(k)] * inv;
            const Rgb v = xyzToLinearSrgb({xyz[0], xyz[1], xyz[2]});
            for (int k = 0; k < 3; ++k) rgb[3 * p + static_cast<size_t>(k)] = static_cast<float>(v[static_cast<size_t>(k)]);
        }
        return rgb;
    };
    auto spectralOf = [&](std::array<double, 2> weights, std::string prefix) {
        SpectralLayer layer;
        layer.prefix = std::move(prefix);
        layer.wavelengthsNm = binCenters_;
        layer.values.resize(bins * pixels);
        for (size_t p = 0; p < pixels; ++p)
            for (size_t b = 0; b < bins; ++b)
                layer.values[b * pixels + p] = static_cast<float>(
                    (weights[0] * spectral_[0][p * bins + b] + weights[1] * spectral_[1][p * bins + b]) * inv);
        return layer;
    };
    img.rgb = rgbOf({1, 1});
    img.spectral.push_back(spectralOf({1, 1}, ""));
    if (separate_) {
        img.rgbLayers.push_back({"elastic", rgbOf({1, 0})});
        img.rgbLayers.push_back({"fluorescent", rgbOf({0, 1})});
        img.spectral.push_back(spectralOf({1, 0}, "elastic"));
        img.spectral.push_back(spectralOf({0, 1}, "fluorescent"));
    }
    return img;
}

uint64_t Film::nonFiniteSamples() const { return std::accumulate(nonFinite_.begin(), nonFinite_.end(), uint64_t(0)); }

double Film::meanLuminance(int spp) const {
    double sum = 0;
    for (const auto& xyz : xyz_)
        for (size_t p = 1; p < xyz.size(); p += 3) sum += xyz[p];
    return spp > 0 ? sum / spp / (static_cast<double>(width_) * height_) : 0.0;
}

Film Film::band(int rows) const { return Film(width_, rows, lambdaMin_, lambdaMax_, binWidth_, cmf_, separate_); }

void Film::placeRows(int firstRow, const Film& band) {
    if (band.width_ != width_ || band.binCount() != binCount() || band.separate_ != separate_ || firstRow < 0 ||
        firstRow + band.height_ > height_)
        throw Error("a film band of " + std::to_string(band.width_) + "x" + std::to_string(band.height_) + " at row " +
                    std::to_string(firstRow) + " does not fit a film of " + std::to_string(width_) + "x" + std::to_string(height_));
    const size_t first = static_cast<size_t>(firstRow) * static_cast<size_t>(width_), bins = static_cast<size_t>(binCount());
    for (int c = 0; c < 2; ++c) {
        std::copy(band.xyz_[c].begin(), band.xyz_[c].end(), xyz_[c].begin() + static_cast<std::ptrdiff_t>(3 * first));
        std::copy(band.spectral_[c].begin(), band.spectral_[c].end(), spectral_[c].begin() + static_cast<std::ptrdiff_t>(bins * first));
    }
    std::copy(band.nonFinite_.begin(), band.nonFinite_.end(), nonFinite_.begin() + static_cast<std::ptrdiff_t>(first));
}

std::string Film::sums() const {
    std::string bytes;
    const auto append = [&](const auto& v) {
        bytes.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(v[0]));
    };
    for (int c = 0; c < 2; ++c) append(xyz_[c]);
    for (int c = 0; c < 2; ++c) append(spectral_[c]);
    append(nonFinite_);
    return bytes;
}

void Film::setSums(std::string_view bytes) {
    size_t expected = nonFinite_.size() * sizeof(uint32_t);
    for (int c = 0; c < 2; ++c) expected += (xyz_[c].size() + spectral_[c].size()) * sizeof(double);
    if (bytes.size() != expected)
        throw Error("film sums of " + std::to_string(bytes.size()) + " bytes for a film that needs " + std::to_string(expected));
    size_t at = 0;
    const auto take = [&](auto& v) {
        std::memcpy(v.data(), bytes.data() + at, v.size() * sizeof(v[0]));
        at += v.size() * sizeof(v[0]);
    };
    for (int c = 0; c < 2; ++c) take(xyz_[c]);
    for (int c = 0; c < 2; ++c) take(spectral_[c]);
    take(nonFinite_);
}

}  // namespace fluorosim
