#pragma once
// xoshiro256+ (Blackman & Vigna 2018) seeded through splitmix64. Streams are keyed by (seed, pixel, sample) so that results do not depend
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
    Rng() : Rng(0x853c49e6748fea9bULL, 0xda3e39cb94b95bdbULL) {}
    Rng(uint64_t seedValue, uint64_t stream) { seed(seedValue, stream); }

    // xoshiro256+ state filled by splitmix64 from the (seed, stream) pair.
    void seed(uint64_t seedValue, uint64_t stream) {
        uint64_t x = mixBits(seedValue) ^ mixBits(stream + 0x9E3779B97F4A7C15ULL);
        for (uint64_t& word : s_) {
            x += 0x9E3779B97F4A7C15ULL;
            word = mixBits(x);
        }
    }
    // Stream for one (seed, a, b) triple, e.g. (render seed, pixel, sample index).
    static Rng forKey(uint64_t seedValue, uint64_t a, uint64_t b) {
        return Rng(seedValue, mixBits(a * 0x9E3779B97F4A7C15ULL + mixBits(b)));
    }

    uint64_t next64() {
        const uint64_t result = s_[0] + s_[3];
        const uint64_t t = s_[1] << 17;
        s_[2] ^= s_[0];
        s_[3] ^= s_[1];
        s_[1] ^= s_[2];
        s_[0] ^= s_[3];
        s_[2] ^= t;
        s_[3] = (s_[3] << 45) | (s_[3] >> 19);
        return result;
    }
    // Uniform in [0, 1) from the top 53 bits (the low bits of xoshiro256+ are weaker).
    double uniform() { return static_cast<double>(next64() >> 11) * (1.0 / 9007199254740992.0); }

private:
    uint64_t s_[4];
};

}  // namespace fluorosim
