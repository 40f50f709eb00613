#include "optics/concentration_fit.h"

#include <ceres/ceres.h>
#include <ceres/covariance.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <numeric>

#include "core/errors.h"
#include "core/message.h"
#include "core/units.h"
#include "optics/emission_labels.h"

namespace fluorosim::optics {
namespace {

double secondsSince(std::chrono::steady_clock::time_point t) { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(); }

std::string format(const char* fmt, double a, double b = 0, double c = 0, double d = 0) {
    char buf[256];
    std::snprintf(buf, sizeof buf, fmt, a, b, c, d);
    return buf;
}

class PixelBlockCost final : public ceres::CostFunction {
public:
    PixelBlockCost(std::vector<double> x, std::vector<double> b, Eigen::MatrixXd A, double shift, double f2, FitLikelihood likelihood)
        : x_(std::move(x)), b_(std::move(b)), A_(std::move(A)), shift_(shift), f2_(f2), lambdaMin_(std::max(shift / f2, 1e-12)), likelihood_(likelihood) {
        set_num_residuals(static_cast<int>(x_.size()));
        for (Eigen::Index j = 0; j < A_.cols(); ++j) mutable_parameter_block_sizes()->push_back(1);
    }
    bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
        for (size_t i = 0; i < x_.size(); ++i) {
            double mu = b_[i];
            for (Eigen::Index j = 0; j < A_.cols(); ++j) mu += A_(static_cast<Eigen::Index>(i), j) * parameters[j][0];
            const double lambda = std::max((mu + shift_) / f2_, lambdaMin_);
            double r, dr;
            if (likelihood_ == FitLikelihood::Deviance) {
                const DevianceResidual d = devianceResidual(x_[i], lambda, lambdaMin_);
                r = d.r;
                dr = d.dr;
            } else {
                const double s = std::sqrt(lambda);
                r = (x_[i] - lambda) / s;
                dr = -1 / s - 0.5 * (x_[i] - lambda) / (lambda * s);
            }
            residuals[i] = r;
            if (jacobians)
                for (Eigen::Index j = 0; j < A_.cols(); ++j)
                    if (jacobians[j]) jacobians[j][i] = dr * A_(static_cast<Eigen::Index>(i), j) / f2_;
        }
        return true;
    }

private:
    std::vector<double> x_, b_;
    Eigen::MatrixXd A_;
    double shift_, f2_, lambdaMin_;
    FitLikelihood likelihood_;
};

// Fisher-weighted residuals at fixed λ̂: (x − λ(θ)) / √λ̂, whitened, for the covariance.
class FisherBlockCost final : public ceres::CostFunction {
public:
    FisherBlockCost(std::vector<double> x, std::vector<double> b, std::vector<double> weight, Eigen::MatrixXd A, double shift, double f2)
        : x_(std::move(x)), b_(std::move(b)), w_(std::move(weight)), A_(std::move(A)), shift_(shift), f2_(f2) {
        set_num_residuals(static_cast<int>(x_.size()));
        for (Eigen::Index j = 0; j < A_.cols(); ++j) mutable_parameter_block_sizes()->push_back(1);
    }
    bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
        for (size_t i = 0; i < x_.size(); ++i) {
            double mu = b_[i];
            for (Eigen::Index j = 0; j < A_.cols(); ++j) mu += A_(static_cast<Eigen::Index>(i), j) * parameters[j][0];
            residuals[i] = (x_[i] - (mu + shift_) / f2_) * w_[i];
            if (jacobians)
                for (Eigen::Index j = 0; j < A_.cols(); ++j)
                    if (jacobians[j]) jacobians[j][i] = -A_(static_cast<Eigen::Index>(i), j) / f2_ * w_[i];
        }
        return true;
    }

private:
    std::vector<double> x_, b_, w_;
    Eigen::MatrixXd A_;
    double shift_, f2_;
};

// √α (θ_a − θ_b): the gradient prior between neighbouring grid nodes.
class DifferenceCost final : public ceres::SizedCostFunction<1, 1, 1> {
public:
    explicit DifferenceCost(double sqrtAlpha) : s_(sqrtAlpha) {}
    bool Evaluate(double const* const* p, double* r, double** J) const override {
        r[0] = s_ * (p[0][0] - p[1][0]);
        if (J) {
            if (J[0]) J[0][0] = s_;
            if (J[1]) J[1][0] = -s_;
        }
        return true;
    }

private:
    double s_;
};

class LogCallback final : public ceres::IterationCallback {
public:
    LogCallback(const FitOptions& o, int outer, std::vector<std::string>* lines) : o_(o), outer_(outer), lines_(lines) {}
    ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
        if (lines_ || o_.log) {
            const std::string line = "outer " + std::to_string(outer_) + ", iteration " + std::to_string(s.iteration) +
                                     format(": cost %.10g, change %.3g, gradient %.3g, step %.3g", s.cost, s.cost_change, s.gradient_max_norm, s.step_norm);
            if (lines_) lines_->push_back(line);
            if (o_.log) o_.log(line);
        }
        return o_.cancel && o_.cancel->load() ? ceres::SOLVER_ABORT : ceres::SOLVER_CONTINUE;
    }

private:
    const FitOptions& o_;
    int outer_;
    std::vector<std::string>* lines_;
};

// Neighbouring grid nodes (6-connectivity) that are both parameters.
std::vector<std::pair<int, int>> gridNeighbours(const ParameterMap& map) {
    std::map<std::array<int, 3>, int> index;
    for (size_t j = 0; j < map.size(); ++j) index[map.parameters()[j].cell] = static_cast<int>(j);
    std::vector<std::pair<int, int>> out;
    for (const auto& [cell, j] : index)
        for (int a = 0; a < 3; ++a) {
            std::array<int, 3> n = cell;
            ++n[static_cast<size_t>(a)];
            if (const auto it = index.find(n); it != index.end()) out.push_back({j, it->second});
        }
    return out;
}

}  // namespace

const char* fitParametrisationName(FitParametrisation p) { return p == FitParametrisation::Grid ? "grid" : "labels"; }
const char* scatteredModelName(ScatteredModel s) {
    return s == ScatteredModel::Reestimated ? "reestimated" : s == ScatteredModel::PerLabel ? "labels" : "none";
}
const char* fitLikelihoodName(FitLikelihood l) { return l == FitLikelihood::Pearson ? "pearson" : "deviance"; }

void setParametrisation(FitOptions& o, const std::string& text, const std::string& option) {
    if (text == "labels") {
        o.parametrisation = FitParametrisation::Labels;
        return;
    }
    if (text.rfind("grid:", 0) == 0) {
        // "grid:16um>8um>4um": coarse to fine, the last cell the fit's.
        std::vector<double> cells;
        size_t begin = 5;
        while (true) {
            const size_t end = text.find('>', begin);
            const double cell = parseQuantity(text.substr(begin, end == std::string::npos ? std::string::npos : end - begin), Dimension::Length, option);
            if (!(cell > 0)) throw ConfigError(option + ": the grid cell must be positive, got \"" + excerpt(text) + "\"");
            if (!cells.empty() && !(cell * 1e3 < cells.back()))
                throw ConfigError(option + ": coarse to fine, each cell smaller than the one before, got \"" + excerpt(text) + "\"");
            cells.push_back(cell * 1e3);
            if (end == std::string::npos) break;
            begin = end + 1;
        }
        o.parametrisation = FitParametrisation::Grid;
        o.gridCellUm = cells.back();
        o.coarserCellsUm.assign(cells.begin(), cells.end() - 1);
        return;
    }
    throw ConfigError(option + ": expected \"labels\", \"grid:CELL\" (e.g. grid:8um) or \"grid:16um>8um\" (coarse to fine), got \"" + excerpt(text) + "\"");
}

