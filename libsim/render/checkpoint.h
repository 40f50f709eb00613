#pragma once
// Render checkpoints: the film's accumulators bit for bit, with what is needed to continue the render
// and to refuse a checkpoint that belongs to another one. A render continued from a checkpoint gives
// the same image, bit for bit, as an uninterrupted one: every sample draws from its own stream
// (seed, pixel, sample index), and each pixel's sums are formed in sample order either way.
//
// The file is binary in the machine's byte order, written under a temporary name and renamed, and
// ends with a 64-bit FNV-1a checksum of everything before it, so a truncated or damaged file is
// recognised.
#include <cstdint>
#include <string>

#include "render/film.h"
#include "render/path_tracer.h"

namespace fluorosim {

struct RenderCheckpoint {
    uint64_t sceneHash = 0;       // of the scene file's text (fnv1a64)
    uint64_t seed = 0;
    std::string fluorescence;     // the model's name
    std::string integrator;       // integratorName()
    int sppDone = 0;              // samples per pixel in the film
    int sppTarget = 0;            // what the interrupted run was asked for
    double seconds = 0;           // rendering time so far
    PathStats stats;              // of the passes in the film
};

// Writes `film` and `c` to `path` (through `path`.partial). Throws IoError.
void writeCheckpoint(const std::string& path, const RenderCheckpoint& c, const Film& film);
// Reads a checkpoint into `film`, which must have the checkpoint's size. Throws IoError for a file that
// cannot be read or is damaged, ConfigError for one of another film size.
RenderCheckpoint readCheckpoint(const std::string& path, Film& film);

uint64_t fnv1a64(const void* data, size_t bytes, uint64_t hash = 0xcbf29ce484222325ull);

}  // namespace fluorosim
