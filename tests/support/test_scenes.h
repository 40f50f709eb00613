#pragma once
// Small scenes built in code for analytic tests.
#include <cmath>

#include "core/math.h"
#include "core/rng.h"
#include "render/path_tracer.h"
#include "scene/scene.h"
#include "spectral/color.h"
#include "spectral/wavelength_sampler.h"

namespace fluorosim::testing {

// Adds an inward-looking, two-sided emitting sphere of constant radiance `Le` (a uniform radiance field).
inline void addEnclosure(Scene& scene, double radius, double Le) {
    const uint32_t id = scene.geometry.addSphere(Vec3(0, 0, 0), radius);
    ShapeInfo info;
    info.name = "enclosure";
    scene.shapes.push_back(info);
    scene.addAreaLight(id, AreaEmission{Spectrum::constant(Le), true});
}

inline int addMedium(Scene& scene, const std::string& name, double sigmaA, double sigmaS, double g, double ior) {
    scene.media.emplace_back(name, Spectrum::constant(sigmaA), Spectrum::constant(sigmaS), g, ior);
    return static_cast<int>(scene.media.size()) - 1;
}

// Describes shape `id` (just added to the geometry) as an interface between two media.
inline uint32_t addInterfaceInfo(Scene& scene, uint32_t id, const char* name, int inside, int outside, int material) {
    ShapeInfo info;
    info.name = name;
    info.isInterface = true;
    info.insideMedium = inside;
    info.outsideMedium = outside;
    info.material = material;
    scene.shapes.push_back(info);
    return id;
}

inline uint32_t addInterfaceSphere(Scene& scene, const Vec3& c, double r, int inside, int outside, int material = kNone) {
    return addInterfaceInfo(scene, scene.geometry.addSphere(c, r), "sphere", inside, outside, material);
}

struct Estimate {
    double mean = 0, stderr_ = 0;
};

// Mean and standard error of `paths` independent estimates estimate(i).
template <class Estimator>
Estimate meanOf(int paths, Estimator&& estimate) {
    double sum = 0, sum2 = 0;
    for (int i = 0; i < paths; ++i) {
        const double v = estimate(i);
        sum += v;
        sum2 += v * v;
    }
    const double n = paths;
    Estimate e;
    e.mean = sum / n;
    e.stderr_ = std::sqrt(std::max(0.0, sum2 / n - e.mean * e.mean) / (n - 1));
    return e;
}

// Mean and standard error of the wavelength-averaged radiance along rays from `origin` in random
// directions towards the unit ball at `target` (each path is one independent sample).
inline Estimate meanRadiance(const Scene& scene, const Vec3& origin, int originMedium, const Vec3& target, double targetRadius,
                             int paths, uint64_t seed, double lambdaMin = 400, double lambdaMax = 700) {
    const PathTracer tracer(scene);
    const WavelengthSampler ws(lambdaMin, lambdaMax, {}, true);
    PathStats stats;
    return meanOf(paths, [&](int i) {
        Rng rng = Rng::forKey(seed, static_cast<uint64_t>(i), 7);
        const SampledWavelengths wl = ws.sample(rng.uniform(), rng.uniform());
        // Aim at a random point of the target ball, so paths see its whole volume.
        Vec3 p;
        do p = Vec3(2 * rng.uniform() - 1, 2 * rng.uniform() - 1, 2 * rng.uniform() - 1);
        while (dot(p, p) > 1);
        const Vec3 dir = normalize(target + p * targetRadius - origin);
        return tracer.radiance(Ray{origin, dir}, originMedium, wl, rng, stats).total().average();
    });
}

// Colour matching functions equal to 1 everywhere: the film's XYZ sums are then plain radiance sums.
inline ColorMatchingFunctions flatCmf() {
    const TabulatedSpectrum one({360, 830}, {1, 1});
    return {one, one, one};
}

// A glass ball of thin scattering fog (index 1.33) in a glowing enclosure, seen by a width x height
// camera: paths of varied length, for tests of the render driver.
inline Scene foggyBallScene(int width, int height) {
    Scene scene;
    addEnclosure(scene, 20, 1.0);
    const int m = addMedium(scene, "fog", 0.05, 2.0, 0.6, 1.33);
    scene.materials.push_back(makeDielectric(0.0));
    addInterfaceSphere(scene, Vec3(0, 0, 0), 1.0, m, kNone, 0);
    scene.camera.position = Vec3(0, 0, -6);
    scene.camera.frame = Frame{Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
    scene.camera.width = width;
    scene.camera.height = height;
    scene.camera.tanHalfFovY = 0.3;
    scene.finalize();
    return scene;
}

}  // namespace fluorosim::testing
