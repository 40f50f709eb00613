#pragma once
// Checks of command-line values that CLI11 would otherwise convert silently: an unsigned option given
// "-1" becomes 18446744073709551615.
#include <CLI/CLI.hpp>
#include <charconv>
#include <cstdint>
#include <string>

#include "core/message.h"

namespace fluorosim::app {

// Accepts decimal digits only (an optional leading '+') up to 2^64 - 1, so "-1", "1e3", "0x10" and
// 18446744073709551616 are refused before conversion (CLI11 would wrap or saturate them), with the
// option's name and the value: "--seed: must be an integer in [0, 18446744073709551615], got ...".
inline CLI::Validator nonNegativeInteger() {
    return CLI::Validator(
        [](std::string& s) -> std::string {
            const char* b = s.data() + (!s.empty() && s[0] == '+' ? 1 : 0);
            const char* e = s.data() + s.size();
            uint64_t v = 0;
            const auto [ptr, ec] = std::from_chars(b, e, v);
            if (ec == std::errc() && ptr == e && b != e) return {};
            return "must be an integer in [0, 18446744073709551615], got \"" + excerpt(s) + "\"";
        },
        "UINT");
}

}  // namespace fluorosim::app
