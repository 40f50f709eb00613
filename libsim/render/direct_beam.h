#pragma once
// The unscattered light of beams (light sheets) along camera rays, estimated with low variance: the
// part of the transport that a microscope's image is mostly made of. Along a camera ray's first
// straight segment (through null interfaces, before any surface), every point y inside a beam's core
// contributes, per unit length,
//   fluorescence:  K(λx -> λ; c(y)) / (4π) · E(y, λx) · T_beam(y, λx) · T_camera(y, λ)
//   elastic:       σs(y, λx) · p(beam -> camera) · E(y, λx) · T_beam(y, λx) · T_camera(y, λx)
// with E the unattenuated irradiance of one beam side and line, T_beam the transmittance back along
// the beam to where it entered the sample and T_camera that from the ray's origin to y. The integral
// along each core is estimated with stratified points from the beam's own proposal (the Gaussian
// across a sheet). The transmittances are nearly the same for every point of a pixel, so they are
// estimated at a few points picked in proportion to the rest of the integrand, which keeps the estimate
// unbiased. The path tracer, with PathStart::directBeamsSeparate, leaves exactly these contributions
// out (docs/model.md, "Split estimator"), so the sum of both is the full model.
#include <functional>
#include <vector>

#include "render/beam_core.h"
#include "render/path_tracer.h"

namespace fluorosim {

class DirectBeamEstimator {
public:
    // `detection(λ)` weighs radiance at λ in the caller's measurement (a filter, a QE, λ/hc); the
    // estimates are of ∫ detection(λ) L(λ) dλ. `tracer` supplies the lights and the transmittances and
    // must outlive the estimator.
    DirectBeamEstimator(const Scene& scene, const PathTracer& tracer, std::function<double(double)> detection);

    // False when no light is a beam with a spectral line (then every estimate is 0).
    bool active() const { return !lines_.empty(); }

    // A spectral part of the direct light, chosen first so that the caller can draw wavelength-
    // dependent optics (the PSF) at its wavelength: the fluorescence at a camera wavelength, or the
    // elastic light of one beam line. `weight` is 1/pdf (per nm for fluorescence, per mass for a line).
    struct Component {
        double lambdaNm = 0;
        double weight = 0;
        int elasticLine = -1;  // index into the lines, or -1 for fluorescence
    };
    Component sampleComponent(double u) const;

    // The points of one pixel's samples, before transmittances.
    struct Point {
        CorePoint core;
        Vec3 origin;  // of the camera ray
        int cameraMedium;
        double cameraLambda;
    };
    struct Pixel {
        std::vector<Point> points;
        double sum = 0, sum2 = 0;  // of the samples' transmittance-free estimates
        int samples = 0;
        std::vector<CorePoint> scratch;  // one sample's core points, reused across samples
    };
    // Adds one sample: a camera ray starting in `medium`, a component, the shift of its stratified
    // points, and `scale` (what the caller multiplies the radiance by, e.g. the étendue).
    void addSample(Pixel& pixel, const Ray& ray, int medium, const Component& component, double uPoints, double scale) const;

    struct Estimate {
        double mean = 0, variance = 0;  // of the pixel's mean over its samples
    };
    // Estimates the transmittances at `picks` points drawn in proportion to their weights
    // (systematically, from uPick) and returns the pixel's estimate.
    Estimate finish(const Pixel& pixel, int picks, double uPick, Rng& rng) const;

private:
    const Scene& scene_;
    const PathTracer& tracer_;
    std::function<double(double)> detection_;
    std::vector<BeamLine> lines_;
    double fluorescenceProbability_ = 0;
    std::vector<double> lineMass_;                // elastic component probability per line
    double lambdaMin_ = 0, cellWidth_ = 1;
    std::vector<double> cellPdf_, cellCdf_;       // the fluorescence camera wavelength (per nm)
};

}  // namespace fluorosim
