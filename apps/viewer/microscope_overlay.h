#pragma once
// The microscope as geometry the viewer draws, in world µm, at one plane of the stack: the camera's
// field of view on the focal plane, the detection objective's collection cone, and each light
// sheet's 1/e² envelope ±w(x) around its moved centre. Computed from optics::Microscope and the
// scene's light sheets; no VTK here.
#include <array>
#include <string>
#include <vector>

#include "optics/microscope.h"

namespace fluorosim::viewer {

struct FieldOfView {
    Vec3 centreUm;
    Vec3 right, up, towardObjective;  // unit axes of the image: columns along right, rows along -up
    double pixelUm = 1;
    int width = 0, height = 0;
    std::array<Vec3, 4> cornersUm;    // top-left, top-right, bottom-right, bottom-left as the camera sees them
    // World position of the centre of pixel (x, y), row 0 at the top.
    Vec3 pixelCentreUm(double x, double y) const;
};

struct CollectionCone {
    Vec3 apexUm;           // the centre of the field of view
    Vec3 axis;             // towards the objective
    double halfAngleRad = 0;
    double lengthUm = 0;   // the working distance
};

struct SheetEnvelope {
    Vec3 centreUm;           // the waist, moved with the plane
    Vec3 u, n, h;            // propagation, normal, height
    double lambdaNm = 488;
    double waistUm = 0, rayleighUm = 0, heightUm = 0;
    bool dual = false;
    double halfWidthUm(double xUm) const;  // w(x)
};

class MicroscopeOverlay {
public:
    // `planes` and `stepUm` may differ from the scene's stack (a stack file with its own z).
    MicroscopeOverlay(const Scene& scene, const optics::Microscope& microscope, int planes, double stepUm);

    int planes() const { return planes_; }
    double stepUm() const { return stepUm_; }
    double offsetUm(int plane) const;
    FieldOfView fieldOfView(int plane) const;
    CollectionCone cone(int plane) const;
    // Every light sheet any channel switches on, once each.
    std::vector<SheetEnvelope> sheets(int plane) const;

private:
    const Scene& scene_;
    optics::Microscope microscope_;  // with the stack geometry given above
    int planes_;
    double stepUm_;
    std::vector<size_t> sheetLights_;
};

}  // namespace fluorosim::viewer
