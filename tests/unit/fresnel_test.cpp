// Fresnel reflectance at edge cases (sampling and reciprocity are in tests/statistical).
#include <gtest/gtest.h>

#include <cmath>

#include "materials/fresnel.h"

namespace fluorosim {
namespace {

// Found in review: a conductor with zero index divided by zero.
TEST(Fresnel, ConductorWithZeroIndexIsFinite) {
    EXPECT_EQ(fresnelConductor(0.5, {0.0, 0.0}), 1.0);
    EXPECT_TRUE(std::isfinite(fresnelConductor(1e-9, {0.2, 3.0})));
}

}  // namespace
}  // namespace fluorosim
