#pragma once
// The in-memory scene: geometry, what each shape is (material, media on each side, emission),
// lights, camera and the sampled wavelength range. Built by scene_loader or directly in code.
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "geometry/geometry.h"
#include "materials/material.h"
#include "media/medium.h"
#include "scene/beam.h"
#include "scene/scene_field.h"
#include "spectral/spectrum.h"

namespace fluorosim {

inline constexpr int kNone = -1;

struct AreaEmission {
    Spectrum radiance;  // spectral radiance, W m^-2 sr^-1 nm^-1 (or power per line)
    bool twoSided = false;
};

struct ShapeInfo {
    std::string name;
    int material = kNone;        // kNone: a pure interface (or a black emitter)
    int insideMedium = kNone;    // media on the side opposite / along the outward normal;
    int outsideMedium = kNone;   // kNone on both sides means the shape is not an interface
    bool isInterface = false;
    int areaLight = kNone;       // index into Scene::lights
};

struct AreaLight {
    uint32_t shape;
    AreaEmission emission;
    std::vector<double> triangleCdf;  // area CDF for meshes, normalized
};
struct PointLight {
    Vec3 position;
    Spectrum intensity;  // W sr^-1 nm^-1 (lines: W sr^-1); irradiance at d mm is I / (d * 1e-3 m)^2
};
struct SpotLight {
    Vec3 position, direction;
    Spectrum intensity;  // on the axis
    double cosTotalWidth, cosFalloffStart;
};
// A light sheet or beam (see scene/beam.h), connected to exactly by next-event estimation.
struct BeamLight {
    std::shared_ptr<BeamProfile> profile;
    LightSheetSpec spec;
};
using Light = std::variant<AreaLight, PointLight, SpotLight, BeamLight>;

// What a light emits: an area light's radiance, a point or spot light's intensity, or a beam's
// normalised spectrum.
const Spectrum& emissionSpectrum(const Light& light);

struct Camera {
    Vec3 position;
    Frame frame;        // n: forward, s: right, t: up
    double tanHalfFovY = 0.5;
    int width = 64, height = 64;
    int medium = kNone;
};

struct SpectralSettings {
    double lambdaMin = 300, lambdaMax = 800;  // nm
    double binWidth = 10;                     // nm, spectral EXR channels
};

// How dyes re-emit. Full: the unbiased model (any number of fluorescence generations, multiple
// scattering at every wavelength). Paper: Abdellah et al.'s model (one fluorescence event, lit
// directly from the lights through transmittance). None: dyes only absorb.
enum class FluorescenceModel { Full, Paper, None };
// "full", "paper" or "none"; nullopt for anything else.
std::optional<FluorescenceModel> fluorescenceModelFromName(const std::string& name);
const char* fluorescenceModelName(FluorescenceModel model);

// How light reaches medium vertices. Path: next-event estimation along straight shadow rays, and
// phase sampling (the reference). Mnee adds manifold next-event estimation through concentric smooth
// spherical interfaces (render/specular_chain.h): light behind a glass shell reaches the medium inside.
// Light is Mnee for the elastic light, and traces the fluorescence seen through glass spheres from the
// lights (render/light_tracer.h): photons connect to the camera through the glass from every vertex.
enum class Integrator { Path, Mnee, Light };
// "path", "mnee" or "light"; nullopt for anything else.
std::optional<Integrator> integratorFromName(const std::string& name);
const char* integratorName(Integrator integrator);

struct RenderSettings {
    FluorescenceModel fluorescence = FluorescenceModel::Full;
    Integrator integrator = Integrator::Path;
    int spp = 16;
    int maxDepth = 100000;  // a safety cap; paths that hit it are counted, never silently
    uint64_t seed = 1;
    int photonsPerPixel = 1;  // Integrator::Light: photons traced per sample per pixel of the image
    // Integrator::Light: the radius of photon merging behind glass at the first sample, in pixel
    // footprints at the merged segment (render/photon_merging.h); 0 leaves those paths to the camera.
    double mergeRadiusPixels = 1;
};

struct Scene {
    Geometry geometry;
    std::vector<ShapeInfo> shapes;  // indexed by shape id
    std::vector<std::unique_ptr<Material>> materials;
    std::vector<std::string> materialNames;
    std::vector<Medium> media;
    std::vector<Light> lights;
    Camera camera;
    SpectralSettings spectral;
    RenderSettings render;
    std::vector<std::string> warnings;  // things the user must know that are not errors
    std::optional<SceneField> microscope;  // the "microscope" block, read by optics::Microscope::fromScene

    // Refractive index on each side of an interface (1 where no medium is given).
    double ior(int medium) const { return medium == kNone ? 1.0 : media[static_cast<size_t>(medium)].ior(); }
    // Adds an area light on an existing shape.
    void addAreaLight(uint32_t shape, AreaEmission emission);
    // Finishes construction: commits geometry and checks consistency. Throws ConfigError.
    void finalize();
};

}  // namespace fluorosim
