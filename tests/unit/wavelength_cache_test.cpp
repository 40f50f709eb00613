// The per-thread caches of spectra (spectral/wavelength_cache.h): a medium's cached spectra are the
// ones it evaluates, for every medium and set of wavelengths a thread alternates between, and a medium
// made where a destroyed one lived never gets the old one's values.
#include <gtest/gtest.h>

#include <memory>
#include <optional>
#include <thread>

#include "media/medium.h"
#include "spectral/tabulated_spectrum.h"
#include "spectral/wavelength_cache.h"

namespace fluorosim {
namespace {

Medium mediumWith(double absorptionAt500) {
    return Medium("m", Spectrum::tabulated(TabulatedSpectrum({400, 500, 700}, {0.1, absorptionAt500, 0.3}, "a")), Spectrum::constant(2.0), 0.5, 1.33);
}

void expectSpectra(const MediumSpectra& s, double absorptionAt500, const SampledWavelengths& wl) {
    for (int k = 0; k < kNumWavelengths; ++k) {
        const double l = wl.lambda[static_cast<size_t>(k)];
        const double expected = l <= 500 ? 0.1 + (absorptionAt500 - 0.1) * (l - 400) / 100 : absorptionAt500 + (0.3 - absorptionAt500) * (l - 500) / 200;
        EXPECT_NEAR(s.sigmaA[kSolventChannel][k], expected, 1e-12) << "at " << l << " nm";
        EXPECT_EQ(s.sigmaS[k], 2.0);
    }
}

TEST(WavelengthCache, HoldsEachMediumsOwnSpectraAcrossAlternatingCalls) {
    const Medium a = mediumWith(1.0), b = mediumWith(5.0);
    const SampledWavelengths w1 = SampledWavelengths::sampleUniform(0.3, 400, 700), w2 = SampledWavelengths::sampleUniform(0.7, 400, 700);
    for (int round = 0; round < 3; ++round) {  // more pairs than the cache holds, in turn
        expectSpectra(a.spectra(w1), 1.0, w1);
        expectSpectra(b.spectra(w1), 5.0, w1);
        expectSpectra(a.spectra(w2), 1.0, w2);
        expectSpectra(b.spectra(w2), 5.0, w2);
        expectSpectra(mediumWith(3.0).spectra(w1), 3.0, w1);
    }
    const Medium copy = a;  // a copy has the same spectra, so it may share the entries
    expectSpectra(copy.spectra(w1), 1.0, w1);
}

TEST(WavelengthCache, AMediumMadeWhereADestroyedOneLivedGetsItsOwnSpectra) {
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.5, 400, 700);
    std::optional<Medium> slot;
    for (double a500 : {1.0, 2.0, 4.0, 8.0}) {
        slot.emplace(mediumWith(a500));  // the same storage each time
        expectSpectra(slot->spectra(wl), a500, wl);
    }
}

TEST(WavelengthCache, ThreadsKeepTheirOwnEntries) {
    const Medium a = mediumWith(1.0), b = mediumWith(5.0);
    const SampledWavelengths wl = SampledWavelengths::sampleUniform(0.25, 400, 700);
    std::thread other([&] {
        for (int i = 0; i < 1000; ++i) expectSpectra(b.spectra(wl), 5.0, wl);
    });
    for (int i = 0; i < 1000; ++i) expectSpectra(a.spectra(wl), 1.0, wl);
    other.join();
}

TEST(WavelengthCache, KeysOnObjectIndexAndEveryWavelength) {
    WavelengthCache<int, 2> cache;
    int evaluations = 0;
    const SampledWavelengths w = SampledWavelengths::sampleUniform(0.5, 400, 700);
    SampledWavelengths w2 = w;
    w2.lambda[3] += 1e-9;  // one companion differs
    const auto get = [&](uint64_t id, int index, const SampledWavelengths& wl, int value) {
        return cache.get(id, index, wl, [&] {
            ++evaluations;
            return value;
        });
    };
    EXPECT_EQ(get(1, 0, w, 10), 10);
    EXPECT_EQ(get(1, 0, w, 99), 10);  // cached
    EXPECT_EQ(evaluations, 1);
    EXPECT_EQ(get(1, 1, w, 11), 11);   // another index
    EXPECT_EQ(get(1, 0, w2, 12), 12);  // another wavelength: evicts the oldest entry (1, 0, w)
    EXPECT_EQ(get(1, 0, w, 13), 13);
    EXPECT_EQ(evaluations, 4);
    EXPECT_NE(newWavelengthCacheId(), newWavelengthCacheId());
}

}  // namespace
}  // namespace fluorosim
