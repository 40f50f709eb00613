#pragma once
// Light-sheet test scenes: AF594 on a grid in scattering tissue (g 0.9, n 1.33) filling a water-index bath,
// lit by a 561 nm sheet of 1 mW along x through the origin.
#include <memory>
#include <vector>

#include "optics/light_sheet.h"
#include "support/fluorescent_scenes.h"
#include "volume/volume_fields.h"

namespace fluorosim::testing {

// A scene of 450–750 nm whose tissue (medium 0, σs /mm) holds AF594 at `micromolar` (µM), in a bath of
// half-width 0.4 mm.
inline Scene af594Tissue(const DensityGrid& micromolar, double sigmaS) {
    Scene scene;
    scene.spectral.lambdaMin = 450;
    scene.spectral.lambdaMax = 750;
    std::vector<VolumeChannel> ch(3);
    ch[kSolventChannel].offset = 1;
    ch[kScatteringChannel].offset = 1;
    ch[kFirstDyeChannel].grid = micromolar;
    ch[kFirstDyeChannel].scale = 1e-6;
    auto volume = std::make_shared<const VolumeFields>(std::move(ch), Affine(), Interpolation::Trilinear, MajorantGridOptions{});
    scene.media.emplace_back("tissue", Spectrum::constant(0.0), Spectrum::constant(sigmaS), 0.9, 1.33,
                             std::vector<DyeComponent>{{databaseDye("AF594"), 0.0}}, volume);
    addBath(scene, 0.4, 0);
    return scene;
}

// Adds the 561 nm sheet (waist and height in mm), puts the camera in medium 0 and finalizes the scene.
inline void addSheetAndFinalize(Scene& scene, double waistMm, double heightMm) {
    LightSheetSpec spec;
    spec.wavelengthNm = 561;
    spec.powerMw = 1;
    spec.waistMm = waistMm;
    spec.heightMm = heightMm;
    spec.refractiveIndex = 1.33;
    scene.lights.push_back(BeamLight{optics::makeLightSheet(spec), spec});
    scene.camera.medium = 0;
    scene.finalize();
}

}  // namespace fluorosim::testing
