#include "optics/acquisition.h"

#include <chrono>
#include <cmath>
#include <mutex>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/parallel.h"
#include "core/rng.h"
#include "optics/image_pooling.h"
#include "render/fluence_field.h"
#include "render/fluorescence.h"
#include "render/straight_line.h"

namespace fluorosim::optics {
namespace {

constexpr double kPlanckTimesC = 1.98644586e-16;  // h c in J nm

uint64_t hashName(const std::string& s) {
    uint64_t h = 0xcbf29ce484222325ULL;  // FNV-1a
    for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ULL;
    return h;
}

// Photoelectrons per joule of light at λ reaching the camera: emission path, QE and photons per joule.
std::function<double(double)> detectionOf(const Filter& emission, const DetectorOptions& detector) {
    return [&emission, &detector](double lambda) { return emission.transmission(lambda) * detector.qe(lambda) * lambda / kPlanckTimesC; };
}

}  // namespace

const char* estimatorName(Estimator e) { return e == Estimator::Path ? "path" : "split"; }

std::optional<Estimator> estimatorFromName(const std::string& name) {
    if (name == "path") return Estimator::Path;
    if (name == "split") return Estimator::Split;
    return std::nullopt;
}

void ExcitationFieldOptions::validate() const {
    auto positive = [](double v, const char* what) {
        if (!(v > 0) || !std::isfinite(v)) throw ConfigError(std::string("excitation field ") + what + " must be positive and finite, got " + std::to_string(v));
    };
    auto nonNegative = [](double v, const char* what) {
        if (!(v >= 0) || !std::isfinite(v)) throw ConfigError(std::string("excitation field ") + what + " must be >= 0 and finite, got " + std::to_string(v));
    };
    if (lateralUm != 0) positive(lateralUm, "lateral spacing (um)");
    positive(axialUm, "axial spacing (um)");
    positive(halfDepthUm, "half depth (um)");
    if (marginUm) nonNegative(*marginUm, "margin (um)");
    if (reachUm) nonNegative(*reachUm, "reach (um)");
    if (diffuseUm && *diffuseUm != 0) positive(*diffuseUm, "diffuse spacing (um)");
    positive(coarseAxialUm, "coarse axial spacing (um)");
    positive(coarseLateralUm, "coarse lateral spacing (um)");
    if (photons == 1 || photons > (uint64_t(1) << 40)) throw ConfigError("excitation field photons must be 0 or lie in [2, 2^40], got " + std::to_string(photons));
}

void AcquireOptions::validate() const {
    if (spp < 1) throw ConfigError("spp must be at least 1, got " + std::to_string(spp));
    if (threads < 0) throw ConfigError("threads must be >= 0, got " + std::to_string(threads));
    if (noiseRatio && !(*noiseRatio > 0 && std::isfinite(*noiseRatio)))
        throw ConfigError("noise ratio must be positive and finite, got " + std::to_string(*noiseRatio));
    if (noiseRatio && (maxSpp < spp || firstPilotSpp < 2 || pilotSpp < firstPilotSpp))
        throw ConfigError("adaptive sampling needs max spp >= spp and 2 <= first pilot samples <= pilot samples, got max " + std::to_string(maxSpp) +
                          ", spp " + std::to_string(spp) + ", pilot " + std::to_string(firstPilotSpp) + " then " + std::to_string(pilotSpp));
    if (!(poolingFraction >= 0 && poolingFraction <= 1)) throw ConfigError("pooling fraction must lie in [0, 1], got " + std::to_string(poolingFraction));
    if (labels && labelCount < 1) throw ConfigError("a label tally needs at least one label");
    unscattered.validate();
    psf.validate();
    field.validate();
    emission.validate();
}

uint64_t planeStreamKey(const std::string& channelName, int plane) { return mixBits(hashName(channelName) + mixBits(static_cast<uint64_t>(plane) + 1)); }

namespace {

// What the microscope puts around one camera path: the PSF weight at its first vertex, the computed
// part the path leaves out, and that part's emission for the path to connect to after scattering.
class PathImaging final : public CameraPathImaging {
public:
    PathImaging(const Imaging& imaging, const UnscatteredModel* computed, const EmissionPoints* emission, const Vec3& pixelPoint,
                double poolingFraction, const ScatteredEmissionImage* traced = nullptr)
        : imaging_(imaging), computed_(computed), emission_(emission && !emission->empty() ? emission : nullptr), pixelPoint_(pixelPoint),
          poolingFraction_(poolingFraction), traced_(traced) {}
    bool tracesFieldLitEmission(int medium) const override { return traced_ && traced_->tracesFieldLit(medium); }
    bool tracesBeamLitEmissionAt(const Vec3& y, int medium) const override { return traced_ && traced_->tracesBeamLit(y, medium); }
    SampledSpectrum firstVertexWeight(const Vec3& y, const SampledWavelengths& wl) const override {
        return imaging_.firstVertexWeight(pixelPoint_, y, wl);
    }
    bool computesUnscatteredAt(const Vec3& y) const override { return computed_ && computed_->covers(imaging_, y); }
    std::optional<EmissionPoint> sampleEmissionPoint(double uCell, double ux, double uy, double uz) const override {
        if (!emission_) return std::nullopt;
        const EmissionPoints::Sample s = emission_->sample(uCell, ux, uy, uz);
        return EmissionPoint{s.p, s.pdf};
    }
    double emissionPointPdf(const Vec3& p) const override { return emission_ ? emission_->pdf(p) : 0.0; }
    // Blocks of 2^k pixels with 2^k <= fraction × the radius (in pixels) of y's geometric defocus disc.
    int imageLevel(const Vec3& y) const override {
        if (!(poolingFraction_ > 0)) return 0;
        const double disc = std::abs(imaging_.local(y).dz) * imaging_.tanThetaMax() / imaging_.pixelMm();
        const double block = poolingFraction_ * disc;
        return block >= 2 ? std::min(kImageLevels - 1, static_cast<int>(std::floor(std::log2(block)))) : 0;
    }

private:
    const Imaging& imaging_;
    const UnscatteredModel* computed_;
    const EmissionPoints* emission_;
    Vec3 pixelPoint_;
    double poolingFraction_;
    const ScatteredEmissionImage* traced_;
};

// Adaptive sampling traces at most this many times the first count of field photons.
constexpr double kMostFieldFactor = 16;
// Under a target at the camera's noise or finer the field starts at this many times its count: its noise is
// correlated across the image, so its estimate from two halves has about one degree of freedom over the
// brightest pixels, and on two seeds in six it read a fraction of the field's variance and stopped short
// (σs 1–2 /mm at --noise-ratio 0.6: 0.11–0.26 of the camera's variance; docs/performance.md, "The field's
// start under a camera target"). Starting there, not adding to a pilot's field, traces the field and the
// computed image once.
constexpr double kAdaptiveFieldStart = 4;
// Pilot paths of adaptive sampling draw from sample indices the estimate never reaches.
constexpr uint64_t kPilotSample = uint64_t(1) << 40;
// The further traces of adaptive sampling (field and photons) draw from streams keyed apart from the first's.
constexpr uint64_t kAdaptiveStreams = 0x6d6f7265ULL;

// One rule for the adaptive field and photons: a part whose median variance over the camera's is `ratio`,
// against half the target's square (the rest is left to the other parts), takes that multiple of its
// `first` count (at most `mostFactor` times it) in all: the photons to add, or 0 when it already meets it
// or the addition is below two (the tracers' smallest count).
uint64_t adaptiveExtraPhotons(double ratio, double noiseRatio, double mostFactor, uint64_t first) {
    const double target = 0.5 * sqr(noiseRatio);
    if (!(ratio > target)) return 0;
    const double extra = std::ceil((std::min(mostFactor, ratio / target) - 1) * static_cast<double>(first));
    return extra >= 2 ? static_cast<uint64_t>(extra) : 0;
}

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

// Adds the pooled parts to an image: per level k, the rows' sums of pixel means by block column become
// block means (summed in row order, whatever the thread count), interpolated bilinearly between block
// centres to every pixel, with their variances by the same weights squared.
template <class Rows, class SumOf, class VarianceOf>
void addPooledParts(const Rows& rows, int width, int height, PlaneImage& r, SumOf sumOf, VarianceOf varianceOf) {
    std::vector<double> variance(r.electrons.size());
    for (size_t i = 0; i < variance.size(); ++i) variance[i] = sqr(r.stderrElectrons[i]);
    for (int k = 1; k < kImageLevels; ++k) {
        const PoolingBlocks blocks(width, height, k);
        std::vector<double> mean(blocks.count(), 0.0), var(mean.size(), 0.0);
        bool any = false;
        for (int y = 0; y < height; ++y) {
            const std::vector<double>& sum = sumOf(rows[static_cast<size_t>(y)], k);
            if (sum.empty()) continue;
            any = true;
            const std::vector<double>& v = varianceOf(rows[static_cast<size_t>(y)], k);
            for (int c = 0; c < blocks.bx; ++c) {
                mean[static_cast<size_t>((y >> k) * blocks.bx + c)] += sum[static_cast<size_t>(c)];
                var[static_cast<size_t>((y >> k) * blocks.bx + c)] += v[static_cast<size_t>(c)];
            }
        }
        if (!any) continue;
        for (size_t b = 0; b < mean.size(); ++b) {
            mean[b] /= blocks.pixels(b);
            var[b] /= blocks.pixels(b) * blocks.pixels(b);
        }
        blocks.forEachPixel([&](size_t pixel, const std::array<std::pair<size_t, double>, 4>& w) {
            double m = 0, v = 0;
            for (const auto& [i, wi] : w) {
                m += wi * mean[i];
                v += wi * wi * var[i];
            }
            r.electrons[pixel] += m;
            variance[pixel] += v;
            r.pathElectrons += m;
            r.pooledElectrons += m;
        });
    }
    for (size_t i = 0; i < variance.size(); ++i) r.stderrElectrons[i] = std::sqrt(variance[i]);
}

PlaneImage renderWith(const Scene& scene, const PathTracer& tracer, const ObjectiveOptions& objective, const FocalPlane& focus,
                      const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                      const AcquireOptions& o, const ChannelImaging& channel) {
    const auto start = std::chrono::steady_clock::now();
    const WavelengthSampler wavelengths = cameraWavelengthSampler(scene, tracer.lights(), tracer.fluorescence().active());
    const Imaging imaging(objective, focus, detector, width, height, channel.psfAt(focus));
    const WidefieldPsf& psf = imaging.psf();
    const auto detection = detectionOf(emission, detector);
    const UnscatteredModel* model = o.estimator == Estimator::Split && channel.unscattered && channel.unscattered->active()
                                        ? channel.unscattered.get()
                                        : nullptr;
    PlaneImage r;
    r.width = width;
    r.height = height;
    r.electrons.assign(static_cast<size_t>(width) * height, 0.0);
    r.stderrElectrons.assign(r.electrons.size(), 0.0);
    // Dark electrons of the exposure: part of the camera noise an adaptive target is relative to.
    const double darkElectrons = detector.darkCurrentElectronsPerS * detector.exposureS;
    std::vector<double> computed(r.electrons.size(), 0.0);
    std::shared_ptr<const EmissionPoints> emissionPoints;
    std::unique_ptr<const BeamExcitationField> field;
    // The traced photons' sources in the field-lit dye: their density is the field's, so the traces with one
    // field share them, and more field makes them again.
    std::optional<DyeCells> dyeCells;
    auto fieldComplete = [&] {
        return !field || std::all_of(field->fields().begin(), field->fields().end(), [](const BeamFluence& f) { return f.stats.complete; });
    };
    // The computed image with the current field, and what the plane keeps of it (false: cancelled).
    auto makeComputed = [&] {
        const UnscatteredPlane u = computeUnscatteredImage(scene, tracer.lights(), imaging, *model, o.threads, o.cancel, field.get());
        if (!u.complete) return false;
        r.fieldPhotons = 0;
        r.fieldSeconds = 0;
        if (field)
            for (const BeamFluence& f : field->fields()) {
                r.fieldPhotons += f.stats.photons;
                r.fieldSeconds += f.stats.seconds;
                r.fieldLateralSpacingUm = f.mean.box().hx * 1e3;
                r.fieldMarginUm = (f.reach().halfX - f.mean.box().halfX) * 1e3;
                r.fieldReachUm = f.reach().halfZ * 1e3;
                r.fieldDiffuseSpacingUm = f.diffuse ? f.diffuse->box().hx * 1e3 : 0.0;
            }
        computed = u.electrons;
        emissionPoints = u.emission;
        r.computedPoints = u.points;
        r.computedDroppedFraction = u.droppedFraction;
        r.computedSeconds += u.seconds;
        r.computedTimings = u.timings;
        r.computedImage = u.electrons;
        r.fieldElectrons = u.fieldElectrons;
        r.fieldHalfDifference = u.fieldHalfDifference;
        return true;
    };
    // Adaptive sampling of the field: `photons` more per line side, in a further trace from the streams
    // `streams` apart, pooled with what it has, and the computed image made again (false: cancelled).
    auto poolMoreField = [&](uint64_t photons, uint64_t streams) {
        AcquireOptions more = o;
        more.field.photons = photons;
        std::unique_ptr<const BeamExcitationField> extra = traceExcitationField(scene, tracer, imaging, *model, more, mixBits(streamKey + streams));
        if (extra) {
            std::vector<BeamFluence> pooled;
            for (size_t i = 0; i < field->fields().size(); ++i) pooled.push_back(pooledFluence(field->fields()[i], extra->fields()[i]));
            field = std::make_unique<const BeamExcitationField>(std::move(pooled));
            dyeCells.reset();
        }
        return fieldComplete() && makeComputed();
    };
    // A part's variance over the camera's, the larger of its medians over the brightest tenth and the brightest
    // 1 % (at least 64 pixels): where the neurites are.
    auto overBrightest = [&](const std::vector<double>& variance, const std::vector<double>& signal) {
        const double brightest = std::min(0.99, 1.0 - 64.0 / double(signal.size()));
        return std::max(medianVarianceOverCamera(variance, signal, 0.9, darkElectrons, detector.readNoiseElectrons),
                        medianVarianceOverCamera(variance, signal, brightest, darkElectrons, detector.readNoiseElectrons));
    };
    AcquireOptions fieldStart = o;
    if (o.noiseRatio && *o.noiseRatio <= 1) fieldStart.field.photons = static_cast<uint64_t>(kAdaptiveFieldStart * static_cast<double>(o.field.photons));
    if (model) {
        field = traceExcitationField(scene, tracer, imaging, *model, fieldStart, streamKey);
        if (!fieldComplete() || !makeComputed()) {
            r.complete = false;
            return r;
        }
    }
    const bool bends = hasRefractingSurfaces(scene);
    // The computed emission's scattered light, traced forward; the paths then leave it out.
    ScatteredEmissionImage traced;
    // Only where something scatters: in clear tissue the paths' share (re-emission alone) costs less than photons.
    const bool scattersEmission = std::any_of(scene.media.begin(), scene.media.end(), [&](const Medium& m) {
        if (m.isVacuumLike() || !(m.channelMax()[kScatteringChannel] > 0)) return false;
        for (double l = scene.spectral.lambdaMin; l <= scene.spectral.lambdaMax; l += 1)
            if (m.scatteringAt(l) > 0 && emission.transmission(l) > 0) return true;
        return false;
    });
    // Not with labels: the paths split their re-emissions by label, the photons do not (a fit's per-label
    // scattered light would put the traced part in what no label scales).
    const bool emissionTraced = model && emissionPoints && !emissionPoints->empty() && o.emission.photonsFor(static_cast<size_t>(width) * height) > 0 &&
                                scattersEmission && tracer.fluorescence().model() == FluorescenceModel::Full && !o.labels;
    if (emissionTraced) {
        std::optional<PathImaging> covered;
        double discardedSeconds = 0;  // a pilot traced before more field is time spent all the same
        // `photons` of the plane's photons, from the streams `streams` apart from the first's (false: cancelled).
        auto traceEmission = [&](uint64_t photons, uint64_t streams, ScatteredEmissionImage& into) {
            covered.emplace(imaging, model, emissionPoints.get(), imaging.centre(), o.poolingFraction);
            if (field && !field->fields().empty() && !dyeCells) dyeCells.emplace(scene, tracer, *field, tracer.lineWavelengths(), detection, imaging, o.threads);
            ScatteredEmissionOptions count = o.emission;
            count.photons = photons;
            into = traceScatteredEmission(scene, tracer, imaging, *covered, *emissionPoints, field.get(), dyeCells ? &*dyeCells : nullptr, detection,
                                          detector.exposureS, count, o.seed, streams ? mixBits(streamKey + streams) : streamKey, o.threads, o.cancel);
            return into.complete;
        };
        const uint64_t first = o.emission.photonsFor(static_cast<size_t>(width) * height);
        // Adaptive sampling: a pilot of a quarter of the photons decides the field first. The field's noise
        // reaches the computed image and, through the photons' sources, the haze (docs/performance.md, "Weight
        // windows"). Where the two together miss half the target's over the brightest tenth or 1 % (where the
        // neurites are; at least 64 pixels): more field photons (within kMostFieldFactor times the first count)
        // in one further trace pooled with the first, the computed image made again, and all the photons traced
        // with the pooled field; else the pilot is a quarter of them.
        const uint64_t pilot = o.noiseRatio && field ? first / 4 : 0;
        if (pilot >= 2) {
            if (!traceEmission(pilot, kAdaptiveStreams + 2, traced)) {
                r.complete = false;
                return r;
            }
            uint64_t fieldPhotons = 0;
            if (traced.fieldHalfDifference.size() == computed.size()) {
                std::vector<double> variance(computed.size()), signal(computed.size());
                for (size_t i = 0; i < variance.size(); ++i) {
                    // In the photons' units: a half difference is one degree of freedom.
                    const double halfDifference = (r.fieldHalfDifference.empty() ? 0.0 : r.fieldHalfDifference[i]) + traced.fieldHalfDifference[i];
                    variance[i] = sqr(halfDifference) / kMedianOfChiSquare1;
                    signal[i] = computed[i] + traced.electrons[i];
                }
                fieldPhotons = adaptiveExtraPhotons(overBrightest(variance, signal), *o.noiseRatio,
                                                    kMostFieldFactor * static_cast<double>(o.field.photons) / static_cast<double>(fieldStart.field.photons),
                                                    fieldStart.field.photons);
                if (fieldPhotons > 0 && !poolMoreField(fieldPhotons, kAdaptiveStreams)) {
                    r.complete = false;
                    return r;
                }
            }
            ScatteredEmissionImage rest;
            if (!traceEmission(fieldPhotons > 0 ? first : first - pilot, 0, rest)) {
                r.complete = false;
                return r;
            }
            if (fieldPhotons > 0) discardedSeconds += traced.seconds;
            traced = fieldPhotons > 0 ? std::move(rest) : pooledTraces(traced, rest);
        } else if (!traceEmission(first, 0, traced)) {
            r.complete = false;
            return r;
        }
        // Adaptive sampling: more photons, in one further trace from other streams, until the traced part's
        // median variance over the brightest tenth and 1 % is at most half the target's (the rest is the
        // paths' and the field's), at most kMostTracedFactor times the first count. Its slots see only the
        // photons' own noise, not the field's that reaches their sources (docs/performance.md).
        if (o.noiseRatio && traced.photons > 0) {
            constexpr double kMostTracedFactor = 32;
            std::vector<double> signal = computed;
            for (size_t i = 0; i < signal.size(); ++i) signal[i] += traced.electrons[i];
            const uint64_t photons = adaptiveExtraPhotons(overBrightest(traced.variance, signal), *o.noiseRatio, kMostTracedFactor, traced.photons);
            if (photons > 0) {
                ScatteredEmissionImage extra;
                if (!traceEmission(photons, kAdaptiveStreams, extra)) {
                    r.complete = false;
                    return r;
                }
                traced = pooledTraces(traced, extra);
            }
        }
        // The field's noise in the image: the computed part's and the traced part's, from the same halves.
        if (traced.fieldHalfDifference.size() == computed.size()) {
            if (r.fieldHalfDifference.empty()) r.fieldHalfDifference.assign(computed.size(), 0.0);
            for (size_t i = 0; i < computed.size(); ++i) r.fieldHalfDifference[i] += traced.fieldHalfDifference[i];
        }
        r.emissionPhotons = traced.photons;
        r.emissionVertices = traced.vertices;
        r.emissionSeconds = traced.seconds + discardedSeconds;
        r.emissionVariance = traced.variance;
        r.emissionEstimates = traced.slots;
        for (size_t i = 0; i < computed.size(); ++i) {
            computed[i] += traced.electrons[i];
            r.emissionElectrons += traced.electrons[i];
        }
    }
    // Each row's totals, kept apart so that threads never share them; summed into the image at the end.
    struct RowTotals {
        PathStats stats;
        double largest = 0, computed = 0, path = 0, pathSeconds = 0;
        uint64_t samples = 0, pilots = 0, nonFinite = 0;
        bool done = false;
        // Pooled parts: per level, this row's sums of its pixels' means (and their variances) by block column.
        std::array<std::vector<double>, kImageLevels> pooledSum, pooledVariance;
    };
    std::vector<RowTotals> rows(static_cast<size_t>(height));
    // Per label and image level, the mean of each pixel's samples.
    std::vector<std::array<std::vector<double>, kImageLevels>> labelledLevels(o.labels ? static_cast<size_t>(o.labelCount) : 0);
    if (o.labels) {
        requireMemory(8.0 * kImageLevels * static_cast<double>(o.labelCount) * static_cast<double>(r.electrons.size()), "the scattered light's tally per label");
        for (auto& levels : labelledLevels)
            for (auto& image : levels) image.assign(r.electrons.size(), 0.0);
    }
    std::vector<double> largestInPixel(r.electrons.size(), 0.0);  // largest per-pixel path sample
    int rowsDone = 0;
    std::mutex progressMutex;  // the callback is called from one thread at a time
    // A sample's electrons, the parts of them pooled at each level, and by label.
    struct Sample {
        double total = 0;
        std::array<double, kImageLevels> pooled{};
        std::vector<std::pair<uint32_t, double>> labelled;  // (key × kImageLevels + level, electrons)
    };
    auto samplePath = [&](int x, int y, uint64_t s, PathStats& stats, uint64_t& nonFinite) {
        const size_t pixel = static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x);
        Rng rng = Rng::forKey(o.seed, streamKey + pixel, s);
        const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
        const Vec3 point = imaging.pixelPoint(x, y, rng.uniform(), rng.uniform());
        // The focal point moves by a sample of the in-focus PSF at the hero wavelength. Its density
        // ratios p_j/p_0 and throughputs f_j/p_0 start the path, so the tracer's spectral MIS weighs
        // the displacement together with the rest of the path.
        PathStart pathStart;
        double radius = 0;
        const Vec3 focal = point + imaging.displacement(rng.uniform(), rng.uniform(), wl.lambda[0], &radius);
        if (!wl.discrete) {
            const double hero = psf.displacementDensity(radius, wl.lambda[0]);
            for (int j = 1; j < kNumWavelengths; ++j) pathStart.r_u[j] = psf.displacementDensity(radius, wl.lambda[j]) / hero;
            pathStart.beta = pathStart.r_u;
        }
        const PathImaging pathImaging(imaging, model, emissionPoints.get(), point, o.poolingFraction, emissionTraced ? &traced : nullptr);
        pathStart.imaging = &pathImaging;
        pathStart.labels = o.labels;
        pathStart.field = field.get();
        pathStart.computedEmissionTraced = emissionTraced;
        const double uPhi = rng.uniform();  // drawn in the order the streams have always used
        const double uCos = rng.uniform();
        const Imaging::CameraStart cameraStart = imaging.cameraStart(scene, bends, focal, uCos, uPhi, wl);
        const double cosT = cameraStart.cosTheta;
        pathStart.beta *= cameraStart.weight;
        pathStart.tMin = cameraStart.tMin;
        const PathRadiance radiance = tracer.radiance(cameraStart.ray, cameraStart.medium, wl, rng, stats, pathStart);
        auto electrons = [&](const SampledSpectrum& L) {
            double e = 0;
            for (int j = 0; j < kNumWavelengths; ++j)
                if (L[j] != 0 && wl.pdf[j] != 0) e += L[j] / wl.pdf[j] * detection(wl.lambda[j]);
            return e * cosT * imaging.sampleEtendue() / kNumWavelengths;
        };
        Sample out;
        out.total = electrons(radiance.total());
        for (int k = 1; k < kImageLevels; ++k)
            if (radiance.pooled[static_cast<size_t>(k)]) out.pooled[static_cast<size_t>(k)] = electrons(radiance.pooled[static_cast<size_t>(k)]);
        for (const PathRadiance::Labelled& l : radiance.labelled)
            out.labelled.push_back({l.key * kImageLevels + static_cast<uint32_t>(std::clamp(l.level, 0, kImageLevels - 1)), electrons(l.radiance)});
        bool finite = std::isfinite(out.total);
        for (double e : out.pooled) finite = finite && std::isfinite(e);
        for (const auto& l : out.labelled) finite = finite && std::isfinite(l.second);
        if (!finite) {
            ++nonFinite;
            return Sample{};
        }
        return out;
    };
    // The paths a pixel's pilots ask for: as many as bring its standard error to the target.
    auto pathsWanted = [&](const PixelTally& pilot, size_t pixel) {
        const double signal = std::max(0.0, pilot.mean() + computed[pixel]);
        const double target = sqr(*o.noiseRatio) * (signal + darkElectrons + sqr(detector.readNoiseElectrons));
        return std::ceil(pilot.varianceOfMean() * pilot.n / target);
    };
    // Adaptive sampling: first the pilots of a lattice of every kPilotStride-th pixel across and down; the
    // other pixels draw pilots only in the lattice's cells that have a corner whose pilots ask for more than
    // spp. Where the field and the traced photons carry the scattered light the paths hold little of the
    // noise, and pilots in every pixel cost several times the paths they decide on (docs/performance.md,
    // "Pilots on a lattice"). Not at one path per pixel: a pixel's one path says nothing of its spread, its
    // pilots are all there is.
    constexpr int kPilotStride = 4;
    const bool latticeFirst = o.noiseRatio && o.spp >= 2;
    const int latticeWidth = (width + kPilotStride - 1) / kPilotStride, latticeHeight = (height + kPilotStride - 1) / kPilotStride;
    auto latticeIndex = [&](int lx, int ly) { return static_cast<size_t>(ly) * static_cast<size_t>(latticeWidth) + static_cast<size_t>(lx); };
    std::vector<PixelTally> latticePilots;
    std::vector<uint8_t> latticeAsks;  // whether a lattice pixel's first pilots ask for more than spp
    if (latticeFirst) {
        latticePilots.resize(static_cast<size_t>(latticeWidth) * static_cast<size_t>(latticeHeight));
        latticeAsks.assign(latticePilots.size(), 0);
        std::vector<RowTotals> latticeRows(static_cast<size_t>(latticeHeight));
        parallelFor(latticeRows.size(), o.threads, [&](size_t j) {
            if (o.cancel && o.cancel->load()) return;
            const auto t0 = std::chrono::steady_clock::now();
            RowTotals& row = latticeRows[j];
            const int y = static_cast<int>(j) * kPilotStride;
            for (int i = 0; i < latticeWidth; ++i) {
                const int x = i * kPilotStride;
                const size_t at = latticeIndex(i, static_cast<int>(j));
                for (int d = 0; d < o.firstPilotSpp; ++d)
                    latticePilots[at].add(samplePath(x, y, kPilotSample + static_cast<uint64_t>(d), row.stats, row.nonFinite).total);
                latticeAsks[at] = pathsWanted(latticePilots[at], static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x)) > o.spp;
            }
            row.pathSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        });
        for (const RowTotals& row : latticeRows) {
            r.stats.add(row.stats);
            r.nonFiniteSamples += row.nonFinite;
            r.pathSeconds += row.pathSeconds;
        }
        r.pilotSamples += latticePilots.size() * static_cast<uint64_t>(o.firstPilotSpp);
        r.pilotsOnLatticeOnly = std::none_of(latticeAsks.begin(), latticeAsks.end(), [](uint8_t a) { return a != 0; });
    }
    // Whether a pixel draws pilots of its own: a corner of its lattice cell asks for more paths.
    auto pilotsAt = [&](int x, int y) {
        if (!latticeFirst) return o.noiseRatio.has_value();
        const int lx = x / kPilotStride, ly = y / kPilotStride;
        for (int dy = 0; dy <= 1; ++dy)
            for (int dx = 0; dx <= 1; ++dx)
                if (latticeAsks[latticeIndex(std::min(lx + dx, latticeWidth - 1), std::min(ly + dy, latticeHeight - 1))]) return true;
        return false;
    };
    parallelFor(static_cast<size_t>(height), o.threads, [&](size_t yRow) {
        if (o.cancel && o.cancel->load()) return;
        const int y = static_cast<int>(yRow);
        RowTotals& row = rows[yRow];
        for (int x = 0; x < width; ++x) {
            const size_t pixel = yRow * static_cast<size_t>(width) + static_cast<size_t>(x);
            PixelTally paths;
            double largest = 0, largestOwn = 0;
            const auto t0 = std::chrono::steady_clock::now();
            auto pathSample = [&](uint64_t s) { return samplePath(x, y, s, row.stats, row.nonFinite); };
            int n = o.spp;
            if (pilotsAt(x, y)) {
                // Pilot paths from streams the estimate never uses decide how many to trace: the first few (a
                // lattice pixel's are drawn), and the rest of them where those ask for more than spp.
                const bool onLattice = latticeFirst && x % kPilotStride == 0 && y % kPilotStride == 0;
                PixelTally pilot = onLattice ? latticePilots[latticeIndex(x / kPilotStride, y / kPilotStride)] : PixelTally{};
                int drawn = onLattice ? o.firstPilotSpp : 0;
                const int alreadyDrawn = drawn;
                auto drawPilots = [&](int upTo) {
                    for (; drawn < upTo; ++drawn) pilot.add(pathSample(kPilotSample + static_cast<uint64_t>(drawn)).total);
                };
                drawPilots(o.firstPilotSpp);
                if (pathsWanted(pilot, pixel) > o.spp) drawPilots(o.pilotSpp);
                n = static_cast<int>(std::clamp(pathsWanted(pilot, pixel), double(o.spp), double(o.maxSpp)));
                row.pilots += static_cast<uint64_t>(drawn - alreadyDrawn);
            }
            std::array<PixelTally, kImageLevels> pooled;
            for (int s = 0; s < n; ++s) {
                const Sample e = pathSample(static_cast<uint64_t>(s));
                for (const auto& [slot, v] : e.labelled) {
                    const size_t key = slot / kImageLevels, level = slot % kImageLevels;
                    if (key >= labelledLevels.size()) continue;
                    labelledLevels[key][level][pixel] += v / n;
                }
                double own = e.total;  // the part imaged per pixel
                for (int k = 1; k < kImageLevels; ++k) {
                    own -= e.pooled[static_cast<size_t>(k)];
                    pooled[static_cast<size_t>(k)].add(e.pooled[static_cast<size_t>(k)]);
                    largest = std::max(largest, e.pooled[static_cast<size_t>(k)] / double(1 << (2 * k)));
                }
                paths.add(own);
                largest = std::max(largest, own);
                largestOwn = std::max(largestOwn, own);
            }
            for (int k = 1; k < kImageLevels; ++k) {
                const PixelTally& t = pooled[static_cast<size_t>(k)];
                if (t.sum == 0 && t.sum2 == 0) continue;
                std::vector<double>& sum = row.pooledSum[static_cast<size_t>(k)];
                std::vector<double>& var = row.pooledVariance[static_cast<size_t>(k)];
                if (sum.empty()) {
                    sum.assign(static_cast<size_t>(((width - 1) >> k) + 1), 0.0);
                    var.assign(sum.size(), 0.0);
                }
                sum[static_cast<size_t>(x >> k)] += t.mean();
                var[static_cast<size_t>(x >> k)] += t.varianceOfMean();
            }
            row.samples += static_cast<uint64_t>(n);
            row.pathSeconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
            r.electrons[pixel] = paths.mean() + computed[pixel];
            r.stderrElectrons[pixel] = std::sqrt(paths.varianceOfMean() + (emissionTraced ? traced.variance[pixel] : 0.0));
            row.largest = std::max(row.largest, largest);
            largestInPixel[pixel] = largestOwn;
            row.computed += computed[pixel] - (emissionTraced ? traced.electrons[pixel] : 0.0);
            row.path += paths.mean();
        }
        row.done = true;
        const std::lock_guard<std::mutex> lock(progressMutex);
        ++rowsDone;
        if (o.progress) o.progress(double(rowsDone) / height);
    });
    addPooledParts(rows, width, height, r, [](const RowTotals& row, int k) -> const std::vector<double>& { return row.pooledSum[static_cast<size_t>(k)]; },
                   [](const RowTotals& row, int k) -> const std::vector<double>& { return row.pooledVariance[static_cast<size_t>(k)]; });
    // Each label's share, pooled as the total is: per level, the block means of its pixels' means,
    // interpolated bilinearly between block centres.
    for (auto& levels : labelledLevels) {
        std::vector<double> image = levels[0];
        for (int k = 1; k < kImageLevels; ++k)
            if (std::any_of(levels[static_cast<size_t>(k)].begin(), levels[static_cast<size_t>(k)].end(), [](double v) { return v != 0; })) {
                const std::vector<double> pooled = poolImage(levels[static_cast<size_t>(k)], width, height, k);
                for (size_t i = 0; i < image.size(); ++i) image[i] += pooled[i];
            }
        r.labelledElectrons.push_back(std::move(image));
    }
    // Heavy tails: a pixel's largest path sample against its value, where the value is above the read
    // noise² (below it a ratio says nothing about the camera).
    for (size_t i = 0; i < r.electrons.size(); ++i)
        if (r.electrons[i] > std::max(1.0, sqr(detector.readNoiseElectrons)))
            r.largestSampleOverPixel = std::max(r.largestSampleOverPixel, largestInPixel[i] / r.electrons[i]);
    for (const RowTotals& row : rows) {
        r.stats.add(row.stats);
        r.largestSample = std::max(r.largestSample, row.largest);
        r.complete = r.complete && row.done;
        r.computedElectrons += row.computed;
        r.pathElectrons += row.path;
        r.pathSeconds += row.pathSeconds;
        r.pathSamples += row.samples;
        r.pilotSamples += row.pilots;
        r.nonFiniteSamples += row.nonFinite;
    }
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

void checkPlaneArguments(const ObjectiveOptions& objective, const FocalPlane& focus, const DetectorOptions& detector, int width, int height,
                         const AcquireOptions& o) {
    objective.validate();
    focus.validate();
    detector.validate();
    o.validate();
    if (width < 1 || height < 1) throw ConfigError("image size must be positive, got " + std::to_string(width) + " x " + std::to_string(height));
}

// The centre of the channel's emission path: the wavelength the PSF's apodisation is measured at.
double emissionCentreNm(const Filter& emission, const Scene& scene) {
    double sum = 0, weight = 0;
    for (double l = scene.spectral.lambdaMin; l <= scene.spectral.lambdaMax; l += 1) {
        const double t = emission.transmission(l);
        sum += t * l;
        weight += t;
    }
    return weight > 0 ? sum / weight : 0.5 * (scene.spectral.lambdaMin + scene.spectral.lambdaMax);
}

}  // namespace