void setScatteredModel(FitOptions& o, const std::string& text, const std::string& option) {
    if (text == "auto") o.scattered = o.parametrisation == FitParametrisation::Grid ? ScatteredModel::Reestimated : ScatteredModel::PerLabel;
    else if (text == "none") o.scattered = ScatteredModel::None;
    else if (text == "reestimated") o.scattered = ScatteredModel::Reestimated;
    else if (text == "labels") o.scattered = ScatteredModel::PerLabel;
    else throw ConfigError(option + ": expected \"auto\", \"none\", \"reestimated\" or \"labels\", got \"" + excerpt(text) + "\"");
}

void setLikelihood(FitOptions& o, const std::string& text, const std::string& option) {
    if (text == "deviance") o.likelihood = FitLikelihood::Deviance;
    else if (text == "pearson") o.likelihood = FitLikelihood::Pearson;
    else throw ConfigError(option + ": expected \"deviance\" (maximum likelihood) or \"pearson\", got \"" + excerpt(text) + "\"");
}

void FitOptions::validate() const {
    if (parametrisation == FitParametrisation::Grid && !(gridCellUm > 0 && std::isfinite(gridCellUm) && gridCellUm <= 1e4))
        throw ConfigError("fit: grid cell must lie in (0, 10000] um, got " + std::to_string(gridCellUm));
    if (scatteredSpp < 1 || scatteredSpp > (1 << 20)) throw ConfigError("fit: scattered spp must lie in [1, 1048576], got " + std::to_string(scatteredSpp));
    if (outerIterations < 1 || outerIterations > 100) throw ConfigError("fit: outer iterations must lie in [1, 100], got " + std::to_string(outerIterations));
    if (!(outerTolerance > 0) || !std::isfinite(outerTolerance)) throw ConfigError("fit: outer tolerance must be positive, got " + std::to_string(outerTolerance));
    if (maxIterations < 1 || maxIterations > 10000) throw ConfigError("fit: iterations must lie in [1, 10000], got " + std::to_string(maxIterations));
    if (priorWeight && !(*priorWeight >= 0 && std::isfinite(*priorWeight))) throw ConfigError("fit: prior weight must be finite and >= 0, got " + std::to_string(*priorWeight));
    if (!(saturationSigmas >= 0) || !std::isfinite(saturationSigmas)) throw ConfigError("fit: saturation margin must be finite and >= 0, got " + std::to_string(saturationSigmas));
    for (int l : labels)
        if (l <= 0) throw ConfigError("fit: labels must be positive, got " + std::to_string(l));
    if (parametrisation == FitParametrisation::Grid && scattered == ScatteredModel::PerLabel)
        throw ConfigError("fit: the scattered light per label needs per-label parameters (with a grid: scattered none or reestimated)");
    if (!labels.empty() && parametrisation == FitParametrisation::Grid) throw ConfigError("fit: labels choose parameters of a per-label fit, not of a grid");
    if (start)
        for (double v : *start)
            if (!(v >= 0) || !std::isfinite(v)) throw ConfigError("fit: starting values must be finite and >= 0, got " + std::to_string(v));
    if (!coarserCellsUm.empty() && parametrisation != FitParametrisation::Grid) throw ConfigError("fit: coarse-to-fine cells need a grid");
    for (size_t i = 0; i < coarserCellsUm.size(); ++i) {
        const double next = i + 1 < coarserCellsUm.size() ? coarserCellsUm[i + 1] : gridCellUm;
        if (!(coarserCellsUm[i] > next) || !std::isfinite(coarserCellsUm[i]) || coarserCellsUm[i] > 1e4)
            throw ConfigError("fit: coarse-to-fine cells must shrink to the grid's " + std::to_string(gridCellUm) + " um, got " + std::to_string(coarserCellsUm[i]) +
                              " um before " + std::to_string(next) + " um");
    }
    if (coarser && (parametrisation != FitParametrisation::Grid || !coarser->map || !coarser->map->isGrid()))
        throw ConfigError("fit: a coarser start needs a grid fit on a grid");
    if (coarser && start) throw ConfigError("fit: give a start or a coarser fit, not both");
    acquisition.validate();
}

