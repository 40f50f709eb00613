#pragma once
// Channel colours, window/level, and the additive RGB composites the slice and image views show.
// A channel's value v maps to intensity clamp((v - low) / (high - low), 0, 1) times its colour; the
// channels add up and clip at 1, as in napari's additive blending and Fiji's composite mode.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "spectral/color.h"

namespace fluorosim::viewer {

using Colour = std::array<double, 3>;  // linear 0..1 per component

// "green", "magenta", "cyan", "yellow", "red", "blue", "orange", "white" or "#rrggbb"; ConfigError
// naming `what` otherwise.
Colour parseColour(const std::string& text, const std::string& what);
// Green, magenta, cyan, then yellow, red, blue, orange, white, repeating.
Colour defaultChannelColour(int channel);
// The colour of a wavelength (CIE 1931 to sRGB, clipped and scaled to a largest component of 1).
Colour wavelengthColour(double lambdaNm, const ColorMatchingFunctions& cmf);

struct Window {
    double low = 0, high = 1;
    double width() const { return high - low; }
    double level() const { return 0.5 * (high + low); }
    double intensity(double v) const;                       // 0..1
    static Window fromWidthLevel(double width, double level);
};

// Accumulates channel images into a float RGB buffer, then converts to 8-bit.
class Composite {
public:
    Composite(int width, int height) : width_(width), height_(height), rgb_(size_t(width) * height * 3, 0.f) {}
    // values[y * width + x] (rows from the bottom, as VTK images are stored).
    template <class Value>
    void add(const Value* values, const Window& window, const Colour& colour, size_t stride = 1) {
        for (size_t i = 0; i < size_t(width_) * height_; ++i) {
            const auto t = static_cast<float>(window.intensity(static_cast<double>(values[i * stride])));
            for (int c = 0; c < 3; ++c) rgb_[i * 3 + size_t(c)] += t * static_cast<float>(colour[size_t(c)]);
        }
    }
    std::vector<uint8_t> rgb8() const;
    int width() const { return width_; }
    int height() const { return height_; }

private:
    int width_, height_;
    std::vector<float> rgb_;
};

// A diverging map for signed values: blue (-limit) through black (0) to red (+limit).
std::array<uint8_t, 3> divergingColour(double value, double limit);

}  // namespace fluorosim::viewer
