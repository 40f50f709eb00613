#pragma once
// An independent forward estimator for validating the path tracer's fluorescence: analog photons
// leave the point lights, scatter, are absorbed and re-emitted by dyes (new wavelength from the
// emission spectrum, energy scaled by λ_absorbed/λ_emitted, isotropic direction), cross smooth
// dielectric interfaces by Fresnel sampling, and the fluorescent ones that escape to infinity are
// tallied. It shares only geometry queries, the HG sampler and the Fresnel formula with the path
// tracer; the adjoint weights, MIS and NEE it checks are not involved.
#include <cstdint>
#include <vector>

#include "core/rng.h"
#include "render/tally.h"
#include "scene/scene.h"

namespace fluorosim {

struct ForwardPhotonOptions {
    uint64_t photons = 1000000;
    uint64_t seed = 1;
    int threads = 0;
    // Photons are emitted only into the cone that subtends this ball (it must enclose every medium
    // and interface), and weighted by the cone's solid angle.
    Vec3 aimCenter;
    double aimRadius = 1;
    std::vector<double> binEdgesNm;  // spectral bins for the tally (at least 2 edges)
    void validate() const;           // throws ConfigError
};

// Escaping fluorescence in watts (with the scene's units: point-light intensity in W sr^-1 nm^-1 or
// W sr^-1 per line), and the photon-count-proportional sum of power x wavelength (W nm).
struct ForwardPhotonResult {
    TallyValue fluorescentPower, fluorescentPowerTimesLambda;
    std::vector<TallyValue> binPower;  // per bin of binEdgesNm
    TallyValue absorbedPower;          // power absorbed by dyes (first absorption of light photons)
    uint64_t photons = 0;
    double seconds = 0;
};

// Only point lights are supported (others throw ConfigError); opaque surfaces absorb.
ForwardPhotonResult traceForwardPhotons(const Scene& scene, const ForwardPhotonOptions& options);

// One analog photon: where it goes, the medium it is in, its wavelength and the power it carries
// (watts, or W mm² m⁻² where the caller keeps lengths in mm: see render/light_tracer.h).
struct Photon {
    Ray ray;
    int medium = kNone;
    double lambda = 0;
    double weight = 0;
    bool fluorescent = false;  // re-emitted at least once
    double tMin = 0;           // > 0 when the ray starts on the surface it leaves
    double sigmaT = -1;        // at a scattering: the extinction there at lambda (-1 elsewhere)
};

// What a photon's walk meets, in order. The default handlers ignore everything.
class PhotonEvents {
public:
    virtual ~PhotonEvents() = default;
    // A real scattering at p in the photon's medium; ph.ray.d is still the direction it arrived in.
    virtual void scattered(const Photon& /*ph*/, const Vec3& /*p*/) {}
    // A free flight in medium m along ph.ray from t = 0 to tEnd (mm), ended by a collision or at the surface
    // `reach` ahead (infinite if none); sigmaS: the medium's scattering at ph.lambda per unit of its
    // scattering channel. Called before the collision's event. The expected scatterings in [t, t + dt] of a
    // flight are σs(ray.at(t)) dt, so a sum of ∫ σs g dt over the flights has the mean of g summed at the
    // scatterings (a track-length estimator); which of the two a flight uses may depend on its ray and reach,
    // not on tEnd.
    virtual void flew(const Photon& /*ph*/, double /*tEnd*/, double /*reach*/, const Medium& /*m*/, double /*sigmaS*/) {}
    // A dye absorbed the photon at p (before its quantum yield decides whether it re-emits).
    virtual void absorbedByDye(const Photon& /*ph*/) {}
    // About to scatter off a surface by its BSDF (walkPhoton's scatterAtSurfaces): n is the normal on the
    // side the photon arrives from (opaque surfaces) or the outward one (interfaces), eta as Material takes it.
    virtual void surfaceScattered(const Photon& /*ph*/, const SurfaceHit& /*hit*/, const Vec3& /*n*/, const Material& /*mat*/, double /*eta*/) {}
    // Re-emitted isotropically at p: ph holds the new wavelength and power.
    virtual void reemitted(const Photon& /*ph*/, const Vec3& /*p*/) {}
    // Left the scene.
    virtual void escaped(const Photon& /*ph*/) {}
    // After a scattering or a re-emission at p: how many copies of the photon go on, on average, each with
    // its power divided by it. Below 1 it is Russian roulette (the probability that the photon goes on),
    // which saves time where nothing the caller tallies can follow; above 1 the photon splits into ⌊q⌋ or
    // ⌈q⌉ copies (at most 64 at a vertex and 4096 from one photon), which bounds the power a photon brings
    // back to where the caller tallies (a weight window).
    virtual double survival(const Photon& /*ph*/, const Vec3& /*p*/) { return 1.0; }
    // The same after a reflection or refraction at a smooth dielectric: light guided without loss by total
    // internal reflection (a clear block) would otherwise never end.
    virtual double specularSurvival(const Photon& /*ph*/) { return 1.0; }
};

// Analog transport of one photon: delta tracking at its wavelength in media (scattering, solvent and dye
// absorption, re-emission at a wavelength drawn from the dye's emission spectrum with the energy scaled by
// λ_absorbed/λ_emitted), smooth dielectrics by Fresnel sampling, index-matched interfaces crossed. Other
// surfaces absorb, or with `scatterAtSurfaces` scatter by their BSDF in importance mode, with Russian
// roulette on the BSDF's weight, so the photon's power never grows there.
void walkPhoton(const Scene& scene, Photon ph, Rng& rng, PhotonEvents& events, bool scatterAtSurfaces);

// A wavelength from a light's spectrum (its lines, and its continuous part over [lambdaMin, lambdaMax]):
// returns the spectrum's value there over the sampling density (a line's power over its probability).
double sampleLightWavelength(const Spectrum& s, double lambdaMin, double lambdaMax, Rng& rng, double* lambda);

}  // namespace fluorosim
