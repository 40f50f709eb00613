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
#include <cstdint>
#include <functional>
#include <vector>

#include "optics/detector.h"
#include "optics/filter.h"
#include "scene/scene.h"

namespace fluorosim::optics {

struct ObjectiveOptions {
    double na = 0.8;
    double magnification = 16;
    double immersionIndex = 1.33;
    double workingDistanceMm = 1.0;  // where camera paths start, in front of the focal plane
    void validate() const;           // NA < immersion index, positive values; ConfigError naming them
    double collectionHalfAngle() const;  // asin(NA / n)
};

struct FocalPlane {
    Vec3 centreMm;              // of the field of view, in focus
    Vec3 towardObjective{0, 0, 1};  // unit axis from the sample to the objective
    Vec3 up{0, 1, 0};           // image rows run along -up
};

struct PlaneRenderOptions {
    int width = 64, height = 64;
    int spp = 16;
    uint64_t seed = 1;
    uint64_t planeKey = 0;  // keys the random streams so every plane is independent and reproducible
    int threads = 0;
    bool diffraction = true;  // the Airy PSF; off gives the geometric image
    std::function<void(double)> progress;
};

struct PlaneResult {
    std::vector<double> electrons;  // expected photoelectrons per pixel (signal only, no dark current)
    std::vector<double> stderrElectrons;
    uint64_t paths = 0;
    double seconds = 0;
    double largestSample = 0;  // a diagnostic of heavy tails: the largest single path's electrons
};

// Expected photoelectrons of one image (row-major from the top) with the given filter and detector.
PlaneResult renderPlane(const Scene& scene, const ObjectiveOptions& objective, const FocalPlane& focus, const Filter& emission,
                        const DetectorOptions& detector, const PlaneRenderOptions& options);

}  // namespace fluorosim::optics
