// apps/fluorosim/json_checks.h: integers and index lists read from JSON outside the scene loader.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "fluorosim/json_checks.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;
using app::indexListProblem;
using app::integerProblem;

TEST(JsonChecks, IntegersAreNotTruncatedOrWrapped) {
    EXPECT_FALSE(integerProblem(json(16), 1, 4096));
    EXPECT_FALSE(integerProblem(json(-1), -1, 10));
    // 2.7 used to become 2, 1e308 INT_MIN, 1e10 a bit depth.
    for (const json& bad : {json(2.7), json(1e308), json(1e10), json(0), json(4097), json("16"), json(nullptr), json::array()})
        EXPECT_TRUE(integerProblem(bad, 1, 4096)) << bad.dump();
    EXPECT_NE(integerProblem(json(2.0), 1, 4096)->find("without a decimal point"), std::string::npos);
    // 2^64 - 1 is stored unsigned; read as int64_t it would be -1.
    EXPECT_TRUE(integerProblem(json::parse("18446744073709551615"), -1, 10));
    EXPECT_TRUE(integerProblem(json::parse("9223372036854775808"), -10, 10));
}

TEST(JsonChecks, IndexListsMustBeListsOfValidDistinctIndices) {
    EXPECT_FALSE(indexListProblem(json::parse("[0, 2]"), 3));
    // "lights": 0 used to be taken as a list, and 4294967296 as light 0.
    for (const char* bad : {"0", "[]", "[3]", "[-1]", "[4294967296]", "[1.0]", "[0, 0]", "[\"0\"]", "{\"0\": 1}"})
        EXPECT_TRUE(indexListProblem(json::parse(bad), 3)) << bad;
    EXPECT_TRUE(indexListProblem(json::parse("[0]"), 0));
    EXPECT_NE(indexListProblem(json::parse("[5]"), 3)->find("[0, 2]"), std::string::npos);
}

}  // namespace
}  // namespace fluorosim
