#pragma once
// Input echoed into an error message. Messages quote what the user wrote, but a value may be a 50 MB
// string or hold line breaks; `excerpt` keeps a message to one readable line.
#include <cstddef>
#include <string>
#include <string_view>

namespace fluorosim {

inline constexpr size_t kExcerptChars = 80;

// `text` with control characters escaped (\n, \t, \xNN) and cut after `maxChars` characters with
// "..." and the full length, e.g. "aaaa... (52428800 characters)". Cuts never split a UTF-8 sequence.
std::string excerpt(std::string_view text, size_t maxChars = kExcerptChars);

// A number as a message shows it: 6 significant digits, no trailing zeros ("0.406", "1e-07").
std::string messageNumber(double v);

}  // namespace fluorosim
