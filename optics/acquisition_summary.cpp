#include "optics/acquisition_summary.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/math.h"

namespace fluorosim::optics {
namespace {

double median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    return v[v.size() / 2];
}

std::string formatted(const char* format, auto... args) {
    char buffer[1024];
    std::snprintf(buffer, sizeof buffer, format, args...);
    return buffer;
}

}  // namespace

AcquisitionSummary::Saturation AcquisitionSummary::saturation(const Stack& stack, const DetectorOptions& detector) {
    Saturation out;
    const double fullWell = detector.fullWellElectrons;
    const size_t planePixels = static_cast<size_t>(stack.width) * stack.height;
    for (size_t i = 0; i < stack.expected.size(); ++i) {
        const double e = stack.expected[i], stderrE = stack.stderrElectrons[i];
        out.brightest = std::max(out.brightest, e);
        if (!(e > fullWell)) continue;
        ++out.pixels;
        if (!(e - 4 * stderrE < fullWell)) continue;
        // The expected electrons hold the dark current already.
        const size_t pixel = planePixels > 0 ? i % planePixels : 0;
        if (sqr(stderrE) > e + sqr(detector.readNoiseAt(pixel)))
            ++out.monteCarlo;
        else
            ++out.borderline;
    }
    return out;
}

AcquisitionSummary::AcquisitionSummary(const Microscope& m, const Stack& stack, const AcquireOptions& options)
    : options_(options), darkElectrons_(m.detector.darkCurrentElectronsPerS * m.detector.exposureS), readNoise_(m.detector.readNoiseElectrons) {
    for (size_t c : stack.channels) channelNames_.push_back(m.channels[c].name);
}