ChannelImaging setUpChannelImaging(const Scene& scene, const std::vector<Light>& lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                                   const Filter& emission, const DetectorOptions& detector, int width, int height, const AcquireOptions& o,
                                   std::vector<double> planeOffsetsMm, bool labels) {
    checkPlaneArguments(objective, focus, detector, width, height, o);
    if (planeOffsetsMm.empty()) throw ConfigError("a channel's imaging needs at least one plane");
    ChannelImaging c;
    c.focusMm = focus.centreMm;
    c.axis = normalize(focus.towardObjective);
    c.planeOffsetsMm = planeOffsetsMm;
    c.planePsfs = makePlanePsfs(scene, objective, focus, planeOffsetsMm, emissionCentreNm(emission, scene), o.psf);
    size_t nearest = 0;
    for (size_t i = 1; i < planeOffsetsMm.size(); ++i)
        if (std::abs(planeOffsetsMm[i]) < std::abs(planeOffsetsMm[nearest])) nearest = i;
    c.psf = c.planePsfs[nearest];
    if (o.estimator == Estimator::Split) {
        const FluorescencePlan plan(scene, lights);
        const Imaging imaging(objective, focus, detector, width, height, c.psf);
        c.unscattered = std::make_shared<const UnscatteredModel>(scene, lights, plan, imaging, detectionOf(emission, detector), o.unscattered,
                                                                 std::move(planeOffsetsMm), labels, c.planePsfs);
    }
    return c;
}

