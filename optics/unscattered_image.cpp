#include "optics/unscattered_image.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <tuple>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "optics/index_key.h"
#include "render/beam_core.h"

namespace fluorosim::optics {
namespace {

constexpr double kUmPerMm = 1e3;
constexpr size_t kMaxBeamLines = 32;


double secondsSince(std::chrono::steady_clock::time_point t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); }

}  // namespace

void UnscatteredOptions::validate() const {
    auto require = [](bool ok, const std::string& what) {
        if (!ok) throw ConfigError(what);
    };
    require(lateralSamples >= 1 && lateralSamples <= 16, "unscattered image: lateralSamples must lie in [1, 16], got " + std::to_string(lateralSamples));
    require(axialStepUm > 0 && std::isfinite(axialStepUm) && axialStepUm <= 10,
            "unscattered image: axialStepUm must lie in (0, 10], got " + std::to_string(axialStepUm));
    require(segmentNodes >= 1 && segmentNodes <= 16, "unscattered image: segmentNodes must lie in [1, 16], got " + std::to_string(segmentNodes));
    require(transmittanceStepUm > 0 && std::isfinite(transmittanceStepUm),
            "unscattered image: transmittanceStepUm must be positive, got " + std::to_string(transmittanceStepUm));
    require(transmittanceQuadratureVoxels > 0 && std::isfinite(transmittanceQuadratureVoxels),
            "unscattered image: transmittanceQuadratureVoxels must be positive, got " + std::to_string(transmittanceQuadratureVoxels));
    require(coneRings >= 1 && coneRings <= 32 && coneAzimuths >= 1 && coneAzimuths <= 64,
            "unscattered image: coneRings must lie in [1, 32] and coneAzimuths in [1, 64], got " + std::to_string(coneRings) + " and " +
                std::to_string(coneAzimuths));
    require(spectralNodes >= 1 && spectralNodes <= 256, "unscattered image: spectralNodes must lie in [1, 256], got " + std::to_string(spectralNodes));
    require(pixelQuadrature >= 1 && pixelQuadrature <= 16, "unscattered image: pixelQuadrature must lie in [1, 16], got " + std::to_string(pixelQuadrature));
    require(kernelPhases >= 2 && kernelPhases <= 64 && kernelPhases % (2 * lateralSamples) == 0,
            "unscattered image: kernelPhases must be a multiple of 2 x lateralSamples in [2, 64], got " + std::to_string(kernelPhases));
    require(farBinUm > 0 && std::isfinite(farBinUm), "unscattered image: farBinUm must be positive, got " + std::to_string(farBinUm));
    require(dropDyesBelow >= 0 && dropDyesBelow < 1, "unscattered image: dropDyesBelow must lie in [0, 1), got " + std::to_string(dropDyesBelow));
    require(dropPointsBelow >= 0 && dropPointsBelow <= 0.01, "unscattered image: dropPointsBelow must lie in [0, 0.01], got " + std::to_string(dropPointsBelow));
    require(nearPixels >= 1 && nearPixels <= 64 && nearTaperPixels >= 1 && nearTaperPixels <= 64,
            "unscattered image: nearPixels and nearTaperPixels must lie in [1, 64], got " + std::to_string(nearPixels) + " and " +
                std::to_string(nearTaperPixels));
    require(tailBlockPixels >= 0 && tailBlockPixels <= 64, "unscattered image: tailBlockPixels must lie in [0, 64], got " + std::to_string(tailBlockPixels));
}

// ------------------------------------------------------------------------------------------------
// The emission as a proposal.

EmissionPoints::EmissionPoints(const Imaging& plane, double x0, double yTop, double z0, double lateralMm, double axialMm)
    : right_(plane.world(1, 0, 0) - plane.world(0, 0, 0)), up_(plane.world(0, 1, 0) - plane.world(0, 0, 0)), axis_(plane.axis()),
      centre_(plane.centre()), x0_(x0), yTop_(yTop), z0_(z0), lateral_(lateralMm), axial_(axialMm) {}

