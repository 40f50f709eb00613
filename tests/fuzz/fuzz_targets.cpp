#include "fuzz/fuzz_targets.h"

#include <cmath>
#include <filesystem>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "core/errors.h"
#include "core/units.h"
#include "database.h"
#include "morphology/swc.h"
#include "optics/light_sheet.h"
#include "scene/scene_loader.h"

namespace fluorosim::fuzz {
namespace {

namespace fs = std::filesystem;

void require(bool ok, const char* what) {
    if (!ok) throw std::logic_error(std::string("fuzz invariant broken: ") + what);
}

bool finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

const spectra::Database& database() {
    static const spectra::Database db(fs::path(FLUOROSIM_SOURCE_DIR) / "spectra" / "data");
    return db;
}

}  // namespace

int sceneLoader(const uint8_t* data, size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    const fs::path file = fs::path(FLUOROSIM_SOURCE_DIR) / "samples" / "cornell" / "fuzz.json";
    try {
        const Scene s = loadSceneFromString(
            text, file, [](const std::string& ref, const fs::path& base) { return database().resolve(ref, base); },
            [](const std::string& name, std::optional<double> ec, std::optional<double> qy) { return database().fluorophore(name, ec, qy); },
            [](const LightSheetSpec& spec) { return optics::makeLightSheet(spec); });
        const Camera& c = s.camera;
        require(c.width >= 1 && c.height >= 1 && static_cast<int64_t>(c.width) * c.height <= (int64_t(1) << 26), "camera resolution");
        require(std::isfinite(c.tanHalfFovY) && c.tanHalfFovY > 0, "camera field of view");
        require(finite(c.position) && finite(c.frame.n) && finite(c.frame.s) && finite(c.frame.t), "camera frame");
        require(s.spectral.lambdaMin >= 100 && s.spectral.lambdaMin < s.spectral.lambdaMax && s.spectral.lambdaMax <= 20000, "range");
        require(!s.lights.empty(), "a scene has a light");
        require(s.render.spp >= 1 && s.render.maxDepth >= 1, "render settings");
    } catch (const Error&) {
        // Refused with a message: the expected outcome for most inputs.
    }
    return 0;
}

int swcReader(const uint8_t* data, size_t size) {
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    try {
        const Morphology m = parseSwc(text, "fuzz.swc");
        require(!m.samples.empty(), "samples");
        for (const SwcSample& s : m.samples) require(s.radiusUm > 0 && std::isfinite(s.radiusUm) && finite(s.positionUm), "sample");
        for (const MorphologyPiece& p : morphologyPieces(m))
            require(p.raUm > 0 && p.rbUm > 0 && finite(p.aUm) && finite(p.bUm), "piece");
        const double v = analyticVolumeUm3(m);
        require(v >= 0 && !std::isnan(v), "volume");  // may overflow to inf for coordinates near 1e308
        require(medianRadiusUm(m) > 0, "median radius");
    } catch (const Error&) {
    }
    return 0;
}

int spectraCsv(const uint8_t* data, size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    // Every column of the header after wavelength_nm, once each.
    std::vector<std::string> columns;
    std::set<std::string> seen;
    std::string cell;
    std::istringstream header(text.substr(0, text.find('\n')));
    while (std::getline(header, cell, ',') && columns.size() < 8)
        if (!cell.empty() && cell != "wavelength_nm" && seen.insert(cell).second) columns.push_back(cell);
    try {
        std::istringstream in(text);
        const auto spectra = spectra::parseSpectraCsv(in, "fuzz.csv", columns);
        require(spectra.size() == columns.size(), "one spectrum per column");
        for (const TabulatedSpectrum& s : spectra) {
            const auto& l = s.wavelengths();
            const auto& v = s.values();
            require(l.size() == v.size() && l.size() >= 1, "table size");
            for (size_t i = 0; i < l.size(); ++i) {
                require(std::isfinite(l[i]) && l[i] > 0 && (i == 0 || l[i] > l[i - 1]), "wavelengths increase");
                require(std::isfinite(v[i]) && v[i] >= 0, "values finite and non-negative");
            }
        }
    } catch (const Error&) {
    }
    return 0;
}

int units(const uint8_t* data, size_t size) {
    if (size < 2) return 0;
    constexpr Dimension dims[] = {Dimension::Length,         Dimension::InverseLength,     Dimension::Wavelength, Dimension::Dimensionless,
                                  Dimension::MolarConcentration, Dimension::MassConcentration, Dimension::MolarMass};
    const Dimension dim = dims[data[0] % 7];
    const char* bare[] = {nullptr, "cm", "/cm", "nm", "uM"};
    const char* bareUnit = bare[data[1] % 5];
    const std::string_view text(reinterpret_cast<const char*>(data + 2), size - 2);
    try {
        const double v = bareUnit ? parseQuantity(text, dim, "fuzz", std::string_view(bareUnit)) : parseQuantity(text, dim, "fuzz");
        require(std::isfinite(v), "parseQuantity returns finite values");
    } catch (const Error&) {
    }
    if (const auto scale = unitScale(text, dim)) require(std::isfinite(*scale) && *scale > 0, "unit scales are positive");
    return 0;
}

}  // namespace fluorosim::fuzz
