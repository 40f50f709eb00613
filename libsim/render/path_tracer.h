#pragma once
// Unbiased spectral volumetric path tracer (pbrt-v4's VolPathIntegrator design): hero wavelengths
// with path-space spectral MIS through rescaled path pdfs (r_u, r_l), next-event estimation with
// MIS at surfaces and in media, free flights through sampleTmaj, and Russian roulette on the
// MIS-weighted throughput; after specular bounces survival is at most 0.95 (Mitsuba 3's rule), so
// that light trapped without loss by total internal reflection still ends after a few vertices.
//
// Fluorescence: at every tentative collision in a dyed medium a camera path branches, with a
// probability set by FluorescencePlan::branchDensity, into an excitation sub-path that estimates the
// inelastic source term at new (excitation) wavelengths, then continues elastically. The sub-path is
// a full path of its own (multiple scattering, NEE, further fluorescence generations) in the full
// model, and a single transmittance-weighted light connection in the paper's model.
#include <array>
#include <cstdint>
#include <optional>

#include "core/rng.h"
#include "render/fluorescence.h"
#include "render/specular_chain.h"
#include "scene/light_sampler.h"
#include "scene/scene.h"

namespace fluorosim {

struct PathStats {
    uint64_t paths = 0;
    uint64_t scatteringEvents = 0;   // real collisions in media
    uint64_t absorptionEvents = 0;
    uint64_t tentativeCollisions = 0;  // all collisions sampled against the majorant (real, null, branch points)
    uint64_t surfaceBounces = 0;
    uint64_t fluorescenceBranches = 0;  // excitation sub-paths started
    uint64_t truncated = 0;          // paths stopped by the safety depth cap (a bias, so it is reported)
    void add(const PathStats& o) {
        paths += o.paths;
        scatteringEvents += o.scatteringEvents;
        absorptionEvents += o.absorptionEvents;
        tentativeCollisions += o.tentativeCollisions;
        surfaceBounces += o.surfaceBounces;
        fluorescenceBranches += o.fluorescenceBranches;
        truncated += o.truncated;
    }
};

// Radiance at the camera's wavelengths, split by history: `fluorescent` has gone through at least
// one re-emission, `elastic` never has (it includes elastically scattered excitation light).
inline constexpr int kImageLevels = 8;
struct PathRadiance {
    SampledSpectrum elastic, fluorescent;
    // Of the total, what a camera's imaging pools over blocks of 2^k × 2^k pixels, by k >= 1
    // (CameraPathImaging::imageLevel); the rest is imaged per pixel.
    std::array<SampledSpectrum, kImageLevels> pooled{};
    // With PathStart::labels: the camera path's re-emissions by the label that emitted them, part of
    // `fluorescent`, each with the image level it is pooled at (0: per pixel), as `pooled` splits the total.
    struct Labelled {
        uint32_t key;
        int level;
        SampledSpectrum radiance;
    };
    std::vector<Labelled> labelled;
    SampledSpectrum total() const { return elastic + fluorescent; }
};

// Fluorescence split by what emitted it: the labelled objects (neurons) whose dye re-emits at a point,
// for fits whose parameters are labels. A camera path's re-emission at p is linear in the dye there, so
// each label's share follows from the fluorescence kernel of that label's part of the dye channels.
// Left uninitialised (EmissionLabels::split fills the parts it returns): the tracer declares an array of
// them at every branch point, with or without labels.
struct LabelledChannels {
    uint32_t key;
    ChannelValues channels;  // the label's part of the medium's channels at p (dye channels only)
};
inline constexpr int kMaxLabelsAtPoint = 8;
class EmissionLabels {
public:
    virtual ~EmissionLabels() = default;
    // The parts of the dye at p (in `medium`, whose channels there are `channels`) by label: the count
    // written to out. What no part holds is left unattributed.
    virtual int split(int medium, const Vec3& p, const double* channels, std::array<LabelledChannels, kMaxLabelsAtPoint>& out) const = 0;
};

// What a caller that images camera paths (the microscope) puts around one path: a weight at the path's
// first vertex, where the light the path carries leaves toward the camera (a diffraction PSF in place of
// the geometric image of that point), and the part of the transport the caller computes itself, which
// the path then leaves out so that the two add up to the model (docs/model.md, "The computed image").
class CameraPathImaging {
public:
    virtual ~CameraPathImaging() = default;
    // Factor on the throughput at the first vertex y (a scattering or fluorescence branch point, or a
    // surface) at the path's wavelengths; it multiplies f, not the pdfs.
    virtual SampledSpectrum firstVertexWeight(const Vec3& y, const SampledWavelengths& wl) const = 0;
    // Whether the caller computes the fluorescence that a beam's unscattered light (at a spectral line,
    // inside the beam's core) excites at y, a point of the camera path's first straight segment.
    virtual bool computesUnscatteredAt(const Vec3& y) const = 0;
    // Scattered emission: points of that computed emission, drawn by a density per mm³ roughly in
    // proportion to its power, so that a camera path connects to it from where it scatters (optional).
    struct EmissionPoint {
        Vec3 p;
        double pdf = 0;
    };
    virtual std::optional<EmissionPoint> sampleEmissionPoint(double /*uCell*/, double /*ux*/, double /*uy*/, double /*uz*/) const {
        return std::nullopt;
    }
    virtual double emissionPointPdf(const Vec3& /*p*/) const { return 0.0; }
    // How finely the light that leaves y (a first vertex) is imaged: 0 per pixel, k in [1, kImageLevels)
    // pooled over blocks of 2^k × 2^k pixels (where y's image is a disc much wider than the block).
    virtual int imageLevel(const Vec3& /*y*/) const { return 0; }
    // With PathStart::computedEmissionTraced: whether the caller also traces the emission that an
    // excitation field's light excites beyond the computed part, in `medium` (no branch there counts the
    // field's light then).
    virtual bool tracesFieldLitEmission(int /*medium*/) const { return false; }
    // With PathStart::computedEmissionTraced: whether the caller also traces the emission that the beams'
    // unscattered light excites inside their cores at y, in `medium`, beyond the computed part (no branch
    // there counts that light then).
    virtual bool tracesBeamLitEmissionAt(const Vec3& /*y*/, int /*medium*/) const { return false; }
};

// The scattered light of beams at spectral lines, computed rather than sampled (render/fluence_field.h):
// a fluorescence branch at a line adds it to the beams' unscattered light (next to the branch, exactly)
// instead of tracing an excitation sub-path, whose scattered part reaches a thin sheet only by chance,
// with weights 10³ times the mean.
class ExcitationField {
public:
    virtual ~ExcitationField() = default;
    // (1/4π) × the fluence rate at y of the light of every beam side at this line that has scattered at
    // least once (W/m², as a beam's E in next-event estimation), each side's weighed by coreWeight where y
    // lies in its core and by outsideWeight elsewhere; nullopt where the field does not reach y.
    virtual std::optional<double> scatteredMeanRadiance(const Vec3& y, double lambdaNm, double coreWeight = 1, double outsideWeight = 1) const = 0;
};

// What sampling before a camera path gave each wavelength: a caller that draws part of the path itself
// (a PSF displacement at the hero wavelength) passes the throughput f_j/p_0 and the pdf ratios p_j/p_0
// of that part, so that the tracer's spectral MIS weighs the whole path (pbrt-v4 passes beta and r_u
// into Li). A product of two separately normalized one-sample MIS weights would be biased.
struct PathStart {
    SampledSpectrum beta{1.0}, r_u{1.0};
    const CameraPathImaging* imaging = nullptr;  // none: a plain camera path
    const EmissionLabels* labels = nullptr;      // split the camera path's re-emissions by label (PathRadiance::labelled)
    const ExcitationField* field = nullptr;      // excitation at lines looked up, not traced, where it reaches
    double tMin = 0;                             // > 0 when ray.o lies on a surface the ray leaves
    // A camera path of a render whose light seen through glass spheres is traced from the lights
    // (Integrator::Light, render/light_tracer.h): it leaves out what the photons' connections carry, all
    // its light when its first medium vertex (a scattering, or a fluorescence branch point) lies in the
    // liquid of a stack of shells reached straight from the camera by refraction through every interface of
    // that stack, its fluorescence when its first vertex is an opaque, non-specular surface seen straight
    // from the camera (index-matched interfaces on the way do not matter). docs/model.md, "Fluorescence
    // traced from the lights".
    bool lightTracedFluorescence = false;
    // With it (RenderSettings::mergeRadiusPixels > 0), a camera path that reaches a homogeneous medium through
    // a chain of 1 to kMaxMergedChainEvents smooth dielectric events (reflections or refractions; index-matched
    // crossings and media passed through on the way do not count), other than the connections' refraction
    // into a stack above, leaves out the scatterings and branch points of that medium's segment: photon
    // merging carries them (render/photon_merging.h).
    bool mergedSegments = false;
    // The microscope traces the computed emission's light forward from its points (optics/scattered_emission.h):
    // every branch, of any generation and on any segment, leaves out the beams' light at their lines inside
    // their cores where `imaging` computes the emission (the unscattered light and the excitation field's), and
    // the camera path makes no connections to the computed emission.
    bool computedEmissionTraced = false;
};

// The longest chain of dielectric events before a merged segment (PathStart::mergedSegments). Long, because a
// glass plate guides light by total internal reflection: a vial's 2 mm base or cap takes a camera ray across
// in tens of events, and the light of a longer chain is left to the camera path, which finds it only by
// chance (at 8, such paths were the vials' heaviest samples).
inline constexpr int kMaxMergedChainEvents = 64;

// A camera path's way from the camera into the liquid of a stack of shells by refraction alone, whose first
// free flight there the light tracer's connections carry (PathStart::lightTracedFluorescence). The path
// tracer and photon merging's chain tracer both track it, so that their partitions of the paths match.
struct StackEntry {
    bool open = false;      // still on such a way: no other surface event, no collision yet
    bool inLiquid = false;  // through every interface of the stack: the connections' free flight
    int stack = -1;         // the stack entered (-1 before its outermost interface)
    int crossed = 0;        // its interfaces crossed inward, outermost first
    // A surface of `shape` met: the stack's next interface crossed inward by refraction advances the way;
    // leaving the liquid, or any other surface event, ends it, except an index-matched crossing (the light
    // tracer's transmittance crosses those too).
    void meet(const std::vector<SphericalShells>& shells, uint32_t shape, bool inward, bool indexMatched);
};

// How a sub-path started at a branch point weighs its first vertex's connection to a beam's unscattered
// light where the camera's imaging computes that emission: 0 on the camera path's first segment (the
// caller computes it), the MIS weight after a connection to the computed emission, 1 otherwise.
struct StartBeamWeight {
    const CameraPathImaging* imaging = nullptr;
    double weight = 1;
    // PathStart::computedEmissionTraced: the imaging whose covered emission no branch of this path or its
    // sub-paths counts (null otherwise).
    const CameraPathImaging* traced = nullptr;
};

class PathTracer {
public:
    explicit PathTracer(const Scene& scene);
    // Renders with `lights` instead of the scene's (a microscope channel's lights at one plane): the
    // scene stays untouched and shared. Throws ConfigError if the scene or `lights` has an area light
    // (its shape's index would not match).
    PathTracer(const Scene& scene, std::vector<Light> lights);
    // Radiance arriving along -ray.d at ray.o, for a ray that starts in `medium`.
    PathRadiance radiance(Ray ray, int medium, const SampledWavelengths& wl, Rng& rng, PathStats& stats,
                          const PathStart& start = {}) const;
    // (1/4π)∫ L dω at a point p in `medium`: the mean radiance that excites a dye there, estimated by a
    // path that starts at p in an isotropic direction (as the fluorescence sub-paths do).
    PathRadiance meanRadiance(const Vec3& p, int medium, const SampledWavelengths& wl, Rng& rng, PathStats& stats) const;

