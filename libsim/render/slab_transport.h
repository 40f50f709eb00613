#pragma once
// Forward photon transport through a plane-parallel slab under a normally incident pencil beam,
// with MCML's conventions (Wang, Jacques & Zheng 1995): Rd excludes the specular reflection Rsp at the
// first surface, Tt includes unscattered light. It uses the renderer's HG phase function, free-flight
// sampler (sampleTmaj) and Fresnel code, so it validates them against published values.
#include <cstdint>
#include <functional>

namespace fluorosim {

struct SlabOptions {
    double mua = 0, mus = 0;  // 1/mm
    double g = 0;
    double thickness = 0;     // mm
    double n = 1.0, nAbove = 1.0, nBelow = 1.0;
    uint64_t photons = 1000000;
    uint64_t seed = 1;
    int threads = 0;          // 0 = all cores
    // Throws ConfigError naming the offending option and value.
    void validate() const;
};

struct SlabResult {
    double Rd = 0, Tt = 0, Ta = 0;        // diffuse reflectance, total transmittance, absorbed fraction
    double RdStderr = 0, TtStderr = 0;
    double Rsp = 0;                        // specular reflectance at the first surface
    double Tballistic = 0;                 // part of Tt that never scattered
    uint64_t photons = 0;
    double seconds = 0;
};

// progress(done, total) is called from one thread at a time, as chunks finish.
SlabResult simulateSlab(const SlabOptions& opt, const std::function<void(uint64_t, uint64_t)>& progress = {});

}  // namespace fluorosim
