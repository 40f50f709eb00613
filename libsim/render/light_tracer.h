#pragma once
// Fluorescence seen through glass spheres, traced from the lights (Integrator::Light). Photons leave the
// lights, cross the glass by Fresnel sampling, scatter in media and on surfaces (BSDF sampling in
// importance mode) and are absorbed and re-emitted by dyes (render/photon_tracer.h). From every vertex of
// a photon in the liquid inside a stack of concentric glass spheres (a scattering, or a re-emission), every
// refracted chain through that stack to the camera (render/specular_chain.h) carries its contribution to
// one pixel: a light-tracing connection through the glass, which a camera path makes only by diffusing
// to where the light is. Re-emitted photons also connect straight from opaque, non-specular surfaces.
// The camera paths of the same render leave exactly these paths out (PathStart::lightTracedFluorescence),
// so nothing is counted twice; the model, the weights and the partition are in docs/model.md,
// "Fluorescence traced from the lights".
#include <cstdint>
#include <vector>

#include "render/path_tracer.h"
#include "scene/light_sampler.h"
#include "scene/scene.h"

namespace fluorosim {

// One contribution of a photon to the film: spectral radiance integrated over
// wavelength (the film's unit times nm) at `lambda`, per photon traced per pixel and sample.
struct FilmSplat {
    int32_t x, y;
    double lambda;
    double value;
    bool fluorescent;  // re-emitted at least once: the film's fluorescent layer, else its elastic one
};

struct LightTraceStats {
    uint64_t photons = 0;
    uint64_t connections = 0;  // chains evaluated (after Russian roulette)
    uint64_t merges = 0;       // photon vertices gathered onto camera segments (render/photon_merging.h)
    uint64_t mergedSegments = 0;
    void add(const LightTraceStats& o) {
        photons += o.photons;
        connections += o.connections;
        merges += o.merges;
        mergedSegments += o.mergedSegments;
    }
};

class CameraSegments;

class LightTracer {
public:
    // `tracer` supplies the stacks of shells and the transmittance (it must outlive this). Throws
    // ConfigError for a scene it cannot trace: a beam light, the paper's fluorescence model, a camera
    // inside a medium or inside a stack of shells.
    LightTracer(const Scene& scene, const PathTracer& tracer);
    // Photon `index` of a render with `seed` (its own random stream): appends its splats, scaled so that
    // tracing photonsPerSample() photons per sample adds their share to the film's mean; with `merging`, also
    // its merges with the camera segments of the pass.
    void trace(uint64_t seed, uint64_t index, std::vector<FilmSplat>& out, LightTraceStats& stats,
               const CameraSegments* merging = nullptr) const;
    // Photons a render traces per sample (per pixel): RenderSettings::photonsPerPixel per pixel of the whole image.
    double photonsPerSample() const {
        return static_cast<double>(scene_.camera.width) * scene_.camera.height * scene_.render.photonsPerPixel;
    }

private:
    struct Emitter {
        const Light* light;
        double cdf;  // cumulative selection probability, by power
    };
    const Scene& scene_;
    const PathTracer& tracer_;
    LightSampler lights_;
    std::vector<Emitter> emitters_;
    double pixelArea_;  // of one pixel on the image plane at unit distance
};

}  // namespace fluorosim