const std::shared_ptr<const WidefieldPsf>& ChannelImaging::psfAt(const FocalPlane& focus) const {
    const Vec3 d = focus.centreMm - focusMm;
    const double offset = dot(d, axis);
    if (length(d - axis * offset) <= 1e-9)
        for (size_t i = 0; i < planeOffsetsMm.size(); ++i)
            if (std::abs(planeOffsetsMm[i] - offset) <= 1e-9) return planePsfs[i];
    return psf;
}

// The excitation field's node spacing along the focal plane. Its noise where the sheets light the dye
// falls with the number of photons whose tracks cross a node's support, which grows with the support's
// extent along the sheet's height; coarse nodes smooth the field twice by a hat, an error of about
// (h²/6) φ''/φ. Along the focal plane φ varies on the scattering length (attenuation along the beam) and at
// the sheet's height edges (measured at 16 um spacing in σs 5 /mm tissue: 11 % low 10 um inside a top-hat
// edge, unchanged 30 um inside it). So a coarse spacing h is taken only where h is at most a tenth of the
// scattering length of every medium that scatters at a line ((h²/6)σ² <= 0.2 %), and every side's light per
// unit height (its irradiance integrated across the sheet, ±20 um) varies by at most 2 % over the box grown
// by 2h on each side (both hats' support); else kFineLateralMm.
double fieldLateralSpacingMm(const Scene& scene, const std::vector<BeamLineSide>& lines, const FieldBox& box) {
    constexpr double kFineLateralMm = 0.004;
    double sigmaMax = 0;  // the largest extinction at a line
    for (const BeamLineSide& l : lines) sigmaMax = std::max(sigmaMax, largestExtinctionAt(scene, l.lambdaNm));
    for (double h : {0.016, 0.008}) {
        if (h * sigmaMax > 0.1) continue;
        bool flat = true;
        for (const BeamLineSide& l : lines) {
            // ∫ E dz across the sheet at (x, y) of the focal plane, ±20 um in steps of 0.125 um.
            auto column = [&](double x, double y) {
                double sum = 0;
                for (int k = -160; k <= 160; ++k)
                    sum += l.profile->irradiance(box.centre + box.right * x + box.up * y + box.axis * (k * 1.25e-4), l.side, l.lambdaNm);
                return sum;
            };
            const double centre = column(0, 0);
            flat = centre > 0;
            for (int i = 0; i <= 8 && flat; ++i)
                for (int j = 0; j <= 8 && flat; ++j)
                    flat = std::abs(column((box.halfX + 2 * h) * (i / 4.0 - 1), (box.halfY + 2 * h) * (j / 4.0 - 1)) / centre - 1) <= 0.02;
            if (!flat) break;
        }
        if (flat) return h;
    }
    return kFineLateralMm;
}

