#pragma once
// Drives the path tracer over the image in passes. Random streams are keyed on (seed, pixel,
// sample index), so the image does not depend on the thread count or on where a run was
// interrupted and resumed, and a cancelled run keeps every finished pass.
#include <atomic>
#include <functional>

#include "render/film.h"
#include "render/light_tracer.h"
#include "render/path_tracer.h"

namespace fluorosim {

inline constexpr double kMinPathsPerPass = 65536;

struct RenderOptions {
    int spp = 16;
    int threads = 0;        // 0 = all cores
    uint64_t seed = 1;
    // Granularity of checkpoints and of what a cancellation keeps. 0 = automatic: the fewest samples
    // per pixel that give a pass kMinPathsPerPass paths, so a small image's passes are not so short
    // that synchronising the threads costs more than tracing. The image is the same for any value.
    int sppPerPass = 1;
    // Samples per pixel the film already holds (a resumed checkpoint): passes start there, and the
    // image equals an uninterrupted render of `spp` samples bit for bit.
    int firstSample = 0;
    // The film holds camera rows [firstRow, firstRow + film height): a band of the image rendered apart
    // (distributed renders). Its samples are those of the whole image's render, keyed by absolute pixel.
    int firstRow = 0;
    // 0 = none. Otherwise passes stop once this many seconds have passed since the call began: the film
    // holds the passes finished by then (RenderSummary::timeBudgetSpent), exactly a render of that spp.
    double timeBudgetSeconds = 0;
    // Checked between pixels: a set flag abandons the pass in progress within about one path per
    // thread, and the film keeps its last finished pass.
    const std::atomic<bool>* cancel = nullptr;
    std::function<void(double fractionDone)> progress;            // called from one thread at a time
    // After each finished pass, with the statistics of this call's finished passes: checkpoints.
    std::function<void(const Film&, int sppDone, const PathStats& stats)> passFinished;
    void validate() const;  // throws ConfigError
};

struct RenderSummary {
    int sppCompleted = 0;   // samples per pixel in the film, including firstSample
    double seconds = 0;
    PathStats stats;
    uint64_t nonFiniteSamples = 0;
    bool cancelled = false;
    bool timeBudgetSpent = false;  // stopped before `spp` because RenderOptions::timeBudgetSeconds passed
    LightTraceStats light;         // Integrator::Light: the photons of this call's finished passes
};

RenderSummary render(const Scene& scene, Film& film, const RenderOptions& options);

// Samples per pixel in each pass of render() for an image of width x rows (options.sppPerPass resolved).
int samplesPerPass(const RenderOptions& options, int width, int rows);

// Primary ray through pixel (x, y) jittered by (u1, u2).
Ray cameraRay(const Camera& camera, int x, int y, double u1, double u2);

}  // namespace fluorosim
