#include "scene/tissue_presets.h"

#include <cmath>

namespace fluorosim {

TabulatedSpectrum TissuePreset::scattering() const {
    std::vector<double> lambda, value;
    for (double l = 300; l <= 1100; l += 1) {
        lambda.push_back(l);
        value.push_back(reducedScatteringAt500 * std::pow(l / 500, -powerB) / (1 - g));
    }
    return TabulatedSpectrum(std::move(lambda), std::move(value), "tissue preset " + name);
}

const std::vector<TissuePreset>& tissuePresets() {
    // μs' a and b, g, μa (1/mm), n, estimate, source. Sources in spectra/data/SOURCES.md, "Tissue presets".
    static const std::vector<TissuePreset> presets = {
        {"grey_matter", "rodent cortex, perfused (no blood)", 2.42, 1.611, 0.88, 0.02, 1.365, false,
         "mu_s': Jacques 2013 (brain average); g 0.86-0.90 and mu_s 18-25 /mm at 488 nm cross-checked by Yona et al. 2016; mu_a of "
         "perfused tissue an estimate; n: Binding et al. 2011"},
        {"white_matter", "rodent white matter (corpus callosum), perfused", 15.0, 0.0, 0.85, 0.07, 1.42, true,
         "mu_s 50-150 /mm and g 0.8-0.9 (Taddeucci et al. 1996, estimate: mu_s 100); mu_a: human white matter at 670 nm; n: about 4 % "
         "above cortex (Sun et al. 2012)"},
        {"cleared_clarity", "CLARITY-cleared brain in RIMS", 0.1, 0.0, 0.9, 0.0, 1.46, true,
         "n: RIMS about 1.46; mu_s about 1 /mm (estimate from the transparency of cleared brains: 1-3 /mm in white matter)"},
        {"cleared_cubic", "CUBIC-cleared brain in CUBIC-R", 0.1, 0.0, 0.9, 0.0, 1.52, true,
         "n: CUBIC-R about 1.52; mu_s about 1 /mm (estimate, as for CLARITY)"},
        {"cleared_idisco", "iDISCO-cleared brain in DBE (BABB alike)", 0.05, 0.0, 0.9, 0.0, 1.56, true,
         "n: DBE and BABB about 1.56; mu_s below about 0.5 /mm after solvent clearing (estimate)"},
        {"zebrafish_larva", "unpigmented zebrafish larva (brain)", 0.35, 0.0, 0.93, 0.0, 1.36, true,
         "mu_s 2-10 /mm, g 0.9-0.97 (estimate: mu_s 5, g 0.93; Favre-Bulle et al. 2015); n: soft tissue about 1.36 (no larva measurement "
         "found)"},
    };
    return presets;
}

const TissuePreset* findTissuePreset(std::string_view name) {
    for (const TissuePreset& p : tissuePresets())
        if (p.name == name) return &p;
    return nullptr;
}

std::string tissuePresetNames() {
    std::string out;
    for (const TissuePreset& p : tissuePresets()) out += (out.empty() ? "" : ", ") + p.name;
    return out;
}

}  // namespace fluorosim
