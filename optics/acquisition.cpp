#include "optics/acquisition.h"

#include <chrono>
#include <cmath>
#include <mutex>

#include "core/errors.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "core/sobol.h"
#include "optics/psf.h"
#include "render/direct_beam.h"
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

const char* estimatorName(Estimator e) { return e == Estimator::Path ? "path" : "split"; }

std::optional<Estimator> estimatorFromName(const std::string& name) {
    if (name == "path") return Estimator::Path;
    if (name == "split") return Estimator::Split;
    return std::nullopt;
}

void AcquireOptions::validate() const {
    if (spp < 1) throw ConfigError("spp must be at least 1, got " + std::to_string(spp));
    if (directSpp < 1) throw ConfigError("direct samples per pixel must be at least 1, got " + std::to_string(directSpp));
    if (threads < 0) throw ConfigError("threads must be >= 0, got " + std::to_string(threads));
    if (noiseRatio && !(*noiseRatio > 0 && std::isfinite(*noiseRatio)))
        throw ConfigError("noise ratio must be positive and finite, got " + std::to_string(*noiseRatio));
    if (noiseRatio && (maxSpp < spp || pilotSpp < 2))
        throw ConfigError("adaptive sampling needs max spp >= spp and at least 2 pilot samples, got max " + std::to_string(maxSpp) + ", spp " +
                          std::to_string(spp) + ", pilot " + std::to_string(pilotSpp));
}

uint64_t planeStreamKey(const std::string& channelName, int plane) { return mixBits(hashName(channelName) + mixBits(static_cast<uint64_t>(plane) + 1)); }

namespace {

// Where a camera sample starts: the focal-plane point of a pixel, displaced by the PSF, and a
// direction from the collection cone; the ray starts at the working distance on the objective's side.
struct PlaneCamera {
    Vec3 right, up, axis;
    Frame frame;
    double pixelMm, cosMax, na, workingDistanceMm;
    double perSample;  // object pixel area (m²) × cone solid angle × exposure: the étendue of a sample
    Vec3 centre;
    int width, height;