    // Transmittance from p0 to p1 through null interfaces and media; zero if a surface blocks. Exact in
    // homogeneous media, a ratio-tracking estimate in grid media: unbiased at every wavelength whose
    // majorant is positive wherever the hero wavelength's is (the hero's free flights sample it).
    // When p0 lies on a surface, pass its normal so the ray leaves it without self-intersection.
    SampledSpectrum transmittance(const Vec3& p0, const Vec3& p1, int medium, const SampledWavelengths& wl, Rng& rng,
                                  const Vec3* surfaceNormal = nullptr, double surfaceEpsilon = 0.0) const;

    // Transmittance along a refracted chain through stack `sh` from p (inside its liquid) through the chain's
    // points to `target` outside it (a light, the camera), as transmittance() gives it segment by segment.
    SampledSpectrum chainTransmittance(const SphericalShells& sh, const Vec3& p, const ShellPath& chain, const Vec3& target,
                                       const SampledWavelengths& wl, Rng& rng) const;

    // Transmittance from p back along a beam (unit `towardSource`) to where it entered the sample.
    SampledSpectrum beamTransmittance(const Vec3& p, const Vec3& towardSource, int medium, const SampledWavelengths& wl, Rng& rng) const;

    const FluorescencePlan& fluorescence() const { return fluorescence_; }
    const std::vector<Light>& lights() const { return lightList_; }
    // The stacks of concentric smooth spheres that chains cross (Integrator::Mnee and Light; else none),
    // and the index of the stack whose innermost sphere holds p in `medium` (-1 if none).
    const std::vector<SphericalShells>& shells() const { return shells_; }
    int shellsAround(const Vec3& p, int medium) const;
    // (1/4π) × the light of the beams at their line λ inside their cores at p: the unscattered light, and with
    // `field` its scattered light too; times fluorescence().kernel, the emission that a microscope computes as
    // its unscattered image where it covers p, and traces forward as scattered emission
    // (optics/scattered_emission.h).
    double coreMeanRadiance(const Vec3& p, int medium, double lineNm, const ExcitationField* field, Rng& rng) const;
    // The beams' spectral lines, each once.
    const std::vector<double>& lineWavelengths() const { return lineWavelengths_; }

private:
    struct PathState;
    // Transmittance with the path pdf ratios of its null collisions (pbrt-v4's T_ray, r_u, r_l).
    struct TransmittanceEstimate {
        SampledSpectrum T, r_u, r_l;
    };
    // With `untilRefraction`, the segment ends at the first smooth dielectric it meets (where a beam
    // entered the sample) instead of being blocked by it. `residual` tracks only what varies above the
    // media's floors (for delta lights and plain transmittance; see ratioTrack).
    TransmittanceEstimate estimateTransmittance(const Vec3& p0, const Vec3& p1, int medium, const SampledWavelengths& wl, Rng& rng,
                                                const Vec3* surfaceNormal, double surfaceEpsilon, bool untilRefraction,
                                                bool residual) const;
    // chainTransmittance with the path pdf ratios of its null collisions.
    TransmittanceEstimate estimateChainTransmittance(const SphericalShells& sh, const Vec3& p, const ShellPath& chain, const Vec3& target,
                                                     const SampledWavelengths& wl, Rng& rng) const;
    // Ratio tracking over [0, length) of r in a grid medium; false once the estimate is zero. `oneLine`: every
    // wavelength is the hero's (a spectral line), so one segment at the medium's largest residual weighs no
    // companion wavelength by more than the hero's majorant.
    bool ratioTrack(const Medium& med, const MediumSpectra& spec, const Ray& r, double length, Rng& rng, TransmittanceEstimate& e,
                    bool residual, bool oneLine) const;
    PathRadiance trace(PathState& state, const SampledWavelengths& wl, Rng& rng, PathStats& stats) const;
    // A path that starts at p in an isotropic direction (a re-emission point) with throughput beta.
    PathRadiance traceFromEmission(const Vec3& p, int medium, const SampledWavelengths& wl, const SampledSpectrum& beta, int depth,
                                   int generation, Rng& rng, PathStats& stats, StartBeamWeight startBeam = {},
                                   const ExcitationField* field = nullptr) const;
    // Radiance re-emitted at p towards the path, at the camera wavelengths, for a branch whose
    // source-term estimate is multiplied by `weight` (throughput over branch pdf, MIS-normalized).
    // With `parts`, also each part's share of the result (partResults[i] for parts[i]).
    SampledSpectrum fluorescence(const Vec3& p, int medium, const double* channels, const SampledWavelengths& wl,
                                 const SampledSpectrum& weight, Rng& rng, PathStats& stats, int generation, int depth,
                                 StartBeamWeight startBeam, const ExcitationField* field, const LabelledChannels* parts = nullptr,
                                 int partCount = 0, SampledSpectrum* partResults = nullptr) const;
    int mediumAfterCrossing(const ShapeInfo& shape, const Vec3& n, const Vec3& dir, int current) const;
    // (1/4π) Σ E T over every side of every beam with a line at λ, at y: the unscattered excitation, the
    // light inside a beam's core weighed by coreWeight and outside it by outsideWeight.
    double unscatteredMeanRadiance(const Vec3& y, int medium, double lambdaNm, double coreWeight, double outsideWeight, Rng& rng) const;
    // The density (1/mm) of fluorescence branch points at a point with these channels, as a free flight in
    // `medium` samples them, averaged over the wavelengths; and the medium's floor extinction there.
    double branchDensityAt(int medium, const double* channels, const SampledWavelengths& wl) const;
    double floorExtinctionAt(int medium, const SampledWavelengths& wl) const;

    const Scene& scene_;
    std::vector<Light> lightList_;
    LightSampler lights_;
    FluorescencePlan fluorescence_;
    bool hasBeams_ = false;  // some light is a beam: the sheet-side strategy runs at its lines
    std::vector<double> lineWavelengths_;  // the beams' spectral lines, each once
    // Integrator::Mnee and Light: the stacks of concentric smooth spherical interfaces.
    std::vector<SphericalShells> shells_;
};

}  // namespace fluorosim

