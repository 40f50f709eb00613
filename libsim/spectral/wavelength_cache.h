#pragma once
// The last few values of a pure function of (an object, a sub-index, the wavelengths), kept per
// thread by its users (`thread_local`). A path evaluates the same medium's spectra at the same
// wavelengths at every free flight and shadow ray; a table look-up per dye and wavelength each time
// was a tenth of a light-sheet job's CPU.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>

#include "spectral/sampled_wavelengths.h"

namespace fluorosim {

// A process-wide unique id for an object whose values a WavelengthCache holds: two live objects never
// share one, so an entry of a destroyed object is never taken for a new one at the same address.
inline uint64_t newWavelengthCacheId() {
    static std::atomic<uint64_t> last{0};
    return ++last;
}

template <class Value, size_t N = 4>
class WavelengthCache {
public:
    template <class Compute>
    Value get(uint64_t id, int index, const SampledWavelengths& wl, Compute&& compute) {
        for (const Entry& e : entries_)
            if (e.id == id && e.index == index && std::equal(e.lambda.begin(), e.lambda.end(), wl.lambda.begin())) return e.value;
        Entry& e = entries_[oldest_];
        oldest_ = (oldest_ + 1) % N;
        e.value = compute();
        e.id = id;
        e.index = index;
        e.lambda = wl.lambda;
        return e.value;
    }

private:
    struct Entry {
        uint64_t id = 0;  // ids start at 1
        int index = 0;
        std::array<double, kNumWavelengths> lambda{};
        Value value{};
    };
    std::array<Entry, N> entries_{};
    size_t oldest_ = 0;
};

}  // namespace fluorosim
