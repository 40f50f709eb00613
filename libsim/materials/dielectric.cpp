#include "materials/fresnel.h"
#include "materials/material.h"
#include "materials/microfacet.h"

namespace fluorosim {
namespace {

// pbrt-v4's DielectricBxDF: smooth or rough (GGX) interface with Fresnel-weighted lobe choice.
class Dielectric final : public Material {
public:
    explicit Dielectric(double alpha) : distrib_(alpha), smooth_(TrowbridgeReitz::effectivelySmooth(alpha)) {}

    SampledSpectrum f(const Vec3& wo, const Vec3& wi, const SampledWavelengths&, double eta, TransportMode mode) const override {
        if (eta == 1 || smooth_) return SampledSpectrum(0.0);
        double etap;
        Vec3 wm;
        if (!halfVector(wo, wi, eta, &etap, &wm)) return SampledSpectrum(0.0);
        const double F = fresnelDielectric(dot(wo, wm), eta);
        const double cosO = wo.z, cosI = wi.z;
        if (cosO * cosI > 0) return SampledSpectrum(distrib_.D(wm) * distrib_.G(wo, wi) * F / std::abs(4 * cosI * cosO));
        const double denom = sqr(dot(wi, wm) + dot(wo, wm) / etap) * cosI * cosO;
        double ft = distrib_.D(wm) * (1 - F) * distrib_.G(wo, wi) * std::abs(dot(wi, wm) * dot(wo, wm) / denom);
        if (mode == TransportMode::Radiance) ft /= sqr(etap);
        return SampledSpectrum(ft);
    }
    double pdf(const Vec3& wo, const Vec3& wi, double eta) const override {
        if (eta == 1 || smooth_) return 0.0;
        double etap;
        Vec3 wm;
        if (!halfVector(wo, wi, eta, &etap, &wm)) return 0.0;
        const double R = fresnelDielectric(dot(wo, wm), eta), T = 1 - R;
        if (wo.z * wi.z > 0) return distrib_.pdf(wo, wm) / (4 * std::abs(dot(wo, wm))) * R / (R + T);
        const double denom = sqr(dot(wi, wm) + dot(wo, wm) / etap);
        return distrib_.pdf(wo, wm) * std::abs(dot(wi, wm)) / denom * T / (R + T);
    }
    std::optional<BsdfSample> sample(const Vec3& wo, double uc, double u1, double u2, const SampledWavelengths& wl,
                                     double eta, TransportMode mode) const override {
        BsdfSample s;
        if (eta == 1 || smooth_) {
            const double R = fresnelDielectric(wo.z, eta), T = 1 - R;
            if (uc < R / (R + T)) {
                s.wi = Vec3(-wo.x, -wo.y, wo.z);
                s.f = SampledSpectrum(R / std::abs(s.wi.z));
                s.pdf = R / (R + T);
            } else {
                if (!refract(wo, Vec3(0, 0, 1), eta, &s.wi, &s.etap)) return std::nullopt;
                double ft = T / std::abs(s.wi.z);
                if (mode == TransportMode::Radiance) ft /= sqr(s.etap);
                s.f = SampledSpectrum(ft);
                s.pdf = T / (R + T);
                s.transmission = true;
            }
            s.specular = true;
            return s;
        }
        const Vec3 wm = distrib_.sampleVisibleNormal(wo, u1, u2);
        const double R = fresnelDielectric(dot(wo, wm), eta), T = 1 - R;
        if (uc < R / (R + T)) {
            s.wi = reflectAbout(wo, wm);
            if (!sameHemisphere(wo, s.wi)) return std::nullopt;
        } else {
            if (!refract(wo, wm, eta, &s.wi, &s.etap)) return std::nullopt;
            if (sameHemisphere(wo, s.wi) || s.wi.z == 0) return std::nullopt;
            s.transmission = true;
        }
        s.pdf = pdf(wo, s.wi, eta);
        if (!(s.pdf > 0)) return std::nullopt;
        s.f = f(wo, s.wi, wl, eta, mode);
        if (!s.transmission) s.etap = 1.0;
        return s;
    }
    bool isSpecular() const override { return smooth_; }
    bool isTransmissive() const override { return true; }

private:
    // Generalized half vector, facing +z; false for degenerate or back-facing microfacet configurations.
    static bool halfVector(const Vec3& wo, const Vec3& wi, double eta, double* etap, Vec3* wm) {
        const double cosO = wo.z, cosI = wi.z;
        if (cosO == 0 || cosI == 0) return false;
        *etap = 1.0;
        if (cosO * cosI < 0) *etap = cosO > 0 ? eta : 1.0 / eta;
        Vec3 h = wi * *etap + wo;
        if (dot(h, h) == 0) return false;
        h = faceForward(normalize(h), Vec3(0, 0, 1));
        if (dot(h, wi) * cosI < 0 || dot(h, wo) * cosO < 0) return false;
        *wm = h;
        return true;
    }
    TrowbridgeReitz distrib_;
    bool smooth_;
};

}  // namespace

std::unique_ptr<Material> makeDielectric(double alpha) { return std::make_unique<Dielectric>(alpha); }

}  // namespace fluorosim
