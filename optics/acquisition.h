#pragma once
// A simulated light-sheet acquisition: an objective focused on the sheet, an emission filter and a
// camera. Every estimator images through one operator (optics/imaging.h): object pixels of pitch /
// magnification, the collection cone (half-angle asin(NA/n)), the 3-D diffraction PSF and the real
// étendue, so that mean radiance becomes expected photoelectrons through the exposure, the filter and
// the QE:  e = t · A · ∫cone cosθ ∫ L(λ) T(λ) QE(λ) λ/(hc) dλ dω.
//
// Estimators (docs/model.md, "The computed image"):
//  - Split (the default): the unscattered image (fluorescence excited by the beams' unscattered light in
//    their cores, reaching the objective unscattered) is computed by quadrature (optics/unscattered_image.h,
//    no variance), and camera paths estimate the rest, leaving that part out.
//  - Path: camera paths estimate everything (the reference).
// Camera paths start at a point of the pixel displaced by the in-focus PSF, cross the focal plane from
// a direction of the cone and are weighted at their first vertex so that they image through the 3-D PSF.
//
// Layers: renderPlane renders one image for given lights and focal plane; acquirePlane does it for a
// microscope's channel and plane; acquireStack runs the z-stack (plane-major, so an interrupted run
// holds whole planes) and hands each finished plane to the caller. Nothing here prints or exits.
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "optics/imaging.h"
#include "optics/microscope.h"
#include "optics/scattered_emission.h"
#include "optics/unscattered_image.h"
#include "render/fluence_field.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {

// Path: every sample is a full path (the reference). Split: the unscattered image is computed and paths
// estimate the rest.
enum class Estimator { Path, Split };
const char* estimatorName(Estimator e);
std::optional<Estimator> estimatorFromName(const std::string& name);

// The scattered excitation as a field (render/fluence_field.h, docs/model.md "The excitation field"), with
// the split estimator: traced per plane and beam line side over the computed region, out to `halfDepthUm`
// from the focal plane; the computed image adds the dye it excites there, and paths look it up instead of
// tracing excitation sub-paths wherever it reaches.
struct ExcitationFieldOptions {
    uint64_t photons = 200000;  // per beam line side and plane; 0: the paths estimate the scattered excitation
    // Node spacing along the focal plane; 0 (the default) chooses it: 16 or 8 um where the sheets' light per
    // unit height is flat over the box and that spacing is at most a tenth of the scattering length, else 4 um
    // (docs/model.md, "The excitation field").
    double lateralUm = 0;
    double axialUm = 0.5;       // node spacing along the axis (across a light sheet)
    double halfDepthUm = 20;    // how far from the focal plane it reaches (at least the computed region)
    // How far beyond the computed region it reaches along the focal plane. There the traced photons carry the
    // emission the sheets excite, which reaches the image only by scattering: the camera paths would find it
    // by chance, with the sheet's irradiance as weight (docs/model.md, "The excitation field"). Unset: chosen
    // from the tissue (fieldReachMm), as is reachUm.
    std::optional<double> marginUm;
    // Beyond halfDepthUm it reaches out to reachUm from the focal plane, and beyond the region out to the
    // margin, on far nodes: the light that excites the dye the objective sees out of focus or only after
    // scattering, which the camera paths would otherwise find by sub-paths that reach the sheet by chance.
    std::optional<double> reachUm;
    double coarseAxialUm = 4, coarseLateralUm = 16;  // the far nodes' spacing (laterally at least lateralUm's)
    // The node spacing of the diffuse light (photons that have scattered kDiffuseAfterScatterings times), over
    // the whole reach: it varies on the scale of the transport length 1 / μs', not the sheet's waist. Unset:
    // a tenth of the tissue's transport length, within [4, 50] um (fieldDiffuseSpacingMm); 0: no diffuse grid.
    std::optional<double> diffuseUm;
    void validate() const;      // ConfigError naming the option and value
};

