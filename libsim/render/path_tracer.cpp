#include "render/path_tracer.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/errors.h"
#include "core/math.h"
#include "core/sampling.h"
#include "media/free_flight.h"
#include "render/beam_core.h"
#include "render/specular_chain.h"
#include "render/straight_line.h"

namespace fluorosim {
namespace {

// Rays leaving a surface start exactly on it and skip its self-intersection with this tMin, so that
// the medium behind the surface is sampled from the surface itself: an offset origin would drop a
// sliver of medium (measured: 20 nm of a 1 µm dye layer, a 2 % loss) at every crossing.
double leavingTMin(const Vec3& n, const Vec3& dir, double eps) { return eps / std::max(std::abs(dot(n, dir)), 1e-2); }

// Balance heuristic between the sheet-side strategy (density a per point) and phase sampling (b).
double sheetMis(double a, double b) { return a + b > 0 ? a / (a + b) : 0.0; }

SampledSpectrum clampZero(const SampledSpectrum& s) {
    SampledSpectrum r;
    for (int i = 0; i < kNumWavelengths; ++i) r[i] = std::max(0.0, s[i]);
    return r;
}

// Whether the camera's imaging computes this light sample's contribution at p itself: a beam at one of
// its spectral lines (not a continuous beam spectrum), connected from inside the beam's core, where the
// imaging computes the unscattered image (CameraPathImaging).
bool computedByImaging(const LightSample& ls, const Vec3& p, const SampledWavelengths& wl, const CameraPathImaging* imaging) {
    return imaging && ls.beam && wl.discrete && ls.beamProfile->inCore(p, ls.side, wl.lambda[0]) && imaging->computesUnscatteredAt(p);
}

}  // namespace

namespace {
bool anyBeam(const std::vector<Light>& lights) {
    return std::any_of(lights.begin(), lights.end(), [](const Light& l) { return std::holds_alternative<BeamLight>(l); });
}
std::vector<double> lineWavelengthsOf(const std::vector<Light>& lights) {
    std::vector<double> lines;
    for (const BeamLine& l : beamLines(lights))
        if (l.weight > 0 && std::find(lines.begin(), lines.end(), l.lambdaNm) == lines.end()) lines.push_back(l.lambdaNm);
    return lines;
}

// The stacks of concentric spheres whose every surface is a smooth dielectric (or an index-matched
// interface) between consistently nested media: the chains manifold next-event estimation follows.
std::vector<SphericalShells> sphericalShellsOf(const Scene& scene) {
    struct Sphere {
        Vec3 c;
        double r;
        uint32_t shape;
    };
    std::vector<Sphere> spheres;
    for (uint32_t i = 0; i < scene.shapes.size(); ++i) {
        const ShapeInfo& s = scene.shapes[i];
        if (!scene.geometry.isSphere(i) || !s.isInterface || s.insideMedium == s.outsideMedium) continue;
        if (s.material != kNone) {
            const Material& m = *scene.materials[static_cast<size_t>(s.material)];
            if (!m.isSpecular() || !m.isTransmissive()) continue;
        }
        spheres.push_back({scene.geometry.sphereCenter(i), scene.geometry.sphereRadius(i), i});
    }
    std::sort(spheres.begin(), spheres.end(), [](const Sphere& a, const Sphere& b) { return a.r < b.r; });
    std::vector<SphericalShells> stacks;
    std::vector<char> used(spheres.size(), 0);
    for (size_t i = 0; i < spheres.size(); ++i) {
        if (used[i]) continue;
        SphericalShells st;
        st.center = spheres[i].c;
        for (size_t j = i; j < spheres.size() && st.count < kMaxShellInterfaces; ++j) {
            const Vec3 c = spheres[j].c;
            if (used[j] || !(c.x == st.center.x && c.y == st.center.y && c.z == st.center.z)) continue;
            const ShapeInfo& s = scene.shapes[spheres[j].shape];
            if (st.count > 0 && s.insideMedium != st.medium[static_cast<size_t>(st.count)]) break;  // not nested in the stack's order
            const size_t k = static_cast<size_t>(st.count++);
            st.radius[k] = spheres[j].r;
            st.shape[k] = spheres[j].shape;
            st.medium[k] = s.insideMedium;
            st.medium[k + 1] = s.outsideMedium;
            st.ior[k] = scene.ior(s.insideMedium);
            st.ior[k + 1] = scene.ior(s.outsideMedium);
            used[j] = 1;
        }
        // A stack of index-matched interfaces alone is no obstacle: next-event estimation's straight shadow
        // rays pass it, and chains would count the same light twice.
        bool refracting = false;
        for (int k = 0; k < st.count; ++k) refracting = refracting || scene.shapes[st.shape[static_cast<size_t>(k)]].material != kNone;
        if (refracting) stacks.push_back(st);
    }
    return stacks;
}

// The branch density at a point with channel values `ch`, per wavelength: Σ_c perMolar[c] ch[c], capped at
// max(σt, cap) (FluorescencePlan::branchDensityCap): the free flight's and the emission MIS's one rule.
SampledSpectrum cappedBranchDensity(const std::array<SampledSpectrum, kMaxMediumChannels>& perMolar, const double* ch, int channels,
                                    const SampledSpectrum& sigmaT, double cap) {
    SampledSpectrum b(0.0);
    for (int c = kFirstDyeChannel; c < channels; ++c) b += perMolar[static_cast<size_t>(c)] * ch[c];
    for (int j = 0; j < kNumWavelengths; ++j) b[j] = std::min(b[j], std::max(sigmaT[j], cap));
    return b;
}
}  // namespace

PathTracer::PathTracer(const Scene& scene)
    : scene_(scene), lightList_(scene.lights), lights_(scene, lightList_),
      fluorescence_(scene, lightList_), hasBeams_(anyBeam(lightList_)), lineWavelengths_(lineWavelengthsOf(lightList_)),
      shells_(scene.render.integrator != Integrator::Path ? sphericalShellsOf(scene) : std::vector<SphericalShells>{}) {}

PathTracer::PathTracer(const Scene& scene, std::vector<Light> lights)
    : scene_(scene), lightList_(std::move(lights)), lights_(scene, lightList_),
      fluorescence_(scene, lightList_), hasBeams_(anyBeam(lightList_)), lineWavelengths_(lineWavelengthsOf(lightList_)),
      shells_(scene.render.integrator != Integrator::Path ? sphericalShellsOf(scene) : std::vector<SphericalShells>{}) {
    const auto isArea = [](const Light& l) { return std::holds_alternative<AreaLight>(l); };
    if (std::any_of(scene.lights.begin(), scene.lights.end(), isArea) || std::any_of(lightList_.begin(), lightList_.end(), isArea))
        throw ConfigError("a separate light list cannot be used with emitting shapes (their lights are indexed by shape)");
}

int PathTracer::shellsAround(const Vec3& p, int medium) const {
    for (size_t i = 0; i < shells_.size(); ++i) {
        const SphericalShells& s = shells_[i];
        if (s.medium[0] == medium && length(p - s.center) < s.radius[0]) return static_cast<int>(i);
    }
    return -1;
}

void StackEntry::meet(const std::vector<SphericalShells>& shells, uint32_t shape, bool inward, bool indexMatched) {
    if (!open) return;
    if (inLiquid) {  // left the liquid without a collision
        open = inLiquid = false;
        return;
    }
    int s = stack;
    if (s < 0)
        for (size_t i = 0; i < shells.size() && s < 0; ++i)
            if (shells[i].shape[static_cast<size_t>(shells[i].count - 1)] == shape) s = static_cast<int>(i);
    const SphericalShells* sh = s >= 0 ? &shells[static_cast<size_t>(s)] : nullptr;
    if (sh && inward && shape == sh->shape[static_cast<size_t>(sh->count - 1 - crossed)]) {
        stack = s;
        inLiquid = ++crossed == sh->count;
    } else if (!indexMatched) {
        open = false;
    }
}

int PathTracer::mediumAfterCrossing(const ShapeInfo& shape, const Vec3& n, const Vec3& dir, int current) const {
    if (!shape.isInterface) return current;
    return dot(dir, n) < 0 ? shape.insideMedium : shape.outsideMedium;
}

SampledSpectrum PathTracer::transmittance(const Vec3& p0, const Vec3& p1, int medium, const SampledWavelengths& wl, Rng& rng,
                                         const Vec3* surfaceNormal, double surfaceEpsilon) const {
    return estimateTransmittance(p0, p1, medium, wl, rng, surfaceNormal, surfaceEpsilon, false, true).T;
}

PathTracer::TransmittanceEstimate PathTracer::estimateChainTransmittance(const SphericalShells& sh, const Vec3& p, const ShellPath& chain,
                                                                        const Vec3& target, const SampledWavelengths& wl, Rng& rng) const {
    TransmittanceEstimate T{SampledSpectrum(1.0), SampledSpectrum(1.0), SampledSpectrum(1.0)};
    Vec3 from = p, normal;
    double eps = 0;
    for (int i = 0; i <= sh.count && T.T; ++i) {
        const Vec3 to = i < sh.count ? chain.points[static_cast<size_t>(i)] : target;
        const TransmittanceEstimate Ti =
            estimateTransmittance(from, to, sh.medium[static_cast<size_t>(i)], wl, rng, i > 0 ? &normal : nullptr, eps, false, true);
        T.T *= Ti.T;
        T.r_u *= Ti.r_u;
        T.r_l *= Ti.r_l;
        normal = normalize(to - sh.center);
        eps = sphereRayEpsilon(to);
        from = to;
    }
    return T;
}

SampledSpectrum PathTracer::chainTransmittance(const SphericalShells& sh, const Vec3& p, const ShellPath& chain, const Vec3& target,
                                               const SampledWavelengths& wl, Rng& rng) const {
    return estimateChainTransmittance(sh, p, chain, target, wl, rng).T;
}

SampledSpectrum PathTracer::beamTransmittance(const Vec3& p, const Vec3& towardSource, int medium, const SampledWavelengths& wl,
                                             Rng& rng) const {
    // As next-event estimation connects to a beam (LightSampler): back along the beam beyond the scene,
    // ending where it entered the sample.
    const Vec3 far = p + towardSource * (2 * (scene_.geometry.extent() + length(p)) + 1);
    return estimateTransmittance(p, far, medium, wl, rng, nullptr, 0.0, true, true).T;
}

PathTracer::TransmittanceEstimate PathTracer::estimateTransmittance(const Vec3& p0, const Vec3& p1, int medium, const SampledWavelengths& wl,
                                                                    Rng& rng, const Vec3* surfaceNormal, double surfaceEpsilon,
                                                                    bool untilRefraction, bool residual) const {
    TransmittanceEstimate e{SampledSpectrum(1.0), SampledSpectrum(1.0), SampledSpectrum(1.0)};
    const bool oneLine = std::all_of(wl.lambda.begin(), wl.lambda.end(), [&](double l) { return l == wl.lambda[0]; });
    // Rays start exactly on surfaces and skip self-intersections with tMin, so every segment lies on
    // the line from p0 to p1 and its length is exact.
    Vec3 origin = p0;
    const Vec3* normal = surfaceNormal;
    double epsilon = surfaceEpsilon;
    Vec3 lastNormal;
    // Every crossing advances along the segment; the cap only guards against numerical stalls.
    for (int crossings = 0; crossings < 1000000; ++crossings) {
        const Vec3 d = p1 - origin;
        const double dist = length(d);
        if (!(dist > 0)) return e;
        const Ray r{origin, d / dist};
        const double tMin = normal ? epsilon / std::max(std::abs(dot(*normal, r.d)), 1e-2) : 0.0;
        const double tMax = dist - rayEpsilon(p1);
        const auto hit = tMax > tMin ? scene_.geometry.intersect(r, tMin, tMax) : std::nullopt;
        const double segment = hit ? hit->t : dist;
        if (medium != kNone && !scene_.media[static_cast<size_t>(medium)].isVacuumLike()) {
            const Medium& med = scene_.media[static_cast<size_t>(medium)];
            const MediumSpectra spec = med.spectra(wl);
            if (med.isHomogeneous()) {
                // The exact transmittance, with no sampling noise. Ratio tracking against the exact
                // majorant would return T/T[0] with probability T[0], and the same ratio in r_u and r_l;
                // this is its expectation, so spectral MIS sees the same pdf ratios.
                const MediumSample m = spec.at(med.channelMax().data());
                const SampledSpectrum T = expNeg((m.sigmaA + m.sigmaS) * segment);
                if (!(T[0] > 0)) return {SampledSpectrum(0.0), e.r_u, e.r_l};
                e.T *= T;
                e.r_u *= T / T[0];
                e.r_l *= T / T[0];
            } else if (!ratioTrack(med, spec, r, segment, rng, e, residual, oneLine)) {
                return {SampledSpectrum(0.0), e.r_u, e.r_l};
            }
        }
        if (!hit) return e;
        const ShapeInfo& s = scene_.shapes[hit->shape];
        if (untilRefraction && refracts(scene_, s))
            return e;
        if (!(s.isInterface && s.material == kNone)) return {SampledSpectrum(0.0), e.r_u, e.r_l};
        medium = mediumAfterCrossing(s, hit->n, r.d, medium);
        origin = r.at(hit->t);
        lastNormal = hit->n;
        normal = &lastNormal;
        epsilon = hit->epsilon;
    }
    return {SampledSpectrum(0.0), e.r_u, e.r_l};
}

bool PathTracer::ratioTrack(const Medium& med, const MediumSpectra& spec, const Ray& r, double length, Rng& rng, TransmittanceEstimate& e,
                            bool residual, bool oneLine) const {
    // Ratio tracking (pbrt-v4's TraceTransmittance) with the hero wavelength's majorant; r_u and r_l
    // carry the path pdf ratios that spectral MIS needs, with roulette once the estimate is small.
    // Residual tracking (Novák et al. 2014) takes the channels' floors (the constant tissue, the
    // solvent) out exactly and tracks only what varies: where the floor is most of the extinction, a
    // collision no longer zeroes the estimate. Its collisions are not those of a camera path's delta
    // tracking, so MIS against hitting an area light needs plain tracking; delta lights take residual.
    // The residual's majorant is raised kResidualMajorantScale times: ratio tracking's relative variance
    // falls as σ²L/σ̄, and the residual (a sparse dye) is so thin that the extra lookups cost little.
    constexpr double kResidualMajorantScale = 8;
    // A residual whose largest value anywhere expects at most this many collisions (at the raised majorant)
    // over the line is tracked in one segment: a traced vertex's line to the objective through sparse dye
    // crosses tens of majorant cells for a few look-ups (docs/performance.md, "The residual in one segment").
    // Only at one spectral line (the traced photons, the beams' lines), where it was measured: a path's
    // companion wavelengths are weighed by their majorant over the hero's at each collision, and the medium's
    // largest residual can hold another dye's peak at a companion where the local cells hold none.
    constexpr double kFewResidualCollisions = 8;
    ChannelValues floor{};
    if (residual) {
        floor = med.channelFloor();
        const MediumSample c = spec.at(floor.data());
        const SampledSpectrum Tc = expNeg((c.sigmaA + c.sigmaS) * length);
        if (!(Tc[0] > 0)) return false;
        e.T *= Tc;
        e.r_u *= Tc / Tc[0];
        e.r_l *= Tc / Tc[0];
    }
    auto above = [&](const double* values) {
        ChannelValues v;
        for (int c = 0; c < spec.channels; ++c) v[c] = std::max(0.0, values[c] - floor[c]);
        const MediumSample s = spec.at(v.data());
        return s.sigmaA + s.sigmaS;
    };
    const double* segmentMaxima = nullptr;
    auto majorants = med.majorants(r, 0.0, length, [&](const double* values) {
        segmentMaxima = values;
        return residual ? above(values) * kResidualMajorantScale : above(values);
    }, residual && oneLine ? kFewResidualCollisions : 0.0);
    const SampledSpectrum T_maj = sampleTmaj<SampledSpectrum>(majorants, rng, [&](double t, const SampledSpectrum& sigmaMaj, const SampledSpectrum& Tm) {
        ChannelValues ch;
        med.channelValues(r.at(t), ch.data(), segmentMaxima);
        const SampledSpectrum sigmaN = clampZero(sigmaMaj - above(ch.data()));
        const double pdf = Tm[0] * sigmaMaj[0];
        e.T *= Tm * sigmaN / pdf;
        e.r_l *= Tm * sigmaMaj / pdf;
        e.r_u *= Tm * sigmaN / pdf;
        const SampledSpectrum Tr = e.T / (e.r_l + e.r_u).average();
        if (Tr.maxComponent() < 0.05) {
            if (rng.uniform() < 0.75) e.T = SampledSpectrum(0.0);
            else e.T /= 0.25;
        }
        return bool(e.T);
    });
    if (!e.T) return false;
    e.T *= T_maj / T_maj[0];
    e.r_l *= T_maj / T_maj[0];
    e.r_u *= T_maj / T_maj[0];
    return bool(e.T);
}

struct PathTracer::PathState {
    Ray ray;
    int medium = kNone;
    SampledSpectrum beta{1.0}, r_u{1.0}, r_l{1.0};
    // Whether the last vertex sampled the lights (next-event estimation). A hit on an area light is
    // weighed against that sample by MIS; without it (camera rays, specular bounces) it counts fully.
    // Excitation sub-paths do NEE at their first vertex whatever their depth.
    bool lightSampledAtLastVertex = false;
    double etaScale = 1.0;
    int depth = 0;
    Vec3 prevScatter;
    int generation = 0;             // fluorescence events before this path
    bool startsAtEmission = false;  // ray.o is a re-emission point with an isotropic direction still to choose
    // The camera's imaging (PathStart::imaging) weighs the first vertex of a camera path and computes
    // the unscattered image of beam cores on its first straight segment, which sub-paths branched there
    // leave out at their first vertex.
    const CameraPathImaging* imaging = nullptr;
    bool firstSegment = false;
    StartBeamWeight startBeam;  // of a sub-path's first vertex
    const CameraPathImaging* traced = nullptr;  // StartBeamWeight::traced, for every branch of the path
    // The sheet-side strategy ran at the last medium vertex (prevScatter): the phase pdf of the direction
    // the path then took and the proposal's asymmetry there, for the MIS weight of a beam connection
    // at the next vertex (sheetScattering).
    bool sheetSampledAtLastVertex = false;
    double lastPhasePdf = 0, lastProposalG = 0, lastFloorExtinction = 0;
    // A camera path connected to the computed emission at its last medium vertex (emissionConnection):
    // the branch points of the next free flight weigh the same light by the complement.
    bool emissionSampledAtLastVertex = false;
    // Manifold next-event estimation ran at the last medium vertex, inside shells_[chainShells]; the
    // path has since crossed its first chainNext interfaces outward by refraction and nothing else. An
    // area light reached at the end of the whole chain is that strategy's, and the path leaves it out.
    int chainShells = -1, chainNext = 0;
    Vec3 chainOrigin, chainDirection;  // the vertex and the phase-sampled direction (pdf lastPhasePdf) it left in
    // The image level of the first vertex (CameraPathImaging::imageLevel), and what branches on the
    // first segment contributed, by their own levels.
    int level = 0;
    SampledSpectrum firstSegmentTotal;
    std::array<SampledSpectrum, kImageLevels> firstSegmentPooled{};
    double tMin = 0;                // > 0 when ray.o lies on the surface the ray leaves
    const EmissionLabels* labels = nullptr;  // camera paths only: split re-emissions by label
    const ExcitationField* field = nullptr;  // the excitation at lines, looked up where it reaches (all generations)
    std::vector<PathRadiance::Labelled> labelled;
    // PathStart::lightTracedFluorescence: the path's way into a stack's liquid; once inside (entry.inLiquid)
    // its first free flight there has no branch points, and a scattering on it ends the path: the light
    // tracer carries all its light from there. A first vertex on an opaque, non-specular surface hands only
    // the path's fluorescence to the light tracer (fluorescenceCovered).
    StackEntry entry;
    bool fluorescenceCovered = false;
    // PathStart::mergedSegments: the path has met only smooth dielectric events (chainEvents of them) and
    // index-matched crossings, and no collision, since the camera.
    bool mergePrefix = false;
    int chainEvents = 0;
};

PathRadiance PathTracer::radiance(Ray ray, int medium, const SampledWavelengths& wl, Rng& rng, PathStats& stats,
                                  const PathStart& start) const {
    ++stats.paths;
    PathState state;
    state.ray = ray;
    state.medium = medium;
    state.beta = start.beta;
    state.r_u = start.r_u;
    state.imaging = start.imaging;
    state.traced = start.computedEmissionTraced ? start.imaging : nullptr;
    state.labels = start.labels;
    state.field = start.field;
    state.tMin = start.tMin;
    state.firstSegment = true;
    state.entry.open = start.lightTracedFluorescence;
    state.mergePrefix = start.mergedSegments;
    state.prevScatter = ray.o;
    return trace(state, wl, rng, stats);
}

PathRadiance PathTracer::meanRadiance(const Vec3& p, int medium, const SampledWavelengths& wl, Rng& rng, PathStats& stats) const {
    ++stats.paths;
    return traceFromEmission(p, medium, wl, SampledSpectrum(1.0), 0, 0, rng, stats);
}

PathRadiance PathTracer::traceFromEmission(const Vec3& p, int medium, const SampledWavelengths& wl, const SampledSpectrum& beta, int depth,
                                           int generation, Rng& rng, PathStats& stats, StartBeamWeight startBeam,
                                           const ExcitationField* field) const {
    PathState state;
    state.field = field;
    state.ray = Ray{p, Vec3(0, 0, 1)};
    state.medium = medium;
    state.beta = beta;
    state.prevScatter = p;
    state.depth = depth;
    state.generation = generation;
    state.startsAtEmission = true;
    state.startBeam = startBeam;
    state.traced = startBeam.traced;
    return trace(state, wl, rng, stats);
}

SampledSpectrum PathTracer::fluorescence(const Vec3& p, int medium, const double* channels, const SampledWavelengths& wl,
                                         const SampledSpectrum& weight, Rng& rng, PathStats& stats, int generation, int depth,
                                         StartBeamWeight startBeam, const ExcitationField* field, const LabelledChannels* parts,
                                         int partCount, SampledSpectrum* partResults) const {
    for (int i = 0; i < partCount; ++i) partResults[i] = SampledSpectrum(0.0);
    // Generations are ended by roulette; this cap only guards the stack and is reported if reached.
    constexpr int kMaxGenerations = 64;
    if (generation >= kMaxGenerations) {
        ++stats.truncated;
        return SampledSpectrum(0.0);
    }
    const SampledWavelengths wlx = fluorescence_.sampleExcitation(rng.uniform(), rng.uniform());
    // A[j][k]: throughput from the mean radiance at excitation wavelength k to camera wavelength j,
    // Σ_k A[j][k] Lx[k] being the hero-wavelength estimate of ∫ K(λx -> λj) (1/4π)∫L dω dλx.
    double A[kNumWavelengths][kNumWavelengths] = {}, K[kNumWavelengths][kNumWavelengths];
    fluorescence_.kernels(medium, channels, wlx.lambda.data(), wl.lambda.data(), K);
    SampledSpectrum start(0.0);  // initial throughput of the sub-path per excitation slot
    for (int k = 0; k < kNumWavelengths; ++k) {
        if (wlx.pdf[k] == 0) continue;
        for (int j = 0; j < kNumWavelengths; ++j) {
            if (weight[j] == 0) continue;
            A[j][k] = weight[j] * K[j][k] / (wlx.pdf[k] * kNumWavelengths);
            start[k] = std::max(start[k], A[j][k]);
        }
    }
    // Roulette on the branch's throughput keeps the number of sub-paths proportional to the energy
    // they carry, so re-absorption cascades (continuous to continuous wavelengths) stay subcritical
    // however often paths branch. At a line the throughput is per nm of camera bandwidth, not a
    // fraction, so line branches are always traced; a path at a line never branches again.
    const double a = start.maxComponent();
    if (!(a > 0)) return SampledSpectrum(0.0);
    double survival = 1.0;
    if (!wlx.discrete && a < 1) {
        if (rng.uniform() >= a) return SampledSpectrum(0.0);
        survival = a;
    }
    start /= wlx.discrete ? a : std::min(a, 1.0);  // the sub-path starts with throughput <= 1
    ++stats.fluorescenceBranches;
    // Lx: (1/4π)∫L dω at the excitation wavelengths, times `start`.
    SampledSpectrum Lx(0.0);
    // At a line inside the excitation field the scattered light is looked up and the unscattered light
    // evaluated, not traced. Where the camera's imaging computes the emission, it holds both inside the
    // beams' cores, which take the start weight.
    // Where the microscope traces the covered emission forward, no branch counts it.
    // Beyond the computed part, where the microscope traces the beams' emission too, no branch counts it either.
    const bool tracedBeyond = startBeam.traced && startBeam.traced->tracesBeamLitEmissionAt(p, medium);
    if (startBeam.traced && (tracedBeyond || startBeam.traced->computesUnscatteredAt(p))) startBeam = {startBeam.traced, 0.0, startBeam.traced};
    const double coreWeight = startBeam.imaging && (tracedBeyond || startBeam.imaging->computesUnscatteredAt(p)) ? startBeam.weight : 1.0;
    std::optional<double> scattered;
    if (field && wlx.discrete && fluorescence_.model() == FluorescenceModel::Full) {
        // Where the microscope traces the field-lit emission too, the field's light is all the photons'.
        const bool fieldLit = startBeam.traced && startBeam.traced->tracesFieldLitEmission(medium);
        scattered = field->scatteredMeanRadiance(p, wlx.lambda[0], fieldLit ? 0.0 : coreWeight, fieldLit ? 0.0 : 1.0);
    }
    if (scattered) {
        const double mean = *scattered + unscatteredMeanRadiance(p, medium, wlx.lambda[0], coreWeight, 1.0, rng);
        for (int k = 0; k < kNumWavelengths; ++k) Lx[k] = start[k] * mean;
    } else if (fluorescence_.model() == FluorescenceModel::Paper) {
        const double uLight = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        if (const auto ls = lights_.sample(p, uLight, u1, u2, wlx); ls && ls->L && ls->pdf > 0) {
            const double w = computedByImaging(*ls, p, wlx, startBeam.imaging) ? startBeam.weight : 1.0;
            if (w > 0) Lx = start * estimateTransmittance(p, ls->p, medium, wlx, rng, nullptr, 0.0, ls->beam, true).T * ls->L * (w * kInv4Pi / ls->pdf);
        }
    } else {
        Lx = traceFromEmission(p, medium, wlx, start, depth, generation + 1, rng, stats, startBeam, field).total();
    }
    SampledSpectrum result(0.0);
    for (int k = 0; k < kNumWavelengths; ++k) {
        if (Lx[k] == 0) continue;
        for (int j = 0; j < kNumWavelengths; ++j) result[j] += A[j][k] / (start[k] * survival) * Lx[k];
    }
    // Each label's share: the same sub-path, through the kernel of its part of the dye (linear in it).
    for (int i = 0; i < partCount; ++i)
        for (int k = 0; k < kNumWavelengths; ++k) {
            if (Lx[k] == 0 || wlx.pdf[k] == 0) continue;
            for (int j = 0; j < kNumWavelengths; ++j) {
                if (weight[j] == 0) continue;
                const double share = weight[j] * fluorescence_.kernel(medium, parts[i].channels.data(), wlx.lambda[k], wl.lambda[j]) / (wlx.pdf[k] * kNumWavelengths);
                partResults[i][j] += share / (start[k] * survival) * Lx[k];
            }
        }
    return result;
}

double PathTracer::branchDensityAt(int medium, const double* channels, const SampledWavelengths& wl) const {
    if (!fluorescence_.active(medium)) return 0.0;
    const Medium& med = scene_.media[static_cast<size_t>(medium)];
    const MediumSpectra spec = med.spectra(wl);
    const MediumSample m = spec.at(channels);
    // Spectral MIS weighs a branch by the mean of its wavelengths' densities (r_e.average()): a hero
    // wavelength where the dye hardly emits still finds the companions' light.
    return cappedBranchDensity(fluorescence_.branchDensityPerMolar(medium, wl), channels, spec.channels, m.sigmaA + m.sigmaS,
                               fluorescence_.branchDensityCap(medium))
        .average();
}

double PathTracer::floorExtinctionAt(int medium, const SampledWavelengths& wl) const {
    const Medium& med = scene_.media[static_cast<size_t>(medium)];
    if (med.isVacuumLike()) return 0.0;
    const MediumSample fl = med.spectra(wl).at(med.channelFloor().data());
    return fl.sigmaA[0] + fl.sigmaS[0];
}

double PathTracer::unscatteredMeanRadiance(const Vec3& y, int medium, double lambdaNm, double coreWeight, double outsideWeight, Rng& rng) const {
    double total = 0;
    for (const Light& light : lightList_) {
        const BeamLight* beam = std::get_if<BeamLight>(&light);
        if (!beam) continue;
        const BeamProfile& profile = *beam->profile;
        for (const SpectralLine& l : profile.spectrum().spectralLines()) {
            if (l.lambdaNm != lambdaNm || !(l.power > 0)) continue;
            for (int side = 0; side < profile.sides(); ++side) {
                const double w = profile.inCore(y, side, lambdaNm) ? coreWeight : outsideWeight;
                if (!(w > 0)) continue;
                const double E = profile.irradiance(y, side, lambdaNm) * 1e6 * l.power;
                if (!(E > 0)) continue;
                total += w * E * beamTransmittance(y, -profile.direction(side), medium, SampledWavelengths::atLine(lambdaNm, 1.0), rng)[0];
            }
        }
    }
    return total * kInv4Pi;
}

double PathTracer::coreMeanRadiance(const Vec3& p, int medium, double lineNm, const ExcitationField* field, Rng& rng) const {
    return (field ? field->scatteredMeanRadiance(p, lineNm, 1.0, 0.0).value_or(0.0) : 0.0) + unscatteredMeanRadiance(p, medium, lineNm, 1.0, 0.0, rng);
}

PathRadiance PathTracer::trace(PathState& st, const SampledWavelengths& wl, Rng& rng, PathStats& stats) const {
    SampledSpectrum L(0.0), Lf(0.0);
    // Everything after the first vertex is imaged at its level; first-segment branches at their own.
    auto finish = [&] {
        PathRadiance r{L, Lf, st.firstSegmentPooled, std::move(st.labelled)};
        if (st.imaging && st.level > 0) r.pooled[static_cast<size_t>(st.level)] += L + Lf - st.firstSegmentTotal;
        return r;
    };
    SampledSpectrum& beta = st.beta;
    SampledSpectrum& r_u = st.r_u;
    SampledSpectrum& r_l = st.r_l;
    Ray& ray = st.ray;
    int& medium = st.medium;
    int& depth = st.depth;
    bool& lightSampledAtLastVertex = st.lightSampledAtLastVertex;
    double& etaScale = st.etaScale;
    Vec3& prevScatter = st.prevScatter;
    // Roulette on the MIS-weighted throughput (pbrt's rule: survival min(1, max β)). After a specular
    // bounce survival is also capped at 0.95 (Mitsuba 3's rule), so a chain of lossless reflections
    // (total internal reflection in a clear box) ends after about 20 more vertices; dividing by the
    // survival keeps it unbiased. Medium scattering keeps the uncapped rule: in an optically thick,
    // non-absorbing medium a path needs thousands of scattering events to escape, and a cap there would
    // grow the surviving weights as 0.95^-n, with a variance that explodes with depth.
    auto survivesRoulette = [&](bool specular) {
        if (depth <= 1) return true;
        const double q = std::min(specular ? 0.95 : 1.0, (beta * etaScale / r_u.average()).maxComponent());
        if (q >= 1) return true;
        if (!(rng.uniform() < q)) return false;
        beta /= q;
        return true;
    };

    // NEE from a scattering vertex. evalScatter(wi) returns {f * |cos| (or phase value), pdf}.
    // At a surface, `surface` and `n` let the light ray leave through the side of wi (transmission).
    auto directLight = [&](const Vec3& p, int lightMedium, const SampledSpectrum& r_p, auto&& evalScatter,
                           const Vec3& nOffset, const ShapeInfo* surface, double surfaceEps,
                           StartBeamWeight startBeam) -> SampledSpectrum {
        const double uLight = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        const auto ls = lights_.sample(p, uLight, u1, u2, wl);
        if (!ls || !ls->L || !(ls->pdf > 0)) return SampledSpectrum(0.0);
        const double startWeight = computedByImaging(*ls, p, wl, startBeam.imaging) ? startBeam.weight : 1.0;
        if (!(startWeight > 0)) return SampledSpectrum(0.0);
        const auto [fHat, scatterPdf] = evalScatter(ls->wi);
        if (!fHat) return SampledSpectrum(0.0);
        int startMedium = lightMedium;
        if (surface) startMedium = mediumAfterCrossing(*surface, nOffset, ls->wi, lightMedium);
        const TransmittanceEstimate T =
            estimateTransmittance(p, ls->p, startMedium, wl, rng, surface ? &nOffset : nullptr, surfaceEps, ls->beam, ls->delta);
        if (!T.T) return SampledSpectrum(0.0);
        const SampledSpectrum rl = T.r_l * r_p * ls->pdf;
        if (ls->delta) {
            // A medium vertex inside a beam's core reached by a phase-sampled direction from a vertex
            // where the sheet-side strategy also ran: the balance heuristic over that direction.
            double mis = 1;
            if (!surface && ls->beam && wl.discrete && st.sheetSampledAtLastVertex) {
                const Vec3 d = p - prevScatter;
                const double t = length(d);
                const Vec3 w = d / t;
                const BeamCore core = coreAhead(*ls->beamProfile, Ray{prevScatter, w}, ls->side, wl.lambda[0]);
                double pdfPoint = 0;
                for (int k = 0; k < core.count; ++k) pdfPoint += corePointPdf(t, core.intervals[static_cast<size_t>(k)]);
                if (pdfPoint > 0) {
                    const Medium& med = scene_.media[static_cast<size_t>(lightMedium)];
                    ChannelValues ch;
                    med.channelValues(p, ch.data());
                    const double sigmaS = med.scatteringAt(wl.lambda[0]) * ch[kScatteringChannel];
                    const double pdfSheet = HenyeyGreenstein(st.lastProposalG).pdf(ls->beamProfile->direction(ls->side), -w);
                    mis = 1 - sheetMis(kPointsPerCore * pdfPoint * pdfSheet, st.lastPhasePdf * sigmaS * std::exp(-st.lastFloorExtinction * t));
                }
            }
            return beta * fHat * T.T * ls->L * (mis * startWeight) / rl.average();
        }
        const SampledSpectrum ru = T.r_u * r_p * scatterPdf;
        return beta * fHat * T.T * ls->L / (rl + ru).average();
    };

    // Sheet-side sampling of the beam light that scattered once in a beam's core on its way to p, for
    // paths at a beam's line: a direction from the Henyey–Greenstein lobe (asymmetry proposalG) around
    // the beam's axis, and the core integrated along the line from p in that direction (core points,
    // one transmittance pick). A phase-sampled path that next scatters inside the core finds the same
    // light; the balance heuristic weighs both over the direction and the distance t along it: this
    // strategy's density per point is its points × their density × the lobe's pdf, the phase-sampled
    // path's the phase pdf × σs × the floor transmittance to t. Phase sampling alone finds this light
    // with the core's irradiance as weight and the core's thinness as probability (fireflies); this
    // strategy alone is noisy where the phase lobe at p is narrow and the sheet's is not.
    auto sheetScattering = [&](const Vec3& p, double proposalG, double floorExtinction, auto&& phasePdf) -> SampledSpectrum {
        const size_t count = lightList_.size();
        const double uLight = rng.uniform(), uSide = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform(), uPoints = rng.uniform(),
                     uPick = rng.uniform();
        const size_t index = std::min(count - 1, static_cast<size_t>(uLight * static_cast<double>(count)));
        const BeamLight* beam = std::get_if<BeamLight>(&lightList_[index]);
        if (!beam) return SampledSpectrum(0.0);
        const BeamProfile& profile = *beam->profile;
        const int side = std::min(profile.sides() - 1, static_cast<int>(uSide * profile.sides()));
        const double power = profile.spectrum().sampleEmission(wl)[0];
        if (!(power > 0)) return SampledSpectrum(0.0);
        const Vec3 axis = profile.direction(side);
        const HenyeyGreenstein proposal(proposalG);
        double pdfSheet = 0;
        const Vec3 travel = proposal.sample(axis, u1, u2, &pdfSheet);  // the scattered light's direction, toward p
        const Vec3 w = -travel;
        const double f = phasePdf(w);
        if (!(f > 0) || !(pdfSheet > 0)) return SampledSpectrum(0.0);
        const Ray line{p, w};
        const double lambda = wl.lambda[0];
        const BeamCore core = coreAhead(profile, line, side, lambda);
        if (core.count == 0) return SampledSpectrum(0.0);
        const StraightLine straight = traceStraightLine(scene_, line, medium, 0.0, std::numeric_limits<double>::infinity(), LineSurfaces::StopAtAny);
        // Core points, each weighed against a phase-sampled path scattering there (sheetMis).
        struct Point {
            Vec3 y;
            int medium;
            double weight;
        };
        std::array<Point, 2 * kPointsPerCore> points{};
        int n = 0;
        double total = 0;
        ChannelValues ch;
        for (int k = 0; k < core.count; ++k)
            for (int i = 0; i < kPointsPerCore; ++i) {
                double pdf = 0;
                const double t = sampleCorePoint((i + uPoints) / kPointsPerCore, core.intervals[static_cast<size_t>(k)], &pdf);
                if (!(pdf > 0)) continue;
                const auto seg = std::find_if(straight.segments.begin(), straight.segments.end(),
                                              [&](const RaySegment& s) { return t >= s.t0 && t < s.t1; });
                if (seg == straight.segments.end() || seg->medium == kNone) continue;
                const Medium& med = scene_.media[static_cast<size_t>(seg->medium)];
                if (med.isVacuumLike()) continue;
                const Vec3 y = line.at(t);
                med.channelValues(y, ch.data());
                const double sigmaS = med.scatteringAt(lambda) * ch[kScatteringChannel];
                const double E = profile.irradiance(y, side, lambda) * 1e6 * power;
                const double source = sigmaS * med.phase().pdf(axis, travel) * E;
                if (!(source > 0)) continue;
                const double mis = sheetMis(kPointsPerCore * pdf * pdfSheet, f * sigmaS * std::exp(-floorExtinction * t));
                points[static_cast<size_t>(n++)] = {y, seg->medium, mis * source / (kPointsPerCore * pdf)};
                total += points[static_cast<size_t>(n - 1)].weight;
            }
        if (!(total > 0)) return SampledSpectrum(0.0);
        // One point, picked in proportion to its weight, carries the transmittances for all.
        double target = uPick * total, acc = 0;
        int pick = 0;
        for (; pick + 1 < n; ++pick) {
            acc += points[static_cast<size_t>(pick)].weight;
            if (acc > target) break;
        }
        const Point& z = points[static_cast<size_t>(pick)];
        const SampledSpectrum T = transmittance(p, z.y, medium, wl, rng);
        if (!T) return SampledSpectrum(0.0);
        const SampledSpectrum Tb = beamTransmittance(z.y, -axis, z.medium, wl, rng);
        const double select = 1.0 / (static_cast<double>(count) * profile.sides());
        return beta * T * Tb * (total * f / (pdfSheet * select)) / r_u.average();
    };
    auto sheetLinesAt = [&](const SampledWavelengths& w) { return w.discrete && hasBeams_; };

    // A real scattering vertex in a medium: NEE with MIS, the sheet-side strategy, then a new direction
    // from the phase function (sampled exactly, so f / pdf = 1 and beta is unchanged). `proposalG` is the
    // medium's asymmetry (the sheet-side proposal's), which an emission vertex's isotropic phase is not.
    // Scattered emission: from a camera path's medium vertex, a point of the emission the camera's
    // imaging computes (drawn by its density), connected through the medium, with the fluorescence its
    // beams' light excites there; combined with finding that point by a branch of the next free flight,
    // by the balance heuristic over the point: the connection's density per mm³ against the branch's (the
    // phase pdf of the direction over r², times the branch density at the point and the floor's
    // transmittance to it). The connection's weight is then bounded by 1/(σ_b T) however close the point
    // and however sharp the phase lobe that points at it (g = 0.9 raises the phase 190-fold over
    // isotropic), and far from the vertex the connection takes over from free flights, which commit to
    // one direction. Any weights that sum to one keep the estimate unbiased.
    // The connection's share at y (density pc), reached with phase pdf f from a vertex at `distance`.
    // `branchDensity`: the free flight's at y, averaged over the wavelengths (branchDensityAt).
    auto emissionMis = [&](double pc, double f, double distance, double branchDensity, double extinction) {
        const double pb = f * branchDensity * std::exp(-extinction * distance) / (distance * distance);
        return pc + pb > 0 ? pc / (pc + pb) : 0.0;
    };
    // The unscattered excitation of one beam side (chosen as next-event estimation chooses) at each of its
    // lines where y lies in its core, as addLine(λ, mean radiance); false when the chosen light is not a beam.
    auto beamConnectionSource = [&](const Vec3& y, int yMedium, double uLight, double uSide, auto&& addLine) {
        const size_t count = lightList_.size();
        const size_t index = std::min(count - 1, static_cast<size_t>(uLight * static_cast<double>(count)));
        const BeamLight* beam = std::get_if<BeamLight>(&lightList_[index]);
        if (!beam) return false;
        const BeamProfile& profile = *beam->profile;
        const int side = std::min(profile.sides() - 1, static_cast<int>(uSide * profile.sides()));
        const double select = 1.0 / (static_cast<double>(count) * profile.sides());
        for (const SpectralLine& l : profile.spectrum().spectralLines()) {
            if (!(l.power > 0) || !profile.inCore(y, side, l.lambdaNm)) continue;
            const double E = profile.irradiance(y, side, l.lambdaNm) * 1e6 * l.power;
            if (!(E > 0)) continue;
            const double Tb = beamTransmittance(y, -profile.direction(side), yMedium, SampledWavelengths::atLine(l.lambdaNm, 1.0), rng)[0];
            if (!(Tb > 0)) continue;
            addLine(l.lambdaNm, kInv4Pi * E * Tb / select);
        }
        return true;
    };
    auto emissionConnection = [&](const Vec3& p, auto&& phasePdf) -> SampledSpectrum {
        const double uCell = rng.uniform(), ux = rng.uniform(), uy = rng.uniform(), uz = rng.uniform(), uLight = rng.uniform(),
                     uSide = rng.uniform();
        const auto point = st.imaging->sampleEmissionPoint(uCell, ux, uy, uz);
        if (!point || !(point->pdf > 0)) return SampledSpectrum(0.0);
        const Vec3 d = point->p - p;
        const double distance = length(d);
        if (!(distance > 0)) return SampledSpectrum(0.0);
        const Vec3 w = d / distance;
        const double f = phasePdf(w);
        if (!(f > 0)) return SampledSpectrum(0.0);
        const StraightLine line = traceStraightLine(scene_, Ray{p, w}, medium, 0.0, distance, LineSurfaces::StopAtAny);
        if (line.end != LineEnd::Open) return SampledSpectrum(0.0);
        const int pointMedium = line.segments.empty() ? medium : line.segments.back().medium;
        if (!fluorescence_.active(pointMedium)) return SampledSpectrum(0.0);
        const Medium& med = scene_.media[static_cast<size_t>(pointMedium)];
        ChannelValues ch;
        med.channelValues(point->p, ch.data());
        SampledSpectrum source(0.0);
        if (!st.imaging->computesUnscatteredAt(point->p)) return source;
        std::array<LabelledChannels, kMaxLabelsAtPoint> parts;
        std::array<SampledSpectrum, kMaxLabelsAtPoint> partSources;
        const int partCount = st.labels ? st.labels->split(pointMedium, point->p, ch.data(), parts) : 0;
        auto addLine = [&](double lambdaNm, double meanRadiance) {
            for (int j = 0; j < kNumWavelengths; ++j) {
                source[j] += fluorescence_.kernel(pointMedium, ch.data(), lambdaNm, wl.lambda[j]) * meanRadiance;
                for (int i = 0; i < partCount; ++i)
                    partSources[static_cast<size_t>(i)][j] +=
                        fluorescence_.kernel(pointMedium, parts[static_cast<size_t>(i)].channels.data(), lambdaNm, wl.lambda[j]) * meanRadiance;
            }
        };
        if (st.field) {
            // With the excitation field the computed emission holds the scattered excitation too.
            for (double lambdaNm : lineWavelengths_) {
                const double m = st.field->scatteredMeanRadiance(point->p, lambdaNm, 1.0, 0.0).value_or(0.0) +
                                 unscatteredMeanRadiance(point->p, pointMedium, lambdaNm, 1.0, 0.0, rng);
                if (m > 0) addLine(lambdaNm, m);
            }
        } else if (!beamConnectionSource(point->p, pointMedium, uLight, uSide, addLine)) {
            return SampledSpectrum(0.0);
        }
        if (!source) return source;
        const SampledSpectrum T = transmittance(p, point->p, medium, wl, rng);
        if (!T) return SampledSpectrum(0.0);
        const double mis = emissionMis(point->pdf, f, distance, branchDensityAt(pointMedium, ch.data(), wl), medium != kNone ? floorExtinctionAt(medium, wl) : 0.0);
        const SampledSpectrum factor = beta * T * (f * mis / (distance * distance * point->pdf)) / r_u.average();
        for (int i = 0; i < partCount; ++i)
            if (partSources[static_cast<size_t>(i)]) st.labelled.push_back({parts[static_cast<size_t>(i)].key, st.level, factor * partSources[static_cast<size_t>(i)]});
        return factor * source;
    };
    // Manifold next-event estimation from a medium vertex p inside a stack of spherical shells: a point
    // y on an area light (as next-event estimation picks it), every refracted chain from p to y
    // (shellPaths), each weighed by the phase value, the media's transmittance along its segments (each
    // must meet nothing else), the interfaces' Fresnel transmittance and the radiance's n² scaling, over
    // the chain direction's density p_A(y) · dA/dω. The phase-sampled path that follows the same chain
    // to the light finds the same light; the balance heuristic weighs the two, this strategy's density
    // p_A · dA/dω against the phase pdf times the chain's Fresnel transmittance (the probability that
    // the path refracts at every interface) (chainWeight). Alone, this strategy's weight grows without
    // bound where dA/dω vanishes: at the caustics the glass focuses inside the liquid.
    auto chainWeight = [](double pdfChain, double pdfPhase) { return pdfChain + pdfPhase > 0 ? pdfChain / (pdfChain + pdfPhase) : 0.0; };
    auto shellLight = [&](const Vec3& p, const SphericalShells& sh, auto&& phaseValue) -> SampledSpectrum {
        const double uLight = rng.uniform(), u1 = rng.uniform(), u2 = rng.uniform();
        const auto ls = lights_.sample(p, uLight, u1, u2, wl);
        if (!ls || ls->beam || !(ls->pdf > 0) || !(ls->distance > 0)) return SampledSpectrum(0.0);
        // Area lights: radiance at y, density p_A(y) over the light's area. Point and spot lights: their
        // intensity, and the light's solid angle per area across the chain at p, which étendue
        // conservation gives from the area across the exit ray per solid angle at p:
        // dω_y/dA⊥_p = (n_p/n_y)² / (dA⊥_y/dω_p) (the n² is in `scale`).
        const AreaLight* area = nullptr;
        double pdfArea = ls->pdf;  // a delta light's selection probability
        if (!ls->delta) {
            const double cosY = std::abs(dot(ls->n, ls->wi));
            if (!(cosY > 0)) return SampledSpectrum(0.0);
            pdfArea = ls->pdf * cosY / sqr(ls->distance);
            const ShapeInfo& lightShape = scene_.shapes[ls->shape];
            if (lightShape.areaLight == kNone) return SampledSpectrum(0.0);
            area = &std::get<AreaLight>(scene_.lights[static_cast<size_t>(lightShape.areaLight)]);
            // A light dark at these wavelengths (a line light seen by a path at emission wavelengths) needs no chains.
            if (!lights_.emitted(*area, ls->n, ls->n, wl)) return SampledSpectrum(0.0);
        } else if (!ls->L) {
            return SampledSpectrum(0.0);  // dark at these wavelengths, or p outside a spot's cone (checked again per chain)
        }
        std::array<ShellPath, 4> roots;
        const int count = shellPaths(sh, p, ls->p, roots);
        SampledSpectrum sum(0.0);
        for (int k = 0; k < count; ++k) {
            const ShellPath& r = roots[static_cast<size_t>(k)];
            const SampledSpectrum Le =
                area ? lights_.emitted(*area, ls->n, -r.exitDirection, wl) : LightSampler::deltaIntensity(*ls->light, -r.exitDirection, wl);
            if (!Le) continue;
            const double f = phaseValue(r.direction);
            if (!(f > 0)) continue;
            const double dAdw = areaPerSolidAngle(sh, p, r, ls->p, area ? ls->n : r.exitDirection);
            if (!(dAdw > 0)) continue;
            const TransmittanceEstimate T = estimateChainTransmittance(sh, p, r, ls->p, wl, rng);
            if (!T.T) continue;
            const double scale = r.fresnel * sqr(sh.ior[0] / sh.ior[static_cast<size_t>(sh.count)]);
            const double pdfChain = pdfArea * dAdw;
            // Nothing else reaches a delta light; an area light is also found by phase sampling.
            const double weight = area ? chainWeight(pdfChain, f * r.fresnel) : 1.0;
            const SampledSpectrum rl = T.r_l * r_u * pdfChain;
            sum += beta * T.T * Le * (f * scale * weight) / rl.average();
        }
        return sum;
    };
    auto scatterInMedium = [&](const Vec3& p, const HenyeyGreenstein& phase, double proposalG, StartBeamWeight startBeam) {
        const Vec3 dirIn = ray.d;
        st.chainShells = shells_.empty() ? -1 : shellsAround(p, medium);
        st.chainNext = 0;
        if (st.chainShells >= 0)
            L += shellLight(p, shells_[static_cast<size_t>(st.chainShells)], [&](const Vec3& wi) { return phase.pdf(dirIn, wi); });
        L += directLight(
            p, medium, r_u,
            [&](const Vec3& wi) {
                const double v = phase.pdf(dirIn, wi);
                return std::pair{SampledSpectrum(v), v};
            },
            Vec3(), nullptr, 0.0, startBeam);
        const bool sheets = sheetLinesAt(wl);
        // Camera paths (not sub-paths) at emission wavelengths connect to the computed emission.
        const bool emission = st.imaging && !st.traced && !st.startsAtEmission && st.generation == 0 && !wl.discrete && fluorescence_.active();
        if (emission) Lf += emissionConnection(p, [&](const Vec3& wi) { return phase.pdf(dirIn, wi); });
        // In the medium at p, at the hero wavelength: the phase-sampled side's density proxy, for the
        // sheet-side strategy's MIS and the emission connection's.
        const double floorExtinction = (sheets || emission) && medium != kNone ? floorExtinctionAt(medium, wl) : 0.0;
        if (sheets) L += sheetScattering(p, proposalG, floorExtinction, [&](const Vec3& wi) { return phase.pdf(dirIn, wi); });
        double phasePdf = 0;
        const Vec3 wi = phase.sample(dirIn, rng.uniform(), rng.uniform(), &phasePdf);
        r_l = r_u / phasePdf;
        prevScatter = p;
        lightSampledAtLastVertex = true;
        st.chainOrigin = p;
        st.chainDirection = wi;
        st.sheetSampledAtLastVertex = sheets;
        st.lastFloorExtinction = floorExtinction;
        st.emissionSampledAtLastVertex = emission;
        st.lastPhasePdf = phasePdf;
        st.lastProposalG = proposalG;
        ray = Ray{p, wi};
    };

    if (st.startsAtEmission) {
        static const HenyeyGreenstein isotropic(0.0);
        const double g = medium != kNone ? scene_.media[static_cast<size_t>(medium)].phase().g() : 0.0;
        scatterInMedium(ray.o, isotropic, g, st.startBeam);
    }

    while (true) {
        const auto hit = scene_.geometry.intersect(ray, st.tMin, std::numeric_limits<double>::infinity());
        st.tMin = 0;
        if (medium != kNone && !scene_.media[static_cast<size_t>(medium)].isVacuumLike()) {
            const Medium& med = scene_.media[static_cast<size_t>(medium)];
            const double tMax = hit ? hit->t : std::numeric_limits<double>::infinity();
            bool scattered = false, terminated = false;
            const MediumSpectra spec = med.spectra(wl);
            // Fluorescence branch points are extra null density, so the source term is sampled even
            // where the dye barely absorbs at these wavelengths.
            // A path at a spectral line estimates the line's delta weight. Re-emitted light is a
            // continuous density and adds nothing to it (the continuous wavelength branch covers it
            // at that wavelength), so such paths never branch; this also ends every cascade there.
            // A segment seen through glass whose light photon merging carries (PathStart::mergedSegments).
            bool merged = false;
            if (st.mergePrefix) {
                if (!med.isHomogeneous() || !hit) st.mergePrefix = false;
                else merged = st.chainEvents >= 1 && !st.entry.inLiquid;
            }
            const bool dyed = !wl.discrete && fluorescence_.active(medium) && !st.entry.inLiquid && !st.fluorescenceCovered && !merged;
            // Branch density per unit of each channel (it is linear in the concentrations).
            const std::array<SampledSpectrum, kMaxMediumChannels> branchPerChannel =
                dyed ? fluorescence_.branchDensityPerMolar(medium, wl) : std::array<SampledSpectrum, kMaxMediumChannels>{};
            // Capped at max(σt, cap) (1/mm when homogeneous): where the medium is already dense its real collisions are enough,
            // and a concentrated dye (σa ~ 10^2-10^3 /mm) must not flood the path with branch points.
            // The same formula applied to a segment's channel maxima bounds it over the segment.
            const double branchCap = dyed ? fluorescence_.branchDensityCap(medium) : 0.0;
            auto branchDensity = [&](const double* ch, const SampledSpectrum& sigmaT) {
                return dyed ? cappedBranchDensity(branchPerChannel, ch, spec.channels, sigmaT, branchCap) : SampledSpectrum(0.0);
            };
            // The majorant is the sum of two independent processes: tracking (bound sigmaTBar on σt, as
            // in pbrt) and branch points (bound sigmaBBar on the branch density). Each tentative collision
            // belongs to one of them with probability proportional to its rate. Branch-process points are
            // auxiliary: they change beta, r_u and r_l alike, so the MIS weights against next-event
            // estimation (which ratio-tracks the tracking process only) still sum to one.
            SampledSpectrum sigmaBBar(0.0);  // of the segment being sampled
            const double* segmentMaxima = nullptr;
            auto majorants = med.majorants(ray, 0.0, tMax, [&](const double* m) {
                segmentMaxima = m;
                const MediumSample s = spec.at(m);
                const SampledSpectrum sigmaTBar = s.sigmaA + s.sigmaS;
                sigmaBBar = branchDensity(m, sigmaTBar);
                return sigmaTBar + sigmaBBar;
            });
            ChannelValues ch;
            const SampledSpectrum T_maj = sampleTmaj<SampledSpectrum>(
                majorants, rng, [&](double t, const SampledSpectrum& sigmaMaj, const SampledSpectrum& Tm) {
                    ++stats.tentativeCollisions;
                    med.channelValues(ray.at(t), ch.data(), segmentMaxima);
                    const MediumSample mp = spec.at(ch.data());
                    if (dyed && rng.uniform() * sigmaMaj[0] < sigmaBBar[0]) {
                        // A branch-process point; it branches with probability sigmaB(p) / sigmaBBar.
                        const SampledSpectrum sigmaB = branchDensity(ch.data(), mp.sigmaA + mp.sigmaS);
                        if (rng.uniform() * sigmaBBar[0] < sigmaB[0]) {
                            const double pdf = Tm[0] * sigmaB[0];
                            const SampledSpectrum r_e = r_u * sigmaB * Tm / pdf;
                            if (r_e) {
                                const Vec3 y = ray.at(t);
                                // On the first segment the branch point is the vertex the camera images, and the
                                // camera's imaging computes its unscattered excitation; after a connection to
                                // the computed emission, that excitation is weighed against it.
                                StartBeamWeight startBeam;
                                SampledSpectrum w = beta * Tm / (pdf * r_e.average());
                                if (st.firstSegment && st.imaging) {
                                    w *= st.imaging->firstVertexWeight(y, wl);
                                    startBeam = {st.imaging, 0.0};
                                } else if (st.emissionSampledAtLastVertex) {
                                    const double pc = st.imaging->emissionPointPdf(y);
                                    const double mis =
                                        pc > 0 ? 1 - emissionMis(pc, st.lastPhasePdf, length(y - prevScatter), sigmaB.average(), st.lastFloorExtinction) : 1.0;
                                    startBeam = {st.imaging, mis};
                                }
                                startBeam.traced = st.traced;
                                std::array<LabelledChannels, kMaxLabelsAtPoint> parts;
                                std::array<SampledSpectrum, kMaxLabelsAtPoint> partResults;
                                const int partCount = st.labels ? st.labels->split(medium, y, ch.data(), parts) : 0;
                                const SampledSpectrum branch = fluorescence(y, medium, ch.data(), wl, w, rng, stats, st.generation, depth, startBeam,
                                                                            st.field, parts.data(), partCount, partResults.data());
                                Lf += branch;
                                // On the first segment a branch is imaged at its own level; later, at the first vertex's.
                                const int level = st.firstSegment && st.imaging ? st.imaging->imageLevel(y) : st.level;
                                for (int i = 0; i < partCount; ++i)
                                    if (partResults[static_cast<size_t>(i)])
                                        st.labelled.push_back({parts[static_cast<size_t>(i)].key, level, partResults[static_cast<size_t>(i)]});
                                if (st.firstSegment && st.imaging) {
                                    st.firstSegmentTotal += branch;
                                    if (const int k = st.imaging->imageLevel(y); k > 0) st.firstSegmentPooled[static_cast<size_t>(k)] += branch;
                                }
                            }
                        }
                        const SampledSpectrum ratio = Tm * sigmaBBar / (Tm[0] * sigmaBBar[0]);
                        beta *= ratio;
                        r_u *= ratio;
                        r_l *= ratio;
                        return bool(beta) && bool(r_u);
                    }
                    const SampledSpectrum sigmaTBar = sigmaMaj - sigmaBBar;
                    const double pAbsorb = mp.sigmaA[0] / sigmaTBar[0];
                    const double pScatter = mp.sigmaS[0] / sigmaTBar[0];
                    const double pNull = std::max(0.0, 1.0 - pAbsorb - pScatter);
                    const std::array<double, 3> probs{pAbsorb, pScatter, pNull};
                    const int mode = sampleDiscrete(probs, rng.uniform());
                    if (mode == 0) {
                        ++stats.absorptionEvents;
                        terminated = true;
                        return false;
                    }
                    if (mode == 1) {
                        const double pdf = Tm[0] * mp.sigmaS[0];
                        beta *= Tm * mp.sigmaS / pdf;
                        r_u *= Tm * mp.sigmaS / pdf;
                        ++stats.scatteringEvents;
                        if (depth++ >= scene_.render.maxDepth) {
                            ++stats.truncated;
                            terminated = true;
                            return false;
                        }
                        const Vec3 y = ray.at(t);
                        if (st.firstSegment && st.imaging) {
                            beta *= st.imaging->firstVertexWeight(y, wl);
                            st.level = st.imaging->imageLevel(y);
                        }
                        st.firstSegment = false;
                        // A scattering on the camera's first free flight in a stack's liquid: the light tracer's
                        // connections from its photons' vertices there carry everything this path would find.
                        if (st.entry.inLiquid || merged) {
                            terminated = true;
                            return false;
                        }
                        st.entry.open = st.mergePrefix = false;
                        if (beta && r_u) {
                            scatterInMedium(y, med.phase(), med.phase().g(), {});
                            scattered = true;
                        }
                        return false;
                    }
                    const SampledSpectrum sigmaN = clampZero(sigmaTBar - mp.sigmaA - mp.sigmaS);
                    const double pdf = Tm[0] * sigmaN[0];
                    if (pdf == 0) beta = SampledSpectrum(0.0);
                    else {
                        beta *= Tm * sigmaN / pdf;
                        r_u *= Tm * sigmaN / pdf;
                        r_l *= Tm * sigmaTBar / pdf;
                    }
                    return bool(beta) && bool(r_u);
                });
            if (terminated || !beta || !r_u) return finish();
            if (scattered) {
                if (!survivesRoulette(false)) return finish();
                continue;
            }
            beta *= T_maj / T_maj[0];
            r_u *= T_maj / T_maj[0];
            r_l *= T_maj / T_maj[0];
        }

        if (!hit) break;  // no environment light
        const ShapeInfo& shape = scene_.shapes[hit->shape];
        // A surface with a material is the first vertex of a camera path that has met nothing before it;
        // an emitter without one images only its own emission there.
        SampledSpectrum imagingWeight(1.0);
        if (st.firstSegment && st.imaging && (shape.material != kNone || shape.areaLight != kNone)) {
            imagingWeight = st.imaging->firstVertexWeight(hit->p, wl);
            if (shape.material != kNone) st.level = st.imaging->imageLevel(hit->p);
        }
        if (shape.material != kNone) {
            beta *= imagingWeight;
            imagingWeight = SampledSpectrum(1.0);
        }
        if (shape.areaLight != kNone) {
            const auto& light = std::get<AreaLight>(scene_.lights[static_cast<size_t>(shape.areaLight)]);
            const SampledSpectrum Le = lights_.emitted(light, hit->n, -ray.d, wl) * imagingWeight;
            if (Le) {
                SampledSpectrum c;
                if (st.chainShells >= 0 && st.chainNext == shells_[static_cast<size_t>(st.chainShells)].count) {
                    // The end of a chain that manifold next-event estimation also samples: the complement of its weight.
                    const SphericalShells& sh = shells_[static_cast<size_t>(st.chainShells)];
                    const auto path = traceShells(sh, st.chainOrigin, st.chainDirection);
                    const Vec3 toLight = hit->p - st.chainOrigin;
                    const double d2 = dot(toLight, toLight);
                    const double pdfArea = lights_.pdf(st.chainOrigin, hit->shape, hit->p, hit->n) * std::abs(dot(hit->n, toLight)) / (d2 * std::sqrt(d2));
                    const double pdfChain = path ? pdfArea * areaPerSolidAngle(sh, st.chainOrigin, *path, hit->p, hit->n) : 0.0;
                    const double pdfPhase = path ? st.lastPhasePdf * path->fresnel : 0.0;
                    c = beta * Le * (1 - chainWeight(pdfChain, pdfPhase)) / r_u.average();
                } else if (!lightSampledAtLastVertex) c = beta * Le / r_u.average();
                else {
                    const double lightPdf = lights_.pdf(prevScatter, hit->shape, hit->p, hit->n);
                    c = beta * Le / (r_u + r_l * lightPdf).average();
                }
                L += c;
                // An emitter seen directly through the first segment is imaged at its own level.
                if (st.firstSegment && st.imaging && shape.material == kNone) {
                    st.firstSegmentTotal += c;
                    if (const int k = st.imaging->imageLevel(hit->p); k > 0) st.firstSegmentPooled[static_cast<size_t>(k)] += c;
                }
            }
        }
        // The chain of manifold next-event estimation: its next interface, crossed outward by refraction
        // (or index-matched), advances it; any other surface event ends it. Other index-matched
        // interfaces leave it as it is, as they leave its transmittance.
        const bool chainExpectsHit = st.chainShells >= 0 && st.chainNext < shells_[static_cast<size_t>(st.chainShells)].count &&
                                     hit->shape == shells_[static_cast<size_t>(st.chainShells)].shape[static_cast<size_t>(st.chainNext)];
        auto followChain = [&](bool transmitted, const Vec3& dir) {
            if (chainExpectsHit && transmitted && dot(dir, hit->n) > 0) ++st.chainNext;
            else st.chainShells = -1;
        };
        if (shape.material == kNone) {
            if (!shape.isInterface) break;  // black emitter or absorber
            if (chainExpectsHit) followChain(true, ray.d);
            st.entry.meet(shells_, hit->shape, dot(ray.d, hit->n) < 0, true);
            medium = mediumAfterCrossing(shape, hit->n, ray.d, medium);
            ray.o = hit->p;
            st.tMin = leavingTMin(hit->n, ray.d, hit->epsilon);
            continue;
        }
        if (depth++ >= scene_.render.maxDepth) {
            ++stats.truncated;
            break;
        }
        ++stats.surfaceBounces;
        st.firstSegment = false;
        st.sheetSampledAtLastVertex = false;
        st.emissionSampledAtLastVertex = false;
        const Material& mat = *scene_.materials[static_cast<size_t>(shape.material)];
        // An opaque, non-specular surface seen straight from the camera: the light tracer connects its
        // re-emitted light to the camera, so the whole path's fluorescence is the light tracer's.
        if (st.entry.open && st.entry.stack < 0 && !mat.isSpecular() && !mat.isTransmissive()) {
            st.fluorescenceCovered = true;
            st.entry.open = false;
        }
        // The same surface seen through a chain of dielectric events: photon merging's (PathStart::mergedSegments).
        if (st.mergePrefix && st.chainEvents >= 1 && !mat.isSpecular() && !mat.isTransmissive()) st.fluorescenceCovered = true;
        // Opaque surfaces are two-sided; interfaces keep their outward orientation.
        const Vec3 n = shape.isInterface ? hit->n : faceForward(hit->n, -ray.d);
        const double eta = scene_.ior(shape.insideMedium) / scene_.ior(shape.outsideMedium);
        const Frame frame = Frame::fromNormal(n);
        const Vec3 wo = frame.toLocal(-ray.d);
        if (wo.z == 0) break;

        if (!mat.isSpecular()) {
            L += directLight(
                hit->p, medium, r_u,
                [&](const Vec3& wi) {
                    const Vec3 wiLocal = frame.toLocal(wi);
                    const SampledSpectrum f = mat.f(wo, wiLocal, wl, eta, TransportMode::Radiance) * std::abs(wiLocal.z);
                    return std::pair{f, mat.pdf(wo, wiLocal, eta)};
                },
                n, &shape, hit->epsilon, {});
        }

        const auto bs = mat.sample(wo, rng.uniform(), rng.uniform(), rng.uniform(), wl, eta, TransportMode::Radiance);
        if (!bs) break;
        const Vec3 wi = frame.toWorld(bs->wi);
        followChain(bs->transmission && bs->specular, wi);
        st.entry.meet(shells_, hit->shape, bs->transmission && bs->specular && dot(wi, hit->n) < 0, false);
        if (st.mergePrefix && !(shape.isInterface && mat.isSpecular() && mat.isTransmissive() && bs->specular &&
                                ++st.chainEvents <= kMaxMergedChainEvents))
            st.mergePrefix = false;
        beta *= bs->f * std::abs(bs->wi.z) / bs->pdf;
        r_l = r_u / bs->pdf;
        lightSampledAtLastVertex = !bs->specular;
        if (bs->transmission) etaScale *= sqr(bs->etap);
        prevScatter = hit->p;
        medium = mediumAfterCrossing(shape, hit->n, wi, medium);
        ray = Ray{hit->p, wi};
        st.tMin = leavingTMin(n, wi, hit->epsilon);
        if (!beta) break;
        if (!survivesRoulette(bs->specular)) break;
    }
    return finish();
}

}  // namespace fluorosim
