#pragma once
// Henyey-Greenstein phase function. Convention: cosTheta = dot(incoming propagation direction,
// outgoing propagation direction), so g > 0 scatters forward.
#include "core/vec3.h"

namespace fluorosim {

class HenyeyGreenstein {
public:
    // Throws ConfigError unless -1 < g < 1.
    explicit HenyeyGreenstein(double g);
    double g() const { return g_; }

    double pdfCos(double cosTheta) const;  // per steradian, as a function of cos(theta)
    double pdf(const Vec3& dirIn, const Vec3& dirOut) const { return pdfCos(dot(dirIn, dirOut)); }
    // Inverts the CDF of cos(theta). Stable for g -> 0 (exact isotropic limit) and |g| -> 1.
    double sampleCos(double u) const;
    Vec3 sample(const Vec3& dirIn, double u1, double u2, double* pdfOut = nullptr) const;

private:
    double g_;
};

}  // namespace fluorosim
