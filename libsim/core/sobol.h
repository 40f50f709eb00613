#pragma once
// Owen-scrambled Sobol' points (randomized quasi-Monte Carlo). The points come from Boost.Random's
// Sobol' generator (Joe-Kuo direction numbers), with the origin prepended so that every 2^m prefix is
// a (0, m, s)-net; each stream (a pixel) scrambles them with its own seed by the hash-based nested
// uniform scrambling of Burley (2020, "Practical Hash-based Owen Scrambling"). Scrambled points are
// uniform on [0, 1)^s for every stream, so estimates stay unbiased, and streams are independent.
#include <cstdint>
#include <vector>

namespace fluorosim {

class SobolTable {
public:
    // The first `points` points in `dimensions` dimensions (both at least 1).
    SobolTable(int dimensions, int points);
    int dimensions() const { return dimensions_; }
    int points() const { return points_; }
    // Coordinate `dim` of point `index`, scrambled for the stream with `seed`.
    double sample(int index, int dim, uint64_t seed) const;

private:
    int dimensions_, points_;
    std::vector<uint32_t> table_;  // point-major
};

}  // namespace fluorosim
