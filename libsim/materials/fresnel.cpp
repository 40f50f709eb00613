#include "materials/fresnel.h"

#include <algorithm>
#include <cmath>

#include "core/math.h"
#include "core/vec3.h"

namespace fluorosim {

double fresnelDielectric(double cosThetaI, double eta) {
    cosThetaI = std::clamp(cosThetaI, -1.0, 1.0);
    if (cosThetaI < 0) {
        eta = 1.0 / eta;
        cosThetaI = -cosThetaI;
    }
    if (eta == 1.0) return 0.0;
    const double sin2ThetaI = 1.0 - cosThetaI * cosThetaI;
    const double sin2ThetaT = sin2ThetaI / (eta * eta);
    if (sin2ThetaT >= 1.0) return 1.0;
    const double cosThetaT = safeSqrt(1.0 - sin2ThetaT);
    const double rParl = (eta * cosThetaI - cosThetaT) / (eta * cosThetaI + cosThetaT);
    const double rPerp = (cosThetaI - eta * cosThetaT) / (cosThetaI + eta * cosThetaT);
    return 0.5 * (rParl * rParl + rPerp * rPerp);
}

double fresnelConductor(double cosThetaI, std::complex<double> eta) {
    using C = std::complex<double>;
    if (std::norm(eta) == 0.0) return 1.0;  // a vanishing index reflects everything (and 0/0 would be NaN)
    cosThetaI = std::clamp(cosThetaI, 0.0, 1.0);
    const double sin2ThetaI = 1.0 - cosThetaI * cosThetaI;
    const C sin2ThetaT = sin2ThetaI / (eta * eta);
    const C cosThetaT = std::sqrt(C(1.0) - sin2ThetaT);
    const C rParl = (eta * cosThetaI - cosThetaT) / (eta * cosThetaI + cosThetaT);
    const C rPerp = (cosThetaI - eta * cosThetaT) / (cosThetaI + eta * cosThetaT);
    return 0.5 * (std::norm(rParl) + std::norm(rPerp));
}

bool refract(const Vec3& wi, const Vec3& nIn, double eta, Vec3* wt, double* etap) {
    Vec3 n = nIn;
    double cosThetaI = dot(n, wi);
    if (cosThetaI < 0) {
        eta = 1.0 / eta;
        cosThetaI = -cosThetaI;
        n = -n;
    }
    const double sin2ThetaI = std::max(0.0, 1.0 - cosThetaI * cosThetaI);
    const double sin2ThetaT = sin2ThetaI / (eta * eta);
    if (sin2ThetaT >= 1.0) return false;
    const double cosThetaT = safeSqrt(1.0 - sin2ThetaT);
    *wt = -wi / eta + n * (cosThetaI / eta - cosThetaT);
    if (etap) *etap = eta;
    return true;
}

}  // namespace fluorosim