// The largest reduced scattering coefficient μs' = σs (1 - g) (/mm) of the scene's media at the lines.
double largestReducedScattering(const Scene& scene, const std::vector<BeamLineSide>& lines) {
    double reduced = 0;
    for (const Medium& m : scene.media)
        if (!m.isVacuumLike())
            for (const BeamLineSide& l : lines)
                reduced = std::max(reduced, m.scatteringAt(l.lambdaNm) * m.channelMax()[kScatteringChannel] * (1 - m.phase().g()));
    return reduced;
}

// The diffuse light's node spacing where the options leave it unset: a tenth of the transport length 1 / μs',
// within [4, 50] um (0 where nothing scatters). In uncleared cortex (μs' 2 /mm: 50 um) the light that reaches
// the field of view 1 mm from where the sheet enters has scattered 10-100 times; on the far nodes (16 x 16 x
// 4 um) the few photons that crossed a bright dendrite decided its light, and the 488 nm channel's sum over
// four seeds spread 22 % (1.98-3.41 x 10^5 e-); on 50 um nodes 3 %, and the field took 30 % less time.
double fieldDiffuseSpacingMm(const Scene& scene, const std::vector<BeamLineSide>& lines, const ExcitationFieldOptions& o) {
    if (o.diffuseUm) return *o.diffuseUm * 1e-3;
    const double reduced = largestReducedScattering(scene, lines);
    return reduced > 0 ? std::clamp(0.1 / reduced, 0.004, 0.05) : 0.0;
}