struct AcquireOptions {
    Estimator estimator = Estimator::Split;
    ExcitationFieldOptions field;
    // The computed emission's scattered light traced forward from its points (optics/scattered_emission.h;
    // split estimator, scenes without refracting surfaces); photons 0 leaves it to the camera paths.
    ScatteredEmissionOptions emission;
    int spp = 16;                    // path samples per pixel
    UnscatteredOptions unscattered;  // the quadrature of the computed part (split)
    // Light imaged through a first vertex far from focus (its image a disc of radius ρ pixels) is pooled
    // over blocks of 2^k pixels with 2^k <= poolingFraction × ρ; 0 images everything per pixel.
    double poolingFraction = 0.25;
    PsfTableOptions psf;             // the PSF's cut and table resolution
    // Adaptive sampling to a noise target: each pixel traces as many paths (spp at least, maxSpp at
    // most) as bring its Monte Carlo standard error to `noiseRatio` times the camera's noise of its
    // expected signal, √(signal + dark + read²). The number is decided from separate pilot paths that the
    // estimate does not use, so the stopping rule does not bias the mean: `firstPilotSpp` of them, and
    // `pilotSpp` in all where those ask for more than spp (with the field and the traced emission the paths
    // hold little of the noise, and 16 pilots a pixel cost eight times the paths they decided on). A lattice
    // of every fourth pixel draws its first pilots before the rest; the other pixels draw pilots only in the
    // lattice's cells with a corner that asks for more than spp (the rest trace spp). Not at spp 1, where a
    // pixel's own path says nothing of its spread.
    std::optional<double> noiseRatio;
    int maxSpp = 4096;
    int firstPilotSpp = 4, pilotSpp = 16;
    uint64_t seed = 1;
    // Tally the paths' re-emissions by label (PlaneImage::labelledElectrons, `labelCount` keys), pooled as
    // the total is: for fits of the scattered light. The scattered emission is then left to the paths (the
    // traced photons are not split by label).
    const EmissionLabels* labels = nullptr;
    int labelCount = 0;
    int threads = 0;  // 0: all cores
    std::function<void(double)> progress;          // fraction of the current plane, from one thread at a time
    const std::atomic<bool>* cancel = nullptr;     // checked between rows; a cancelled plane is incomplete
    void validate() const;                         // ConfigError naming the option and value
};

struct PlaneImage {
    int width = 0, height = 0;
    std::vector<double> electrons;  // expected photoelectrons per pixel (signal only, no dark current), row-major from the top
    std::vector<double> stderrElectrons;  // Monte Carlo standard error (the computed part has none)
    PathStats stats;
    double seconds = 0;
    bool complete = true;  // false when cancelled before every row was done
    // Split estimator: the computed part and the paths' part, summed over pixels, and the time of each.
    double computedElectrons = 0, pathElectrons = 0;
    double pooledElectrons = 0;  // of the paths' part, what was pooled over pixel blocks (far from focus)
    double computedSeconds = 0, pathSeconds = 0;  // wall time of the computed part, thread time of the paths
    uint64_t computedPoints = 0;                  // emission points of the computed part's quadrature
    double computedDroppedFraction = 0;           // the faintest points' share left out of its projection
    UnscatteredTimings computedTimings;           // where the computed part's time went
    std::vector<double> computedImage;            // the computed part alone (split estimator; empty otherwise)
    // The excitation field (split estimator with a field): its photons and time over the plane's beam line
    // sides, the computed electrons its scattered light excites, and per pixel half the difference of that
    // part's images from the field's two halves: its square estimates the part's variance at the pixel, the
    // square of its sum over a region that of the region's sum (noise correlated across pixels, which
    // stderrElectrons does not hold).
    uint64_t fieldPhotons = 0;
    double fieldSeconds = 0, fieldElectrons = 0;
    double fieldLateralSpacingUm = 0;  // the node spacing along the focal plane (0: no field)
    double fieldMarginUm = 0, fieldReachUm = 0;  // how far it reaches beyond the computed region and from focus
    double fieldDiffuseSpacingUm = 0;            // its diffuse light's node spacing (0: none)
    std::vector<double> fieldHalfDifference;
    // The computed emission's scattered light traced forward (AcquireOptions::emission): its photons, their
    // vertices imaged, its time and its photoelectrons summed over pixels (in `electrons`, its variance in
    // stderrElectrons).
    uint64_t emissionPhotons = 0, emissionVertices = 0;
    double emissionSeconds = 0, emissionElectrons = 0;
    std::vector<double> emissionVariance;                 // per pixel (part of stderrElectrons²)
    std::vector<std::vector<double>> emissionEstimates;   // independent estimates of its image (ScatteredEmissionImage::slots)
    std::vector<std::vector<double>> labelledElectrons;  // with AcquireOptions::labels: per key, the paths' re-emissions per pixel
    // Paths traced for the estimate and for adaptive sampling's pilots (0 without a noise target).
    uint64_t pathSamples = 0, pilotSamples = 0;
    // Adaptive sampling found that the paths meet the target at spp on its whole pilot lattice, and drew no
    // other pilots (AcquireOptions::noiseRatio).
    bool pilotsOnLatticeOnly = false;
    // Heavy tails: the largest single path's electrons, the largest ratio of a pixel's largest path
    // sample to its value, and samples dropped for not being finite.
    double largestSample = 0, largestSampleOverPixel = 0;
    uint64_t nonFiniteSamples = 0;
};

// Random streams of a plane, keyed by the channel's name (not its position in a filtered list) and
// the plane's index, so that acquiring one channel alone reproduces the full acquisition.
uint64_t planeStreamKey(const std::string& channelName, int plane);