std::string AcquisitionSummary::addPlane(size_t slot, int plane, const PlaneImage& image) {
    stats_.add(image.stats);
    seconds_ += image.seconds;
    largest_ = std::max(largest_, image.largestSample);
    largestOverPixel_ = std::max(largestOverPixel_, image.largestSampleOverPixel);
    computedSum_ += image.computedElectrons;
    pathSum_ += image.pathElectrons;
    pooledSum_ += image.pooledElectrons;
    computedSeconds_ += image.computedSeconds;
    pathSeconds_ += image.pathSeconds;
    computedPoints_ += image.computedPoints;
    computedDropped_ = std::max(computedDropped_, image.computedDroppedFraction);
    computedTimings_.lattice += image.computedTimings.lattice;
    computedTimings_.transmittances += image.computedTimings.transmittances;
    computedTimings_.gains += image.computedTimings.gains;
    computedTimings_.projection += image.computedTimings.projection;
    computedTimings_.kernelThreadSeconds += image.computedTimings.kernelThreadSeconds;
    nonFinite_ += image.nonFiniteSamples;
    fieldPhotons_ += image.fieldPhotons;
    fieldSeconds_ += image.fieldSeconds;
    fieldSum_ += image.fieldElectrons;
    if (image.fieldLateralSpacingUm > 0)
        fieldSpacingUm_ = fieldSpacingUm_ > 0 ? std::min(fieldSpacingUm_, image.fieldLateralSpacingUm) : image.fieldLateralSpacingUm;
    fieldMarginUm_ = std::max(fieldMarginUm_, image.fieldMarginUm);
    fieldReachUm_ = std::max(fieldReachUm_, image.fieldReachUm);
    fieldDiffuseSpacingUm_ = std::max(fieldDiffuseSpacingUm_, image.fieldDiffuseSpacingUm);
    emissionPhotons_ += image.emissionPhotons;
    emissionVertices_ += image.emissionVertices;
    emissionSeconds_ += image.emissionSeconds;
    emissionSum_ += image.emissionElectrons;
    pathSamples_ += image.pathSamples;
    pilotSamples_ += image.pilotSamples;
    if (image.pilotsOnLatticeOnly) ++pilotsOnLatticeOnlyPlanes_;
    pixels_ += image.electrons.size();
    if (image.electrons.empty()) return "";
    std::vector<double> sorted = image.electrons;
    std::sort(sorted.begin(), sorted.end());
    const double cut = sorted[static_cast<size_t>(0.9 * static_cast<double>(sorted.size() - 1))];
    const double cut1 = sorted[static_cast<size_t>(0.99 * static_cast<double>(sorted.size() - 1))];
    auto cameraVariance = [&](size_t i) { return std::max(0.0, image.electrons[i]) + darkElectrons_ + sqr(readNoise_); };
    const bool tracedVariance = image.emissionVariance.size() == image.electrons.size();
    for (size_t i = 0; i < image.electrons.size(); ++i) {
        const double camera = cameraVariance(i), variance = sqr(image.stderrElectrons[i]);
        mcOverCameraLargest_ = std::max(mcOverCameraLargest_, variance / camera);
        if (!(variance > camera)) continue;
        ++mcOverCameraAbove1_;
        const double traced = tracedVariance ? image.emissionVariance[i] : 0.0;
        if (traced > camera) ++tracedOverCameraAbove1_;
        if (variance - traced > camera) ++pathsOverCameraAbove1_;
    }
    const bool traced = image.emissionEstimates.size() >= 2;
    const size_t halfSlots = image.emissionEstimates.size() / 2;
    for (size_t i = 0; i < image.electrons.size(); ++i)
        if (image.electrons[i] >= cut) {
            const double camera = cameraVariance(i);
            mcOverCamera_.push_back(sqr(image.stderrElectrons[i]) / camera);
            if (image.electrons[i] > 0) pathRel_.push_back(image.stderrElectrons[i] / image.electrons[i]);
            std::array<std::optional<double>, kBudgetParts> part;
            if (!image.fieldHalfDifference.empty()) part[kFieldPart] = sqr(image.fieldHalfDifference[i]);
            double pathVariance = sqr(image.stderrElectrons[i]);
            if (traced) {
                double a = 0, b = 0;  // the two halves of the slots, each an estimate of the traced image
                for (size_t s = 0; s < 2 * halfSlots; ++s) (s < halfSlots ? a : b) += image.emissionEstimates[s][i] / double(halfSlots);
                part[kTracedPart] = sqr(0.5 * (a - b));
                if (!image.emissionVariance.empty()) pathVariance = std::max(0.0, pathVariance - image.emissionVariance[i]);
            }
            if (options_.spp > 1 || options_.noiseRatio) part[kPathsPart] = pathVariance;  // one path says nothing of its spread
            for (int k = 0; k < kBudgetParts; ++k) {
                if (!part[static_cast<size_t>(k)]) continue;
                budget_[static_cast<size_t>(k)][0].push_back(*part[static_cast<size_t>(k)] / camera);
                if (image.electrons[i] >= cut1) budget_[static_cast<size_t>(k)][1].push_back(*part[static_cast<size_t>(k)] / camera);
            }
        }
    double signal = 0;
    for (double e : image.electrons) signal += e;
    if (signal > 0) return "";
    return formatted("channel \"%s\", plane %d: no signal (the sheet or the focal plane misses the labelled volume)", channelNames_.at(slot).c_str(),
                     plane);
}

