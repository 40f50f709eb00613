// parallelFor and thread counts: absurd counts are refused before TBB sees them (65537 crashed it).
#include <gtest/gtest.h>

#include <atomic>
#include <string>

#include "core/errors.h"
#include "core/parallel.h"

namespace fluorosim {
namespace {

TEST(ParallelFor, RefusesThreadCountsOutsideTheRange) {
    std::atomic<int> calls{0};
    for (int threads : {-1, kMaxThreads + 1, 65537}) {
        try {
            parallelFor(4, threads, [&](size_t) { ++calls; });
            ADD_FAILURE() << threads << " accepted";
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find(std::to_string(threads)), std::string::npos) << e.what();
        }
    }
    EXPECT_EQ(calls.load(), 0);
    parallelFor(4, kMaxThreads, [&](size_t) { ++calls; });
    parallelFor(4, 0, [&](size_t) { ++calls; });
    EXPECT_EQ(calls.load(), 8);
}

TEST(ParallelFor, CheckNamesTheOption) {
    try {
        checkThreadCount(65537, "--threads");
        ADD_FAILURE() << "accepted";
    } catch (const ConfigError& e) {
        EXPECT_EQ(std::string(e.what()), "--threads: must lie in [0, 4096] (0 = all cores), got 65537");
    }
    EXPECT_NO_THROW(checkThreadCount(0, "--threads"));
}

}  // namespace
}  // namespace fluorosim