FitData fitData(const ObservedStack& stack, const Microscope& m, const FitOptions& o) {
    const std::string file = stack.path.string();
    auto mismatch = [&](const std::string& field, const std::string& stackValue, const std::string& sceneValue) {
        throw ConfigError(file + ": " + field + " " + stackValue + " does not match the scene's " + sceneValue);
    };
    auto text = [](double v) {
        char buf[64];
        std::snprintf(buf, sizeof buf, "%.6g", v);
        return std::string(buf);
    };
    if (stack.width != m.width || stack.height != m.height)
        mismatch("size", std::to_string(stack.width) + " x " + std::to_string(stack.height), std::to_string(m.width) + " x " + std::to_string(m.height));
    if (stack.planes != m.stack.planes) mismatch("SizeZ", std::to_string(stack.planes) + " planes", std::to_string(m.stack.planes));
    if (stack.pixelSizeUm > 0 && std::abs(stack.pixelSizeUm - m.pixelSizeMm() * 1e3) > 1e-6 * m.pixelSizeMm() * 1e3)
        mismatch("PhysicalSizeX", text(stack.pixelSizeUm) + " um", text(m.pixelSizeMm() * 1e3) + " um");
    if (stack.planes > 1 && stack.zStepUm > 0 && std::abs(stack.zStepUm - m.stack.stepMm * 1e3) > 1e-6 * m.stack.stepMm * 1e3)
        mismatch("PhysicalSizeZ", text(stack.zStepUm) + " um", text(m.stack.stepMm * 1e3) + " um");
    if (stack.exposureS > 0 && std::abs(stack.exposureS - m.detector.exposureS) > 1e-6 * m.detector.exposureS)
        mismatch("ExposureTime", text(stack.exposureS) + " s", text(m.detector.exposureS) + " s");
    FitData d;
    std::vector<std::string> names = o.channels;
    if (names.empty()) names = stack.channelNames;
    std::vector<int> stackChannel;
    for (const std::string& name : names) {
        const int sc = stack.channelIndex(name);
        bool found = false;
        for (size_t c = 0; c < m.channels.size(); ++c)
            if (m.channels[c].name == name) {
                d.channels.push_back(c);
                found = true;
            }
        if (!found) {
            std::string known;
            for (const auto& c : m.channels) known += (known.empty() ? "\"" : ", \"") + c.name + "\"";
            throw ConfigError(file + ": channel \"" + excerpt(name) + "\" is not a channel of the scene's microscope (" + known + ")");
        }
        stackChannel.push_back(sc);
    }
    if (stack.values.empty()) {
        if (stack.integerPixels)
            throw ConfigError(file + ": the stack carries no camera metadata (Fluorosim's camera annotation with gain and offset), so its ADU cannot be "
                                     "turned into photoelectrons");
        throw ConfigError(file + ": the stack does not say what its float values are (Fluorosim's camera annotation, values \"electrons\")");
    }
    d.adu = stack.values == "adu";
    if (!stack.camera) throw ConfigError(file + ": the stack carries no camera metadata");
    const CameraMetadata& cam = *stack.camera;
    const std::string sceneSensor = m.detector.type == SensorType::Emccd ? "EMCCD" : "sCMOS";
    if (cam.sensor != sceneSensor) mismatch("camera", cam.sensor, sceneSensor + " detector");
    if (std::abs(cam.emGain - m.detector.emGain) > 1e-9 * m.detector.emGain) mismatch("camera EM gain", text(cam.emGain), text(m.detector.emGain));
    d.noise = CameraNoise::fromMetadata(cam, m.detector.exposureS);
    const size_t planePixels = static_cast<size_t>(stack.width) * stack.height;
    d.values.resize(planePixels * stack.planes * d.channels.size());
    const double lowest = -10 * d.noise.readSigmaElectrons() - 1;
    for (size_t slot = 0; slot < d.channels.size(); ++slot)
        for (int z = 0; z < stack.planes; ++z)
            for (int y = 0; y < stack.height; ++y)
                for (int x = 0; x < stack.width; ++x) {
                    const double v = stack.at(stackChannel[slot], z, y, x);
                    const std::string where = "channel \"" + names[slot] + "\", plane " + std::to_string(z) + ", pixel (" + std::to_string(x) + ", " +
                                              std::to_string(y) + ")";
                    if (!std::isfinite(v)) throw ConfigError(file + ": " + where + " is " + text(v) + "; values must be finite");
                    const double e = d.adu ? d.noise.electrons(v) : v;
                    if (e < lowest)
                        throw ConfigError(file + ": " + where + " holds " + text(v) + (d.adu ? " ADU, " + text(-e) + " e- below the offset " + text(cam.offsetAdu) + " ADU" : " e-") +
                                          " (more than 10 read-noise sigmas): the offset or the values are wrong");
                    d.values[((slot * stack.planes + static_cast<size_t>(z)) * stack.height + static_cast<size_t>(y)) * stack.width + static_cast<size_t>(x)] = v;
                }
    return d;
}

namespace {

std::vector<size_t> fitChannels(const Microscope& m, const FitOptions& o) {
    if (o.channels.empty()) {
        std::vector<size_t> all(m.channels.size());
        std::iota(all.begin(), all.end(), 0u);
        return all;
    }
    return m.selectChannels(o.channels, "fit channels");
}

ParameterMap makeMap(const Scene& scene, const StackOperator& op, const FitOptions& o) {
    std::vector<LabelKey> keys = op.labels();
    if (o.parametrisation == FitParametrisation::Labels) {
        bool anyGrid = false;
        for (const Medium& m : scene.media) anyGrid = anyGrid || (m.volume() && m.volume()->labels());
        if (!anyGrid && !o.fitUnlabelled)
            throw ConfigError("fit: the scene's volume has no \"label_grid\", so there are no labels to fit (give one, or fit with --unlabelled or --params grid:CELL)");
        if (!o.labels.empty()) {
            std::vector<LabelKey> chosen;
            for (int value : o.labels) {
                bool found = false;
                for (const LabelKey& k : keys)
                    if (k.value == value) {
                        chosen.push_back(k);
                        found = true;
                    }
                if (found) continue;
                std::string known;
                for (const LabelKey& k : keys)
                    if (k.value) known += (known.empty() ? "" : ", ") + std::to_string(k.value);
                throw ConfigError("fit: label " + std::to_string(value) + " holds no dye that the fitted channels see near the stack's planes (labels with dye: " +
                                  (known.empty() ? "none" : known) + ")");
            }
            keys = chosen;
        }
    }
    ParameterMap map = o.parametrisation == FitParametrisation::Grid ? ParameterMap::grid(o.gridCellUm * 1e-3, op.lattices())
                                                                     : ParameterMap::labels(keys, o.fitUnlabelled);
    // Where each parameter is and what it scales, from the lattices' points.
    std::vector<double> weight(map.size(), 0.0), peak(map.size(), 0.0);
    std::vector<Vec3> centre(map.size(), Vec3(0, 0, 0));
    std::vector<ParameterMap::Entry> entries;
    for (const EmissionLattice* l : op.lattices())
        for (size_t p = 0; p < l->size(); ++p) {
            map.entries(*l, p, entries);
            const LatticePoint& q = l->point(p);
            for (const ParameterMap::Entry& e : entries) {
                if (e.parameter < 0) continue;
                const size_t j = static_cast<size_t>(e.parameter);
                const double c = map.isGrid() ? l->concentration(p, e.slot) : e.coefficient;
                const double w = e.coefficient * q.volumeMm3;
                weight[j] += w;
                centre[j] += l->geometry().world(q.x, q.y, q.z) * w;
                peak[j] = std::max(peak[j], c);
            }
        }
    // A label's reference is the value most of its voxels share (those it covers whole: the neuron's own
    // concentration for voxelized neurons), not its largest lattice point, which a thin neurite never fills,
    // nor its largest voxel, where neurons sharing a grid overlap and add up.
    std::vector<std::map<float, size_t>> counts(map.size());
    if (!map.isGrid())
        for (size_t med = 0; med < scene.media.size(); ++med) {
            const VolumeFields* v = scene.media[med].volume();
            if (!v || !v->labels()) continue;
            for (int c = kFirstDyeChannel; c < v->channelCount(); ++c) {
                const VolumeChannel& ch = v->channel(c);
                if (!ch.grid) continue;
                std::vector<float> values, labels;
                ch.grid->forEachBlock([&](const IndexBox& box, double) {
                    const size_t n = static_cast<size_t>(box.hi[0] - box.lo[0] + 1) * static_cast<size_t>(box.hi[1] - box.lo[1] + 1) *
                                     static_cast<size_t>(box.hi[2] - box.lo[2] + 1);
                    if (n > (size_t(1) << 24)) return;  // a huge tile: uniform dye, no label boundary to resolve
                    values.resize(n);
                    labels.resize(n);
                    ch.grid->copyVoxels(box, values.data());
                    v->labels()->copyVoxels(box, labels.data());
                    for (size_t i = 0; i < n; ++i) {
                        const int param = map.parameterOf({static_cast<int32_t>(med), static_cast<int32_t>(labels[i])});
                        if (param >= 0 && values[i] > 0) ++counts[static_cast<size_t>(param)][static_cast<float>(ch.offset + ch.scale * values[i])];
                    }
                });
            }
        }
    for (size_t j = 0; j < map.size(); ++j) {
        size_t best = 1;
        for (const auto& [value, n] : counts[j])
            if (n > best) best = n, peak[j] = value;
    }
    for (size_t j = 0; j < map.size(); ++j) {
        FitParameter& p = map.parameters()[j];
        p.referenceMolar = peak[j];
        if (!map.isGrid() && weight[j] > 0) p.centreMm = centre[j] / weight[j];
        if (!map.isGrid()) p.name += " (" + scene.media[static_cast<size_t>(p.label.medium)].name() + ")";
    }
    return map;
}

// The scattered light of every fitted plane: the path part of an acquisition at the scene's current
// concentrations.
std::vector<double> scatteredLight(const Scene& scene, const Microscope& m, const std::vector<size_t>& channels, const FitOptions& o, size_t stackPixels) {
    std::vector<double> out(stackPixels, 0.0);
    AcquireOptions a = o.acquisition;
    a.estimator = Estimator::Split;
    // The operator's columns hold the computed image (the unscattered light and the excitation field's
    // emission), so the paths carry the rest here.
    a.spp = o.scatteredSpp;
    a.noiseRatio.reset();
    a.progress = nullptr;
    a.cancel = o.cancel;
    const size_t planePixels = static_cast<size_t>(m.width) * m.height;
    for (size_t slot = 0; slot < channels.size(); ++slot) {
        const ChannelImaging imaging = setUpChannelImaging(scene, m, channels[slot], a);
        for (int k = 0; k < m.stack.planes; ++k) {
            const PlaneImage image = acquirePlane(scene, m, channels[slot], k, a, &imaging);
            if (!image.complete) throw Cancelled("fit cancelled while rendering the scattered light");
            for (size_t i = 0; i < planePixels; ++i)
                out[(slot * m.stack.planes + static_cast<size_t>(k)) * planePixels + i] =
                    image.electrons[i] - (image.computedImage.empty() ? 0.0 : image.computedImage[i]);
        }
    }
    return out;
}

// The scattered light split by label: one render of the scene as it is (the template), its paths'
// re-emissions tallied per parameter's label. `rest` holds what no parameter scales (elastic light, fixed
// labels); perKey[j] label j's share at θ_j = 1.
struct LabelledScatter {
    std::vector<double> rest;
    std::vector<std::vector<double>> perKey;
};
LabelledScatter scatteredByLabel(const Scene& scene, const Microscope& m, const std::vector<size_t>& channels, const FitOptions& o, size_t stackPixels,
                                 const ParameterMap& map) {
    std::vector<LabelKey> keys;
    for (const FitParameter& p : map.parameters()) keys.push_back(p.label);
    const VoxelLabels labels(scene, keys);
    LabelledScatter out;
    out.rest.assign(stackPixels, 0.0);
    out.perKey.assign(keys.size(), std::vector<double>(stackPixels, 0.0));
    AcquireOptions a = o.acquisition;
    a.estimator = Estimator::Split;
    a.spp = o.scatteredSpp;
    a.noiseRatio.reset();
    a.progress = nullptr;
    a.cancel = o.cancel;
    a.labels = &labels;
    a.labelCount = static_cast<int>(keys.size());
    const size_t planePixels = static_cast<size_t>(m.width) * m.height;
    for (size_t slot = 0; slot < channels.size(); ++slot) {
        const ChannelImaging imaging = setUpChannelImaging(scene, m, channels[slot], a);
        for (int k = 0; k < m.stack.planes; ++k) {
            const PlaneImage image = acquirePlane(scene, m, channels[slot], k, a, &imaging);
            if (!image.complete) throw Cancelled("fit cancelled while rendering the scattered light");
            const size_t base = (slot * m.stack.planes + static_cast<size_t>(k)) * planePixels;
            for (size_t i = 0; i < planePixels; ++i) {
                double rest = image.electrons[i] - (image.computedImage.empty() ? 0.0 : image.computedImage[i]);
                for (size_t j = 0; j < keys.size(); ++j) {
                    out.perKey[j][base + i] = image.labelledElectrons[j][i];
                    rest -= image.labelledElectrons[j][i];
                }
                out.rest[base + i] = rest;
            }
        }
    }
    return out;
}

// Restores the scene's media when the fit ends, however it ends.
struct MediaGuard {
    Scene& scene;
    std::vector<Medium> media;
    ~MediaGuard() { scene.media = media; }
};

}  // namespace