// The field's margin and reach where the options leave them unset: 100 and 120 um, or 0.15 mm² × the largest
// reduced scattering coefficient μs' = σs (1 - g) at a line where that is more. Where the sheet's light has
// scattered wide (uncleared cortex, μs' 2 /mm) dye 120-300 um from focus and beside the field of view is lit
// by it: beyond the reach the camera paths found that light by sub-paths, and one sample of 10^5 e- pooled
// over a 32-pixel block was the brightest 1 %'s noise (median MC/shot 47.9 at 120 um, 1.45 at 300 um).
// In σs 1-2 /mm tissue (μs' <= 0.2 /mm) the floors hold: a wider field there costs time and gains nothing.
std::pair<double, double> fieldMarginAndReachMm(const Scene& scene, const std::vector<BeamLineSide>& lines, const ExcitationFieldOptions& o) {
    constexpr double kMarginFloorMm = 0.1, kReachFloorMm = 0.12, kPerReducedScatteringMm2 = 0.15;
    const double scaled = kPerReducedScatteringMm2 * largestReducedScattering(scene, lines);
    return {o.marginUm ? *o.marginUm * 1e-3 : std::max(kMarginFloorMm, scaled), o.reachUm ? *o.reachUm * 1e-3 : std::max(kReachFloorMm, scaled)};
}

