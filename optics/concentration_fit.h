#pragma once
// Reading a stack back: dye concentrations fitted to an observed z-stack by maximum likelihood under the
// camera's noise model (optics/camera_likelihood.h), with the computed image as the forward model
// (optics/imaging_operator.h) and Ceres Solver (only concentration_fit.cpp includes it).
//
// Outer iterations: the operator is linear in the parameters apart from the dyes' own attenuation and
// the scattered light, so each outer iteration freezes the attenuation (g at the current estimate) and
// the scattered light (a Monte Carlo render of the path part at the current estimate, or none), solves
// the linear-Poisson problem with a bounded trust-region method, and the next recomputes them.
// Uncertainties: the covariance of the Fisher-weighted residuals at the fit (ceres::Covariance), which
// is the Cramér–Rao bound of the model at the fitted values; parameters held at their bound are flagged.
#include <atomic>
#include <filesystem>
#include <memory>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "optics/acquisition.h"
#include "optics/camera_likelihood.h"
#include "optics/imaging_operator.h"
#include "optics/observed_stack.h"

namespace fluorosim::optics {

enum class FitParametrisation { Labels, Grid };
// Deviance: maximum likelihood (the signed-root deviance as residual). Pearson: live Pearson weights,
// (x − λ)/√λ, which are biased; only for comparisons.
enum class FitLikelihood { Deviance, Pearson };
// How the scattered light (the Monte Carlo part of an acquisition) enters the model: not at all;
// rendered at the current estimate before each outer iteration and held fixed within it; or tallied per
// label in one render of the template, each label's share scaling with its parameter (the default: it
// stays linear where the scattered light dominates, where a background held fixed drives the outer
// iterations apart, docs/inverse.md).
enum class ScatteredModel { None, Reestimated, PerLabel };

struct FitResult;

struct FitOptions {
    FitParametrisation parametrisation = FitParametrisation::Labels;
    double gridCellUm = 8;            // the coarse grid's cell
    // Grid, coarse to fine: fit on these cells first (coarsest first, each larger than the next and than
    // gridCellUm), each fit's field starting the next (refinement: trilinear values at the finer nodes).
    std::vector<double> coarserCellsUm;
    // Grid: start every node at this coarser fit's field (set by the refinement, or by a caller).
    std::shared_ptr<const FitResult> coarser;
    bool fitUnlabelled = false;       // dye outside every label (and homogeneous dyed media) as parameters too
    std::vector<int> labels;          // per label: fit only these label values (empty: every label); the rest stay fixed
    std::vector<std::string> channels;  // the microscope's channels to fit (empty: every channel of the stack)
    FitLikelihood likelihood = FitLikelihood::Deviance;
    ScatteredModel scattered = ScatteredModel::PerLabel;
    int scatteredSpp = 64;            // paths per pixel of the scattered light's render
    int outerIterations = 3;          // at most
    double outerTolerance = 1e-6;     // relative change of every parameter that ends the outer loop
    int maxIterations = 100;          // trust-region iterations per outer iteration
    std::optional<std::vector<double>> start;  // starting θ (1 = the scene's concentrations); default all 1
    // Grid only: a Tikhonov prior on the gradient of θ between neighbouring nodes, weight α (residual
    // √α (θ_a − θ_b)); none picks α by the discrepancy rule, the largest α whose Pearson statistic at the
    // fit stays within N (1 + 2 √(2/N)) over the N fitted pixels.
    std::optional<double> priorWeight;
    double saturationSigmas = 6;      // pixels within this many noise sigmas of the full well are left out
    AcquireOptions acquisition;       // the model's quadrature, PSF, seed and threads (also the scattered render)
    std::function<void(const std::string&)> log;  // a line per iteration (progress)
    const std::atomic<bool>* cancel = nullptr;
    void validate() const;            // ConfigError naming the option and its value
};

const char* fitParametrisationName(FitParametrisation p);
const char* scatteredModelName(ScatteredModel s);
const char* fitLikelihoodName(FitLikelihood l);
// What a user types, into the options; ConfigError naming `option` and the text.
//  "labels", "grid:8um" (a length with its unit) or "grid:16um>8um>4um" (coarse to fine);  "auto" (labels per label, reestimated with a grid), "none",
//  "reestimated" or "labels" (set the parametrisation first);  "deviance" or "pearson".
void setParametrisation(FitOptions& o, const std::string& text, const std::string& option);
void setScatteredModel(FitOptions& o, const std::string& text, const std::string& option);
void setLikelihood(FitOptions& o, const std::string& text, const std::string& option);

// An observation ready for fitting: values of the fitted channels over the stack, what they are, and
// the camera's noise.
struct FitData {
    std::vector<size_t> channels;  // microscope channel indices, in the order of the values
    std::vector<double> values;    // (channel slot, plane, y, x): ADU, or electrons for noise-free data
    bool adu = true;               // values are camera counts (else expected photoelectrons, noise-free)
    CameraNoise noise;
};

// Matches an observed stack to the scene's microscope: the channels by name (`options.channels`, or all
// the stack holds), sizes, pixel size, z step, exposure and camera; ConfigError naming the file, the field
// and both values on any mismatch, and for NaN or ADU far below the offset.
FitData fitData(const ObservedStack& stack, const Microscope& microscope, const FitOptions& options);

struct FittedParameter {
    FitParameter parameter;
    double theta = 0;            // the scale of the template (1 = the scene's concentrations)
    double standardError = 0;    // of θ, from the covariance at the fit
    double cramerRao = 0;        // √ of the inverse Fisher information's diagonal at the fit (the data alone)
    double snr = 0;              // θ √I_jj: what the data alone say of θ_j with the others held (0 at the bound)
    double concentrationUm = 0;  // θ × the template's reference concentration, µM
    double concentrationStandardErrorUm = 0;
    bool atBound = false;        // held at θ = 0: its error is not a Gaussian one
};

struct FitResult {
    std::vector<FittedParameter> parameters;
    double deviance = 0;         // Σ r² over the fitted pixels (twice the negative log-likelihood ratio to a saturated model)
    double chi2 = 0;             // Σ (x − λ)²/λ at the fit
    double degreesOfFreedom = 0;
    size_t pixels = 0;           // fitted
    size_t saturatedPixels = 0;  // left out
    int iterations = 0;          // trust-region iterations, all outer iterations
    int outerIterations = 0;
    int coarserIterations = 0;   // coarse to fine: the coarser levels' trust-region iterations (not in `iterations`)
    int projections = 0;         // plane images projected (a forward image is planes × channels of them)
    double forwardEquivalents = 0;
    double seconds = 0;
    double priorWeight = 0;      // grid: the prior's weight used
    std::string solverReport;    // Ceres' full reports, one per outer iteration
    std::vector<std::string> logLines;
    std::vector<double> model;   // expected photoelectrons (with dark) per stack pixel at the fit
    std::vector<double> residual;            // observation − model, photoelectrons
    std::vector<double> normalisedResidual;  // signed-root deviance per pixel (0 where left out)
    std::vector<std::string> warnings;
    std::shared_ptr<const ParameterMap> map;  // how θ makes concentrations (for the fitted volume)
    LatticeGeometry frame;                    // the stack frame the grid parameters live in
};

// Fits `data` with the scene's microscope. `scene` is used as the template: its media are rescaled during
// the outer iterations and restored before returning. Throws ConfigError for bad options or no
// parameter to fit, Cancelled when options.cancel is set.
FitResult fitConcentrations(Scene& scene, const Microscope& microscope, const FitData& data, const FitOptions& options);

// The inner problem of a fit, y = A θ + b with A's columns and b fixed (the attenuation and scattered
// light frozen): maximum likelihood under the camera's noise with θ >= 0, by a bounded trust-region method,
// and the uncertainties at the solution. Built once, it solves any number of observations (noise
// realisations, outer iterations).
class LinearPoissonFit {
public:
    // `background`: per stack pixel, the expected photoelectrons that do not depend on θ (dark current,
    // fixed parts, scattered light). Uses the options' likelihood, iterations, threads, saturation margin,
    // log and cancel flag.
    LinearPoissonFit(const SparseColumns& columns, std::vector<double> background, const CameraNoise& noise, const ParameterMap& map,
                     const FitOptions& options);
    ~LinearPoissonFit();
    struct Solution {
        std::vector<double> theta, standardError, cramerRao, snr;  // errors 0 where not reported
        std::vector<bool> atBound;
        double deviance = 0, chi2 = 0, priorWeight = 0;
        size_t pixels = 0, saturatedPixels = 0;
        int iterations = 0;
        bool converged = true;
        std::string report;
    };
    // `observation`: per stack pixel, ADU when `adu`, else photoelectrons. `priorWeight` (grid only): the
    // gradient prior's α; negative picks it by the discrepancy rule. `outer` numbers the log lines.
    Solution solve(const std::vector<double>& observation, bool adu, std::vector<double> start, double priorWeight, bool uncertainties = true,
                   int outer = 1, std::vector<std::string>* log = nullptr) const;
    size_t parameters() const;
    // A new background over the stack's pixels (the same columns): a frozen part refreshed at a new estimate.
    void setBackground(const std::vector<double>& background);

