// parallelFor and thread counts: absurd counts are refused before TBB sees them (65537 crashed it).
#include <gtest/gtest.h>

#include <atomic>
#include <string>
#include <vector>

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

// The arena a render keeps across its passes runs every item of every loop once.
TEST(ThreadArena, RunsEveryItemOfManyLoops) {
    for (int threads : {1, 2, 0}) {
        ThreadArena arena(threads);
        std::vector<std::atomic<int>> hits(37);
        for (int loop = 0; loop < 200; ++loop) arena.parallelFor(hits.size(), [&](size_t i) { ++hits[i]; });
        for (const auto& h : hits) EXPECT_EQ(h.load(), 200) << threads;
    }
    EXPECT_THROW(ThreadArena(65537), ConfigError);
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