// ------------------------------------------------------------------------------------------------
// The inner, linear problem.

struct LinearPoissonFit::Impl {
    CameraNoise noise;
    FitOptions o;
    const ParameterMap* map = nullptr;
    size_t params = 0;
    // Pixel-major rows of A over the pixels any column reaches.
    std::vector<uint32_t> pixel;
    std::vector<double> background;
    std::vector<uint32_t> start;
    std::vector<uint32_t> col;
    std::vector<double> value;
    std::vector<std::pair<int, int>> neighbours;

    // Blocks of up to 64 consecutive used rows and the parameters that touch them.
    struct Block {
        std::vector<uint32_t> rows;
        std::vector<int> params;
        Eigen::MatrixXd A;
    };
    std::vector<Block> blocks(const std::vector<uint32_t>& used) const {
        std::vector<Block> out;
        constexpr size_t kBlock = 64;
        for (size_t b0 = 0; b0 < used.size(); b0 += kBlock) {
            Block b;
            b.rows.assign(used.begin() + static_cast<std::ptrdiff_t>(b0), used.begin() + static_cast<std::ptrdiff_t>(std::min(used.size(), b0 + kBlock)));
            std::map<int, int> local;
            for (uint32_t r : b.rows)
                for (uint32_t e = start[r]; e < start[r + 1]; ++e) local.emplace(static_cast<int>(col[e]), 0);
            int k = 0;
            for (auto& [param, index] : local) {
                index = k++;
                b.params.push_back(param);
            }
            b.A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(b.rows.size()), k);
            for (size_t i = 0; i < b.rows.size(); ++i)
                for (uint32_t e = start[b.rows[i]]; e < start[b.rows[i] + 1]; ++e)
                    b.A(static_cast<Eigen::Index>(i), local.at(static_cast<int>(col[e]))) += value[e];
            out.push_back(std::move(b));
        }
        return out;
    }
    double mean(uint32_t r, const std::vector<double>& theta) const {
        double mu = background[r];
        for (uint32_t e = start[r]; e < start[r + 1]; ++e) mu += value[e] * theta[col[e]];
        return mu;
    }
    double dataDeviance(const std::vector<uint32_t>& used, const std::vector<double>& x, const std::vector<double>& theta) const {
        double d = 0;
        for (uint32_t r : used) {
            const double res = devianceResidual(x[r], std::max(noise.scaledMean(mean(r, theta)), noise.scaledMinimum()), noise.scaledMinimum()).r;
            d += res * res;
        }
        return d;
    }
    struct Run {
        int iterations = 0;
        bool converged = true;
        std::string report;
    };
    Run run(const std::vector<Block>& bs, const std::vector<double>& x, std::vector<double>& theta, double alpha, int outer,
            std::vector<std::string>* log) const {
        ceres::Problem::Options po;
        po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
        ceres::Problem problem(po);
        for (double& t : theta) problem.AddParameterBlock(&t, 1);
        for (const Block& b : bs) {
            std::vector<double*> ps;
            for (int j : b.params) ps.push_back(&theta[static_cast<size_t>(j)]);
            std::vector<double> bx, bb;
            for (uint32_t r : b.rows) {
                bx.push_back(x[r]);
                bb.push_back(background[r]);
            }
            problem.AddResidualBlock(new PixelBlockCost(std::move(bx), std::move(bb), b.A, noise.shift(), noise.excessNoiseFactorSquared, o.likelihood),
                                     nullptr, ps);
        }
        if (alpha > 0)
            for (const auto& [a, b] : neighbours)
                problem.AddResidualBlock(new DifferenceCost(std::sqrt(alpha)), nullptr, &theta[static_cast<size_t>(a)], &theta[static_cast<size_t>(b)]);
        for (double& t : theta) problem.SetParameterLowerBound(&t, 0, 0.0);
        ceres::Solver::Options so;
        so.minimizer_type = ceres::TRUST_REGION;
        so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
        so.linear_solver_type = map->isGrid() ? ceres::SPARSE_NORMAL_CHOLESKY : ceres::DENSE_QR;
        so.max_num_iterations = o.maxIterations;
        so.function_tolerance = 1e-15;
        so.gradient_tolerance = 1e-15;
        so.parameter_tolerance = 1e-13;
        so.num_threads = o.acquisition.threads > 0 ? o.acquisition.threads : 2;
        so.logging_type = ceres::SILENT;
        so.minimizer_progress_to_stdout = false;
        LogCallback callback(o, outer, log);
        so.callbacks.push_back(&callback);
        ceres::Solver::Summary summary;
        ceres::Solve(so, &problem, &summary);
        if (o.cancel && o.cancel->load()) throw Cancelled("fit cancelled");
        return {static_cast<int>(summary.iterations.size()), summary.termination_type == ceres::CONVERGENCE, summary.FullReport()};
    }
};

