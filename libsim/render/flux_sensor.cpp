#include "render/flux_sensor.h"

#include <chrono>

#include "core/errors.h"
#include "core/math.h"
#include "core/parallel.h"
#include "core/sampling.h"

namespace fluorosim {

FluxSensorResult measureExitantFlux(const Scene& scene, const FluxSensorOptions& o) {
    if (!(o.radius > 0) || o.paths == 0) throw ConfigError("flux sensor: radius and path count must be positive");
    const auto start = std::chrono::steady_clock::now();
    const PathTracer tracer(scene);
    const WavelengthSampler wavelengths = cameraWavelengthSampler(scene, tracer.fluorescence().active());
    const double areaTimesPi = 4 * kPi * sqr(o.radius) * 1e-6 * kPi;  // mm^2 -> m^2
    const size_t bins = o.binEdgesNm.empty() ? 0 : o.binEdgesNm.size() - 1;
    struct Batch {
        Accumulator power, powerLambda, elastic;
        std::vector<Accumulator> bins;
        PathStats stats;
    };
    constexpr uint64_t kBatch = 1024;
    const uint64_t batches = (o.paths + kBatch - 1) / kBatch;
    std::vector<Batch> perBatch(batches);
    parallelFor(batches, o.threads, [&](size_t b) {
        Batch& t = perBatch[b];
        t.bins.resize(bins);
        std::vector<double> binValue(bins);
        const uint64_t end = std::min(o.paths, (b + 1) * kBatch);
        for (uint64_t i = b * kBatch; i < end; ++i) {
            Rng rng = Rng::forKey(o.seed, i, 0x666c7578);
            const SampledWavelengths wl = wavelengths.sample(rng.uniform(), rng.uniform());
            const Vec3 n = sampleUniformSphere(rng.uniform(), rng.uniform());
            const Vec3 local = sampleCosineHemisphere(rng.uniform(), rng.uniform());
            const Vec3 dir = Frame::fromNormal(-n).toWorld(local);
            const PathRadiance L = tracer.radiance(Ray{o.center + n * o.radius, dir}, kNone, wl, rng, t.stats);
            double power = 0, powerLambda = 0, elastic = 0;
            std::fill(binValue.begin(), binValue.end(), 0.0);
            for (int k = 0; k < kNumWavelengths; ++k) {
                if (wl.pdf[k] == 0) continue;
                const double f = L.fluorescent[k] / wl.pdf[k] / kNumWavelengths * areaTimesPi;
                power += f;
                powerLambda += f * wl.lambda[k];
                elastic += L.elastic[k] / wl.pdf[k] / kNumWavelengths * areaTimesPi;
                for (size_t q = 0; q < bins; ++q)
                    if (wl.lambda[k] >= o.binEdgesNm[q] && wl.lambda[k] < o.binEdgesNm[q + 1]) binValue[q] += f;
            }
            t.power.add(power);
            t.powerLambda.add(powerLambda);
            t.elastic.add(elastic);
            for (size_t q = 0; q < bins; ++q) t.bins[q].add(binValue[q]);
        }
    });
    FluxSensorResult r;
    Accumulator power, powerLambda, elastic;
    std::vector<Accumulator> binAcc(bins);
    for (const Batch& t : perBatch) {
        power.merge(t.power);
        powerLambda.merge(t.powerLambda);
        elastic.merge(t.elastic);
        for (size_t q = 0; q < bins; ++q) binAcc[q].merge(t.bins[q]);
        r.stats.add(t.stats);
    }
    const double n = static_cast<double>(o.paths);
    r.fluorescentPower = power.value(n);
    r.fluorescentPowerTimesLambda = powerLambda.value(n);
    r.elasticPower = elastic.value(n);
    for (const Accumulator& a : binAcc) r.binPower.push_back(a.value(n));
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return r;
}

}  // namespace fluorosim
