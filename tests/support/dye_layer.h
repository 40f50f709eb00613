#pragma once
// The photon budget of a thin uniform dye layer in the focal plane under a known static sheet, in closed
// form, for the tests that check the microscope's energy (photon budget, index-mismatched samples, the
// ground truth): absorbed photons (σa E / (hc/λx)) × Φ × collection fraction × ∫ f(λ) T(λ) QE dλ ×
// object pixel area × exposure, summed over the pixel centres of a size × size field.
#include <cmath>

#include "media/fluorophore.h"
#include "optics/acquisition.h"
#include "optics/filter.h"
#include "optics/light_sheet.h"
#include "scene/beam.h"
#include "scene/scene.h"
#include "support/fluorescent_scenes.h"

namespace fluorosim::testing {

struct DyeLayer {
    Fluorophore dye;
    double molar = 1e-4;        // mol/L
    double thicknessMm = 0.001;
    double halfWidthMm = 0.05;  // the sheet enters the layer at x = -halfWidth
};

struct LayerCamera {
    double pixelMm = 6.5e-3 / 16;
    int size = 16;
    double exposureS = 0.01;
    double qe = 0.8;
    double collection = 0;  // the fraction of 4π the objective collects (with whatever Fresnel loss applies)
};

// The layer as a box (2 halfWidth wide, centred on the focal plane) of a medium holding its dye at
// `molar` over constant coefficients (1/mm) and index, inside medium `outside`. Returns the layer's medium.
inline int addDyeLayer(Scene& scene, const DyeLayer& layer, int outside, double sigmaA, double sigmaS, double g, double ior) {
    scene.media.emplace_back("layer", Spectrum::constant(sigmaA), Spectrum::constant(sigmaS), g, ior,
                             std::vector<DyeComponent>{{layer.dye, layer.molar}});
    const int medium = static_cast<int>(scene.media.size()) - 1;
    const double h = layer.halfWidthMm, d = layer.thicknessMm;
    addMediumBox(scene, Vec3(-h, -h, -d / 2), Vec3(h, h, d / 2), medium);
    scene.shapes.back().outsideMedium = outside;
    return medium;
}

// The layer's sheet: 488 nm, 1 mW, a waist of 10 µm (ten times the layer: nearly flat across it; the
// closed form integrates it exactly), 1 mm high, in a medium of `index`; added to the scene's lights.
inline std::shared_ptr<BeamProfile> addLayerSheet(Scene& scene, double index) {
    LightSheetSpec spec;
    spec.wavelengthNm = 488;
    spec.powerMw = 1;
    spec.waistMm = 0.01;
    spec.heightMm = 1;
    spec.refractiveIndex = index;
    auto sheet = optics::makeLightSheet(spec);
    scene.lights.push_back(BeamLight{sheet, spec});
    return sheet;
}

// The part of a uniform layer's image that the computed image leaves out by design: the PSF's tail beyond
// its cut (a fraction `tail` of each point's light, spread as tail · vCut / (2π kNA r³) per mm² beyond the
// cut radius; docs/model.md) from dye beyond the computed region, the field with `marginPixels` on each
// side. A pixel at p misses tail · vCut / (2π kNA) ∫ dφ / r_edge(φ), r_edge the distance from p to the
// region's edge in direction φ; averaged over the field's pixel centres (midpoint rule in φ).
inline double layerTailLeftOut(double tail, double vCut, double knaPerMm, const LayerCamera& camera, int marginPixels) {
    const double half = (0.5 * camera.size + marginPixels) * camera.pixelMm;
    const int angles = 720;
    double sum = 0;
    for (int y = 0; y < camera.size; ++y)
        for (int x = 0; x < camera.size; ++x) {
            const double px = (x + 0.5 - 0.5 * camera.size) * camera.pixelMm, py = (y + 0.5 - 0.5 * camera.size) * camera.pixelMm;
            double inverse = 0;
            for (int a = 0; a < angles; ++a) {
                const double phi = 2 * kPi * (a + 0.5) / angles, c = std::cos(phi), s = std::sin(phi);
                const double rx = c > 0 ? (half - px) / c : (-half - px) / c, ry = s > 0 ? (half - py) / s : (-half - py) / s;
                inverse += 1 / std::min(rx, ry);
            }
            sum += tail * vCut / (2 * kPi * knaPerMm) * inverse * 2 * kPi / angles;
        }
    return sum / (camera.size * camera.size);
}

// The fraction of a uniform layer's closed form that the channel's computed image keeps: all but the tail
// its region leaves out (layerTailLeftOut), with the tail's mass from the channel's own PSF table (Parseval:
// 1 − enclosed, averaged over the layer's thickness at `lambdaNm`; widefield_psf_test checks the table).
inline double layerImageKept(const optics::ChannelImaging& imaging, const DyeLayer& layer, double lambdaNm, const LayerCamera& camera) {
    const optics::WidefieldPsf& psf = *imaging.psf;
    const int n = 20;
    double enclosed = 0;
    for (int k = 0; k < n; ++k) enclosed += psf.enclosed(layer.thicknessMm * ((k + 0.5) / n - 0.5), lambdaNm) / n;
    const double kna = 2 * kPi / (lambdaNm * 1e-6) * psf.pupil().na;
    return 1 - layerTailLeftOut(1 - enclosed, psf.table().vCut, kna, camera, imaging.unscattered->geometry().marginPixels);
}

// `attenuated`: the sheet loses light in the layer from where it entered (Beer–Lambert); a perfect
// microscope's image leaves that out. The emission spectrum is integrated on 450-750 nm.
inline double layerElectrons(const DyeLayer& layer, const BeamProfile& sheet, double excitationNm, const optics::Filter& filter,
                             const LayerCamera& camera, bool attenuated) {
    constexpr double hc = 1.98644586e-16;  // J nm
    const double sigmaX = dyeAbsorption(layer.dye, excitationNm, layer.molar), d = layer.thicknessMm;
    double spectral = 0;
    for (double l = 450; l < 750; l += 0.05) spectral += layer.dye.emissionPdf(l + 0.025) * filter.transmission(l + 0.025) * camera.qe * 0.05;
    double expected = 0;
    for (int y = 0; y < camera.size; ++y)
        for (int x = 0; x < camera.size; ++x) {
            const Vec3 p((x + 0.5 - 0.5 * camera.size) * camera.pixelMm, (0.5 * camera.size - y - 0.5) * camera.pixelMm, 0);
            // Mean irradiance through the layer's thickness (midpoint rule, 200 slices).
            double e = 0;
            for (int k = 0; k < 200; ++k) e += sheet.irradiance(p + Vec3(0, 0, -d / 2 + (k + 0.5) * d / 200), 0, excitationNm) / 200;
            if (attenuated) e *= std::exp(-sigmaX * (p.x + layer.halfWidthMm));
            const double absorbedPhotons = sigmaX * d * e / (hc / excitationNm);  // per s per mm²
            expected += absorbedPhotons * layer.dye.quantumYield() * camera.collection * spectral * camera.pixelMm * camera.pixelMm * camera.exposureS;
        }
    return expected;
}

}  // namespace fluorosim::testing
