#pragma once
// Isotropic Trowbridge-Reitz (GGX) microfacet distribution with visible-normal sampling (Heitz 2018).
// Local frame: z is the macro-surface normal.
#include <cmath>

#include "core/math.h"
#include "core/vec3.h"

namespace fluorosim {

class TrowbridgeReitz {
public:
    explicit TrowbridgeReitz(double alpha) : alpha_(std::max(alpha, 1e-4)) {}
    double alpha() const { return alpha_; }
    // Below this roughness the surface is treated as perfectly smooth (specular).
    static bool effectivelySmooth(double alpha) { return alpha < 1e-3; }

    double D(const Vec3& wm) const;
    double lambda(const Vec3& w) const;
    double G1(const Vec3& w) const { return 1.0 / (1.0 + lambda(w)); }
    double G(const Vec3& wo, const Vec3& wi) const { return 1.0 / (1.0 + lambda(wo) + lambda(wi)); }
    // Distribution of visible normals from direction w, and its pdf.
    double visibleD(const Vec3& w, const Vec3& wm) const {
        return G1(w) / std::abs(w.z) * D(wm) * std::abs(dot(w, wm));
    }
    double pdf(const Vec3& w, const Vec3& wm) const { return visibleD(w, wm); }
    Vec3 sampleVisibleNormal(const Vec3& w, double u1, double u2) const;

private:
    double alpha_;
};

inline Vec3 reflectAbout(const Vec3& wo, const Vec3& n) { return -wo + n * (2.0 * dot(wo, n)); }
inline bool sameHemisphere(const Vec3& a, const Vec3& b) { return a.z * b.z > 0; }

}  // namespace fluorosim
