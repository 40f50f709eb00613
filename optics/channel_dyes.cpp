#include "optics/channel_dyes.h"

#include <algorithm>
#include <cmath>

namespace fluorosim::optics {

void quantileNodes(const std::vector<double>& density, double lo, double step, int count, std::vector<double>& lambda,
                   std::vector<double>& weight) {
    double total = 0;
    for (double d : density) total += d;
    lambda.clear();
    weight.clear();
    if (!(total > 0)) return;
    double mass = 0, moment = 0, acc = 0;
    int bin = 0;
    for (size_t c = 0; c < density.size(); ++c) {
        const double m = density[c] / total, centre = lo + (static_cast<double>(c) + 0.5) * step;
        acc += m;
        mass += m;
        moment += m * centre;
        const bool last = c + 1 == density.size();
        if (acc >= double(bin + 1) / count - 1e-12 || last) {
            if (mass > 0) {
                lambda.push_back(moment / mass);
                weight.push_back(mass);
            }
            mass = moment = 0;
            while (bin < count && acc >= double(bin + 1) / count - 1e-12) ++bin;
        }
    }
}

const EmittingDye* ChannelDyes::dyeOf(int medium, int slot) const {
    if (medium < 0 || static_cast<size_t>(medium) >= firstOfMedium.size() || firstOfMedium[static_cast<size_t>(medium)] < 0) return nullptr;
    const size_t i = static_cast<size_t>(firstOfMedium[static_cast<size_t>(medium)] + slot);
    return i < dyes.size() && dyes[i].medium == medium ? &dyes[i] : nullptr;
}

ChannelDyes channelDyes(const Scene& scene, const std::vector<BeamLine>& lines, const FluorescencePlan& plan,
                        const std::function<double(double)>& detection, int spectralNodes, const std::vector<double>& lineIrradiance,
                        double dropBelow) {
    ChannelDyes c;
    for (const BeamLine& l : lines) c.lineLambda.push_back(l.lambdaNm);
    c.firstOfMedium.assign(scene.media.size(), -1);
    if (lines.empty() || !plan.active()) return c;

    // The detected band: the camera wavelengths the paths would use (the scene's range), on 0.5 nm cells.
    const double lo = scene.spectral.lambdaMin, hi = scene.spectral.lambdaMax, cell = 0.5;
    const int cells = std::max(1, static_cast<int>(std::ceil((hi - lo) / cell)));
    const double width = (hi - lo) / cells;
    std::vector<double> channelDensity(static_cast<size_t>(cells), 0.0);
    std::vector<std::vector<double>> dyeDensity;
    for (size_t med = 0; med < scene.media.size(); ++med) {
        if (!plan.active(static_cast<int>(med))) continue;
        const Medium& medium = scene.media[med];
        int slot = 0;
        for (size_t i = 0; i < medium.dyes().size(); ++i) {
            const Fluorophore& dye = medium.dyes()[i].dye;
            const int channel = kFirstDyeChannel + static_cast<int>(i);
            if (!(dye.quantumYield() > 0) || !(medium.channelMax()[static_cast<size_t>(channel)] > 0)) continue;
            EmittingDye t;
            t.medium = static_cast<int>(med);
            t.channel = channel;
            t.name = dye.id();
            t.quantumYield = dye.quantumYield();
            bool excited = false;
            for (const BeamLine& l : lines) {
                t.absorptionPerMolar.push_back(dyeAbsorption(dye, l.lambdaNm, 1.0));
                excited = excited || t.absorptionPerMolar.back() > 0;
            }
            std::vector<double> density(static_cast<size_t>(cells));
            for (int k = 0; k < cells; ++k) {
                const double lambda = lo + (k + 0.5) * width;
                density[static_cast<size_t>(k)] = dye.emissionPdf(lambda) * detection(lambda) / lambda * width;
                t.detected += density[static_cast<size_t>(k)];
            }
            if (!excited || !(t.detected > 0)) continue;
            quantileNodes(density, lo, width, spectralNodes, t.nodeLambda, t.nodeWeight);
            for (int k = 0; k < cells; ++k) channelDensity[static_cast<size_t>(k)] += density[static_cast<size_t>(k)] / t.detected;
            t.slot = slot++;
            if (c.firstOfMedium[med] < 0) c.firstOfMedium[med] = static_cast<int>(c.dyes.size());
            dyeDensity.push_back(std::move(density));
            c.dyes.push_back(std::move(t));
        }
        c.slots = std::max(c.slots, slot);
    }
    // Dyes far less efficient than the channel's best, per mol/L: Φ D Σ_l σa(λ_l; 1 M) λ_l E_l.
    if (!lineIrradiance.empty() && dropBelow > 0 && !c.dyes.empty()) {
        std::vector<double> efficiency;
        double best = 0;
        for (const EmittingDye& t : c.dyes) {
            double e = 0;
            for (size_t l = 0; l < t.absorptionPerMolar.size() && l < lineIrradiance.size(); ++l)
                e += t.absorptionPerMolar[l] * c.lineLambda[l] * lineIrradiance[l];
            efficiency.push_back(e * t.quantumYield * t.detected);
            best = std::max(best, efficiency.back());
        }
        ChannelDyes kept;
        kept.lineLambda = c.lineLambda;
        kept.firstOfMedium.assign(scene.media.size(), -1);
        std::vector<std::vector<double>> keptDensity;
        std::vector<int> slot(scene.media.size(), 0);
        for (size_t i = 0; i < c.dyes.size(); ++i) {
            EmittingDye t = c.dyes[i];
            if (efficiency[i] < dropBelow * best) continue;
            t.slot = slot[static_cast<size_t>(t.medium)]++;
            if (kept.firstOfMedium[static_cast<size_t>(t.medium)] < 0) kept.firstOfMedium[static_cast<size_t>(t.medium)] = static_cast<int>(kept.dyes.size());
            keptDensity.push_back(dyeDensity[i]);
            kept.dyes.push_back(std::move(t));
        }
        for (int n : slot) kept.slots = std::max(kept.slots, n);
        std::fill(channelDensity.begin(), channelDensity.end(), 0.0);
        for (size_t i = 0; i < kept.dyes.size(); ++i)
            for (int k = 0; k < cells; ++k) channelDensity[static_cast<size_t>(k)] += keptDensity[i][static_cast<size_t>(k)] / kept.dyes[i].detected;
        c = std::move(kept);
        dyeDensity = std::move(keptDensity);
    }
    if (c.dyes.empty()) return c;
    // The cone-mean transmittance is kept at the centroids of four equal-mass parts of the channel's
    // detected emission; each dye weighs them by its own mass in each part.
    std::vector<double> camLambda, camWeight;
    quantileNodes(channelDensity, lo, width, kNumWavelengths, camLambda, camWeight);
    for (int j = 0; j < kNumWavelengths; ++j)
        c.cameraLambda[static_cast<size_t>(j)] = camLambda[std::min(camLambda.size() - 1, static_cast<size_t>(j))];
    for (size_t ti = 0; ti < c.dyes.size(); ++ti) {
        EmittingDye& t = c.dyes[ti];
        for (int k = 0; k < cells; ++k) {
            const double lambda = lo + (k + 0.5) * width;
            size_t nearest = 0;
            for (size_t j = 1; j < kNumWavelengths; ++j)
                if (std::abs(lambda - c.cameraLambda[j]) < std::abs(lambda - c.cameraLambda[nearest])) nearest = j;
            t.cameraWeights[nearest] += dyeDensity[ti][static_cast<size_t>(k)] / t.detected;
        }
    }
    // The pixel quadrature follows the PSF's band up to the shortest detected wavelength that matters.
    double below = 0;
    c.shortestDetectedNm = hi;
    for (int k = 0; k < cells; ++k) {
        below += channelDensity[static_cast<size_t>(k)] / static_cast<double>(c.dyes.size());
        if (below >= 1e-3) {
            c.shortestDetectedNm = lo + k * width;
            break;
        }
    }
    return c;
}

}  // namespace fluorosim::optics
