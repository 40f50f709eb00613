#pragma once
// Henyey-Greenstein phase function. Convention: cosTheta = dot(incoming propagation direction,
// outgoing propagation direction), so g > 0 scatters forward.
#include <cmath>

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
    // Inline: it sits in the innermost loop of the slab validator.
    double sampleCos(double u) const {
        // Below 1e-6 the closed form loses digits to cancellation; the isotropic limit differs from HG
        // by O(g) in pdf, which is below any measurable level there.
        if (std::abs(g_) < 1e-6) return 1.0 - 2.0 * u;
        const double s = (1.0 - g_ * g_) / (1.0 - g_ + 2.0 * g_ * u);
        const double c = (1.0 + g_ * g_ - s * s) / (2.0 * g_);
        return c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c);
    }
    Vec3 sample(const Vec3& dirIn, double u1, double u2, double* pdfOut = nullptr) const;

private:
    double g_;
};

}  // namespace fluorosim
