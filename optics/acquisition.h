#pragma once
// A simulated light-sheet acquisition: an objective focused on the sheet, an emission filter and a
// camera. Camera paths start at the focal plane point of each pixel (object-space pixel = pitch /
// magnification), in a direction drawn uniformly from the collection cone (half-angle asin(NA/n)),
// and are traced from the objective side (working distance) through the sample, so defocus and the
// collection cone are geometric and physical. The mean radiance becomes expected photoelectrons
// through the real étendue (object pixel area × ∫cone cosθ dω), the exposure, the filter and the QE:
//     e = t · A · ∫cone cosθ ∫ L(λ) T(λ) QE(λ) λ/(hc) dλ dω.
// The in-focus diffraction PSF (Airy, optics/psf.h) displaces each path's focal-plane point; defocus
// stays geometric, so it is not counted twice (docs/optics.md).
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

#include "optics/microscope.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {

// Path: every sample is a full path (the reference). Split: the unscattered light of the beams' cores
// (render/direct_beam.h) gets its own low-variance samples, and paths estimate the rest.
enum class Estimator { Path, Split };
const char* estimatorName(Estimator e);
std::optional<Estimator> estimatorFromName(const std::string& name);

struct AcquireOptions {
    Estimator estimator = Estimator::Split;
    int spp = 16;          // path samples per pixel
    int directSpp = 64;    // samples of the direct part per pixel (split estimator)
    int directPicks = 16;  // transmittance estimates per pixel for the direct part
    // Adaptive sampling to a noise target: each pixel traces as many paths (spp at least, maxSpp at
    // most) as bring its Monte Carlo standard error to `noiseRatio` times the camera's noise of its
    // expected signal, √(signal + dark + read²). The number is decided from `pilotSpp` separate pilot
    // paths that the estimate does not use, so the stopping rule does not bias the mean.
    std::optional<double> noiseRatio;
    int maxSpp = 4096;
    int pilotSpp = 16;
    uint64_t seed = 1;
    int threads = 0;          // 0: all cores
    bool diffraction = true;  // the Airy PSF; off gives the geometric image
    std::function<void(double)> progress;          // fraction of the current plane, from one thread at a time
    const std::atomic<bool>* cancel = nullptr;     // checked between rows; a cancelled plane is incomplete
    void validate() const;                         // ConfigError for spp < 1, negative threads
};

struct PlaneImage {
    int width = 0, height = 0;
    std::vector<double> electrons;  // expected photoelectrons per pixel (signal only, no dark current), row-major from the top
    std::vector<double> stderrElectrons;
    PathStats stats;
    double seconds = 0;
    double largestSample = 0;  // a diagnostic of heavy tails: the largest single path's electrons
    bool complete = true;      // false when cancelled before every row was done
    // Split estimator: the direct part and the paths' part, summed over pixels, and each part's
    // standard error per pixel (diagnostics: which part needs the samples).
    double directElectrons = 0, pathElectrons = 0;
    std::vector<double> directStderr, pathStderr;
    double directSeconds = 0, pathSeconds = 0;  // thread time spent on each part
    // Paths traced for the estimate and for adaptive sampling's pilots (0 without a noise target).
    uint64_t pathSamples = 0, pilotSamples = 0;
};

// Random streams of a plane, keyed by the channel's name (not its position in a filtered list) and
// the plane's index, so that acquiring one channel alone reproduces the full acquisition.
uint64_t planeStreamKey(const std::string& channelName, int plane);

// Expected photoelectrons of one image with the given lights, focal plane, filter and detector.
PlaneImage renderPlane(const Scene& scene, std::vector<Light> lights, const ObjectiveOptions& objective, const FocalPlane& focus,
                       const Filter& emission, const DetectorOptions& detector, int width, int height, uint64_t streamKey,
                       const AcquireOptions& options);
// The same with the scene's own lights, which may include emitting shapes (tests, benchmarks).
PlaneImage renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                       const DetectorOptions& detector, int width, int height, const AcquireOptions& options);

// Plane `plane` of channel `channel`: the channel's lights moved with the focal plane.
PlaneImage acquirePlane(const Scene& scene, const Microscope& microscope, size_t channel, int plane, const AcquireOptions& options);

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

struct StackCallbacks {
    std::function<void(double)> progress;  // fraction of the whole stack
    // Called after each plane is stored (to checkpoint it); planes already done are skipped.
    std::function<void(size_t channelSlot, int plane, const PlaneImage& image)> planeDone;
};
// Renders every plane not yet done, plane-major. Returns false if cancelled (stack holds what finished).
bool acquireStack(const Scene& scene, const Microscope& microscope, Stack& stack, const AcquireOptions& options,
                  const StackCallbacks& callbacks = {});

}  // namespace fluorosim::optics
