// The widefield PSF tables (optics/widefield_psf.h): seconds to build the default table for matched
// indices (one table, 40x 0.8 NA water) and per wavelength node under a mismatch (cleared tissue n 1.45
// behind water, 100 um deep). Every channel of an acquisition builds these once.
#include <benchmark/benchmark.h>

#include "optics/widefield_psf.h"

namespace {

using fluorosim::optics::PupilOptions;
using fluorosim::optics::WidefieldPsf;

void BM_PsfTableMatched(benchmark::State& state) {
    PupilOptions p;
    p.na = 0.8;
    for (auto _ : state) benchmark::DoNotOptimize(WidefieldPsf(p).enclosed(0, 520));
}
BENCHMARK(BM_PsfTableMatched)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_PsfTablePerMismatchNode(benchmark::State& state) {
    PupilOptions p;
    p.na = 0.8;
    p.sampleIndex = 1.45;
    p.depthMm = 0.1;
    for (auto _ : state) benchmark::DoNotOptimize(WidefieldPsf(p, {}, {520}).enclosed(0, 520));
}
BENCHMARK(BM_PsfTablePerMismatchNode)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
