#include "media/henyey_greenstein.h"

#include <cmath>
#include <string>

#include "core/errors.h"
#include "core/math.h"

namespace fluorosim {

HenyeyGreenstein::HenyeyGreenstein(double g) : g_(g) {
    if (!(g > -1.0 && g < 1.0))
        throw ConfigError("Henyey-Greenstein asymmetry g must lie in (-1, 1), got " + std::to_string(g));
}

double HenyeyGreenstein::pdfCos(double c) const {
    const double denom = 1.0 + g_ * g_ - 2.0 * g_ * c;
    return kInv4Pi * (1.0 - g_ * g_) / (denom * std::sqrt(denom));
}

Vec3 HenyeyGreenstein::sample(const Vec3& dirIn, double u1, double u2, double* pdfOut) const {
    const double cosTheta = sampleCos(u1);
    const double sinTheta = safeSqrt(1.0 - cosTheta * cosTheta);
    const double phi = 2.0 * kPi * u2;
    const Frame f = Frame::fromNormal(dirIn);
    if (pdfOut) *pdfOut = pdfCos(cosTheta);
    return f.toWorld({sinTheta * std::cos(phi), sinTheta * std::sin(phi), cosTheta});
}

}  // namespace fluorosim