std::unique_ptr<const BeamExcitationField> traceExcitationField(const Scene& scene, const PathTracer& tracer, const Imaging& imaging,
                                                               const UnscatteredModel& model, const AcquireOptions& o, uint64_t streamKey) {
    if (o.field.photons == 0 || tracer.fluorescence().model() != FluorescenceModel::Full) return nullptr;
    const std::vector<BeamLineSide> lines = beamLineSides(tracer.lights());
    if (lines.empty()) return nullptr;
    // Something must scatter at a line for the field to hold any light.
    const bool scatters = std::any_of(scene.media.begin(), scene.media.end(), [&](const Medium& m) {
        return !m.isVacuumLike() && m.channelMax()[kScatteringChannel] > 0 &&
               std::any_of(lines.begin(), lines.end(), [&](const BeamLineSide& l) { return m.scatteringAt(l.lambdaNm) > 0; });
    });
    if (!scatters) return nullptr;
    for (const BeamLineSide& l : lines)
        if (!l.profile->axisPoint()) return nullptr;
    const LatticeGeometry& g = model.geometry();
    FieldBox box;
    box.centre = imaging.centre();
    box.right = imaging.world(1, 0, 0) - imaging.world(0, 0, 0);
    box.axis = imaging.axis();
    box.up = imaging.world(0, 1, 0) - imaging.world(0, 0, 0);
    box.halfX = 0.5 * g.regionWidth() * g.pixelMm;
    box.halfY = 0.5 * g.regionHeight() * g.pixelMm;
    box.halfZ = std::max(g.halfDepthMm(), o.field.halfDepthUm * 1e-3);
    // Beyond them, out to the margin and the reach, the far grid.
    const auto [marginMm, reachMm] = fieldMarginAndReachMm(scene, lines, o.field);
    box.farHalfX = box.halfX + marginMm;
    box.farHalfY = box.halfY + marginMm;
    box.farHalfZ = reachMm;
    box.farHz = o.field.coarseAxialUm * 1e-3;
    box.farHxy = o.field.coarseLateralUm * 1e-3;
    box.hx = box.hy = o.field.lateralUm > 0 ? o.field.lateralUm * 1e-3 : fieldLateralSpacingMm(scene, lines, box);
    box.hz = o.field.axialUm * 1e-3;
    box.diffuseH = fieldDiffuseSpacingMm(scene, lines, o.field);
    FluenceOptions fo;
    fo.photons = o.field.photons;
    fo.seed = mixBits(o.seed + mixBits(streamKey + 0x6669656c64ULL));
    fo.threads = o.threads;
    std::vector<BeamFluence> fields;
    for (const BeamLineSide& l : lines) {
        fields.push_back(traceBeamFluence(scene, l, box, fo, o.cancel));
        if (!fields.back().stats.complete) break;
    }
    return std::make_unique<const BeamExcitationField>(std::move(fields));
}

