#include "core/math.h"
#include "core/sampling.h"
#include "materials/material.h"

namespace fluorosim {
namespace {

class Diffuse final : public Material {
public:
    explicit Diffuse(Spectrum r) : reflectance_(std::move(r)) {}
    SampledSpectrum f(const Vec3& wo, const Vec3& wi, const SampledWavelengths& wl, double, TransportMode) const override {
        if (wo.z <= 0 || wi.z <= 0) return SampledSpectrum(0.0);
        return reflectance_.sample(wl) * kInvPi;
    }
    double pdf(const Vec3& wo, const Vec3& wi, double) const override {
        return wo.z > 0 ? cosineHemispherePdf(wi.z) : 0.0;
    }
    std::optional<BsdfSample> sample(const Vec3& wo, double, double u1, double u2, const SampledWavelengths& wl,
                                     double eta, TransportMode mode) const override {
        if (wo.z <= 0) return std::nullopt;
        BsdfSample s;
        s.wi = sampleCosineHemisphere(u1, u2);
        s.pdf = cosineHemispherePdf(s.wi.z);
        if (s.pdf <= 0) return std::nullopt;
        s.f = f(wo, s.wi, wl, eta, mode);
        return s;
    }

private:
    Spectrum reflectance_;
};

}  // namespace

std::unique_ptr<Material> makeDiffuse(Spectrum reflectance) { return std::make_unique<Diffuse>(std::move(reflectance)); }

}  // namespace fluorosim
