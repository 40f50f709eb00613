#pragma once
// Typed exceptions: library code throws these and never exits or prints; apps catch them.
#include <stdexcept>
#include <string>

namespace fluorosim {

struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};
// Invalid user input: scene fields, options, spectra. The message names file, field and value.
struct ConfigError : Error {
    using Error::Error;
};
// A file cannot be read or written.
struct IoError : Error {
    using Error::Error;
};
// A computation produced a non-finite or impossible value.
struct NumericError : Error {
    using Error::Error;
};
// Work stopped because the caller's cancel flag was set (Ctrl-C); what finished is the caller's to keep.
struct Cancelled : Error {
    using Error::Error;
};

}  // namespace fluorosim