std::vector<AcquisitionSummary::Entry> AcquisitionSummary::entries(const Stack& stack, const Microscope& m, const std::optional<AutoExposure>& exposure,
                                                                   int ranks) const {
    float maxE = 0;
    for (float e : stack.expected) maxE = std::max(maxE, e);
    const Saturation sat = saturation(stack, m.detector);
    const double total = std::max(1e-300, computedSum_ + pathSum_ + emissionSum_);
    const auto perPath = [&](uint64_t n) { return double(n) / std::max<double>(1.0, double(stats_.paths)); };
    const double vertices = perPath(stats_.scatteringEvents + stats_.surfaceBounces);
    std::vector<Entry> e = {
        {"", "planes", double(stack.planes), false, true},
        {"", "channels", double(stack.channels.size()), false, true},
        {"", "width", double(stack.width), false, true},
        {"", "height", double(stack.height), false, true},
        {"", "pixel_size_um", m.pixelSizeMm() * 1e3},
        {"", "z_step_um", m.stack.stepMm * 1e3},
        {"", "spp", double(options_.spp), false, true},
        {"", "computed_electrons_fraction", computedSum_ / total},
        {"", "pooled_electrons_fraction", pooledSum_ / total},
        {"", "computed_seconds", computedSeconds_},
        {"", "computed_points", double(computedPoints_), false, true},
        // The largest share of a plane's computed photoelectrons left out with its faintest points.
        {"", "computed_dropped_fraction", computedDropped_},
        // Where the computed part's time went: S and the transmittances once per channel, then per plane
        // the sheet's gains and the projection.
        {"computed_timings", "lattice_seconds", computedTimings_.lattice},
        {"computed_timings", "transmittance_seconds", computedTimings_.transmittances},
        {"computed_timings", "gain_seconds", computedTimings_.gains},
        {"computed_timings", "projection_seconds", computedTimings_.projection},
        {"computed_timings", "kernel_thread_seconds", computedTimings_.kernelThreadSeconds},
        {"", "path_thread_seconds", pathSeconds_},
        // The excitation field (split estimator): the scattered excitation computed, not sampled.
        {"excitation_field", "photons", double(fieldPhotons_), false, true},
        {"excitation_field", "seconds", fieldSeconds_},
        {"excitation_field", "electrons_fraction", fieldSum_ / total},
        {"excitation_field", "lateral_spacing_um", fieldSpacingUm_, !(fieldSpacingUm_ > 0)},
        {"excitation_field", "margin_um", fieldMarginUm_, !(fieldSpacingUm_ > 0)},
        {"excitation_field", "reach_um", fieldReachUm_, !(fieldSpacingUm_ > 0)},
        {"excitation_field", "diffuse_spacing_um", fieldDiffuseSpacingUm_, !(fieldDiffuseSpacingUm_ > 0)},
        // Its noise (correlated across pixels; from the field's two halves) over the camera's, brightest 10 %.
        {"excitation_field", "median_noise_over_camera_variance_top10", median(budget_[kFieldPart][0]), budget_[kFieldPart][0].empty()},
        // The computed emission's scattered light, traced forward from its points (split estimator).
        {"scattered_emission", "photons", double(emissionPhotons_), false, true},
        {"scattered_emission", "vertices", double(emissionVertices_), false, true},
        {"scattered_emission", "seconds", emissionSeconds_},
        {"scattered_emission", "electrons_fraction", emissionSum_ / total},
        // The noise budget: each part's median noise variance over the camera's (docs/performance.md, "Where
        // the noise comes from").
        {"noise_budget", "excitation_field_top10", median(budget_[kFieldPart][0]), budget_[kFieldPart][0].empty()},
        {"noise_budget", "excitation_field_top1", median(budget_[kFieldPart][1]), budget_[kFieldPart][1].empty()},
        {"noise_budget", "scattered_emission_top10", median(budget_[kTracedPart][0]), budget_[kTracedPart][0].empty()},
        {"noise_budget", "scattered_emission_top1", median(budget_[kTracedPart][1]), budget_[kTracedPart][1].empty()},
        {"noise_budget", "paths_top10", median(budget_[kPathsPart][0]), budget_[kPathsPart][0].empty()},
        {"noise_budget", "paths_top1", median(budget_[kPathsPart][1]), budget_[kPathsPart][1].empty()},
        {"noise_budget", "scattered_emission_pixels_above_1", double(tracedOverCameraAbove1_), false, true},
        {"noise_budget", "paths_pixels_above_1", double(pathsOverCameraAbove1_), budget_[kPathsPart][0].empty(), true},
        {"", "median_relative_stderr_top10", median(pathRel_)},
        {"", "non_finite_samples", double(nonFinite_), false, true},
        {"", "largest_sample_over_pixel", largestOverPixel_},
        {"", "noise_ratio_target", options_.noiseRatio.value_or(0.0), !options_.noiseRatio},
        // The standard errors' own estimate (heavy tails make it optimistic; scripts/noise-vs-time.sh
        // measures with two seeds), at the scene's exposure.
        {"", "median_mc_over_camera_variance_top10", median(mcOverCamera_)},
        {"", "largest_mc_over_camera_variance", mcOverCameraLargest_},
        {"", "pixels_mc_over_camera_variance_above_1", double(mcOverCameraAbove1_), false, true},
        {"", "mean_path_spp", double(pathSamples_) / std::max<double>(1.0, double(pixels_))},
        {"", "pilot_paths", double(pilotSamples_), false, true},
        // Planes (per channel) whose pilot lattice found the paths at the target with spp, so that no other pixel drew pilots.
        {"", "pilots_on_lattice_only_planes", double(pilotsOnLatticeOnlyPlanes_), !options_.noiseRatio, true},
        {"", "ranks", double(ranks), false, true},
        {"", "seconds", seconds_},
        {"", "paths", double(stats_.paths), false, true},
        {"", "mean_path_vertices", vertices},
        // Free-flight work per path (real, null and fluorescence branch points) and excitation sub-paths started.
        {"", "mean_tentative_collisions", perPath(stats_.tentativeCollisions)},
        {"", "mean_fluorescence_branches", perPath(stats_.fluorescenceBranches)},
        {"", "truncated_paths", double(stats_.truncated), false, true},
        {"", "largest_sample_electrons", largest_},
        {"", "max_expected_electrons", double(maxE)},
        // Pixels expecting more than the full well; of them those Monte Carlo noise may have lifted there, and
        // those at about the full well by the light itself (Saturation).
        {"", "saturated_pixels", double(sat.pixels), false, true},
        {"", "saturated_monte_carlo_pixels", double(sat.monteCarlo), false, true},
        {"", "saturated_borderline_pixels", double(sat.borderline), false, true},
        {"", "full_well_electrons", m.detector.fullWellElectrons},
        {"", "exposure_s", m.detector.exposureS},
    };
    if (exposure) {
        e.push_back({"exposure_auto", "fraction", exposure->fraction});
        e.push_back({"exposure_auto", "factor", exposure->factor});
        e.push_back({"exposure_auto", "brightest_electrons_before", exposure->brightestElectrons});
    } else {
        e.push_back({"", "exposure_auto", 0.0, true});
    }
    return e;
}