void LinearPoissonFit::setBackground(const std::vector<double>& background) {
    Impl& m = *impl_;
    for (size_t q = 0; q < m.pixel.size(); ++q) {
        if (m.pixel[q] >= background.size()) throw ConfigError("linear fit: the background is smaller than the stack");
        m.background[q] = background[m.pixel[q]];
    }
}

LinearPoissonFit::LinearPoissonFit(const SparseColumns& columns, std::vector<double> background, const CameraNoise& noise, const ParameterMap& map,
                                   const FitOptions& options)
    : impl_(std::make_unique<Impl>()) {
    Impl& m = *impl_;
    m.noise = noise;
    m.o = options;
    m.map = &map;
    m.params = map.size();
    if (columns.pixels.size() != map.size()) throw ConfigError("linear fit: " + std::to_string(columns.pixels.size()) + " columns for " + std::to_string(map.size()) + " parameters");
    std::vector<uint32_t> count(background.size(), 0);
    for (const auto& p : columns.pixels)
        for (uint32_t i : p) {
            if (i >= background.size()) throw ConfigError("linear fit: a column reaches beyond the stack");
            ++count[i];
        }
    std::vector<uint32_t> slot(background.size(), 0);
    uint32_t n = 0;
    for (size_t i = 0; i < background.size(); ++i) {
        if (!count[i]) continue;
        m.pixel.push_back(static_cast<uint32_t>(i));
        m.background.push_back(background[i]);
        m.start.push_back(n);
        slot[i] = n;
        n += count[i];
    }
    m.start.push_back(n);
    m.col.resize(n);
    m.value.resize(n);
    for (size_t j = 0; j < columns.pixels.size(); ++j)
        for (size_t k = 0; k < columns.pixels[j].size(); ++k) {
            const uint32_t i = columns.pixels[j][k];
            m.col[slot[i]] = static_cast<uint32_t>(j);
            m.value[slot[i]] = columns.values[j][k];
            ++slot[i];
        }
    if (map.isGrid()) m.neighbours = gridNeighbours(map);
}

LinearPoissonFit::~LinearPoissonFit() = default;
size_t LinearPoissonFit::parameters() const { return impl_->params; }

