#include "optics/acquisition.h"

#include <chrono>
#include <cmath>
#include <mutex>

#include "core/errors.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "optics/psf.h"
#include "render/fluorescence.h"

namespace fluorosim::optics {
namespace {

constexpr double kPlanckTimesC = 1.98644586e-16;  // h c in J nm

uint64_t hashName(const std::string& s) {
    uint64_t h = 0xcbf29ce484222325ULL;  // FNV-1a
    for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ULL;
    return h;
}

}  // namespace

void AcquireOptions::validate() const {
    if (spp < 1) throw ConfigError("spp must be at least 1, got " + std::to_string(spp));
    if (threads < 0) throw ConfigError("threads must be >= 0, got " + std::to_string(threads));
}

uint64_t planeStreamKey(const std::string& channelName, int plane) { return mixBits(hashName(channelName) + mixBits(static_cast<uint64_t>(plane) + 1)); }

namespace {

PlaneImage renderWith(const Scene& scene, const PathTracer& tracer, const ObjectiveOptions& objective, const FocalPlane& focus,
                      const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                      const AcquireOptions& o) {
    objective.validate();
    focus.validate();
    detector.validate();
    o.validate();
    if (width < 1 || height < 1) throw ConfigError("image size must be positive, got " + std::to_string(width) + " x " + std::to_string(height));
    const auto start = std::chrono::steady_clock::now();
    const WavelengthSampler wavelengths = cameraWavelengthSampler(scene, tracer.lights(), tracer.fluorescence().active());
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
    PlaneImage r;
    r.width = width;
    r.height = height;
    r.electrons.assign(static_cast<size_t>(width) * height, 0.0);
    r.stderrElectrons.assign(r.electrons.size(), 0.0);
    std::vector<PathStats> rowStats(static_cast<size_t>(height));
    std::vector<double> rowLargest(static_cast<size_t>(height), 0.0);
    std::vector<char> rowDone(static_cast<size_t>(height), 0);
    int rowsDone = 0;
    std::mutex progressMutex;  // the callback is called from one thread at a time
    parallelFor(static_cast<size_t>(height), o.threads, [&](size_t y) {
        if (o.cancel && o.cancel->load()) return;
        PathStats& stats = rowStats[y];
        for (int x = 0; x < width; ++x) {
            const size_t pixel = y * static_cast<size_t>(width) + static_cast<size_t>(x);
            double sum = 0, sum2 = 0;
            for (int s = 0; s < o.spp; ++s) {
                Rng rng = Rng::forKey(o.seed, streamKey + pixel, static_cast<uint64_t>(s));
                const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
                const double px = (x + rng.uniform() - 0.5 * width) * pixelMm;
                const double py = (0.5 * height - (static_cast<double>(y) + rng.uniform())) * pixelMm;
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
        rowDone[y] = 1;
        const std::lock_guard<std::mutex> lock(progressMutex);
        ++rowsDone;
        if (o.progress) o.progress(double(rowsDone) / height);
    });
    for (size_t y = 0; y < rowStats.size(); ++y) {
        r.stats.add(rowStats[y]);
        r.largestSample = std::max(r.largestSample, rowLargest[y]);
        r.complete = r.complete && rowDone[y];
    }
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

}  // namespace

PlaneImage renderPlane(const Scene& scene, std::vector<Light> lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                       const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                       const AcquireOptions& options) {
    const PathTracer tracer(scene, std::move(lights));
    return renderWith(scene, tracer, objective, focus, emission, detector, width, height, streamKey, options);
}

PlaneImage renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                       const DetectorOptions& detector, int width, int height, const AcquireOptions& options) {
    const PathTracer tracer(scene);
    return renderWith(scene, tracer, objective, focus, emission, detector, width, height, 0, options);
}

PlaneImage acquirePlane(const Scene& scene, const Microscope& m, size_t channel, int plane, const AcquireOptions& options) {
    if (channel >= m.channels.size()) throw ConfigError("channel index " + std::to_string(channel) + " is out of range");
    if (plane < 0 || plane >= m.stack.planes)
        throw ConfigError("plane " + std::to_string(plane) + " is outside the stack of " + std::to_string(m.stack.planes));
    const MicroscopeChannel& c = m.channels[channel];
    const double offset = m.planeOffsetMm(plane);
    return renderPlane(scene, m.lightsAt(scene, c, offset), m.objective, m.focalPlaneAt(offset), c.emissionPath, m.detector, m.width,
                       m.height, planeStreamKey(c.name, plane), options);
}

int Stack::completePlanes() const {
    for (int k = 0; k < planes; ++k)
        for (size_t c = 0; c < channels.size(); ++c)
            if (!done[index(c, k)]) return k;
    return planes;
}

Stack emptyStack(const Microscope& m, std::vector<size_t> channels) {
    if (channels.empty()) throw ConfigError("a stack needs at least one channel");
    for (size_t c : channels)
        if (c >= m.channels.size()) throw ConfigError("channel index " + std::to_string(c) + " is out of range");
    if (stackBytes(m.width, m.height, m.stack.planes, static_cast<int>(channels.size())) > kMaxStackBytes)
        throw ConfigError("the stack needs more memory than the cap of " + std::to_string(kMaxStackBytes >> 30) + " GiB");
    Stack s;
    s.width = m.width;
    s.height = m.height;
    s.planes = m.stack.planes;
    s.channels = std::move(channels);
    const size_t n = static_cast<size_t>(s.width) * s.height * s.planes * s.channels.size();
    s.expected.assign(n, 0.0f);
    s.stderrElectrons.assign(n, 0.0f);
    s.counts.assign(n, 0);
    s.done.assign(s.channels.size() * static_cast<size_t>(s.planes), false);
    return s;
}

void storePlane(Stack& stack, const Microscope& m, size_t slot, int plane, const PlaneImage& image, uint64_t seed) {
    if (image.width != stack.width || image.height != stack.height) throw ConfigError("plane image size does not match the stack");
    const Detector camera(m.detector);
    const std::vector<double> withDark = camera.expectedElectrons(image.electrons);
    const std::vector<uint16_t> frame = camera.readOut(withDark, seed, planeStreamKey(m.channels[stack.channels[slot]].name, plane));
    const size_t off = stack.pixelOffset(slot, plane);
    for (size_t i = 0; i < withDark.size(); ++i) {
        stack.expected[off + i] = static_cast<float>(withDark[i]);
        stack.stderrElectrons[off + i] = static_cast<float>(image.stderrElectrons[i]);
        stack.counts[off + i] = frame[i];
    }
    stack.done[stack.index(slot, plane)] = true;
}

bool acquireStack(const Scene& scene, const Microscope& m, Stack& stack, const AcquireOptions& options, const StackCallbacks& cb) {
    const size_t total = stack.done.size();
    size_t finished = 0;
    for (bool d : stack.done) finished += d;
    for (int k = 0; k < stack.planes; ++k)
        for (size_t slot = 0; slot < stack.channels.size(); ++slot) {
            if (stack.done[stack.index(slot, k)]) continue;
            AcquireOptions o = options;
            o.progress = [&](double f) {
                if (cb.progress) cb.progress((double(finished) + f) / double(total));
            };
            const PlaneImage image = acquirePlane(scene, m, stack.channels[slot], k, o);
            if (!image.complete) return false;
            storePlane(stack, m, slot, k, image, options.seed);
            ++finished;
            if (cb.planeDone) cb.planeDone(slot, k, image);
            if (options.cancel && options.cancel->load()) return false;
        }
    return true;
}

}  // namespace fluorosim::optics