std::vector<std::string> AcquisitionSummary::warnings(const Stack& stack, const Microscope& m) const {
    std::vector<std::string> out;
    // An adaptive run that stopped at its path limit says so, with the noise it reached.
    const double mcOverCameraMedian = median(mcOverCamera_);
    if (options_.noiseRatio && mcOverCameraMedian > sqr(*options_.noiseRatio) * 1.5)
        out.push_back(formatted("noise target %.3g missed: the Monte Carlo error over the camera's noise is %.3g (median over the brightest 10 %% "
                                "of pixels, as a ratio of standard deviations), at %.3g paths per pixel on average (--max-spp %d)",
                                *options_.noiseRatio, std::sqrt(mcOverCameraMedian), double(pathSamples_) / std::max<double>(1.0, double(pixels_)),
                                options_.maxSpp));
    const Saturation sat = saturation(stack, m.detector);
    if (sat.pixels > 0) {
        std::string which;
        if (sat.monteCarlo == sat.pixels)
            which = "; each is within 4 Monte Carlo standard errors of the full well, each error over the camera's noise (rare large samples: more "
                    "paths, not less exposure, may be what they need)";
        else if (sat.monteCarlo > 0)
            which = formatted("; %zu of them lie within 4 Monte Carlo standard errors of it, each error over the camera's noise (they may be Monte "
                              "Carlo noise)",
                              sat.monteCarlo);
        out.push_back(formatted("%zu of %zu pixels expect more than the full well (%.3g e-; brightest %.3g e-): the camera saturates there%s", sat.pixels,
                                stack.expected.size(), m.detector.fullWellElectrons, sat.brightest, which.c_str()));
    }
    return out;
}

}  // namespace fluorosim::optics