LinearPoissonFit::Solution LinearPoissonFit::solve(const std::vector<double>& observation, bool adu, std::vector<double> theta, double alpha,
                                                   bool uncertainties, int outer, std::vector<std::string>* log) const {
    const Impl& m = *impl_;
    const CameraNoise& noise = m.noise;
    if (theta.size() != m.params) throw ConfigError("linear fit: " + std::to_string(theta.size()) + " starting values for " + std::to_string(m.params) + " parameters");
    Solution s;
    // The Poisson-scaled observations of the rows, and the rows used (saturated pixels left out).
    std::vector<double> x(m.pixel.size());
    std::vector<uint32_t> used;
    for (uint32_t r = 0; r < m.pixel.size(); ++r) {
        const double v = observation.at(m.pixel[r]);
        x[r] = noise.scaledObservation(adu ? noise.electrons(v) : v);
        if (adu && noise.saturated(v, m.o.saturationSigmas)) {
            ++s.saturatedPixels;
            continue;
        }
        used.push_back(r);
    }
    s.pixels = used.size();
    const std::vector<Impl::Block> bs = m.blocks(used);
    if (m.map->isGrid() && alpha < 0) {
        // The discrepancy rule (Morozov): the largest α whose Pearson statistic Σ (x − λ)²/λ stays within two
        // standard deviations of its expectation N under the camera model, N (1 + 2 √(2/N)). (The deviance's
        // own expectation is not N where read noise dominates: about 1.25 per pixel at λ = 2.) The statistic
        // grows with α, so log α is bisected between a scale of the data's curvature (the median diagonal of
        // AᵀWA) times 1e-8 and 1e3, each solve warm-started from the last.
        const double n = static_cast<double>(used.size());
        const double target = n * (1 + 2 * std::sqrt(2 / std::max(n, 1.0)));
        std::vector<double> diagonal(m.params, 0.0);
        for (uint32_t q : used) {
            const double w = 1 / std::max(noise.scaledMean(m.mean(q, theta)), noise.scaledMinimum());
            for (uint32_t e = m.start[q]; e < m.start[q + 1]; ++e) diagonal[m.col[e]] += m.value[e] * m.value[e] * w;
        }
        std::nth_element(diagonal.begin(), diagonal.begin() + static_cast<std::ptrdiff_t>(diagonal.size() / 2), diagonal.end());
        const double scale = std::max(diagonal[diagonal.size() / 2], 1e-300) / (noise.excessNoiseFactorSquared * noise.excessNoiseFactorSquared);
        auto pearson = [&](const std::vector<double>& t) {
            double c = 0;
            for (uint32_t q : used) {
                const double l = std::max(noise.scaledMean(m.mean(q, t)), noise.scaledMinimum());
                c += (x[q] - l) * (x[q] - l) / l;
            }
            return c;
        };
        double lo = std::log(scale * 1e-8), hi = std::log(scale * 1e3);
        std::vector<double> trial = theta, best = theta;
        double chosen = 0;
        // The unregularised fit first: if even it misses the target, no α helps.
        s.iterations += m.run(bs, x, trial, 0.0, outer, log).iterations;
        if (pearson(trial) <= target) {
            best = trial;
            for (int step = 0; step < 10; ++step) {
                const double mid = 0.5 * (lo + hi);
                std::vector<double> t = best;
                s.iterations += m.run(bs, x, t, std::exp(mid), outer, log).iterations;
                if (pearson(t) <= target) {
                    lo = mid;
                    chosen = std::exp(mid);
                    best = t;
                } else {
                    hi = mid;
                }
            }
        }
        alpha = chosen;
        theta = best;
    }
    alpha = std::max(alpha, 0.0);
    const Impl::Run r = m.run(bs, x, theta, m.map->isGrid() ? alpha : 0.0, outer, log);
    s.iterations += r.iterations;
    s.converged = r.converged;
    s.report = r.report;
    s.priorWeight = m.map->isGrid() ? alpha : 0.0;
    s.theta = theta;
    std::vector<double> lambda(m.pixel.size());
    for (uint32_t q : used) {
        lambda[q] = std::max(noise.scaledMean(m.mean(q, theta)), noise.scaledMinimum());
        const double res = devianceResidual(x[q], lambda[q], noise.scaledMinimum()).r;
        s.deviance += res * res;
        s.chi2 += (x[q] - lambda[q]) * (x[q] - lambda[q]) / lambda[q];
    }
    s.standardError.assign(m.params, 0.0);
    s.cramerRao.assign(m.params, 0.0);
    s.atBound.assign(m.params, false);
    // At the bound with the cost still falling toward negative values: held there.
    std::vector<double> gradient(m.params, 0.0);
    for (uint32_t q : used) {
        const DevianceResidual d = devianceResidual(x[q], lambda[q], noise.scaledMinimum());
        for (uint32_t e = m.start[q]; e < m.start[q + 1]; ++e) gradient[m.col[e]] += 2 * d.r * d.dr * m.value[e] / noise.excessNoiseFactorSquared;
    }
    for (size_t j = 0; j < m.params; ++j) s.atBound[j] = theta[j] <= 1e-12 && gradient[j] > 0;
    // The conditional SNR θ_j √I_jj, I = Σ a aᵀ / (F⁴ λ).
    s.snr.assign(m.params, 0.0);
    {
        std::vector<double> diagonal(m.params, 0.0);
        const double f2 = noise.excessNoiseFactorSquared;
        for (uint32_t q : used)
            for (uint32_t e = m.start[q]; e < m.start[q + 1]; ++e) diagonal[m.col[e]] += m.value[e] * m.value[e] / (f2 * f2 * lambda[q]);
        for (size_t j = 0; j < m.params; ++j) s.snr[j] = theta[j] * std::sqrt(diagonal[j]);
    }
    if (!uncertainties) return s;

    // The covariance of the Fisher-weighted residuals (x − λ(θ))/√λ̂ at the fit, with held parameters fixed.
    {
        ceres::Problem::Options po;
        po.cost_function_ownership = ceres::TAKE_OWNERSHIP;
        ceres::Problem problem(po);
        std::vector<double> t = theta;
        for (double& v : t) problem.AddParameterBlock(&v, 1);
        for (const Impl::Block& b : bs) {
            std::vector<double*> ps;
            std::vector<double> bx, bb, w;
            for (uint32_t q : b.rows) {
                bx.push_back(x[q]);
                bb.push_back(m.background[q]);
                w.push_back(1 / std::sqrt(lambda[q]));
            }
            for (int j : b.params) ps.push_back(&t[static_cast<size_t>(j)]);
            problem.AddResidualBlock(new FisherBlockCost(std::move(bx), std::move(bb), std::move(w), b.A, noise.shift(), noise.excessNoiseFactorSquared), nullptr,
                                     ps);
        }
        if (m.map->isGrid() && alpha > 0)
            for (const auto& [a, b] : m.neighbours)
                problem.AddResidualBlock(new DifferenceCost(std::sqrt(alpha)), nullptr, &t[static_cast<size_t>(a)], &t[static_cast<size_t>(b)]);
        std::vector<std::pair<const double*, const double*>> pairs;
        for (size_t j = 0; j < m.params; ++j) {
            if (s.atBound[j]) {
                problem.SetParameterBlockConstant(&t[j]);
                continue;
            }
            pairs.push_back({&t[j], &t[j]});
        }
        ceres::Covariance::Options co;
        co.algorithm_type = m.map->isGrid() ? ceres::SPARSE_QR : ceres::DENSE_SVD;
        co.null_space_rank = m.map->isGrid() ? 0 : -1;
        co.num_threads = m.o.acquisition.threads > 0 ? m.o.acquisition.threads : 2;
        ceres::Covariance covariance(co);
        if (!pairs.empty() && covariance.Compute(pairs, &problem)) {
            for (size_t j = 0; j < m.params; ++j) {
                if (s.atBound[j]) continue;
                double v = 0;
                covariance.GetCovarianceBlock(&t[j], &t[j], &v);
                s.standardError[j] = std::sqrt(std::max(0.0, v));
            }
        }
    }
    // The Cramér–Rao bound of the data alone (dense, up to 2000 free parameters).
    std::vector<int> freeIndex(m.params, -1);
    std::vector<int> freeParams;
    for (size_t j = 0; j < m.params; ++j)
        if (!s.atBound[j]) {
            freeIndex[j] = static_cast<int>(freeParams.size());
            freeParams.push_back(static_cast<int>(j));
        }
    if (!freeParams.empty() && freeParams.size() <= 2000) {
        const Eigen::Index n = static_cast<Eigen::Index>(freeParams.size());
        Eigen::MatrixXd fisher = Eigen::MatrixXd::Zero(n, n);
        const double f2 = noise.excessNoiseFactorSquared;
        std::vector<std::pair<int, double>> row;
        for (uint32_t q : used) {
            row.clear();
            for (uint32_t e = m.start[q]; e < m.start[q + 1]; ++e)
                if (freeIndex[m.col[e]] >= 0) row.push_back({freeIndex[m.col[e]], m.value[e] / f2});
            const double w = 1 / lambda[q];
            for (const auto& [a, va] : row)
                for (const auto& [b, vb] : row) fisher(a, b) += va * vb * w;
        }
        const Eigen::LDLT<Eigen::MatrixXd> ldlt(fisher);
        if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
            const Eigen::MatrixXd inverse = ldlt.solve(Eigen::MatrixXd::Identity(n, n));
            for (Eigen::Index a = 0; a < n; ++a) s.cramerRao[static_cast<size_t>(freeParams[static_cast<size_t>(a)])] = std::sqrt(std::max(0.0, inverse(a, a)));
        }
    }
    return s;
}

