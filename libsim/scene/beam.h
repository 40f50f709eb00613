#pragma once
// A light whose direction is known at every point, such as a light sheet or a collimated beam. Next-
// event estimation connects to it exactly: from p back along -direction(side) to where the beam
// enters the scene, with the unattenuated irradiance profile at p times the transmittance of that
// segment. The Gaussian light sheet implements this in optics/ (libsim never includes optics).
// Profiles are immutable: a z-stack moves a sheet by wrapping it (optics::Microscope::lightsAt).
#include <array>
#include <limits>
#include <memory>
#include <optional>

#include "core/vec3.h"
#include "spectral/spectrum.h"

namespace fluorosim {

// A piece [tMin, tMax] of a ray inside a beam's core, with a proposal for placing points along it:
// a normal density of t (mean `centre`, deviation `sigma`) that follows the profile across the beam,
// or uniform when sigma is infinite.
struct BeamCoreInterval {
    double tMin = 0, tMax = 0;
    double centre = 0, sigma = std::numeric_limits<double>::infinity();
};
struct BeamCore {
    int count = 0;
    std::array<BeamCoreInterval, 2> intervals{};
};

class BeamProfile {
public:
    virtual ~BeamProfile() = default;
    virtual int sides() const = 0;                    // 1, or 2 for counter-propagating beams
    virtual Vec3 direction(int side) const = 0;       // unit direction the light travels
    // Irradiance (W/mm²) of the unattenuated beam of `side` at p, per unit of normalised spectral weight.
    virtual double irradiance(const Vec3& p, int side, double lambdaNm) const = 0;
    virtual const Spectrum& spectrum() const = 0;     // normalised to total weight 1

    // The core: where a direct estimator (the microscope's) integrates the unscattered beam along
    // camera rays, so that paths leave it out (docs/model.md, "Split estimator"). inCore(p) holds
    // exactly for the points of coreAlong's intervals (up to rounding at the edge, where a sheet is
    // e^-32 of its peak); outside the core paths keep the beam. Default: no core.
    virtual bool inCore(const Vec3& /*p*/, int /*side*/, double /*lambdaNm*/) const { return false; }
    virtual BeamCore coreAlong(const Ray& /*ray*/, int /*side*/, double /*lambdaNm*/) const { return {}; }

    // What a forward tracer of the beam's light needs (render/fluence_field.h): a point of its axis, and a
    // point of the cross-section through `axisPoint` (normal to the direction) drawn roughly in
    // proportion to the irradiance there, with its density per mm² (any density that covers the profile
    // keeps the tracer unbiased). Default: none, and no field is traced for the beam.
    struct CrossSectionPoint {
        Vec3 p;
        double pdf = 0;
    };
    virtual std::optional<Vec3> axisPoint() const { return std::nullopt; }
    virtual std::optional<CrossSectionPoint> sampleCrossSection(const Vec3& /*axisPoint*/, int /*side*/, double /*lambdaNm*/, double /*u1*/,
                                                                double /*u2*/) const {
        return std::nullopt;
    }
};

// Solutions t of a t² + b t + c <= 0 (a quadric region crossed by a ray), as at most two intervals,
// unbounded ends at ±infinity. Shared by the beam cores.
BeamCore quadraticCore(double a, double b, double c);

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