uint64_t EmissionPoints::key(int64_t i, int64_t j, int64_t l) const { return packIndexKey(i, j, l); }

void EmissionPoints::add(int64_t i, int64_t j, int64_t layer, double power) {
    if (power > 0) pending_.push_back({key(i, j, layer), power});
}

void EmissionPoints::finish() {
    // Cells sorted by key, their powers summed; the cdf over them, each cell's power kept for pdf().
    std::sort(pending_.begin(), pending_.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    cells_.clear();
    power_.clear();
    for (const auto& [k, v] : pending_) {
        if (!cells_.empty() && cells_.back() == k) power_.back() += v;
        else {
            cells_.push_back(k);
            power_.push_back(v);
        }
    }
    pending_ = {};
    cdf_.resize(cells_.size());
    total_ = 0;
    for (size_t n = 0; n < cells_.size(); ++n) cdf_[n] = total_ += power_[n];
}

EmissionPoints::Sample EmissionPoints::sample(double uCell, double ux, double uy, double uz) const {
    const size_t n = std::min(cells_.size() - 1, static_cast<size_t>(std::upper_bound(cdf_.begin(), cdf_.end(), uCell * total_) - cdf_.begin()));
    const uint64_t k = cells_[n];
    const int64_t i = static_cast<int64_t>(k >> 42) - (1 << 20), j = static_cast<int64_t>((k >> 21) & 0x1FFFFF) - (1 << 20),
                  l = static_cast<int64_t>(k & 0x1FFFFF) - (1 << 20);
    const double x = x0_ + (static_cast<double>(i) + ux) * lateral_, y = yTop_ - (static_cast<double>(j) + uy) * lateral_,
                 z = z0_ + (static_cast<double>(l) + uz) * axial_;
    return {centre_ + right_ * x + up_ * y + axis_ * z, power_[n] / total_ / (lateral_ * lateral_ * axial_)};
}

double EmissionPoints::pdf(const Vec3& p) const {
    if (cells_.empty()) return 0.0;
    const Vec3 d = p - centre_;
    const int64_t i = static_cast<int64_t>(std::floor((dot(d, right_) - x0_) / lateral_));
    const int64_t j = static_cast<int64_t>(std::floor((yTop_ - dot(d, up_)) / lateral_));
    const int64_t l = static_cast<int64_t>(std::floor((dot(d, axis_) - z0_) / axial_));
    const uint64_t k = key(i, j, l);
    const auto it = std::lower_bound(cells_.begin(), cells_.end(), k);
    return it == cells_.end() || *it != k ? 0.0 : power_[static_cast<size_t>(it - cells_.begin())] / total_ / (lateral_ * lateral_ * axial_);
}

// ------------------------------------------------------------------------------------------------
// The model of a channel.

struct UnscatteredModel::Impl {
    UnscatteredOptions o;
    std::vector<Light> lights;  // at the reference plane
    ChannelDyes dyes;
    LatticeGeometry geometry;
    std::vector<std::unique_ptr<PsfProjector>> projectors;  // one per distinct PSF
    std::vector<size_t> planeProjector;                     // per plane offset
    std::unique_ptr<Imaging> reference;
    bool labels = false;
    mutable std::mutex buildMutex;
    mutable std::unique_ptr<EmissionLattice> lattice;
    mutable std::unique_ptr<EmissionGains> gains;

    TransmittanceOptions transmittanceOptions() const {
        return {o.transmittanceStepUm, o.transmittanceQuadratureVoxels, o.coneRings, o.coneAzimuths, o.attenuation};
    }
};

UnscatteredModel::UnscatteredModel(const Scene& scene, const std::vector<Light>& lights, const FluorescencePlan& plan, const Imaging& plane,
                                   std::function<double(double)> detection, UnscatteredOptions options, std::vector<double> planeOffsetsMm,
                                   bool labels, std::vector<std::shared_ptr<const WidefieldPsf>> planePsfs)
    : impl_(std::make_unique<Impl>()) {
    options.validate();
    if (planeOffsetsMm.empty()) throw ConfigError("unscattered image: a stack needs at least one plane");
    if (planePsfs.empty()) planePsfs.assign(planeOffsetsMm.size(), plane.sharedPsf());
    if (planePsfs.size() != planeOffsetsMm.size())
        throw ConfigError("unscattered image: " + std::to_string(planePsfs.size()) + " plane PSFs for " + std::to_string(planeOffsetsMm.size()) + " planes");
    for (const auto& psf : planePsfs)
        if (!psf || psf->pupil().na != plane.psf().pupil().na || psf->pupil().sampleIndex != plane.psf().pupil().sampleIndex)
            throw ConfigError("unscattered image: every plane's PSF needs the reference's objective and sample medium");
    for (double o : planeOffsetsMm)
        if (!std::isfinite(o)) throw ConfigError("unscattered image: plane offsets must be finite");
    Impl& m = *impl_;
    m.o = options;
    m.lights = lights;
    m.labels = labels;
    m.reference = std::make_unique<Imaging>(plane);
    LatticeGeometry& g = m.geometry;
    g.centre = plane.centre();
    g.axis = plane.axis();
    g.right = plane.world(1, 0, 0) - plane.world(0, 0, 0);
    g.up = plane.world(0, 1, 0) - plane.world(0, 0, 0);
    g.pixelMm = plane.pixelMm();
    g.lateralSamples = m.o.lateralSamples;
    g.width = plane.width();
    g.height = plane.height();
    g.planeOffsetsMm = std::move(planeOffsetsMm);

    const std::vector<BeamLine> lines = beamLines(lights);
    if (lines.size() > kMaxBeamLines)
        throw ConfigError("unscattered image: at most " + std::to_string(kMaxBeamLines) + " beam lines per channel, got " + std::to_string(lines.size()));
    std::vector<double> lineIrradiance(lines.size(), 0.0);
    for (size_t l = 0; l < lines.size(); ++l)
        for (int side = 0; side < lines[l].profile->sides(); ++side)
            lineIrradiance[l] += lines[l].profile->irradiance(plane.centre(), side, lines[l].lambdaNm) * lines[l].weight;
    m.dyes = channelDyes(scene, lines, plan, detection, m.o.spectralNodes, lineIrradiance, m.o.dropDyesBelow);
    if (m.dyes.empty()) return;

    double lambdaMax = 0, lambdaMin = 1e9;
    for (const EmittingDye& t : m.dyes.dyes)
        for (double l : t.nodeLambda) {
            lambdaMax = std::max(lambdaMax, l);
            lambdaMin = std::min(lambdaMin, l);
        }
    const WidefieldPsf& psf = plane.psf();
    const double cutMm = psf.cutRadiusMm(lambdaMax);
    const double tanThetaMax = std::tan(std::acos(plane.cosMax()));
    // Pixel integration: the PSF holds spatial frequencies up to 2 NA/λ, k = pixel × 2 NA/λ cycles per
    // pixel, and n Gauss–Legendre nodes integrate e^{2πikx} over a pixel to 1e-4 for k <= (n − 3)/2
    // (tests/optics/unscattered_image_test.cpp), at the shortest wavelength that matters.
    const double cyclesPerPixel = g.pixelMm * 2 * psf.pupil().na / (m.dyes.shortestDetectedNm * 1e-6);
    const int pixelNodes = std::clamp(static_cast<int>(std::ceil(2 * cyclesPerPixel + 3)), m.o.pixelQuadrature, 32);
    // Axial layers: the PSF is interpolated linearly between them, so they are at most 1/8 of the depth
    // of field n λ/NA² apart (a bead's axial FWHM at NA 0.8 read 1.0 % wide at 0.25 um); and a divisor
    // of a uniform plane step, so that every plane sees the points at its own layers.
    {
        const double na = psf.pupil().na, n = psf.pupil().sampleIndex;
        g.axialMm = std::min(m.o.axialStepUm / kUmPerMm, n * lambdaMin * 1e-6 / (na * na) / 8);
        std::vector<double> sorted = g.planeOffsetsMm;
        std::sort(sorted.begin(), sorted.end());
        if (sorted.size() >= 2) {
            const double step = sorted[1] - sorted[0];
            bool uniform = step > 0;
            for (size_t i = 1; i < sorted.size() && uniform; ++i) uniform = std::abs(sorted[i] - sorted[i - 1] - step) <= 1e-9 * std::max(1.0, step);
            if (uniform) g.axialMm = step / std::ceil(step / g.axialMm - 1e-9);
        }
    }
    // The axial extent: the cores' largest |dz| over the field with margins, within the PSF's table.
    const double dzLimit = psf.maxDzMm(lambdaMin);
    double depth = 0;
    {
        const double xHalf = 0.5 * g.width * g.pixelMm + cutMm + dzLimit * tanThetaMax;
        const double yHalf = 0.5 * g.height * g.pixelMm + cutMm + dzLimit * tanThetaMax;
        const int n = 16;
        for (int iy = 0; iy <= n; ++iy)
            for (int ix = 0; ix <= n; ++ix) {
                const double x = -xHalf + 2 * xHalf * ix / n, y = -yHalf + 2 * yHalf * iy / n;
                const Ray column{plane.world(x, y, dzLimit), -plane.axis()};
                for (const BeamLine& l : lines)
                    for (int side = 0; side < l.profile->sides(); ++side) {
                        const BeamCore core = l.profile->coreAlong(column, side, l.lambdaNm);
                        for (int k = 0; k < core.count; ++k) {
                            const BeamCoreInterval& iv = core.intervals[static_cast<size_t>(k)];
                            for (double t : {iv.tMin, iv.tMax})
                                depth = std::max(depth, std::min(dzLimit, std::abs(dzLimit - std::clamp(t, 0.0, 2 * dzLimit))));
                        }
                    }
            }
    }
    g.planeLayers = 2 * std::max(1, static_cast<int>(std::ceil(depth / g.axialMm - 1e-9)));
    g.marginPixels = static_cast<int>(std::ceil((cutMm + g.halfDepthMm() * tanThetaMax) / g.pixelMm)) + 2;

    ProjectorGeometry pg;
    pg.pixelMm = g.pixelMm;
    pg.width = g.width;
    pg.height = g.height;
    pg.marginPixels = g.marginPixels;
    pg.layers = g.planeLayers;
    pg.axialMm = g.axialMm;
    pg.tanThetaMax = tanThetaMax;
    ProjectorOptions po;
    po.pixelQuadrature = m.o.pixelQuadrature;
    po.kernelPhases = m.o.kernelPhases;
    po.farBinUm = m.o.farBinUm;
    po.nearPixels = m.o.nearPixels;
    po.nearTaperPixels = m.o.nearTaperPixels;
    po.tailBlockPixels = m.o.tailBlockPixels;
    std::vector<const WidefieldPsf*> distinct;
    for (const auto& planePsf : planePsfs) {
        if (std::find(distinct.begin(), distinct.end(), planePsf.get()) == distinct.end()) {
            distinct.push_back(planePsf.get());
            m.projectors.push_back(std::make_unique<PsfProjector>(m.dyes, planePsf, pg, pixelNodes, po));
        }
        m.planeProjector.push_back(static_cast<size_t>(std::find(distinct.begin(), distinct.end(), planePsf.get()) - distinct.begin()));
    }
}

UnscatteredModel::~UnscatteredModel() = default;

bool UnscatteredModel::active() const { return !impl_->dyes.empty(); }
const UnscatteredOptions& UnscatteredModel::options() const { return impl_->o; }
const ChannelDyes& UnscatteredModel::dyes() const { return impl_->dyes; }
const LatticeGeometry& UnscatteredModel::geometry() const { return impl_->geometry; }
const PsfProjector& UnscatteredModel::projector(double planeOffsetMm) const {
    const Impl& m = *impl_;
    if (m.projectors.empty()) throw ConfigError("unscattered image: the channel computes nothing, so it has no projector");
    const std::vector<double>& offsets = m.geometry.planeOffsetsMm;
    for (size_t i = 0; i < offsets.size(); ++i)
        if (std::abs(offsets[i] - planeOffsetMm) <= 1e-9) return *m.projectors[m.planeProjector[i]];
    throw ConfigError("unscattered image: no plane of the stack lies " + std::to_string(planeOffsetMm * kUmPerMm) + " um from the reference");
}
const std::vector<Light>& UnscatteredModel::referenceLights() const { return impl_->lights; }

bool UnscatteredModel::covers(const Imaging& plane, const Vec3& y) const {
    const Impl& m = *impl_;
    if (m.dyes.empty()) return false;
    const Imaging::Local p = plane.local(y);
    const double xHalf = 0.5 * m.geometry.regionWidth() * m.geometry.pixelMm, yHalf = 0.5 * m.geometry.regionHeight() * m.geometry.pixelMm;
    return std::abs(p.x) <= xHalf && std::abs(p.y) <= yHalf && std::abs(p.dz) <= m.geometry.halfDepthMm();
}

double UnscatteredModel::planeOffset(const Imaging& plane) const {
    const LatticeGeometry& g = impl_->geometry;
    const Vec3 d = plane.centre() - g.centre;
    const double offset = dot(d, g.axis);
    const Vec3 lateral = d - g.axis * offset;
    const Vec3 right = plane.world(1, 0, 0) - plane.world(0, 0, 0);
    const bool sameFrame = length(lateral) <= 1e-9 && length(plane.axis() - g.axis) <= 1e-12 && length(right - g.right) <= 1e-12 &&
                           plane.width() == g.width && plane.height() == g.height && std::abs(plane.pixelMm() - g.pixelMm) <= 1e-15;
    if (sameFrame)
        for (double o : g.planeOffsetsMm)
            if (std::abs(o - offset) <= 1e-9) return o;
    throw ConfigError("unscattered image: the plane (offset " + std::to_string(offset * kUmPerMm) + " um along the axis) is not a plane of the model's stack");
}

const EmissionLattice* UnscatteredModel::lattice(const Scene& scene, int threads, const std::atomic<bool>* cancel) const {
    const Impl& m = *impl_;
    const std::lock_guard<std::mutex> lock(m.buildMutex);
    if (!m.lattice && !m.dyes.empty()) {
        auto l = std::make_unique<EmissionLattice>(scene, m.dyes, m.geometry, m.o.segmentNodes, m.labels, threads, cancel);
        if (!l->complete()) return nullptr;
        m.lattice = std::move(l);
    }
    return m.lattice.get();
}

const EmissionGains* UnscatteredModel::gains(const Scene& scene, int threads, const std::atomic<bool>* cancel) const {
    const EmissionLattice* l = lattice(scene, threads, cancel);
    if (!l) return nullptr;
    const Impl& m = *impl_;
    const std::lock_guard<std::mutex> lock(m.buildMutex);
    if (!m.gains) {
        auto g = std::make_unique<EmissionGains>(scene, *l, m.dyes, m.lights, *m.reference, m.transmittanceOptions(), threads, cancel);
        if (!g->complete()) return nullptr;
        m.gains = std::move(g);
    }
    return m.gains.get();
}

std::unique_ptr<EmissionGains> UnscatteredModel::gainsFor(const Scene& scene, int threads, const std::atomic<bool>* cancel) const {
    const EmissionLattice* l = lattice(scene, threads, cancel);
    if (!l) return nullptr;
    const Impl& m = *impl_;
    auto g = std::make_unique<EmissionGains>(scene, *l, m.dyes, m.lights, *m.reference, m.transmittanceOptions(), threads, cancel);
    if (!g->complete()) return nullptr;
    return g;
}

PointEmission pointEmission(const LatticeGeometry& g, const LatticePoint& q, double planeOffsetMm) {
    PointEmission em;
    em.u = (q.x - g.xLeft()) / g.pixelMm;
    em.v = (g.yTop() - q.y) / g.pixelMm;
    em.layer = g.layerPosition(q.z, planeOffsetMm);
    return em;
}

std::vector<PointEmission> planeEmissions(const UnscatteredModel& model, const EmissionLattice& lattice, const EmissionGains& gains,
                                          const std::vector<Light>& lights, double planeOffsetMm, int threads, const BeamExcitationField* field,
                                          std::vector<PointEmission>* fieldEmissions) {
    const LatticeGeometry& g = model.geometry();
    const auto [first, last] = lattice.zRange(planeOffsetMm - g.halfDepthMm(), planeOffsetMm + g.halfDepthMm());
    std::vector<double> gain;
    EmissionGains::FieldGains fieldGains;
    gains.planeGains(lights, planeOffsetMm, first, last, gain, threads, field, fieldEmissions ? &fieldGains : nullptr);
    const int slots = lattice.slots();
    // In chunks of points, each filled on its own and joined in order: the same list whatever the threads.
    constexpr size_t kChunkPoints = 16384;
    const size_t chunks = (last - first + kChunkPoints - 1) / kChunkPoints;
    std::vector<std::vector<PointEmission>> parts(chunks), fieldChunks(fieldEmissions ? chunks : 0);
    parallelFor(chunks, threads, [&](size_t chunk) {
        std::vector<PointEmission>& part = parts[chunk];
        const size_t begin = first + chunk * kChunkPoints, end = std::min(last, begin + kChunkPoints);
        part.reserve((end - begin) * static_cast<size_t>(slots));
        for (size_t p = begin; p < end; ++p) {
            const LatticePoint& q = lattice.point(p);
            PointEmission em = pointEmission(g, q, planeOffsetMm);
            const int firstDye = model.dyes().firstOfMedium[static_cast<size_t>(q.medium)];
            for (int slot = 0; slot < slots; ++slot) {
                const size_t at = (p - first) * static_cast<size_t>(slots) + static_cast<size_t>(slot);
                const double c = lattice.concentration(p, slot);
                const double e = gain[at] * c;
                if (!(e > 0)) continue;
                em.e = e;
                em.dye = static_cast<uint32_t>(firstDye + slot);
                em.target = 0;
                part.push_back(em);
                if (fieldEmissions && fieldGains.scattered[at] > 0) {
                    PointEmission scattered = em;
                    scattered.e = fieldGains.scattered[at] * c;
                    fieldChunks[chunk].push_back(scattered);
                    scattered.e = fieldGains.halfDifference[at] * c;
                    scattered.target = 1;
                    if (scattered.e != 0) fieldChunks[chunk].push_back(scattered);
                }
            }
        }
    });
    const auto join = [](std::vector<std::vector<PointEmission>>& pieces) {
        size_t total = 0;
        for (const auto& piece : pieces) total += piece.size();
        std::vector<PointEmission> joined;
        joined.reserve(total);
        for (auto& piece : pieces) {
            joined.insert(joined.end(), piece.begin(), piece.end());
            piece = {};
        }
        return joined;
    };
    std::vector<PointEmission> out = join(parts);
    if (fieldEmissions) *fieldEmissions = join(fieldChunks);
    return out;
}

namespace {

// The emissions without the faintest, whose photoelectrons together stay within `fraction` of all: whole
// binary orders of magnitude of e relative to the total are left out, faintest first, while their sum
// fits the budget (relative, so that a scene at another exposure leaves out the same points). Returns
// false, and leaves `kept` empty, when none is left out.
bool leaveOutFaintest(const std::vector<PointEmission>& emissions, double fraction, std::vector<PointEmission>& kept, uint64_t& dropped,
                      double& droppedFraction) {
    kept.clear();
    dropped = 0;
    droppedFraction = 0;
    double total = 0;
    for (const PointEmission& em : emissions) total += std::abs(em.e);
    if (!(fraction > 0) || !(total > 0)) return false;
    constexpr int kMinExponent = -1100, kExponents = 2200;
    std::vector<double> byExponent(kExponents, 0.0);
    const auto exponentOf = [&](double e) {
        int x = 0;
        (void)std::frexp(std::abs(e) / total, &x);
        return std::clamp(x - kMinExponent, 0, kExponents - 1);
    };
    for (const PointEmission& em : emissions) byExponent[static_cast<size_t>(exponentOf(em.e))] += std::abs(em.e);
    int keepFrom = 0;
    double sum = 0;
    while (keepFrom < kExponents && sum + byExponent[static_cast<size_t>(keepFrom)] <= fraction * total) sum += byExponent[static_cast<size_t>(keepFrom++)];
    if (keepFrom == 0) return false;
    kept.reserve(emissions.size());
    for (const PointEmission& em : emissions) {
        if (exponentOf(em.e) >= keepFrom) kept.push_back(em);
        else ++dropped;
    }
    droppedFraction = sum / total;
    return true;
}

// The field's noise: the image of half the difference of its halves, from the points of each pixel's
// column, dye and group of kFieldNoiseLayers layers gathered at the pixel's centre and the group's middle
// layer (about a sixteenth of the points: where within a pixel and half a micrometre a point lies matters
// to its image, little to the size of the noise: the summary's field noise moved 4 % on the README job's
// first plane against gathering in pixels alone). The parts arrive by layer (the lattice's order), so each
// group of layers is gathered on a dense image of the region per dye and flushed by pixel when the next
// group begins. Target 0 parts are the field's own emission: their sum goes to `fieldEmitted`.
std::vector<PointEmission> gatheredFieldNoise(const std::vector<PointEmission>& fieldParts, const LatticeGeometry& g, size_t dyes, double& fieldEmitted) {
    constexpr int kFieldNoiseLayers = 4;
    const double lastLayer = g.planeLayers - 1;
    const int64_t W = g.regionWidth(), H = g.regionHeight(), D = static_cast<int64_t>(dyes);
    std::vector<PointEmission> out;
    std::vector<double> sum(static_cast<size_t>(W * H * D), 0.0);
    std::vector<uint8_t> seen(sum.size(), 0);
    std::vector<uint32_t> touched;
    int64_t group = -1;
    const auto flush = [&] {
        std::sort(touched.begin(), touched.end());
        for (uint32_t index : touched) {
            PointEmission em;
            em.dye = static_cast<uint32_t>(index % D);
            em.u = static_cast<double>((index / D) % W) + 0.5;
            em.v = static_cast<double>(index / D / W) + 0.5;
            em.layer = std::min(lastLayer, static_cast<double>(group * kFieldNoiseLayers + kFieldNoiseLayers / 2));
            em.e = sum[index];
            out.push_back(em);
            sum[index] = 0;
            seen[index] = 0;
        }
        touched.clear();
    };
    fieldEmitted = 0;
    for (const PointEmission& em : fieldParts) {
        if (em.target == 0) {
            fieldEmitted += em.e;
            continue;
        }
        const int64_t px = static_cast<int64_t>(std::floor(em.u)), py = static_cast<int64_t>(std::floor(em.v));
        const int64_t layerGroup = static_cast<int64_t>(std::floor(std::max(0.0, em.layer) / kFieldNoiseLayers));
        if (px < 0 || px >= W || py < 0 || py >= H || em.dye >= D) continue;  // the lattice lies within the region
        if (layerGroup != group) {
            flush();
            group = layerGroup;
        }
        const size_t index = static_cast<size_t>((py * W + px) * D + em.dye);
        if (!seen[index]) {
            seen[index] = 1;
            touched.push_back(static_cast<uint32_t>(index));
        }
        sum[index] += em.e;
    }
    flush();
    return out;
}

}  // namespace

UnscatteredPlane computeUnscatteredImage(const Scene& scene, const std::vector<Light>& lights, const Imaging& plane, const UnscatteredModel& model,
                                         int threads, const std::atomic<bool>* cancel, const BeamExcitationField* field) {
    const auto start = std::chrono::steady_clock::now();
    UnscatteredPlane out;
    out.electrons.assign(static_cast<size_t>(plane.width()) * plane.height(), 0.0);
    if (!model.active()) return out;
    const double offset = model.planeOffset(plane);
    auto t = std::chrono::steady_clock::now();
    const EmissionLattice* lattice = model.lattice(scene, threads, cancel);
    out.timings.lattice = secondsSince(t);
    t = std::chrono::steady_clock::now();
    const EmissionGains* gains = lattice ? model.gains(scene, threads, cancel) : nullptr;
    out.timings.transmittances = secondsSince(t);
    if (!lattice || !gains) {
        out.complete = false;
        return out;
    }
    t = std::chrono::steady_clock::now();
    std::vector<PointEmission> fieldParts;
    std::vector<PointEmission> emissions = planeEmissions(model, *lattice, *gains, lights, offset, threads, field, field ? &fieldParts : nullptr);
    out.timings.gains = secondsSince(t);
    out.points = emissions.size();
    t = std::chrono::steady_clock::now();
    const PsfProjector& projector = model.projector(offset);
    const double kernelsBefore = projector.kernelSeconds();
    const LatticeGeometry& g = model.geometry();
    double fieldEmitted = 0, emitted = 0;
    for (const PointEmission& em : emissions) emitted += em.e;
    const std::vector<PointEmission> halfDifference = gatheredFieldNoise(fieldParts, g, model.dyes().dyes.size(), fieldEmitted);
    std::vector<PointEmission> brighter;
    const bool leftOut = leaveOutFaintest(emissions, model.options().dropPointsBelow, brighter, out.droppedPoints, out.droppedFraction);
    std::vector<std::vector<double>> images = projector.project(leftOut ? brighter : emissions, 1, threads, cancel);
    if (field && !images.empty()) {
        std::vector<std::vector<double>> noise = projector.project(halfDifference, 1, threads, cancel, ProjectorParts::WithoutTail);
        if (!noise.empty()) out.fieldHalfDifference = std::move(noise[0]);
    }
    if (images.empty() || (cancel && cancel->load())) {
        out.complete = false;
        return out;
    }
    out.timings.kernelThreadSeconds = projector.kernelSeconds() - kernelsBefore;
    out.timings.projection = secondsSince(t);
    // The FFT leaves round-off of both signs (about 1e-16 of the largest value) where the far part is 0.
    for (size_t i = 0; i < out.electrons.size(); ++i) out.electrons[i] = std::max(0.0, images[0][i]);
    // The field's share of what the points emit, applied to what lands on the camera.
    if (emitted > 0) {
        double total = 0;
        for (double e : out.electrons) total += e;
        out.fieldElectrons = total * fieldEmitted / emitted;
    }

    auto emission = std::make_shared<EmissionPoints>(plane, g.xLeft(), g.yTop(), -g.halfDepthMm(), g.lateralMm(), g.axialMm);
    for (const PointEmission& em : emissions)
        emission->add(static_cast<int64_t>(std::floor(em.u * g.lateralSamples)), static_cast<int64_t>(std::floor(em.v * g.lateralSamples)),
                      static_cast<int64_t>(std::floor(em.layer + 0.5)), em.e);
    emission->finish();
    out.emission = std::move(emission);
    out.seconds = secondsSince(start);
    return out;
}

}  // namespace fluorosim::optics
