#include <algorithm>

#include "core/sampling.h"
#include "materials/fresnel.h"
#include "materials/material.h"
#include "materials/microfacet.h"

namespace fluorosim {
namespace {

// Diffuse base under a rough dielectric coat; a one-sample mixture of the two lobes is sampled.
class Plastic final : public Material {
public:
    Plastic(Spectrum diffuse, double ior, double alpha) : diffuse_(std::move(diffuse)), ior_(ior), distrib_(std::max(alpha, 1e-3)) {}

    SampledSpectrum f(const Vec3& wo, const Vec3& wi, const SampledWavelengths& wl, double, TransportMode) const override {
        if (wo.z <= 0 || wi.z <= 0) return SampledSpectrum(0.0);
        const Vec3 wm = normalize(wo + wi);
        const double spec = distrib_.D(wm) * distrib_.G(wo, wi) * fresnelDielectric(dot(wo, wm), ior_) / (4 * wo.z * wi.z);
        const double trans = (1 - fresnelDielectric(wo.z, ior_)) * (1 - fresnelDielectric(wi.z, ior_));
        return diffuse_.sample(wl) * (trans * kInvPi) + SampledSpectrum(spec);
    }
    double pdf(const Vec3& wo, const Vec3& wi, double) const override {
        if (wo.z <= 0 || wi.z <= 0) return 0.0;
        const double pSpec = specularProbability(wo);
        const Vec3 wm = normalize(wo + wi);
        const double specPdf = distrib_.pdf(wo, wm) / (4 * std::abs(dot(wo, wm)));
        return pSpec * specPdf + (1 - pSpec) * cosineHemispherePdf(wi.z);
    }
    std::optional<BsdfSample> sample(const Vec3& wo, double uc, double u1, double u2, const SampledWavelengths& wl,
                                     double eta, TransportMode mode) const override {
        if (wo.z <= 0) return std::nullopt;
        BsdfSample s;
        if (uc < specularProbability(wo)) {
            s.wi = reflectAbout(wo, distrib_.sampleVisibleNormal(wo, u1, u2));
            if (s.wi.z <= 0) return std::nullopt;
        } else {
            s.wi = sampleCosineHemisphere(u1, u2);
        }
        s.pdf = pdf(wo, s.wi, eta);
        if (!(s.pdf > 0)) return std::nullopt;
        s.f = f(wo, s.wi, wl, eta, mode);
        return s;
    }

private:
    // Fresnel at normal-ish incidence is small; keep a floor so the highlight is always sampled.
    double specularProbability(const Vec3& wo) const {
        return std::clamp(fresnelDielectric(wo.z, ior_), 0.1, 0.9);
    }
    Spectrum diffuse_;
    double ior_;
    TrowbridgeReitz distrib_;
};

}  // namespace

std::unique_ptr<Material> makePlastic(Spectrum diffuse, double ior, double alpha) {
    return std::make_unique<Plastic>(std::move(diffuse), ior, alpha);
}

}  // namespace fluorosim
