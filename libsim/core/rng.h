#pragma once
// PCG32 (O'Neill 2014). Streams are keyed by (seed, pixel, sample) so that results do not depend
// on the thread count or the order in which work is scheduled.
#include <cstdint>

namespace fluorosim {

inline uint64_t mixBits(uint64_t v) {
    v ^= v >> 31;
    v *= 0x7fb5d329728ea185ULL;
    v ^= v >> 27;
    v *= 0x81dadef4bc2dd44dULL;
    v ^= v >> 33;
    return v;
}

class Rng {
public:
    Rng() { seed(0x853c49e6748fea9bULL, 0xda3e39cb94b95bdbULL); }
    Rng(uint64_t seedValue, uint64_t stream) { seed(seedValue, stream); }

    void seed(uint64_t seedValue, uint64_t stream) {
        state_ = 0u;
        inc_ = (stream << 1u) | 1u;
        next32();
        state_ += seedValue;
        next32();
    }
    // Stream for one (seed, a, b) triple, e.g. (render seed, pixel, sample index).
    static Rng forKey(uint64_t seedValue, uint64_t a, uint64_t b) {
        return Rng(mixBits(seedValue ^ mixBits(a * 0x9E3779B97F4A7C15ULL + b)), mixBits(a) ^ (b << 1));
    }

    uint32_t next32() {
        const uint64_t old = state_;
        state_ = old * 0x5851f42d4c957f2dULL + inc_;
        const uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
        const uint32_t rot = static_cast<uint32_t>(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
    }
    // Uniform in [0, 1), 53 random bits.
    double uniform() {
        const uint64_t hi = next32() >> 5, lo = next32() >> 6;
        return (static_cast<double>(hi) * 67108864.0 + static_cast<double>(lo)) * (1.0 / 9007199254740992.0);
    }
    // Uniform in (0, 1]: safe for -log(u).
    double uniformOpenZero() { return 1.0 - uniform(); }

private:
    uint64_t state_ = 0, inc_ = 0;
};

}  // namespace fluorosim
