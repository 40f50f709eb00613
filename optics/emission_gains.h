#pragma once
// g of the computed image y = P · diag(g) · S · c (optics/unscattered_image.h): per emission point and
// emitting dye, the expected photoelectrons per mol/L of that dye,
//   g = t Ω V/(4π) · T̄_cam,dye(y) · Φ D · Σ_l λ_l σa(λ_l; 1 M) Σ_s E_ls(y) T_beam,ls(y),
// t the exposure, Ω the cone's solid angle, V the point's volume, T̄_cam the cone-mean transmittance
// toward the objective, E_ls the unattenuated irradiance of line l's side s where y is in its core
// (0 elsewhere), T_beam the transmittance back along the beam to where it entered the sample.
//
// Both transmittances depend only on where a point is: a stack moves the sheets along the detection axis,
// which keeps their direction, and the cone with the focus. So they are computed once per stack at the
// scene's concentrations (the dyes' own attenuation frozen there: a fit recomputes them between its
// outer iterations), and a plane only evaluates the irradiance. The camera's path through the immersion
// medium grows with the plane's offset; that factor is applied per plane where the immersion medium is
// homogeneous (docs/model.md, "The computed image").
#include <atomic>
#include <vector>

#include "optics/emission_lattice.h"
#include "optics/imaging.h"
#include "render/fluence_field.h"

namespace fluorosim::optics {

struct TransmittanceOptions {
    double stepUm = 2;            // the coarse lattice of grid media's transmittances, trilinearly interpolated
    double quadratureVoxels = 4;  // midpoint step along rays through grid media, in voxels
    int coneRings = 3, coneAzimuths = 4;  // the cone mean: Gauss–Legendre in cos θ, uniform in azimuth
    bool attenuation = true;              // false: every transmittance is 1 (a perfect microscope)
};

// One side of one beam line of a plane's lights.
struct LineSide {
    const BeamProfile* profile = nullptr;
    double lambdaNm = 0, weight = 0;
    int side = 0;
    size_t line = 0;  // index into ChannelDyes::lineLambda
};
std::vector<LineSide> lineSides(const std::vector<Light>& lights);

class EmissionGains {
public:
    // `reference`: the imaging of the lattice's reference plane; `lights`: the channel's lights at any
    // plane (only their directions matter here). Throws ConfigError when the beams differ from the dyes'.
    EmissionGains(const Scene& scene, const EmissionLattice& lattice, const ChannelDyes& dyes, const std::vector<Light>& lights,
                  const Imaging& reference, const TransmittanceOptions& options, int threads, const std::atomic<bool>* cancel = nullptr);

    // Gains of points [first, last) for the plane at `planeOffsetMm` lit by `lights` (that plane's lights),
    // into out[(p − first) × slots + slot]: photoelectrons per mol/L. Zero outside every core. With
    // `field` (the plane's excitation field, for the same lights) each core adds its beam's scattered
    // light too; then `fieldGains`, if given, receives the scattered light's part of the gains and half
    // the difference of the field's two halves (the field's own noise), laid out as `out`.
    struct FieldGains {
        std::vector<double> scattered, halfDifference;
    };
    void planeGains(const std::vector<Light>& lights, double planeOffsetMm, size_t first, size_t last, std::vector<double>& out, int threads,
                    const BeamExcitationField* field = nullptr, FieldGains* fieldGains = nullptr) const;

    bool complete() const { return complete_; }
    double seconds() const { return seconds_; }
    size_t transmittanceNodes() const { return nodes_; }

private:
    const EmissionLattice& lattice_;
    const ChannelDyes& dyes_;
    size_t sides_ = 0;
    std::vector<float> beamT_;    // [point × sides + side]
    std::vector<float> base_;     // [point × slots + slot]: t Ω V/(4π) Φ D T̄_cam (0 for a slot the medium lacks)
    std::array<double, kNumWavelengths> cameraExtinction_{};  // of a homogeneous immersion medium, 1/mm
    std::vector<double> coneCos_, coneWeight_;                // the cone's rings, for the immersion factor
    bool complete_ = true;
    double seconds_ = 0;
    size_t nodes_ = 0;
};

}  // namespace fluorosim::optics
