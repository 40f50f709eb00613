#pragma once
// Mean and standard error of independent per-sample values.
#include <algorithm>
#include <cmath>

namespace fluorosim {

struct TallyValue {
    double mean = 0, stderr_ = 0;
};

struct Accumulator {
    double sum = 0, sum2 = 0;
    void add(double v) {
        sum += v;
        sum2 += v * v;
    }
    void merge(const Accumulator& o) {
        sum += o.sum;
        sum2 += o.sum2;
    }
    // Over n samples (values never added count as zeros).
    TallyValue value(double n) const {
        const double mean = sum / n;
        return {mean, std::sqrt(std::max(0.0, sum2 / n - mean * mean) / std::max(1.0, n - 1))};
    }
};

}  // namespace fluorosim