PlaneImage renderPlane(const Scene& scene, std::vector<Light> lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                       const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                       const AcquireOptions& options, const ChannelImaging* channel) {
    checkPlaneArguments(objective, focus, detector, width, height, options);
    const PathTracer tracer(scene, std::move(lights));
    const ChannelImaging own = channel ? ChannelImaging{} : setUpChannelImaging(scene, tracer.lights(), objective, focus, emission, detector, width,
                                                                                 height, options);
    return renderWith(scene, tracer, objective, focus, emission, detector, width, height, streamKey, options, channel ? *channel : own);
}

PlaneImage renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                       const DetectorOptions& detector, int width, int height, const AcquireOptions& options) {
    checkPlaneArguments(objective, focus, detector, width, height, options);
    const PathTracer tracer(scene);
    const ChannelImaging own = setUpChannelImaging(scene, tracer.lights(), objective, focus, emission, detector, width, height, options);
    return renderWith(scene, tracer, objective, focus, emission, detector, width, height, 0, options, own);
}

ChannelImaging setUpChannelImaging(const Scene& scene, const Microscope& m, size_t channel, const AcquireOptions& options, bool labels) {
    if (channel >= m.channels.size()) throw ConfigError("channel index " + std::to_string(channel) + " is out of range");
    const MicroscopeChannel& c = m.channels[channel];
    // The stack's centre: planes are offset symmetrically about the focus.
    std::vector<double> offsets;
    for (int k = 0; k < m.stack.planes; ++k) offsets.push_back(m.planeOffsetMm(k));
    return setUpChannelImaging(scene, m.lightsAt(scene, c, 0.0), m.objective, m.focalPlaneAt(0.0), c.emissionPath, m.detector, m.width, m.height,
                               options, std::move(offsets), labels);
}

