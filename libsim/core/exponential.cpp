#include "core/exponential.h"

namespace fluorosim {

ExponentialZiggurat::ExponentialZiggurat() {
    x[0] = kV / std::exp(-kR);
    x[1] = kR;
    for (int i = 2; i < 256; ++i) x[i] = -std::log(kV / x[i - 1] + std::exp(-x[i - 1]));
    x[256] = 0.0;
    for (int i = 0; i <= 256; ++i) f[i] = std::exp(-x[i]);
}

}  // namespace fluorosim
