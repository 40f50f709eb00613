#pragma once
// Forward photon transport through a plane-parallel slab under a normally incident pencil beam,
// with MCML's conventions (Wang, Jacques & Zheng 1995): Rd excludes the specular reflection Rsp at the
// first surface, Tt includes unscattered light. It uses the renderer's HG phase function, free-flight
// sampler (sampleTmaj) and Fresnel code, so it validates them against published values.
//
// Optionally the slab holds a grey fluorescent dye: it absorbs with muaDye at every excitation
// wavelength and re-emits a fraction quantumYield of the absorbed photons isotropically into an
// emission band, whose coefficients default to the excitation band's. Emission-band photons that the
// dye absorbs again re-emit in the same band (secondary fluorescence). Fluorescence is tallied in
// photons per incident photon as Rf and Tf, apart from the elastic Rd and Tt.
#include <cstdint>
#include <functional>
#include <optional>

namespace fluorosim {

struct SlabBand {
    double mua = 0, mus = 0;  // 1/mm, absorption other than the dye's, and scattering
    double g = 0;
    double muaDye = 0;        // 1/mm, absorption by the fluorescent dye
};

struct SlabOptions {
    double mua = 0, mus = 0;  // 1/mm
    double g = 0;
    double muaDye = 0;        // 1/mm; 0 = no fluorescence
    double quantumYield = 0;  // photons emitted per photon absorbed by the dye, [0, 1]
    std::optional<SlabBand> emission;  // emission-band coefficients; default: the excitation band's
    double thickness = 0;     // mm
    double n = 1.0, nAbove = 1.0, nBelow = 1.0;
    uint64_t photons = 1000000;
    uint64_t seed = 1;
    int threads = 0;          // 0 = all cores
    SlabBand excitation() const { return {mua, mus, g, muaDye}; }
    SlabBand emissionBand() const { return emission.value_or(excitation()); }
    // Throws ConfigError naming the offending option and value.
    void validate() const;
};

struct SlabResult {
    double Rd = 0, Tt = 0, Ta = 0;        // diffuse reflectance, total transmittance, absorbed fraction
    double RdStderr = 0, TtStderr = 0;
    double Rsp = 0;                        // specular reflectance at the first surface
    double Tballistic = 0;                 // part of Tt that never scattered
    double Rf = 0, Tf = 0, RfStderr = 0, TfStderr = 0;  // escaping fluorescence, photons per incident photon
    double guided = 0;  // trapped by total internal reflection in a band where nothing interacts (leaves at the edge)
    uint64_t photons = 0;
    double seconds = 0;
};

// progress(done, total) is called from one thread at a time, as chunks finish.
SlabResult simulateSlab(const SlabOptions& opt, const std::function<void(uint64_t, uint64_t)>& progress = {});

}  // namespace fluorosim