    PlaneCamera(const ObjectiveOptions& objective, const FocalPlane& focus, const DetectorOptions& detector, int w, int h)
        : axis(normalize(focus.towardObjective)), width(w), height(h) {
        right = normalize(cross(focus.up, axis));
        up = cross(axis, right);
        frame = Frame{right, up, axis};
        pixelMm = detector.pixelPitchUm * 1e-3 / objective.magnification;
        cosMax = std::cos(objective.collectionHalfAngle());
        na = objective.na;
        workingDistanceMm = objective.workingDistanceMm;
        perSample = pixelMm * pixelMm * 1e-6 * 2 * kPi * (1 - cosMax) * detector.exposureS;
        centre = focus.centreMm;
    }
    Vec3 focalPoint(int x, int y, double ux, double uy) const {
        return centre + right * ((x + ux - 0.5 * width) * pixelMm) + up * ((0.5 * height - (y + uy)) * pixelMm);
    }
    Vec3 psfOffset(double radiusMm, double uAngle) const {
        const double a = 2 * kPi * uAngle;
        return (right * std::cos(a) + up * std::sin(a)) * radiusMm;
    }
    // The ray toward the focal point from the cone (uniform in solid angle); *cosTheta for the étendue.
    Ray ray(const Vec3& focal, double uCos, double uPhi, double* cosTheta) const {
        const double cosT = 1 - uCos * (1 - cosMax), phi = 2 * kPi * uPhi;
        const double sinT = std::sqrt(std::max(0.0, 1 - cosT * cosT));
        const Vec3 toObjective = frame.toWorld(Vec3(sinT * std::cos(phi), sinT * std::sin(phi), cosT));
        *cosTheta = cosT;
        return Ray{focal + toObjective * workingDistanceMm, -toObjective};
    }
};

// Pilot paths of adaptive sampling draw from sample indices the estimate never reaches.
constexpr uint64_t kPilotSample = uint64_t(1) << 40;

struct PixelTally {
    double sum = 0, sum2 = 0;
    int n = 0;
    void add(double v) {
        sum += v;
        sum2 += v * v;
        ++n;
    }
    double mean() const { return n ? sum / n : 0.0; }
    double varianceOfMean() const { return n > 1 ? std::max(0.0, sum2 / n - sqr(sum / n)) / (n - 1) : 0.0; }
};

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
    const PlaneCamera camera(objective, focus, detector, width, height);
    // Photoelectrons per unit of spectral radiance at λ: filter, QE and photons per joule.
    const auto detection = [&](double lambda) { return emission.transmission(lambda) * detector.qe(lambda) * lambda / kPlanckTimesC; };
    const bool split = o.estimator == Estimator::Split;
    const DirectBeamEstimator direct(scene, tracer, detection);
    const bool useDirect = split && direct.active();
    // Dimensions: component, pixel area (2), PSF (2), cone (2), points along the core.
    const std::optional<SobolTable> sobol = useDirect ? std::optional<SobolTable>(std::in_place, 8, o.directSpp) : std::nullopt;
    static const AiryPattern airy;
    PlaneImage r;
    r.width = width;
    r.height = height;
    r.electrons.assign(static_cast<size_t>(width) * height, 0.0);
    r.stderrElectrons.assign(r.electrons.size(), 0.0);
    r.directStderr.assign(r.electrons.size(), 0.0);
    r.pathStderr.assign(r.electrons.size(), 0.0);
    // Each row's totals, kept apart so that threads never share them; summed into the image at the end.
    struct RowTotals {
        PathStats stats;
        double largest = 0, direct = 0, path = 0, directSeconds = 0, pathSeconds = 0;
        uint64_t samples = 0, pilots = 0;
        bool done = false;
    };
    std::vector<RowTotals> rows(static_cast<size_t>(height));
    // Dark electrons of the exposure: part of the camera noise an adaptive target is relative to.
    const double darkElectrons = detector.darkCurrentElectronsPerS * detector.exposureS;
    int rowsDone = 0;
    std::mutex progressMutex;  // the callback is called from one thread at a time
    parallelFor(static_cast<size_t>(height), o.threads, [&](size_t yRow) {
        if (o.cancel && o.cancel->load()) return;
        const int y = static_cast<int>(yRow);
        RowTotals& row = rows[yRow];
        PathStats& stats = row.stats;
        for (int x = 0; x < width; ++x) {
            const size_t pixel = yRow * static_cast<size_t>(width) + static_cast<size_t>(x);
            PixelTally paths, directTally;
            double directVariance = 0;
            const auto t0 = std::chrono::steady_clock::now();
            // The direct part: Owen-scrambled Sobol' points over the component, the pixel area, the PSF,
            // the cone and the points along the core, scrambled per pixel; transmittances from a stream
            // keyed apart from the paths'.
            if (useDirect) {
                const uint64_t scramble = mixBits(o.seed ^ mixBits(streamKey + pixel));
                DirectBeamEstimator::Pixel points;
                for (int s = 0; s < o.directSpp; ++s) {
                    auto u = [&](int dim) { return sobol->sample(s, dim, scramble); };
                    const DirectBeamEstimator::Component c = direct.sampleComponent(u(0));
                    Vec3 focal = camera.focalPoint(x, y, u(1), u(2));
                    if (o.diffraction) focal += camera.psfOffset(airy.sampleRadiusMm(u(3), c.lambdaNm, objective.na), u(4));
                    double cosT = 0;
                    const Ray ray = camera.ray(focal, u(5), u(6), &cosT);
                    direct.addSample(points, ray, scene.camera.medium, c, u(7), cosT * camera.perSample);
                }
                Rng rng = Rng::forKey(o.seed, mixBits(streamKey + pixel) ^ 0x5DEECE66DULL, 0);
                const DirectBeamEstimator::Estimate d = direct.finish(points, o.directPicks, rng.uniform(), rng);
                directTally.sum = d.mean;
                directTally.n = 1;
                directVariance = d.variance;
            }
            const auto t1 = std::chrono::steady_clock::now();
            auto pathSample = [&](uint64_t s) {
                Rng rng = Rng::forKey(o.seed, streamKey + pixel, s);
                const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
                Vec3 focal = camera.focalPoint(x, y, rng.uniform(), rng.uniform());
                // Diffraction: the focal point moves by a sample of the hero wavelength's Airy pattern. Its
                // density ratios p_j/p_0 and throughputs f_j/p_0 start the path, so the tracer's spectral
                // MIS weighs the displacement together with the rest of the path.
                PathStart pathStart;
                pathStart.directBeamsSeparate = useDirect;
                if (o.diffraction) {
                    const double radius = airy.sampleRadiusMm(rng.uniform(), wl.lambda[0], objective.na);
                    focal += camera.psfOffset(radius, rng.uniform());
                    if (!wl.discrete) {
                        const double hero = airy.densityPerMm2(radius, wl.lambda[0], objective.na);
                        for (int j = 1; j < kNumWavelengths; ++j)
                            pathStart.r_u[j] = airy.densityPerMm2(radius, wl.lambda[j], objective.na) / hero;
                        pathStart.beta = pathStart.r_u;
                    }
                }
                double cosT = 0;
                const Ray ray = camera.ray(focal, rng.uniform(), rng.uniform(), &cosT);
                const SampledSpectrum L = tracer.radiance(ray, scene.camera.medium, wl, rng, stats, pathStart).total();
                double e = 0;
                for (int j = 0; j < kNumWavelengths; ++j)
                    if (L[j] != 0 && wl.pdf[j] != 0) e += L[j] / wl.pdf[j] * detection(wl.lambda[j]);
                e *= cosT * camera.perSample / kNumWavelengths;
                return e;
            };
            int n = o.spp;
            if (o.noiseRatio) {
                // Pilot paths from streams the estimate never uses decide how many to trace.
                PixelTally pilot;
                for (int s = 0; s < o.pilotSpp; ++s) pilot.add(pathSample(kPilotSample + static_cast<uint64_t>(s)));
                const double signal = std::max(0.0, pilot.mean() + directTally.mean());
                const double target = sqr(*o.noiseRatio) * (signal + darkElectrons + sqr(detector.readNoiseElectrons));
                const double perPath = pilot.varianceOfMean() * pilot.n;
                const double room = target - directVariance;
                const double wanted = room > 0 ? std::ceil(perPath / room) : double(o.maxSpp);
                n = static_cast<int>(std::clamp(wanted, double(o.spp), double(o.maxSpp)));
                row.pilots += static_cast<uint64_t>(o.pilotSpp);
            }
            for (int s = 0; s < n; ++s) {
                const double e = pathSample(static_cast<uint64_t>(s));
                paths.add(e);
                row.largest = std::max(row.largest, e);
            }
            row.samples += static_cast<uint64_t>(n);
            const auto t2 = std::chrono::steady_clock::now();
            row.directSeconds += std::chrono::duration<double>(t1 - t0).count();
            row.pathSeconds += std::chrono::duration<double>(t2 - t1).count();
            r.directStderr[pixel] = std::sqrt(directVariance);
            r.pathStderr[pixel] = std::sqrt(paths.varianceOfMean());
            r.electrons[pixel] = paths.mean() + directTally.mean();
            r.stderrElectrons[pixel] = std::sqrt(paths.varianceOfMean() + directVariance);
            row.direct += directTally.mean();
            row.path += paths.mean();
        }
        row.done = true;
        const std::lock_guard<std::mutex> lock(progressMutex);
        ++rowsDone;
        if (o.progress) o.progress(double(rowsDone) / height);
    });
    for (const RowTotals& row : rows) {
        r.stats.add(row.stats);
        r.largestSample = std::max(r.largestSample, row.largest);
        r.complete = r.complete && row.done;
        r.directElectrons += row.direct;
        r.pathElectrons += row.path;
        r.directSeconds += row.directSeconds;
        r.pathSeconds += row.pathSeconds;
        r.pathSamples += row.samples;
        r.pilotSamples += row.pilots;
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
