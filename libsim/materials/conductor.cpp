#include "materials/fresnel.h"
#include "materials/material.h"
#include "materials/microfacet.h"

namespace fluorosim {
namespace {

class Conductor final : public Material {
public:
    Conductor(Spectrum eta, Spectrum k, double alpha) : eta_(std::move(eta)), k_(std::move(k)), distrib_(alpha), smooth_(TrowbridgeReitz::effectivelySmooth(alpha)) {}

    SampledSpectrum f(const Vec3& wo, const Vec3& wi, const SampledWavelengths& wl, double, TransportMode) const override {
        if (smooth_ || !sameHemisphere(wo, wi) || wo.z <= 0) return SampledSpectrum(0.0);
        const double cosO = wo.z, cosI = wi.z;
        Vec3 wm = wi + wo;
        if (dot(wm, wm) == 0) return SampledSpectrum(0.0);
        wm = normalize(wm);
        return fresnel(std::abs(dot(wo, wm)), wl) * (distrib_.D(wm) * distrib_.G(wo, wi) / (4 * cosI * cosO));
    }
    double pdf(const Vec3& wo, const Vec3& wi, double) const override {
        if (smooth_ || !sameHemisphere(wo, wi) || wo.z <= 0) return 0.0;
        Vec3 wm = wo + wi;
        if (dot(wm, wm) == 0) return 0.0;
        wm = faceForward(normalize(wm), Vec3(0, 0, 1));
        return distrib_.pdf(wo, wm) / (4 * std::abs(dot(wo, wm)));
    }
    std::optional<BsdfSample> sample(const Vec3& wo, double, double u1, double u2, const SampledWavelengths& wl,
                                     double eta, TransportMode mode) const override {
        if (wo.z <= 0) return std::nullopt;
        BsdfSample s;
        if (smooth_) {
            s.wi = Vec3(-wo.x, -wo.y, wo.z);
            s.f = fresnel(wo.z, wl) / std::abs(s.wi.z);
            s.pdf = 1.0;
            s.specular = true;
            return s;
        }
        const Vec3 wm = distrib_.sampleVisibleNormal(wo, u1, u2);
        s.wi = reflectAbout(wo, wm);
        if (!sameHemisphere(wo, s.wi)) return std::nullopt;
        s.pdf = distrib_.pdf(wo, wm) / (4 * std::abs(dot(wo, wm)));
        if (!(s.pdf > 0)) return std::nullopt;
        s.f = f(wo, s.wi, wl, eta, mode);
        return s;
    }
    bool isSpecular() const override { return smooth_; }

private:
    SampledSpectrum fresnel(double cosTheta, const SampledWavelengths& wl) const {
        SampledSpectrum r;
        for (int i = 0; i < kNumWavelengths; ++i)
            r[i] = fresnelConductor(cosTheta, {eta_(wl.lambda[i]), k_(wl.lambda[i])});
        return r;
    }
    Spectrum eta_, k_;
    TrowbridgeReitz distrib_;
    bool smooth_;
};

}  // namespace

std::unique_ptr<Material> makeConductor(Spectrum eta, Spectrum k, double alpha) {
    return std::make_unique<Conductor>(std::move(eta), std::move(k), alpha);
}

}  // namespace fluorosim
