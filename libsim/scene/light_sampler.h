#pragma once
// Next-event estimation: picks a light uniformly and a point on it; evaluates the solid-angle pdf
// of the same strategy for MIS when a path hits an emitter.
#include <optional>

#include "scene/scene.h"

namespace fluorosim {

// Intensities are W sr^-1 nm^-1 and distances mm; radiance is W m^-2 sr^-1 nm^-1, so I / d^2
// is converted from per mm^2 to per m^2.
inline constexpr double kMm2PerM2 = 1e6;

struct LightSample {
    Vec3 p;             // point on the light
    Vec3 n;             // its normal (zero for point lights)
    Vec3 wi;            // unit direction from the reference point to the light
    double distance = 0;
    SampledSpectrum L;  // incident radiance (area) or intensity / distance^2 (delta lights)
    double pdf = 0;     // solid-angle pdf including light selection, or selection probability for delta lights
    bool delta = false;
    // A beam (light sheet): its profile holds inside the sample, so the shadow ray ends where the beam
    // entered it, at the first refracting interface, instead of at `p`.
    bool beam = false;
    const BeamProfile* beamProfile = nullptr;  // the beam and side sampled, when `beam`
    int side = 0;
    uint32_t shape = 0;
    const Light* light = nullptr;  // the light sampled
};

class LightSampler {
public:
    // Samples `lights` (the scene's own by default; both must outlive the sampler). An area light in a
    // separate light list would not match its shape's index, so such lists hold no area lights.
    explicit LightSampler(const Scene& scene) : scene_(scene), lights_(scene.lights) {}
    LightSampler(const Scene& scene, const std::vector<Light>& lights) : scene_(scene), lights_(lights) {}
    std::optional<LightSample> sample(const Vec3& ref, double uLight, double u1, double u2, const SampledWavelengths& wl) const;
    // Solid-angle pdf of sampling point `pLight` (normal nLight) on the area light of `shape` from `ref`.
    double pdf(const Vec3& ref, uint32_t shape, const Vec3& pLight, const Vec3& nLight) const;
    // A point of an area light's shape drawn uniformly by area, and its normal (a mesh's by winding).
    std::pair<Vec3, Vec3> pointByArea(const AreaLight& light, double u1, double u2) const;
    // Radiance leaving an area light at a point with normal n towards direction w.
    SampledSpectrum emitted(const AreaLight& light, const Vec3& n, const Vec3& w, const SampledWavelengths& wl) const;
    // A point or spot light's intensity toward direction w (leaving it), times kMm2PerM2, over
    // squaredDistanceMm: at the default 1, the intensity; at a squared distance, LightSample::L there.
    // Zero for other lights.
    // A spot light's smoothstep falloff towards its cone edge, toward direction w (leaving it).
    static double spotFalloff(const SpotLight& light, const Vec3& w);
    static SampledSpectrum deltaIntensity(const Light& light, const Vec3& w, const SampledWavelengths& wl, double squaredDistanceMm = 1.0);

private:
    const Scene& scene_;
    const std::vector<Light>& lights_;
};

}  // namespace fluorosim