double checkFitDerivatives(const LinearPoissonFit& fit, const std::vector<double>& observation, bool adu, const std::vector<double>& theta) {
    const LinearPoissonFit::Impl& m = *fit.impl_;
    std::vector<uint32_t> used(m.pixel.size());
    std::iota(used.begin(), used.end(), 0u);
    const auto bs = m.blocks(used);
    double worst = 0;
    for (const auto& b : bs) {
        std::vector<double> bx, bb;
        for (uint32_t r : b.rows) {
            bx.push_back(m.noise.scaledObservation(adu ? m.noise.electrons(observation.at(m.pixel[r])) : observation.at(m.pixel[r])));
            bb.push_back(m.background[r]);
        }
        const PixelBlockCost cost(bx, bb, b.A, m.noise.shift(), m.noise.excessNoiseFactorSquared, m.o.likelihood);
        std::vector<double> values;
        for (int j : b.params) values.push_back(theta.at(static_cast<size_t>(j)));
        std::vector<const double*> ps;
        for (const double& v : values) ps.push_back(&v);
        ceres::NumericDiffOptions nd;
        nd.ridders_relative_initial_step_size = 1e-3;
        const std::vector<const ceres::Manifold*>* manifolds = nullptr;
        const ceres::GradientChecker checker(&cost, manifolds, nd);
        ceres::GradientChecker::ProbeResults results;
        checker.Probe(ps.data(), 1e-5, &results);
        // Per block, the largest difference over the largest entry: entries from the PSF's far tail are
        // 1e-10 of the peak, where a relative error only measures the numeric derivative's noise.
        double scale = 0, diff = 0;
        for (size_t k = 0; k < results.jacobians.size(); ++k) {
            scale = std::max(scale, results.jacobians[k].cwiseAbs().maxCoeff());
            diff = std::max(diff, (results.jacobians[k] - results.numeric_jacobians[k]).cwiseAbs().maxCoeff());
        }
        if (scale > 0) worst = std::max(worst, diff / scale);
    }
    return worst;
}

// ------------------------------------------------------------------------------------------------
// The outer iterations.

FitResult fitConcentrations(Scene& scene, const Microscope& m, const FitData& data, const FitOptions& o) {
    const auto start = std::chrono::steady_clock::now();
    o.validate();
    if (!o.coarserCellsUm.empty()) {
        // Coarse to fine: each level's field starts the next; the last level is the fit.
        FitOptions level = o;
        level.coarserCellsUm.clear();
        std::vector<std::string> lines;
        int iterations = 0, projections = 0;
        double forward = 0;
        for (double cell : o.coarserCellsUm) {
            level.gridCellUm = cell;
            auto coarse = std::make_shared<FitResult>(fitConcentrations(scene, m, data, level));
            const std::string line = format("level %g um: ", cell) + std::to_string(coarse->parameters.size()) + " nodes, " +
                                     std::to_string(coarse->iterations) + " iterations, deviance " + format("%.10g", coarse->deviance);
            lines.insert(lines.end(), coarse->logLines.begin(), coarse->logLines.end());
            lines.push_back(line);
            if (o.log) o.log(line);
            iterations += coarse->iterations;
            projections += coarse->projections;
            forward += coarse->forwardEquivalents;
            level.start.reset();
            level.coarser = std::move(coarse);
        }
        level.gridCellUm = o.gridCellUm;
        FitResult r = fitConcentrations(scene, m, data, level);
        r.logLines.insert(r.logLines.begin(), lines.begin(), lines.end());
        r.coarserIterations = iterations;
        r.projections += projections;
        r.forwardEquivalents += forward;
        r.seconds = secondsSince(start);
        return r;
    }
    if (data.channels.empty()) throw ConfigError("fit: no channel to fit");
    FitResult result;
    StackOperator op(scene, m, data.channels, o.acquisition);
    if (data.values.size() != op.stackPixels())
        throw ConfigError("fit: " + std::to_string(data.values.size()) + " values for a stack of " + std::to_string(op.stackPixels()) + " pixels");
    auto map = std::make_shared<ParameterMap>(makeMap(scene, op, o));
    if (map->size() == 0) throw ConfigError("fit: nothing to fit (no label holds dye the fitted channels see)");
    std::vector<double> theta(map->size(), 1.0);
    if (o.start) {
        if (o.start->size() != map->size())
            throw ConfigError("fit: " + std::to_string(o.start->size()) + " starting values for " + std::to_string(map->size()) + " parameters");
        theta = *o.start;
    }
    const CameraNoise& noise = data.noise;
    const MediaGuard guard{scene, scene.media};
    const LatticeGeometry& frame = op.model(0).geometry();
    if (o.coarser) {  // every node at the coarser fit's field there (the same stack frame)
        std::vector<double> coarseTheta;
        for (const FittedParameter& p : o.coarser->parameters) coarseTheta.push_back(p.theta);
        for (size_t j = 0; j < map->size(); ++j) {
            const std::array<double, 3> x = map->nodePosition(j);
            theta[j] = std::max(0.0, o.coarser->map->gridFactor(x[0], x[1], x[2], coarseTheta));
        }
    }
    std::vector<double> scattered(op.stackPixels(), 0.0);
    std::vector<double> previous;
    // Per label: the template's scattered light, once; each label's share joins its column.
    LabelledScatter labelled;
    if (o.scattered == ScatteredModel::PerLabel) {
        if (map->isGrid()) throw ConfigError("fit: the scattered light per label needs per-label parameters; use --scattered reestimated or none with a grid");
        labelled = scatteredByLabel(scene, m, data.channels, o, op.stackPixels(), *map);
        scattered = labelled.rest;
    }
    auto withScatter = [&](SparseColumns cols) {
        if (labelled.perKey.empty()) return cols;
        for (size_t j = 0; j < cols.pixels.size(); ++j) {
            std::vector<double> dense(op.stackPixels(), 0.0);
            for (size_t k = 0; k < cols.pixels[j].size(); ++k) dense[cols.pixels[j][k]] = cols.values[j][k];
            for (size_t i = 0; i < dense.size(); ++i) dense[i] += labelled.perKey[j][i];
            cols.pixels[j].clear();
            cols.values[j].clear();
            for (size_t i = 0; i < dense.size(); ++i)
                if (dense[i] != 0) {
                    cols.pixels[j].push_back(static_cast<uint32_t>(i));
                    cols.values[j].push_back(dense[i]);
                }
        }
        return cols;
    };
    const double alpha = map->isGrid() ? o.priorWeight.value_or(-1.0) : 0.0;
    LinearPoissonFit::Solution solution;
    std::unique_ptr<LinearPoissonFit> linear;
    for (int outer = 1; outer <= o.outerIterations; ++outer) {
        if (o.cancel && o.cancel->load()) throw Cancelled("fit cancelled");
        // Freeze the attenuation (and the scattered light) at the current estimate.
        scene.media = scaledMedia(guard.media, *map, theta, frame);
        if (!op.refreshGains(scene, o.cancel)) throw Cancelled("fit cancelled");
        if (o.scattered == ScatteredModel::Reestimated) scattered = scatteredLight(scene, m, data.channels, o, op.stackPixels());
        const SparseColumns cols = withScatter(op.columns(*map, o.cancel));
        const std::vector<double> fixed = op.apply(*map, std::vector<double>(map->size(), 0.0), true);
        // The PSF's tail beyond its cut (0.4 % of the light, reaching every pixel) is not in the columns, so
        // that they stay sparse: it is frozen at the estimate, and refreshed once at the solution when that
        // moved (a refresh shrinks the tail's error about 250 times: after one, 1.6e-5 of the step).
        auto background = [&](const std::vector<double>& at) {
            const std::vector<double> tail = op.tail(*map, at, false);
            std::vector<double> b(op.stackPixels());
            for (size_t i = 0; i < b.size(); ++i) b[i] = noise.darkElectrons + fixed[i] + tail[i] + scattered[i];
            return b;
        };
        linear = std::make_unique<LinearPoissonFit>(cols, background(theta), noise, *map, o);
        for (int refresh = 0;; ++refresh) {
            solution = linear->solve(data.values, data.adu, theta, alpha, false, outer, &result.logLines);
            result.iterations += solution.iterations;
            bool still = true;
            for (size_t j = 0; j < theta.size() && still; ++j)
                still = std::abs(solution.theta[j] - theta[j]) <= o.outerTolerance * std::max(std::abs(solution.theta[j]), 1e-3);
            theta = solution.theta;
            if (still || refresh == 1) break;
            linear->setBackground(background(theta));
        }
        result.solverReport += "outer iteration " + std::to_string(outer) + "\n" + solution.report + "\n";
        result.outerIterations = outer;
        if (!solution.converged) result.warnings.push_back("outer iteration " + std::to_string(outer) + ": the solver stopped without converging (see the report)");
        // Done when no parameter changed by more than the tolerance (relative to max(|θ|, 1e-3)).
        bool settled = !previous.empty();
        for (size_t j = 0; j < theta.size() && settled; ++j)
            settled = std::abs(theta[j] - previous[j]) <= o.outerTolerance * std::max(std::abs(theta[j]), 1e-3);
        const std::string line = "outer " + std::to_string(outer) + " done: deviance " + format("%.10g", solution.deviance) + " over " +
                                 std::to_string(solution.pixels) + " pixels" + (settled ? ", settled" : "");
        result.logLines.push_back(line);
        if (o.log) o.log(line);
        previous = theta;
        if (settled) break;
    }
    if (solution.saturatedPixels)
        result.warnings.push_back(std::to_string(solution.saturatedPixels) + " pixels within " + format("%g", o.saturationSigmas) +
                                  " noise sigmas of the full well (or at the ADC's maximum) are left out of the fit");
    // Uncertainties with the last outer iteration's frozen model, at the final estimate.
    const LinearPoissonFit::Solution final = linear->solve(data.values, data.adu, theta, solution.priorWeight, true, result.outerIterations + 1);
    result.iterations += final.iterations;
    theta = final.theta;
    result.deviance = final.deviance;
    result.chi2 = final.chi2;
    result.pixels = final.pixels;
    result.saturatedPixels = final.saturatedPixels;
    result.priorWeight = final.priorWeight;
    result.degreesOfFreedom = static_cast<double>(final.pixels) - static_cast<double>(map->size());
    // The model at the fit.
    const std::vector<double> mu0 = op.apply(*map, theta, true);
    result.model.resize(op.stackPixels());
    result.residual.resize(op.stackPixels());
    result.normalisedResidual.assign(op.stackPixels(), 0.0);
    for (size_t i = 0; i < result.model.size(); ++i) {
        result.model[i] = mu0[i] + noise.darkElectrons + scattered[i];
        for (size_t j = 0; j < labelled.perKey.size(); ++j) result.model[i] += theta[j] * labelled.perKey[j][i];
        const double e = data.adu ? noise.electrons(data.values[i]) : data.values[i];
        result.residual[i] = e - result.model[i];
        const bool saturated = data.adu && noise.saturated(data.values[i], o.saturationSigmas);
        if (mu0[i] != 0 && !saturated)
            result.normalisedResidual[i] =
                devianceResidual(noise.scaledObservation(e), std::max(noise.scaledMean(result.model[i]), noise.scaledMinimum()), noise.scaledMinimum()).r;
    }
    for (size_t j = 0; j < map->size(); ++j) {
        FittedParameter p;
        p.parameter = map->parameters()[j];
        p.theta = theta[j];
        p.standardError = final.standardError[j];
        p.cramerRao = final.cramerRao[j];
        p.snr = final.snr[j];
        p.atBound = final.atBound[j];
        p.concentrationUm = p.theta * p.parameter.referenceMolar * 1e6;
        p.concentrationStandardErrorUm = p.standardError * p.parameter.referenceMolar * 1e6;
        if (p.atBound) result.warnings.push_back(p.parameter.name + " is held at zero concentration (its bound): its error is not reported");
        result.parameters.push_back(p);
    }
    result.map = map;
    result.frame = frame;
    result.projections = op.projections();
    result.forwardEquivalents = static_cast<double>(op.projections()) / static_cast<double>(op.planes() * static_cast<int>(op.channelCount()));
    result.seconds = secondsSince(start);
    return result;
}

