#include "materials/microfacet.h"

namespace fluorosim {

double TrowbridgeReitz::D(const Vec3& wm) const {
    const double cos2 = wm.z * wm.z;
    if (cos2 <= 0) return 0.0;
    const double sin2 = std::max(0.0, 1.0 - cos2);
    const double tan2 = sin2 / cos2;
    if (std::isinf(tan2)) return 0.0;
    const double e = tan2 / (alpha_ * alpha_);
    return 1.0 / (kPi * alpha_ * alpha_ * cos2 * cos2 * sqr(1.0 + e));
}

double TrowbridgeReitz::lambda(const Vec3& w) const {
    const double cos2 = w.z * w.z;
    if (cos2 <= 0) return 1e30;
    const double tan2 = std::max(0.0, 1.0 - cos2) / cos2;
    return (std::sqrt(1.0 + alpha_ * alpha_ * tan2) - 1.0) / 2.0;
}

Vec3 TrowbridgeReitz::sampleVisibleNormal(const Vec3& w, double u1, double u2) const {
    Vec3 wh = normalize(Vec3(alpha_ * w.x, alpha_ * w.y, w.z));
    if (wh.z < 0) wh = -wh;
    const Vec3 t1 = wh.z < 0.99999 ? normalize(cross(Vec3(0, 0, 1), wh)) : Vec3(1, 0, 0);
    const Vec3 t2 = cross(wh, t1);
    // Uniform disk (polar), then warp the half-disk hidden by the projected hemisphere.
    const double r = std::sqrt(u1), phi = 2.0 * kPi * u2;
    double px = r * std::cos(phi), py = r * std::sin(phi);
    const double h = std::sqrt(std::max(0.0, 1.0 - px * px));
    py = lerp((1.0 + wh.z) / 2.0, h, py);
    const double pz = safeSqrt(1.0 - px * px - py * py);
    const Vec3 nh = t1 * px + t2 * py + wh * pz;
    return normalize(Vec3(alpha_ * nh.x, alpha_ * nh.y, std::max(1e-6, nh.z)));
}

}  // namespace fluorosim
