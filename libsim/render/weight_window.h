#pragma once
// Russian roulette and splitting by a weight window (as MCNP's): a photon's power is kept within [½, 2] ×
// its unit power over the importance of where it is. Where the importance falls (away from what is tallied)
// photons die, and the survivors carry more power; where it rises they split into copies that carry less, so
// a photon that roamed where it is unseen comes back as copies of bounded power, not as one whose power grew
// at every unseen vertex.
#include <algorithm>
#include <cmath>

#include "core/rng.h"

namespace fluorosim {

// How many copies go on, on average (1 inside the window): the power over the window's centre. Each copy
// carries the power over it.
inline double weightWindowSurvival(double power, double importance, double unitPower) {
    const double q = power * importance / unitPower;
    return q < 0.5 || q > 2 ? q : 1.0;
}

// At most this many copies at one vertex, and this many in all from one photon: once they are spent, a
// survival above 1 goes on as one (unbiased still). The window bounds the splitting; this bounds a caller
// whose survival grows without end.
constexpr double kMostCopiesAtAVertex = 64;
constexpr int kMostCopiesOfAPhoton = 4096;

// The copies that go on after a vertex whose survival is q: ⌊q⌋ or ⌈q⌉, q on average (Russian roulette below
// 1), with q first bounded as above; q is left as the one used, by which each copy's power is divided. No
// random number is drawn when q is 1.
inline int copiesGoingOn(double& q, int& copiesLeft, Rng& rng) {
    if (q == 1) return 1;
    if (q > 1) q = std::min({q, kMostCopiesAtAVertex, 1.0 + copiesLeft});
    if (q == 1) return 1;
    const double whole = std::floor(q);
    const int copies = static_cast<int>(whole) + (rng.uniform() < q - whole ? 1 : 0);
    copiesLeft -= std::max(0, copies - 1);
    return copies;
}

}  // namespace fluorosim
