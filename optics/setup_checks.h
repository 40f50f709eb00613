#pragma once
// Checks of a microscope set-up against its scene before anything is rendered: mistakes that would cost
// minutes or hours of rendering for an image that means nothing (a typo in a unit, a focus off the
// specimen). Each finding names the quantity and its value.
//  - refused (ConfigError): camera rays that would start in a scattering medium that no surface bounds
//    (they random-walk without end);
//  - warned: the objective's front inside a scattering medium (rays start in the specimen), planes whose
//    field meets no dyed shape, a focal plane off the sheet, a sheet far thicker than the depth of field, an
//    exposure that looks like milliseconds written as seconds.
#include <string>
#include <vector>

#include "optics/microscope.h"

namespace fluorosim::optics {

// Throws ConfigError where the result cannot mean anything; returns warnings for `channels` (indices into
// the microscope's channels) with the stack as given.
std::vector<std::string> checkSetup(const Scene& scene, const Microscope& microscope, const std::vector<size_t>& channels);

}  // namespace fluorosim::optics
