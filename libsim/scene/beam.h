#pragma once
// A light whose direction is known at every point, such as a light sheet or a collimated beam. Next-
// event estimation connects to it exactly: from p back along -direction(side) to where the beam
// enters the scene, with the unattenuated irradiance profile at p times the transmittance of that
// segment. The Gaussian light sheet implements this in optics/ (libsim never includes optics).
// Profiles are immutable: a z-stack moves a sheet by wrapping it (optics::Microscope::lightsAt).
#include <memory>
#include <optional>

#include "core/vec3.h"
#include "spectral/spectrum.h"

namespace fluorosim {

class BeamProfile {
public:
    virtual ~BeamProfile() = default;
    virtual int sides() const = 0;                    // 1, or 2 for counter-propagating beams
    virtual Vec3 direction(int side) const = 0;       // unit direction the light travels
    // Irradiance (W/mm²) of the unattenuated beam of `side` at p, per unit of normalised spectral weight.
    virtual double irradiance(const Vec3& p, int side, double lambdaNm) const = 0;
    virtual const Spectrum& spectrum() const = 0;     // normalised to total weight 1
};

// What a scene file says about a light sheet (or, with `widefield`, an epi-illumination field: a
// uniform beam along `propagation` over a disc of `fieldDiameterMm` around `centreMm`), in internal
// units; optics turns it into a profile.
struct LightSheetSpec {
    bool widefield = false;
    double fieldDiameterMm = 0.5;
    std::optional<double> wavelengthNm;
    std::optional<Spectrum> spectrum;
    double powerMw = 1;
    Vec3 propagation{1, 0, 0}, normal{0, 0, 1}, centreMm;
    std::optional<double> waistMm, illuminationNa;
    double heightMm = 0.2, refractiveIndex = 1.33;
    bool scanned = false, dual = false;
};

}  // namespace fluorosim
