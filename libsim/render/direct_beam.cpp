#include "render/direct_beam.h"

#include <algorithm>
#include <cmath>

#include "core/math.h"
#include "core/sampling.h"

namespace fluorosim {
namespace {

constexpr double kCellNm = 1.0;    // resolution of the camera wavelength density

SampledWavelengths atWavelength(double lambdaNm) { return SampledWavelengths::atLine(lambdaNm, 1.0); }

}  // namespace

DirectBeamEstimator::DirectBeamEstimator(const Scene& scene, const PathTracer& tracer, std::function<double(double)> detection)
    : scene_(scene), tracer_(tracer), detection_(std::move(detection)) {
    lines_ = beamLines(tracer.lights());
    if (lines_.empty()) return;

    // The camera wavelength of the fluorescence follows Σ_i Φ_i σa,i(lines; c_max) f_i(λ) detection(λ)
    // over every emitting dye, mixed with 5 % uniform so that no wavelength with signal is missed.
    const FluorescencePlan& plan = tracer.fluorescence();
    lambdaMin_ = scene.spectral.lambdaMin;
    const int cells = std::max(1, static_cast<int>(std::ceil((scene.spectral.lambdaMax - lambdaMin_) / kCellNm)));
    cellWidth_ = (scene.spectral.lambdaMax - lambdaMin_) / cells;
    std::vector<double> density(static_cast<size_t>(cells), 0.0);
    double fluorescence = 0;  // ∫ of the density, a rough size of the fluorescent signal
    for (size_t m = 0; m < scene.media.size(); ++m) {
        if (!plan.active(static_cast<int>(m))) continue;
        const Medium& med = scene.media[m];
        for (size_t i = 0; i < med.dyes().size(); ++i) {
            const Fluorophore& dye = med.dyes()[i].dye;
            double excitation = 0;
            for (const BeamLine& l : lines_) excitation += l.weight * dyeAbsorption(dye, l.lambdaNm, med.channelMax()[kFirstDyeChannel + i]);
            const double a = dye.quantumYield() * excitation;
            if (!(a > 0)) continue;
            for (int c = 0; c < cells; ++c) {
                const double lo = lambdaMin_ + c * cellWidth_;
                double v = 0;
                for (double f : {0.0, 0.25, 0.5, 0.75, 1.0}) v += dye.emissionPdf(lo + f * cellWidth_) * detection_(lo + f * cellWidth_) / 5;
                density[static_cast<size_t>(c)] += a * v;
                fluorescence += a * v * cellWidth_ * kInv4Pi;
            }
        }
    }
    bool fluorescent = false;
    for (size_t m = 0; m < scene.media.size(); ++m) fluorescent = fluorescent || plan.active(static_cast<int>(m));
    // Elastic light of each line: singly scattered by the tissue and weighed by the detection there.
    double elasticTotal = 0;
    std::vector<double> elastic;
    for (const BeamLine& l : lines_) {
        double sigmaS = 0;
        for (const Medium& m : scene.media) sigmaS = std::max(sigmaS, m.scatteringAt(l.lambdaNm) * m.channelMax()[kScatteringChannel]);
        elastic.push_back(l.weight * sigmaS * kInv4Pi * detection_(l.lambdaNm));
        elasticTotal += elastic.back();
    }
    lineMass_.assign(lines_.size(), 0.0);
    double lineTotal = 0;
    for (size_t i = 0; i < lines_.size(); ++i) {
        if (!(elastic[i] > 0)) continue;
        lineMass_[i] = fluorescent ? std::clamp(elastic[i] / (fluorescence + elasticTotal), 0.02, 0.5) : elastic[i] / elasticTotal;
        lineTotal += lineMass_[i];
    }
    if (lineTotal > 0.9 && fluorescent)
        for (double& m : lineMass_) m *= 0.9 / lineTotal;
    lineTotal = 0;
    for (double m : lineMass_) lineTotal += m;
    fluorescenceProbability_ = fluorescent ? 1 - lineTotal : 0.0;
    if (!fluorescent && !(lineTotal > 0)) {
        lines_.clear();  // nothing the direct estimator could see
        return;
    }
    double sum = 0;
    for (double d : density) sum += d;
    cellPdf_.resize(density.size());
    cellCdf_.resize(density.size());
    double acc = 0;
    for (size_t c = 0; c < density.size(); ++c) {
        const double p = (sum > 0 ? 0.95 * density[c] / sum : 0.0) + (sum > 0 ? 0.05 : 1.0) / cells;
        cellPdf_[c] = p / cellWidth_;
        acc += p;
        cellCdf_[c] = acc;
    }
    cellCdf_.back() = 1.0;
}

DirectBeamEstimator::Component DirectBeamEstimator::sampleComponent(double u) const {
    Component c;
    for (size_t i = 0; i < lines_.size(); ++i) {
        if (u < lineMass_[i]) {
            c.lambdaNm = lines_[i].lambdaNm;
            c.weight = 1.0 / lineMass_[i];
            c.elasticLine = static_cast<int>(i);
            return c;
        }
        u -= lineMass_[i];
    }
    if (!(fluorescenceProbability_ > 0)) return c;  // weight 0: nothing to estimate
    u = std::clamp(u / fluorescenceProbability_, 0.0, 1.0);
    const size_t cell = std::min(cellPdf_.size() - 1, static_cast<size_t>(std::upper_bound(cellCdf_.begin(), cellCdf_.end(), u) - cellCdf_.begin()));
    const double before = cell == 0 ? 0.0 : cellCdf_[cell - 1], mass = cellCdf_[cell] - before;
    const double f = mass > 0 ? std::clamp((u - before) / mass, 0.0, 1.0) : 0.5;
    c.lambdaNm = lambdaMin_ + (static_cast<double>(cell) + f) * cellWidth_;
    c.weight = 1.0 / (fluorescenceProbability_ * cellPdf_[cell]);
    return c;
}

void DirectBeamEstimator::addSample(Pixel& pixel, const Ray& ray, int medium, const Component& component, double uPoints,
                                    double scale) const {
    ++pixel.samples;
    if (!(component.weight > 0)) return;
    const double detection = detection_(component.lambdaNm) * component.weight * scale;
    if (!(detection > 0)) return;
    std::array<RaySegment, kMaxRaySegments> segments;
    const int count = straightSegments(scene_, ray, medium, 0.0, segments);
    const FluorescencePlan& plan = tracer_.fluorescence();
    const bool elastic = component.elasticLine >= 0;
    std::vector<CorePoint>& points = pixel.scratch;
    points.clear();
    for (size_t li = 0; li < lines_.size(); ++li) {
        if (elastic && static_cast<int>(li) != component.elasticLine) continue;
        const BeamLine& line = lines_[li];
        // The source per unit of each channel (it is linear in the channels).
        addCorePoints(scene_, line, static_cast<int>(li), ray, segments.data(), count, uPoints, [&](int m, int side) {
            std::array<double, kMaxMediumChannels> perChannel{};
            const Medium& med = scene_.media[static_cast<size_t>(m)];
            if (elastic) {
                perChannel[kScatteringChannel] = med.scatteringAt(line.lambdaNm) * med.phase().pdf(ray.d, -line.profile->direction(side));
            } else if (plan.active(m)) {
                perChannel = plan.kernelPerMolar(m, line.lambdaNm, component.lambdaNm);
                for (double& k : perChannel) k *= kInv4Pi;
            }
            return perChannel;
        }, points);
    }
    double sampleSum = 0;
    for (CorePoint& p : points) {
        p.weight *= detection;
        sampleSum += p.weight;
        pixel.points.push_back({p, ray.o, medium, component.lambdaNm});
    }
    pixel.sum += sampleSum;
    pixel.sum2 += sampleSum * sampleSum;
}

DirectBeamEstimator::Estimate DirectBeamEstimator::finish(const Pixel& pixel, int picks, double uPick, Rng& rng) const {
    Estimate e;
    if (pixel.samples == 0 || !(pixel.sum > 0) || picks < 1) return e;
    const double n = pixel.samples;
    // Systematic picks: point i is chosen with probability weight_i / sum at every pick.
    double tSum = 0, tSum2 = 0;
    double cumulative = 0;
    size_t i = 0;
    for (int m = 0; m < picks; ++m) {
        const double target = (m + uPick) / picks * pixel.sum;
        while (i + 1 < pixel.points.size() && cumulative + pixel.points[i].core.weight <= target) cumulative += pixel.points[i++].core.weight;
        const Point& p = pixel.points[i];
        const BeamLine& line = lines_[static_cast<size_t>(p.core.line)];
        double T = tracer_.transmittance(p.origin, p.core.y, p.cameraMedium, atWavelength(p.cameraLambda), rng)[0];
        if (T > 0)
            T *= tracer_.beamTransmittance(p.core.y, -line.profile->direction(p.core.side), p.core.medium, atWavelength(line.lambdaNm), rng)[0];
        tSum += T;
        tSum2 += T * T;
    }
    const double meanT = tSum / picks, meanA = pixel.sum / n;
    e.mean = meanA * meanT;
    const double varA = n > 1 ? std::max(0.0, pixel.sum2 / n - meanA * meanA) / (n - 1) : 0.0;
    const double varT = picks > 1 ? std::max(0.0, tSum2 / picks - meanT * meanT) / (picks - 1) : 0.0;
    e.variance = varA * meanT * meanT + meanA * meanA * varT;
    return e;
}

}  // namespace fluorosim
