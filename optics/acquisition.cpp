#include "optics/acquisition.h"

#include <atomic>
#include <chrono>
#include <mutex>
#include <cmath>
#include <string>

#include "core/errors.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "optics/psf.h"
#include "render/fluorescence.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {
namespace {

constexpr double kPlanckTimesC = 1.98644586e-16;  // h c in J nm

}  // namespace

void ObjectiveOptions::validate() const {
    if (!(immersionIndex >= 1) || !std::isfinite(immersionIndex))
        throw ConfigError("objective immersion_index must be >= 1, got " + std::to_string(immersionIndex));
    if (!(na > 0) || !std::isfinite(na)) throw ConfigError("objective na must be positive, got " + std::to_string(na));
    if (na >= immersionIndex)
        throw ConfigError("objective na " + std::to_string(na) + " is not below the immersion index " + std::to_string(immersionIndex) +
                          " (NA = n sin θ cannot reach n)");
    if (!(magnification > 0) || !std::isfinite(magnification))
        throw ConfigError("objective magnification must be positive, got " + std::to_string(magnification));
    if (!(workingDistanceMm > 0) || !std::isfinite(workingDistanceMm))
        throw ConfigError("objective working_distance must be positive, got " + std::to_string(workingDistanceMm) + " mm");
}

double ObjectiveOptions::collectionHalfAngle() const { return std::asin(na / immersionIndex); }

PlaneResult renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                        const DetectorOptions& detector, const PlaneRenderOptions& o) {
    objective.validate();
    detector.validate();
    if (o.width < 1 || o.height < 1 || o.spp < 1) throw ConfigError("image size and spp must be positive");
    const auto start = std::chrono::steady_clock::now();
    const PathTracer tracer(scene);
    const WavelengthSampler wavelengths = cameraWavelengthSampler(scene, tracer.fluorescence().active());
    const Vec3 w = normalize(focus.towardObjective);
    const Vec3 right = normalize(cross(focus.up, w));
    const Vec3 up = cross(w, right);
    const double pixelMm = detector.pixelPitchUm * 1e-3 / objective.magnification;
    const double cosMax = std::cos(objective.collectionHalfAngle());
    const double solidAngle = 2 * kPi * (1 - cosMax);
    // Étendue factor per sample: object pixel area (m²) × solid angle (uniform sampling) × exposure.
    const double areaM2 = pixelMm * pixelMm * 1e-6;
    const Frame frame{right, up, w};
    static const AiryPattern airy;
    PlaneResult r;
    r.electrons.assign(static_cast<size_t>(o.width) * o.height, 0.0);
    r.stderrElectrons.assign(r.electrons.size(), 0.0);
    std::vector<uint64_t> rowPaths(static_cast<size_t>(o.height), 0);
    std::vector<double> rowLargest(static_cast<size_t>(o.height), 0.0);
    std::atomic<int> rowsDone{0};
    std::mutex progressMutex;  // the callback is called from one thread at a time
    parallelFor(static_cast<size_t>(o.height), o.threads, [&](size_t y) {
        PathStats stats;
        for (int x = 0; x < o.width; ++x) {
            const size_t pixel = y * static_cast<size_t>(o.width) + static_cast<size_t>(x);
            double sum = 0, sum2 = 0;
            for (int s = 0; s < o.spp; ++s) {
                Rng rng = Rng::forKey(o.seed, o.planeKey * 0x100000000ULL + pixel, static_cast<uint64_t>(s));
                const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
                const double px = (x + rng.uniform() - 0.5 * o.width) * pixelMm;
                const double py = (0.5 * o.height - (static_cast<double>(y) + rng.uniform())) * pixelMm;
                Vec3 focal = focus.centreMm + right * px + up * py;
                // Diffraction: the focal point moves by a sample of the hero wavelength's Airy pattern. Its
                // density ratios p_j/p_0 and throughputs f_j/p_0 start the path, so the tracer's spectral
                // MIS weighs the displacement together with the rest of the path.
                PathStart pathStart;
                if (o.diffraction) {
                    const double radius = airy.sampleRadiusMm(rng.uniform(), wl.lambda[0], objective.na);
                    const double a = 2 * kPi * rng.uniform();
                    focal += (right * std::cos(a) + up * std::sin(a)) * radius;
                    if (!wl.discrete) {
                        const double hero = airy.densityPerMm2(radius, wl.lambda[0], objective.na);
                        for (int j = 1; j < kNumWavelengths; ++j)
                            pathStart.r_u[j] = airy.densityPerMm2(radius, wl.lambda[j], objective.na) / hero;
                        pathStart.beta = pathStart.r_u;
                    }
                }
                const double cosT = 1 - rng.uniform() * (1 - cosMax), phi = 2 * kPi * rng.uniform();
                const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT));
                const Vec3 toObjective = frame.toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT));
                const Ray ray{focal + toObjective * objective.workingDistanceMm, -toObjective};
                const SampledSpectrum L = tracer.radiance(ray, scene.camera.medium, wl, rng, stats, pathStart).total();
                double e = 0;
                for (int j = 0; j < kNumWavelengths; ++j) {
                    if (L[j] == 0 || wl.pdf[j] == 0) continue;
                    const double lambda = wl.lambda[j];
                    e += L[j] / wl.pdf[j] * emission.transmission(lambda) * detector.qe(lambda) * lambda / kPlanckTimesC;
                }
                e *= cosT * solidAngle * areaM2 * detector.exposureS / kNumWavelengths;
                sum += e;
                sum2 += e * e;
                rowLargest[y] = std::max(rowLargest[y], e);
            }
            const double n = o.spp;
            r.electrons[pixel] = sum / n;
            r.stderrElectrons[pixel] = n > 1 ? std::sqrt(std::max(0.0, sum2 / n - sqr(sum / n)) / (n - 1)) : 0.0;
        }
        rowPaths[y] = stats.paths;
        const int done = ++rowsDone;
        if (o.progress) {
            const std::lock_guard<std::mutex> lock(progressMutex);
            o.progress(double(done) / o.height);
        }
    });
    for (uint64_t p : rowPaths) r.paths += p;
    for (double l : rowLargest) r.largestSample = std::max(r.largestSample, l);
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

}  // namespace fluorosim::optics
