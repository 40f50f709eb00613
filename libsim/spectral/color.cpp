#include "spectral/color.h"

#include <algorithm>
#include <cmath>

namespace fluorosim {

double srgbEncode(double v) {
    if (!(v > 0)) return 0.0;
    if (v <= 0.0031308) return 12.92 * v;
    return std::min(1.0, 1.055 * std::pow(v, 1.0 / 2.4) - 0.055);
}

}  // namespace fluorosim