    struct Impl;

private:
    friend double checkFitDerivatives(const LinearPoissonFit&, const std::vector<double>&, bool, const std::vector<double>&);
    std::unique_ptr<Impl> impl_;
};

// Checks the residuals' analytic derivatives against numeric ones (Ceres' GradientChecker) at θ for
// the observation; returns the largest relative error over the residual blocks.
double checkFitDerivatives(const LinearPoissonFit& fit, const std::vector<double>& observation, bool adu, const std::vector<double>& theta);

// The model's Jacobian columns for users who drive their own optimiser: ∂(expected photoelectrons)/∂θ_j
// per stack pixel of the computed image (the scattered light is not in them), at the scene's
// concentrations (θ = 1), for `options.channels`.
struct Gradient {
    std::vector<FitParameter> parameters;
    std::vector<size_t> channels;
    std::vector<std::vector<float>> columns;  // per parameter, the stack (channel slot, plane, y, x)
};
Gradient fitGradient(const Scene& scene, const Microscope& microscope, const FitOptions& options);

// The fitted concentrations as an OpenVDB file: each volume medium's dye grids rescaled by the fit (under
// their names, prefixed with the medium's name when several media have volumes) and its label grid.
// Throws IoError naming the file.
void writeFittedConcentrations(const std::filesystem::path& vdb, const Scene& scene, const FitResult& result);

}  // namespace fluorosim::optics
