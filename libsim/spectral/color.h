#pragma once
// CIE 1931 XYZ from spectra, and XYZ to linear sRGB (D65).
#include <array>

#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

struct ColorMatchingFunctions {
    TabulatedSpectrum x, y, z;
};

using Rgb = std::array<double, 3>;
using Xyz = std::array<double, 3>;

// IEC 61966-2-1 matrix.
inline Rgb xyzToLinearSrgb(const Xyz& c) {
    return {3.2404542 * c[0] - 1.5371385 * c[1] - 0.4985314 * c[2],
            -0.9692660 * c[0] + 1.8760108 * c[1] + 0.0415560 * c[2],
            0.0556434 * c[0] - 0.2040259 * c[1] + 1.0572252 * c[2]};
}

// sRGB transfer function for display previews.
double srgbEncode(double linear);

}  // namespace fluorosim