Gradient fitGradient(const Scene& scene, const Microscope& m, const FitOptions& options) {
    FitOptions o = options;
    o.scattered = ScatteredModel::None;  // the columns are the computed image's
    o.validate();
    Gradient g;
    g.channels = fitChannels(m, o);
    StackOperator op(scene, m, g.channels, o.acquisition);
    ParameterMap map = makeMap(scene, op, o);
    if (map.size() == 0) throw ConfigError("gradient: no parameter (no label holds dye the chosen channels see)");
    if (!op.refreshGains(scene, o.cancel)) throw Cancelled("gradient cancelled");
    const SparseColumns cols = op.columns(map, o.cancel, true);  // whole columns: they are written dense anyway
    g.parameters = map.parameters();
    for (size_t j = 0; j < map.size(); ++j) {
        std::vector<float> c(op.stackPixels(), 0.0f);
        for (size_t k = 0; k < cols.pixels[j].size(); ++k) c[cols.pixels[j][k]] = static_cast<float>(cols.values[j][k]);
        g.columns.push_back(std::move(c));
    }
    return g;
}

void writeFittedConcentrations(const std::filesystem::path& vdb, const Scene& scene, const FitResult& result) {
    if (!result.map) throw ConfigError("fitted concentrations: the result holds no parameters");
    std::vector<double> theta;
    for (const FittedParameter& p : result.parameters) theta.push_back(p.theta);
    const std::vector<Medium> media = scaledMedia(scene.media, *result.map, theta, result.frame);
    int volumes = 0;
    for (const Medium& m : media) volumes += m.volume() != nullptr;
    std::vector<GridToWrite> grids;
    for (const Medium& m : media) {
        const VolumeFields* v = m.volume();
        if (!v) continue;
        const std::string prefix = volumes > 1 ? m.name() + "." : "";
        for (int c = kFirstDyeChannel; c < v->channelCount(); ++c)
            if (v->channel(c).grid) grids.push_back({prefix + v->channel(c).grid->name(), &*v->channel(c).grid, false});
        if (v->labels()) grids.push_back({prefix + v->labels()->name(), v->labels(), true});
    }
    if (grids.empty()) throw ConfigError("fitted concentrations: the scene has no volume to write (its dyes are homogeneous)");
    writeDensityGrids(vdb.string(), grids);
}

}  // namespace fluorosim::optics
