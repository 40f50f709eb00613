#pragma once
// The ground truth of a stack on the detector grid of each plane: what is there and what a perfect
// microscope would record, to set beside a simulated acquisition (training pairs, or seeing what
// scattering and attenuation did).
//  - concentration: each dye's concentration (mol/L) at the pixel centres of each focal plane;
//  - ideal: the expected photoelectrons of a perfect microscope with this objective, sheets, filters and
//    camera: the computed unscattered image with every transmittance 1 (no attenuation by the media or
//    by the dyes themselves) and no scattered light, no dark current and no noise. The sheet's light
//    beyond its core (e^-8 of its peak irradiance) is left out, as the computed image leaves it.
// Arrays are row-major (dye or channel, z, y, x): x along the focal plane's right = up × axis, y down
// the rows (along -up), z along the axis toward the objective, as the acquired stack.
#include <string>
#include <vector>

#include "optics/acquisition.h"

namespace fluorosim::optics {

struct GroundTruth {
    int width = 0, height = 0, planes = 0;
    std::vector<std::string> dyes;     // dye ids, in the order of `concentration`
    std::vector<float> concentration;  // (dye, z, y, x), mol/L
    std::vector<size_t> channels;      // microscope channel indices, in the order of `ideal`
    std::vector<float> ideal;          // (channel, z, y, x), photoelectrons
};

// Throws ConfigError when no channel excites an emitting dye (no image to compute).
GroundTruth groundTruth(const Scene& scene, const Microscope& microscope, const std::vector<size_t>& channels, const AcquireOptions& options);

// The world position (mm) of the centre of pixel (x, y) of plane `plane`.
Vec3 pixelCentreMm(const Microscope& microscope, int plane, double x, double y);

}  // namespace fluorosim::optics