// What the planes of one channel share: the PSFs of its planes (makePlanePsfs: one per group of planes
// whose pupils agree within the PSF's depth tolerance) and the computed part's model (built only for the
// split estimator, and null when nothing is computed).
struct ChannelImaging {
    std::shared_ptr<const WidefieldPsf> psf;  // at the plane nearest the reference focus
    Vec3 focusMm, axis;                       // the reference focus and the axis toward the objective
    std::vector<double> planeOffsetsMm;
    std::vector<std::shared_ptr<const WidefieldPsf>> planePsfs;  // per plane offset
    std::shared_ptr<const UnscatteredModel> unscattered;
    // The PSF of the stack's plane at `focus` (`psf` for a focus that is not one of its planes).
    const std::shared_ptr<const WidefieldPsf>& psfAt(const FocalPlane& focus) const;
};
// Builds it for lights and a focal plane (any plane of the stack; the central one is used by acquireStack).
// `planeOffsetsMm`: the stack's planes along the axis from `focus` (the computed part's lattice serves them all).
ChannelImaging setUpChannelImaging(const Scene& scene, const std::vector<Light>& lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                                   const Filter& emission, const DetectorOptions& detector, int width, int height, const AcquireOptions& options,
                                   std::vector<double> planeOffsetsMm = {0.0}, bool labels = false);

// The plane's excitation field (render/fluence_field.h) over the computed region and out to the options'
// depth, traced with the plane's stream key: null when options.field.photons is 0, when the tracer's
// lights hold no beam line, or when nothing in the scene scatters at its lines.
std::unique_ptr<const BeamExcitationField> traceExcitationField(const Scene& scene, const PathTracer& tracer, const Imaging& imaging,
                                                               const UnscatteredModel& model, const AcquireOptions& options, uint64_t streamKey);

// Expected photoelectrons of one image with the given lights, focal plane, filter and detector. Without
// `channel`, the PSF and the computed part's model are built for this plane alone.
PlaneImage renderPlane(const Scene& scene, std::vector<Light> lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                       const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                       const AcquireOptions& options, const ChannelImaging* channel = nullptr);
// The same with the scene's own lights, which may include emitting shapes (tests, benchmarks).
PlaneImage renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                       const DetectorOptions& detector, int width, int height, const AcquireOptions& options);

// The channel's shared imaging for a microscope (its lights and focal plane at the stack's centre).
// With `labels`, the computed part's lattice is split by label (for fits).
ChannelImaging setUpChannelImaging(const Scene& scene, const Microscope& microscope, size_t channel, const AcquireOptions& options,
                                   bool labels = false);
// Plane `plane` of channel `channel`: the channel's lights moved with the focal plane.
PlaneImage acquirePlane(const Scene& scene, const Microscope& microscope, size_t channel, int plane, const AcquireOptions& options,
                        const ChannelImaging* imaging = nullptr);

// A z-stack in memory, channel-major (CZYX), as written to OME-TIFF.
struct Stack {
    int width = 0, height = 0, planes = 0;
    std::vector<size_t> channels;       // indices into the microscope's channels
    std::vector<float> expected;        // expected electrons with dark current, before noise
    std::vector<float> stderrElectrons; // Monte Carlo standard error of `expected`
    std::vector<uint16_t> counts;       // one noisy read-out in ADU
    std::vector<bool> done;             // per (channel, plane): acquired
    size_t index(size_t c, int plane) const { return c * static_cast<size_t>(planes) + static_cast<size_t>(plane); }
    size_t pixelOffset(size_t c, int plane) const { return index(c, plane) * static_cast<size_t>(width) * height; }
    // Planes 0 .. n-1 are done for every channel.
    int completePlanes() const;
};

Stack emptyStack(const Microscope& microscope, std::vector<size_t> channels);
// Stores a rendered plane: adds dark current, reads it out through the detector with its own stream.
void storePlane(Stack& stack, const Microscope& microscope, size_t channelSlot, int plane, const PlaneImage& image, uint64_t seed);

// The exposure chosen after the fact, as a careful experimenter sets it: every photoelectron scales with
// the exposure (the sheets' energy and the dark current), so a stack acquired at one exposure is exactly
// that stack at another, its planes re-read with their own noise streams. The brightest pixel is the
// largest expected signal (dark excluded) among pixels whose standard error is at most a quarter of it,
// so that a rare large Monte Carlo sample does not set the exposure (the plain largest if none is).
struct AutoExposure {
    double fraction = 0;            // of the full well, asked for
    double factor = 0;              // new exposure / old
    double exposureS = 0;           // the new exposure
    double brightestElectrons = 0;  // the brightest pixel's expected signal before scaling
};
// Scales the done planes of `stack` and sets microscope.detector.exposureS. Throws ConfigError for a
// fraction outside (0, 1] or a stack without signal.
AutoExposure autoExpose(Stack& stack, Microscope& microscope, double fraction, uint64_t seed);

struct StackCallbacks {
    std::function<void(double)> progress;  // fraction of the whole stack
    // Called after each plane is stored (to checkpoint it); planes already done are skipped.
    std::function<void(size_t channelSlot, int plane, const PlaneImage& image)> planeDone;
};
// Renders every plane not yet done, plane-major. Returns false if cancelled (stack holds what finished).
bool acquireStack(const Scene& scene, const Microscope& microscope, Stack& stack, const AcquireOptions& options,
                  const StackCallbacks& callbacks = {});

}  // namespace fluorosim::optics
