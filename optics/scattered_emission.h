#pragma once
// The computed emission's light that reaches the camera only after scattering, traced forward (docs/model.md,
// "Scattered emission, traced forward"). Photons leave the points of the computed part's emission (drawn in
// proportion to the power each cell sends to the camera, at a wavelength drawn from the dyes' detected
// emission, weighted by the exact emission coefficient there over that density), are traced by analog
// transport (render/photon_tracer.h: scattering, absorption, re-emission by dyes), and each vertex where they
// scatter or are re-emitted is imaged as a point source: a few directions of the collection cone, drawn from
// the phase lobe and the cone in turn (the cone's stratified in azimuth), each with its transmittance to the objective, landing where the
// camera paths' geometry puts it and weighed by the PSF's h/h_geo there, so that the photons estimate exactly
// what the camera paths' connections and branches estimated (those then leave it out:
// PathStart::computedEmissionTraced). A vertex far from focus is imaged on pooled blocks, as the paths are;
// near focus the scattering is imaged at points along the flights instead (ScatteredEmissionOptions::trackSlabMm).
//
// Every deposit is bounded (the photon's power over the directions drawn, times at most 2 and the PSF's
// reweight), so the heavy tails of the camera side's connections, which met a bright neurite along a phase
// lobe by chance, do not arise.
#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "optics/dye_cells.h"
#include "optics/imaging.h"
#include "optics/unscattered_image.h"
#include "render/fluence_field.h"
#include "render/path_tracer.h"

namespace fluorosim::optics {

struct ScatteredEmissionOptions {
    // Photons per plane and channel: `photons` when set (0: the camera paths carry it), else photonsPerPixel times
    // the plane's pixels. The default, 4 (2^18 on a 256² plane) with 8 directions per vertex: at σs 2 /mm a
    // vertex's directions hold most of the photons' noise and cost a tenth of a photon each (docs/performance.md,
    // "Directions per vertex").
    std::optional<uint64_t> photons;
    double photonsPerPixel = 4;
    uint64_t photonsFor(size_t pixels) const;
    int directions = 8;                    // per vertex imaged, pooled or not
    // The share of photons that leave their source into a cone about the axis toward the objective, 15° wider
    // than the collection cone's half-angle, where the tissue above the focus is thin (times e^{-τ}, τ its
    // scattering optical depth along the axis); the rest leave uniformly, and every photon is weighed by the
    // isotropic emission over the mixture's density. There the light that reaches the image after scattering
    // is mostly light that left toward the objective and scattered forward once: drawn isotropically, a few
    // photons carried it with large weights (docs/performance.md, "Photons toward the objective"). In [0, 1).
    double towardObjective = 0.7;
    // Within this distance of the focal plane (mm) the photons' scattering is imaged along their flights (a
    // track-length estimator: points of each flight across the slab, weighed by σs times the length they
    // stand for; where the tissue is thin across the slab, σs × its thickness at most 0.25) instead of at their
    // vertices: a vertex there images on a disc of a few pixels, and the few photons that scatter near focus
    // made the traced part's heaviest deposits (docs/model.md, "Near focus, along the flights"). 0 images every
    // scattering vertex. In [0, 1].
    double trackSlabMm = 0.02;
    void validate() const;                 // ConfigError naming the field and value
};

struct ScatteredEmissionImage {
    std::vector<double> electrons;  // expected photoelectrons per pixel (pooled parts spread back to pixels)
    std::vector<double> variance;   // of each pixel's estimate, from the spread of independent slots
    // The independent estimates whose mean is `electrons` (each slot's photons, scaled to all of them): a
    // region's variance follows from their sums over it (the deposits of one photon are correlated across
    // the pixels its vertices light, which the per-pixel variance does not see).
    std::vector<std::vector<double>> slots;
    // The excitation field's noise in it, per pixel: half the difference of the images its two halves give
    // the photons' sources (empty without a field). It is correlated with the computed image's
    // (PlaneImage::fieldHalfDifference, the same halves), so the two add before they are squared.
    std::vector<double> fieldHalfDifference;
    uint64_t photons = 0, vertices = 0;
    // The media whose field-lit emission the photons carry (by index; empty when none).
    std::vector<bool> fieldLitMedia;
    bool tracesFieldLit(int medium) const { return medium >= 0 && static_cast<size_t>(medium) < fieldLitMedia.size() && fieldLitMedia[static_cast<size_t>(medium)]; }
    // Where the photons also carry the beams' core emission beyond the computed part (the field's box) in
    // the media whose field-lit emission they carry.
    std::optional<FieldBox> beamLitBox;
    bool tracesBeamLit(const Vec3& y, int medium) const { return beamLitBox && tracesFieldLit(medium) && beamLitBox->contains(y); }
    double seconds = 0;
    bool complete = true;
};

// Two traces of one plane pooled as one with all their photons: each slot the photon-weighted mean of the
// two traces' same slots (independent estimates still), the variance from the pooled slots'.
ScatteredEmissionImage pooledTraces(const ScatteredEmissionImage& a, const ScatteredEmissionImage& b);

// Traces the photons of `emission` (a plane's computed emission) for one plane. `covered` decides which
// points the computed part holds (CameraPathImaging::computesUnscatteredAt) and how finely a vertex is imaged
// (imageLevel); `detection` gives photoelectrons per joule at λ. With a field, `dyeCells` (built for this
// channel from `field` or an earlier estimate of it over the same box: only its density changes) are the
// field-lit emission's sources; without them the lattice's points carry the computed emission. Refracting surfaces on the way to the
// objective are taken as the camera paths take them (Imaging::cameraStart). The image does not depend on
// the thread count.
ScatteredEmissionImage traceScatteredEmission(const Scene& scene, const PathTracer& tracer, const Imaging& imaging, const CameraPathImaging& covered,
                                              const EmissionPoints& emission, const BeamExcitationField* field, const DyeCells* dyeCells,
                                              const std::function<double(double)>& detection, double exposureS,
                                              const ScatteredEmissionOptions& options, uint64_t seed, uint64_t streamKey, int threads,
                                              const std::atomic<bool>* cancel = nullptr);

}  // namespace fluorosim::optics
