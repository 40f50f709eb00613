#include <cstdio>
#include <memory>
#include <optional>
#include <sstream>

#include "cli_checks.h"
#include "commands.h"
#include "core/errors.h"
#include "core/units.h"
#include "progress.h"
#include "render/slab_transport.h"

namespace fluorosim::app {
namespace {

struct SlabArgs {
    std::string mua = "0", mus = "0", thickness, n = "1", nAbove = "1", nBelow = "1";
    double g = 0;
    std::string muaDye = "0";
    double quantumYield = 0;
    std::optional<std::string> muaEm, musEm, muaDyeEm;
    std::optional<double> gEm;
    double photons = 1e6;
    uint64_t seed = 1;
    int threads = 0;
    bool quiet = false;
};

double index(const std::string& s, const char* name) {
    const double v = parseQuantity(s, Dimension::Dimensionless, std::string("--") + name);
    if (!(v >= 1.0 && v <= 10.0)) throw ConfigError(std::string("--") + name + ": refractive index must lie in [1, 10], got \"" + s + "\"");
    return v;
}

// Parses an option and checks its sign against the text the user typed, so messages quote it.
double physical(const std::string& text, Dimension dim, const char* name, const char* bareUnit, bool allowZero) {
    const double v = parseQuantity(text, dim, std::string("--") + name, bareUnit);
    if (v < 0 || (!allowZero && v == 0))
        throw ConfigError(std::string("--") + name + ": must be " + (allowZero ? "non-negative" : "positive") + ", got \"" + text + "\"");
    return v;
}

void runSlab(const SlabArgs& a) {
    SlabOptions o;
    // Bare numbers follow MCML: 1/cm and cm. Internally everything is mm.
    o.mua = physical(a.mua, Dimension::InverseLength, "mua", "/cm", true);
    o.mus = physical(a.mus, Dimension::InverseLength, "mus", "/cm", true);
    o.thickness = physical(a.thickness, Dimension::Length, "thickness", "cm", false);
    o.g = a.g;
    o.muaDye = physical(a.muaDye, Dimension::InverseLength, "mua-dye", "/cm", true);
    o.quantumYield = a.quantumYield;
    if (a.muaEm || a.musEm || a.muaDyeEm || a.gEm) {
        SlabBand em = o.excitation();
        if (a.muaEm) em.mua = physical(*a.muaEm, Dimension::InverseLength, "mua-emission", "/cm", true);
        if (a.musEm) em.mus = physical(*a.musEm, Dimension::InverseLength, "mus-emission", "/cm", true);
        if (a.muaDyeEm) em.muaDye = physical(*a.muaDyeEm, Dimension::InverseLength, "mua-dye-emission", "/cm", true);
        if (a.gEm) em.g = *a.gEm;
        o.emission = em;
    }
    o.n = index(a.n, "n");
    o.nAbove = index(a.nAbove, "n-above");
    o.nBelow = index(a.nBelow, "n-below");
    if (!(a.photons >= 2 && a.photons <= 1.1e12)) {
        std::ostringstream os;
        os << "--photons: must lie in [2, 1.1e12], got " << a.photons;
        throw ConfigError(os.str());
    }
    o.photons = static_cast<uint64_t>(a.photons);
    o.seed = a.seed;
    o.threads = a.threads;
    o.validate();
    std::unique_ptr<ProgressBar> bar;
    if (!a.quiet) bar = std::make_unique<ProgressBar>("slab");
    const SlabResult r = simulateSlab(o, [&](uint64_t done, uint64_t total) {
        if (bar) bar->update(static_cast<double>(done) / static_cast<double>(total));
    });
    if (bar) bar->finish();
    std::printf(
        "{\"Rd\": %.8f, \"Tt\": %.8f, \"Rd_stderr\": %.8f, \"Tt_stderr\": %.8f, \"Rsp\": %.8f, \"Ta\": %.8f, "
        "\"Tt_ballistic\": %.8f, \"Rf\": %.8f, \"Tf\": %.8f, \"Rf_stderr\": %.8f, \"Tf_stderr\": %.8f, \"guided\": %.8f, "
        "\"photons\": %llu, \"seconds\": %.4f, \"photons_per_second\": %.1f, "
        "\"input\": {\"mua_per_cm\": %.8g, \"mus_per_cm\": %.8g, \"g\": %.8g, \"mua_dye_per_cm\": %.8g, \"quantum_yield\": %.8g, "
        "\"emission_band\": {\"mua_per_cm\": %.8g, \"mus_per_cm\": %.8g, \"g\": %.8g, \"mua_dye_per_cm\": %.8g}, "
        "\"thickness_cm\": %.8g, \"n\": %.8g, \"n_above\": %.8g, \"n_below\": %.8g, \"seed\": %llu}}\n",
        r.Rd, r.Tt, r.RdStderr, r.TtStderr, r.Rsp, r.Ta, r.Tballistic, r.Rf, r.Tf, r.RfStderr, r.TfStderr, r.guided,
        static_cast<unsigned long long>(r.photons), r.seconds, static_cast<double>(r.photons) / std::max(r.seconds, 1e-9), o.mua * 10,
        o.mus * 10, o.g, o.muaDye * 10, o.quantumYield, o.emissionBand().mua * 10, o.emissionBand().mus * 10, o.emissionBand().g,
        o.emissionBand().muaDye * 10, o.thickness / 10, o.n, o.nAbove, o.nBelow, static_cast<unsigned long long>(o.seed));
}

}  // namespace

void addValidateCommands(CLI::App& app) {
    CLI::App* validate = app.add_subcommand("validate", "Validation runs against independent results");
    validate->require_subcommand(1);
    auto a = std::make_shared<SlabArgs>();
    CLI::App* slab = validate->add_subcommand("slab", "Rd and Tt of a slab under a normal pencil beam (MCML conventions)");
    slab->add_option("--mua", a->mua, "Absorption coefficient (bare: 1/cm; or e.g. 9/mm)");
    slab->add_option("--mus", a->mus, "Scattering coefficient (bare: 1/cm)");
    slab->add_option("--g", a->g, "Henyey-Greenstein anisotropy in (-1, 1)");
    slab->add_option("--thickness", a->thickness, "Slab thickness (bare: cm; or e.g. 0.2mm)")->required();
    slab->add_option("--n", a->n, "Refractive index of the slab");
    slab->add_option("--n-above", a->nAbove, "Refractive index above (incident side)");
    slab->add_option("--n-below", a->nBelow, "Refractive index below");
    slab->add_option("--mua-dye", a->muaDye, "Absorption by a grey fluorescent dye (bare: 1/cm)");
    slab->add_option("--quantum-yield", a->quantumYield, "Photons re-emitted per photon absorbed by the dye, [0, 1]");
    slab->add_option("--mua-emission", a->muaEm, "Emission band: absorption other than the dye's (default: --mua)");
    slab->add_option("--mus-emission", a->musEm, "Emission band: scattering (default: --mus)");
    slab->add_option("--g-emission", a->gEm, "Emission band: anisotropy (default: --g)");
    slab->add_option("--mua-dye-emission", a->muaDyeEm, "Emission band: dye re-absorption (default: --mua-dye)");
    slab->add_option("--photons", a->photons, "Number of photons (e.g. 1e6)");
    slab->add_option("--seed", a->seed, "Random seed")->check(nonNegativeInteger());
    slab->add_option("--threads", a->threads, "Threads (0 = all cores)");
    slab->add_flag("--quiet", a->quiet, "No progress bar");
    slab->callback([a] { runSlab(*a); });
    addFluorescenceValidations(*validate);
    addLightSheetValidation(*validate);
}

}  // namespace fluorosim::app
