// Slab photons per second (MCML classic case), on 1 and 2 threads.
#include <benchmark/benchmark.h>

#include "render/slab_transport.h"

namespace {

void BM_SlabClassicMcml(benchmark::State& state) {
    fluorosim::SlabOptions o;
    o.mua = 1.0;  // 10 /cm
    o.mus = 9.0;  // 90 /cm
    o.g = 0.75;
    o.thickness = 0.2;  // 0.02 cm
    o.photons = 2000000;
    o.threads = static_cast<int>(state.range(0));
    double rd = 0, rdErr = 0;
    for (auto _ : state) {
        const auto r = fluorosim::simulateSlab(o);
        rd = r.Rd;
        rdErr = r.RdStderr;
        ++o.seed;
    }
    state.counters["photons_per_s"] = benchmark::Counter(static_cast<double>(o.photons) * static_cast<double>(state.iterations()),
                                                         benchmark::Counter::kIsRate);
    state.counters["Rd"] = rd;
    state.counters["Rd_err_vs_vdHulst"] = rd - 0.09739;
    state.counters["Rd_stderr"] = rdErr;
}
BENCHMARK(BM_SlabClassicMcml)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

}  // namespace
