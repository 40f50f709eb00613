#pragma once
// Checks of JSON values read outside the scene loader (the microscope block that `acquire` reads):
// integers that must not be truncated from floats or wrap from unsigned values, and lists of indices
// that must be lists. Each returns the problem as text (for the caller's own "path: problem (got
// value)" message), or nothing when the value is fine.
#include <cstdint>
#include <limits>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace fluorosim::app {

// An integer in [lo, hi]: 2.7, 1e308 and 4294967296 for an int are problems, not 2, INT_MIN and 0.
inline std::optional<std::string> integerProblem(const nlohmann::json& j, int64_t lo, int64_t hi) {
    const std::string range = "must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    if (!j.is_number_integer()) return j.is_number() ? range + " (a JSON integer, without a decimal point or exponent)" : range;
    if (j.is_number_unsigned() && j.get<uint64_t>() > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) return range;
    const auto v = j.get<int64_t>();
    if (v < lo || v > hi) return range;
    return std::nullopt;
}

// A non-empty JSON array of distinct integers in [0, count): "lights": 0 is not a list.
inline std::optional<std::string> indexListProblem(const nlohmann::json& j, size_t count) {
    const std::string what =
        "expected a non-empty array of distinct indices in [0, " + std::to_string(count == 0 ? 0 : count - 1) + "]";
    if (!j.is_array() || j.empty() || count == 0) return what;
    std::vector<bool> seen(count, false);
    for (const auto& e : j) {
        if (integerProblem(e, 0, static_cast<int64_t>(count) - 1)) return what;
        const auto i = static_cast<size_t>(e.get<int64_t>());
        if (seen[i]) return what;
        seen[i] = true;
    }
    return std::nullopt;
}

}  // namespace fluorosim::app
