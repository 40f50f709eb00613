#pragma once
// Free-flight sampling against a majorant, as one function with a callback (pbrt-v4's SampleT_maj).
// Every transport code in Fluorosim (renderer, slab validator) samples distances through sampleTmaj,
// so delta, ratio and spectral tracking plug in by changing the majorant iterator or the callback.
#include <cmath>
#include <optional>

#include "core/exponential.h"
#include "core/rng.h"
#include "spectral/sampled_spectrum.h"

namespace fluorosim {

inline double heroComponent(double s) { return s; }
inline double heroComponent(const SampledSpectrum& s) { return s[0]; }
inline double expNeg(double x) { return std::exp(-x); }
inline SampledSpectrum expNeg(const SampledSpectrum& x) { return exp(x * -1.0); }

// A ray interval [tMin, tMax) over which sigmaMaj bounds the extinction.
template <class S>
struct MajorantSegment {
    double tMin, tMax;
    S sigmaMaj;
};

// The majorant iterator of a homogeneous medium: one segment whose majorant is sigma_t itself.
template <class S>
class HomogeneousMajorantIterator {
public:
    HomogeneousMajorantIterator(double tMin, double tMax, const S& sigmaT) : seg_{tMin, tMax, sigmaT} {}
    std::optional<MajorantSegment<S>> next() {
        if (done_) return std::nullopt;
        done_ = true;
        return seg_;
    }

private:
    MajorantSegment<S> seg_;
    bool done_ = false;
};

// Samples tentative collisions with density sigma_maj(hero) * T_maj along the segments of `iter`.
// At each, callback(t, sigmaMaj, T_maj) is called with T_maj from the previous collision; it returns
// false to stop. Returns T_maj from the last collision to the end of the last segment, or 1 if the
// callback stopped.
template <class S, class Iter, class Callback>
S sampleTmaj(Iter iter, Rng& rng, Callback&& callback) {
    S Tmaj(1.0);
    while (const auto seg = iter.next()) {
        const double sigmaHero = heroComponent(seg->sigmaMaj);
        if (!(sigmaHero > 0)) {
            // Empty segments are common (a sparse grid's empty cells): skip the exponentials.
            if (std::isfinite(seg->tMax) && bool(seg->sigmaMaj)) Tmaj *= expNeg(seg->sigmaMaj * (seg->tMax - seg->tMin));
            continue;
        }
        double tMin = seg->tMin;
        while (true) {
            const double t = tMin + sampleStandardExponential(rng) / sigmaHero;
            if (t < seg->tMax) {
                Tmaj *= expNeg(seg->sigmaMaj * (t - tMin));
                if (!callback(t, seg->sigmaMaj, Tmaj)) return S(1.0);
                Tmaj = S(1.0);
                tMin = t;
            } else {
                Tmaj *= expNeg(seg->sigmaMaj * (seg->tMax - tMin));
                break;
            }
        }
    }
    return Tmaj;
}

}  // namespace fluorosim
