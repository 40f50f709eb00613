#pragma once
// What an acquisition reports about itself, accumulated plane by plane: the numbers of `fluorosim
// acquire`'s JSON summary and of the Python result's "summary", and the warnings about the result (a
// plane without signal, a missed noise target, saturated pixels). One place, so that both say the same.
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "optics/acquisition.h"
#include "optics/microscope.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {

class AcquisitionSummary {
public:
    AcquisitionSummary(const Microscope& microscope, const Stack& stack, const AcquireOptions& options);

    // A finished plane. Returns a warning when it holds no signal, else "".
    std::string addPlane(size_t channelSlot, int plane, const PlaneImage& image);

    // One number of the summary: `group` names a nested block ("" at the top), `null` a value that does
    // not apply (a noise target when none was set), `count` an integer.
    struct Entry {
        std::string group, name;
        double value = 0;
        bool null = false, count = false;
    };
    // The summary of the finished stack (after autoExpose, if any), in the CLI's order; the seed (a 64-bit
    // integer), the estimator and the files are the caller's.
    std::vector<Entry> entries(const Stack& stack, const Microscope& microscope, const std::optional<AutoExposure>& exposure, int ranks) const;
    // Warnings about the finished stack: a missed noise target, pixels expecting more than the full well.
    std::vector<std::string> warnings(const Stack& stack, const Microscope& microscope) const;

    // Pixels of the stack expecting more than the full well; of them, those Monte Carlo noise may have lifted
    // there: within 4 standard errors of it, with an error over the camera's own noise of the pixel's signal
    // (sqrt(signal + dark + read²), the project's yardstick). A pixel within 4 errors whose error is under the
    // camera's noise is `borderline`: it expects about the full well by the light the exposure puts there, and
    // the camera's shot noise moves it across the full well from frame to frame more than the Monte Carlo does.
    struct Saturation {
        size_t pixels = 0, monteCarlo = 0, borderline = 0;
        double brightest = 0;
    };
    static Saturation saturation(const Stack& stack, const DetectorOptions& detector);

private:
    AcquireOptions options_;
    double darkElectrons_, readNoise_;
    std::vector<std::string> channelNames_;
    PathStats stats_;
    double seconds_ = 0, largest_ = 0, largestOverPixel_ = 0, computedSum_ = 0, pathSum_ = 0, pooledSum_ = 0, computedSeconds_ = 0, pathSeconds_ = 0;
    std::vector<double> pathRel_;       // relative standard errors over the brightest pixels
    std::vector<double> mcOverCamera_;  // Monte Carlo variance over the camera's noise variance, brightest pixels
    // Over every pixel: the largest Monte Carlo variance over the camera's, and the pixels where it is above 1
    // (Monte Carlo noise above the camera's: specks a viewer sees).
    double mcOverCameraLargest_ = 0;
    uint64_t mcOverCameraAbove1_ = 0;
    uint64_t tracedOverCameraAbove1_ = 0, pathsOverCameraAbove1_ = 0;  // the same by part: the traced photons', the paths'
    uint64_t pathSamples_ = 0, pilotSamples_ = 0, pixels_ = 0, computedPoints_ = 0, nonFinite_ = 0;
    uint64_t pilotsOnLatticeOnlyPlanes_ = 0;
    double computedDropped_ = 0;
    UnscatteredTimings computedTimings_;  // summed over planes
    // The excitation field: photons, seconds, the electrons its scattered light excites (its noise is the
    // budget's first part).
    uint64_t fieldPhotons_ = 0;
    double fieldSeconds_ = 0, fieldSum_ = 0, fieldSpacingUm_ = 0;  // the finest lateral spacing of any plane's field
    double fieldMarginUm_ = 0, fieldReachUm_ = 0;                  // how far the fields reached (the largest)
    double fieldDiffuseSpacingUm_ = 0;                             // their diffuse light's node spacing (the largest)
    uint64_t emissionPhotons_ = 0, emissionVertices_ = 0;
    double emissionSeconds_ = 0, emissionSum_ = 0;
    // The noise budget: each part's own noise variance over the camera's, per pixel, over the brightest 10 %
    // and 1 % of each plane's pixels ([part][0] and [part][1]). The field's and the traced emission's from
    // half the difference of their two halves (one degree of freedom, as two seeds give it), the paths'
    // from their samples' spread.
    enum BudgetPart { kFieldPart, kTracedPart, kPathsPart, kBudgetParts };
    std::array<std::array<std::vector<double>, 2>, kBudgetParts> budget_;
};

}  // namespace fluorosim::optics