PlaneImage acquirePlane(const Scene& scene, const Microscope& m, size_t channel, int plane, const AcquireOptions& options,
                        const ChannelImaging* imaging) {
    if (channel >= m.channels.size()) throw ConfigError("channel index " + std::to_string(channel) + " is out of range");
    if (plane < 0 || plane >= m.stack.planes)
        throw ConfigError("plane " + std::to_string(plane) + " is outside the stack of " + std::to_string(m.stack.planes));
    const MicroscopeChannel& c = m.channels[channel];
    const double offset = m.planeOffsetMm(plane);
    const ChannelImaging own = imaging ? ChannelImaging{} : setUpChannelImaging(scene, m, channel, options);
    return renderPlane(scene, m.lightsAt(scene, c, offset), m.objective, m.focalPlaneAt(offset), c.emissionPath, m.detector, m.width, m.height,
                       planeStreamKey(c.name, plane), options, imaging ? imaging : &own);
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

AutoExposure autoExpose(Stack& stack, Microscope& m, double fraction, uint64_t seed) {
    if (!(fraction > 0 && fraction <= 1)) throw ConfigError("--exposure auto: the full-well fraction must lie in (0, 1], got " + std::to_string(fraction));
    const std::vector<double> dark = Detector(m.detector).expectedElectrons(std::vector<double>(static_cast<size_t>(stack.width) * stack.height, 0.0));
    double reliable = 0, any = 0;
    for (size_t slot = 0; slot < stack.channels.size(); ++slot)
        for (int k = 0; k < stack.planes; ++k) {
            if (!stack.done[stack.index(slot, k)]) continue;
            const size_t off = stack.pixelOffset(slot, k);
            for (size_t i = 0; i < static_cast<size_t>(stack.width) * stack.height; ++i) {
                const double signal = stack.expected[off + i] - dark[i];
                any = std::max(any, signal);
                if (stack.stderrElectrons[off + i] <= 0.25 * signal) reliable = std::max(reliable, signal);
            }
        }
    AutoExposure a;
    a.fraction = fraction;
    a.brightestElectrons = reliable > 0 ? reliable : any;
    if (!(a.brightestElectrons > 0)) throw ConfigError("--exposure auto: the stack holds no signal to set the exposure by");
    a.factor = fraction * m.detector.fullWellElectrons / a.brightestElectrons;
    a.exposureS = m.detector.exposureS * a.factor;
    m.detector.exposureS = a.exposureS;
    const Detector camera(m.detector);
    for (size_t slot = 0; slot < stack.channels.size(); ++slot)
        for (int k = 0; k < stack.planes; ++k) {
            if (!stack.done[stack.index(slot, k)]) continue;
            const size_t off = stack.pixelOffset(slot, k), n = static_cast<size_t>(stack.width) * stack.height;
            std::vector<double> signal(n);
            for (size_t i = 0; i < n; ++i) signal[i] = (stack.expected[off + i] - dark[i]) * a.factor;
            const std::vector<double> withDark = camera.expectedElectrons(signal);
            const std::vector<uint16_t> frame = camera.readOut(withDark, seed, planeStreamKey(m.channels[stack.channels[slot]].name, k));
            for (size_t i = 0; i < n; ++i) {
                stack.expected[off + i] = static_cast<float>(withDark[i]);
                stack.stderrElectrons[off + i] = static_cast<float>(stack.stderrElectrons[off + i] * a.factor);
                stack.counts[off + i] = frame[i];
            }
        }
    return a;
}

bool acquireStack(const Scene& scene, const Microscope& m, Stack& stack, const AcquireOptions& options, const StackCallbacks& cb) {
    const size_t total = stack.done.size();
    size_t finished = 0;
    for (bool d : stack.done) finished += d;
    // Each channel's PSF and computed-part model, built for its first plane and reused for the others.
    std::vector<std::optional<ChannelImaging>> imaging(stack.channels.size());
    for (int k = 0; k < stack.planes; ++k)
        for (size_t slot = 0; slot < stack.channels.size(); ++slot) {
            if (stack.done[stack.index(slot, k)]) continue;
            AcquireOptions o = options;
            o.progress = [&](double f) {
                if (cb.progress) cb.progress((double(finished) + f) / double(total));
            };
            if (!imaging[slot]) imaging[slot] = setUpChannelImaging(scene, m, stack.channels[slot], options);
            const PlaneImage image = acquirePlane(scene, m, stack.channels[slot], k, o, &*imaging[slot]);
            if (!image.complete) return false;
            storePlane(stack, m, slot, k, image, options.seed);
            ++finished;
            if (cb.planeDone) cb.planeDone(slot, k, image);
            if (options.cancel && options.cancel->load()) return false;
        }
    return true;
}

}  // namespace fluorosim::optics
