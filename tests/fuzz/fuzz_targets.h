#pragma once
// Bodies of the libFuzzer harnesses, as ordinary functions: tests/fuzz/fuzz_*.cpp wrap them for
// libFuzzer (clang, FLUOROSIM_BUILD_FUZZERS), and tests/unit/fuzz_corpus_test.cpp replays the
// corpora in tests/fuzz/corpus through them in the normal (gcc) suite.
//
// Each takes arbitrary bytes, expects fluorosim::Error for bad input and nothing else, and checks what
// an accepted input must satisfy; a broken invariant throws std::logic_error (a crash under libFuzzer).
#include <cstddef>
#include <cstdint>

namespace fluorosim::fuzz {

// The bytes are a scene file's text (loadSceneFromString with the spectral database, dyes and light
// sheets), read as if the file lay in samples/cornell so that relative references resolve.
int sceneLoader(const uint8_t* data, size_t size);
// The bytes are an SWC file (parseSwc), whose morphology is then turned into pieces and a volume.
int swcReader(const uint8_t* data, size_t size);
// The bytes are a spectrum CSV file; every column named in its header after wavelength_nm is read.
int spectraCsv(const uint8_t* data, size_t size);
// Byte 0 picks the dimension, byte 1 whether a bare number has a default unit; the rest is the text
// given to parseQuantity and unitScale.
int units(const uint8_t* data, size_t size);

}  // namespace fluorosim::fuzz
