#pragma once
// Named tissues for a scene's media (`"tissue": "grey_matter"`): scattering, anisotropy, absorption and
// refractive index from the literature, each with its source (spectra/data/SOURCES.md, "Tissue
// presets"). A medium's own `sigma_a`, `sigma_s`, `g` and `ior` override the preset's.
#include <string>
#include <string_view>
#include <vector>

#include "spectral/tabulated_spectrum.h"

namespace fluorosim {

struct TissuePreset {
    std::string name, description;
    // Reduced scattering μs'(λ) = a (λ / 500 nm)^−b in 1/mm (b = 0: flat), and μs = μs' / (1 − g).
    double reducedScatteringAt500 = 0, powerB = 0;
    double g = 0;
    double absorption = 0;  // 1/mm, flat
    double ior = 1.33;
    bool estimate = false;  // bounds derived from the sources rather than a measurement
    std::string source;

    // μs on 300–1100 nm in 1/mm (1 nm steps: linear interpolation within 3e-6 of the power law).
    TabulatedSpectrum scattering() const;
};

const std::vector<TissuePreset>& tissuePresets();
// The preset of that name, or nullptr.
const TissuePreset* findTissuePreset(std::string_view name);
// "grey_matter, white_matter, ..." for error messages.
std::string tissuePresetNames();

}  // namespace fluorosim
