#include <gtest/gtest.h>

#include "render/slab_transport.h"

namespace fluorosim {
namespace {
// Placeholder until the reference table lands.
TEST(Slab, Smoke) {
    SlabOptions o;
    o.mua = 1.0; o.mus = 9.0; o.g = 0.75; o.thickness = 0.2; o.photons = 100000;
    const auto r = simulateSlab(o);
    EXPECT_NEAR(r.Rd, 0.09739, 4 * r.RdStderr);
    EXPECT_NEAR(r.Tt, 0.66096, 4 * r.TtStderr);
}
}  // namespace
}  // namespace fluorosim
