#include "viewer/microscope_overlay.h"

#include <algorithm>
#include <cmath>

#include "optics/light_sheet.h"
#include "viewer/specimen.h"

namespace fluorosim::viewer {

Vec3 FieldOfView::pixelCentreUm(double x, double y) const {
    // The acquisition's convention (optics/acquisition.cpp): columns along right, rows along -up.
    return centreUm + right * ((x + 0.5 - 0.5 * width) * pixelUm) + up * ((0.5 * height - y - 0.5) * pixelUm);
}

double SheetEnvelope::halfWidthUm(double xUm) const {
    return waistUm * std::sqrt(1 + (xUm / rayleighUm) * (xUm / rayleighUm));
}

MicroscopeOverlay::MicroscopeOverlay(const Scene& scene, const optics::Microscope& microscope, int planes, double stepUm)
    : scene_(scene), microscope_(microscope), planes_(planes), stepUm_(stepUm) {
    microscope_.stack = {planes, stepUm / kUmPerMm};
    for (const optics::MicroscopeChannel& c : microscope.channels)
        for (size_t l : c.lights) {
            const auto* beam = std::get_if<BeamLight>(&scene.lights.at(l));
            if (!beam || beam->spec.widefield || !dynamic_cast<const optics::LightSheet*>(beam->profile.get())) continue;
            if (std::find(sheetLights_.begin(), sheetLights_.end(), l) == sheetLights_.end()) sheetLights_.push_back(l);
        }
}

double MicroscopeOverlay::offsetUm(int plane) const { return microscope_.planeOffsetMm(plane) * kUmPerMm; }

FieldOfView MicroscopeOverlay::fieldOfView(int plane) const {
    const optics::FocalPlane f = microscope_.focalPlaneAt(microscope_.planeOffsetMm(plane));
    FieldOfView v;
    v.towardObjective = f.axis();
    v.right = f.right();
    v.up = f.imageUp();
    v.centreUm = f.centreMm * kUmPerMm;
    v.pixelUm = microscope_.pixelSizeMm() * kUmPerMm;
    v.width = microscope_.width;
    v.height = microscope_.height;
    const Vec3 halfW = v.right * (0.5 * v.width * v.pixelUm), halfH = v.up * (0.5 * v.height * v.pixelUm);
    v.cornersUm = {v.centreUm - halfW + halfH, v.centreUm + halfW + halfH, v.centreUm + halfW - halfH, v.centreUm - halfW - halfH};
    return v;
}

CollectionCone MicroscopeOverlay::cone(int plane) const {
    const FieldOfView v = fieldOfView(plane);
    return {v.centreUm, v.towardObjective, microscope_.objective.collectionHalfAngle(),
            microscope_.objective.workingDistanceMm * kUmPerMm};
}

std::vector<SheetEnvelope> MicroscopeOverlay::sheets(int plane) const {
    std::vector<SheetEnvelope> out;
    const Vec3 axis = normalize(microscope_.focus.towardObjective);
    const double offsetMm = microscope_.planeOffsetMm(plane);
    for (size_t l : sheetLights_) {
        const auto& beam = std::get<BeamLight>(scene_.lights[l]);
        const auto& sheet = dynamic_cast<const optics::LightSheet&>(*beam.profile);
        SheetEnvelope e;
        e.u = sheet.propagationAxis();
        e.n = sheet.normalAxis();
        e.h = sheet.heightAxis();
        // Microscope::lightsAt moves a sheet along its normal by the plane offset's component on it.
        e.centreUm = (sheet.centre() + e.n * (offsetMm * dot(e.n, axis))) * kUmPerMm;
        e.lambdaNm = sheet.options().wavelengthNm.value_or(500.0);
        e.waistUm = sheet.waistMm(e.lambdaNm) * kUmPerMm;
        e.rayleighUm = sheet.rayleighRangeMm(e.lambdaNm) * kUmPerMm;
        e.heightUm = sheet.options().heightMm * kUmPerMm;
        e.dual = sheet.sides() == 2;
        out.push_back(e);
    }
    return out;
}

}  // namespace fluorosim::viewer
