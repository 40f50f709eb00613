#pragma once
// Surface scattering (BSDFs) in the local shading frame, z = outward surface normal.
// `eta` is n(inside, -z side) / n(outside, +z side); only dielectric interfaces use it.
#include <memory>
#include <optional>

#include "core/vec3.h"
#include "spectral/spectrum.h"

namespace fluorosim {

enum class TransportMode { Radiance, Importance };

struct BsdfSample {
    SampledSpectrum f;   // BSDF value (for specular lobes: the delta's weight divided by |cos|)
    Vec3 wi;
    double pdf = 0;      // solid-angle pdf, or a discrete probability for specular lobes
    bool specular = false;
    bool transmission = false;
    double etap = 1.0;   // relative index crossed (1 for reflection)
};

class Material {
public:
    virtual ~Material() = default;
    virtual SampledSpectrum f(const Vec3& wo, const Vec3& wi, const SampledWavelengths& wl, double eta,
                              TransportMode mode) const = 0;
    virtual double pdf(const Vec3& wo, const Vec3& wi, double eta) const = 0;
    virtual std::optional<BsdfSample> sample(const Vec3& wo, double uc, double u1, double u2,
                                             const SampledWavelengths& wl, double eta, TransportMode mode) const = 0;
    // True when every lobe is a delta (no next-event estimation possible).
    virtual bool isSpecular() const { return false; }
    virtual bool isTransmissive() const { return false; }
};

// Lambertian reflector. Parameters: reflectance in [0, 1] per wavelength.
std::unique_ptr<Material> makeDiffuse(Spectrum reflectance);
// Rough (GGX) or smooth (alpha < 1e-3) conductor with complex index eta + i k per wavelength.
std::unique_ptr<Material> makeConductor(Spectrum eta, Spectrum k, double alpha);
// Plastic: a GGX dielectric coat of index `ior` over a Lambertian base; reciprocal, not energy-
// compensated (multiple scattering in the coat is ignored).
std::unique_ptr<Material> makePlastic(Spectrum diffuse, double ior, double alpha);
// Dielectric interface, smooth (alpha < 1e-3) or rough GGX (Walter et al. 2007).
std::unique_ptr<Material> makeDielectric(double alpha);

}  // namespace fluorosim
