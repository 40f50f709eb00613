#pragma once
// The spectral database: dyes, filters, solvents and CIE tables, loaded by name from CSV files in a
// data folder (spectra/data, with SOURCES.md naming the origin of every file).
#include <filesystem>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "media/fluorophore.h"
#include "spectral/color.h"
#include "spectral/tabulated_spectrum.h"

namespace fluorosim::spectra {

// Reads the named columns of a CSV file with a header line. Throws IoError when the file cannot be
// opened and ConfigError (naming file, row and column) for missing columns, malformed numbers,
// non-increasing wavelengths or negative values.
std::vector<TabulatedSpectrum> readSpectraCsv(const std::filesystem::path& file,
                                              const std::vector<std::string>& columns);
// The same on a stream; `source` names it in messages.
std::vector<TabulatedSpectrum> parseSpectraCsv(std::istream& in, const std::string& source, const std::vector<std::string>& columns);

struct DyeRecord {
    std::string id, name;
    TabulatedSpectrum excitation;  // relative, peak 1
    TabulatedSpectrum emission;    // relative, peak 1
    std::optional<double> extinctionPeak;  // M^-1 cm^-1
    std::optional<double> quantumYield;
    double excitationPeakNm = 0, emissionPeakNm = 0;
};

class Database {
public:
    // Uses `dataDir`, or $FLUOROSIM_SPECTRA_DIR, or the source tree's spectra/data.
    explicit Database(std::optional<std::filesystem::path> dataDir = std::nullopt);
    const std::filesystem::path& dataDir() const { return dir_; }

    ColorMatchingFunctions cie1931() const;
    TabulatedSpectrum d65() const;
    TabulatedSpectrum filter(const std::string& name) const;
    // Solvent absorption in 1/mm (water: Pope & Fry 1997 with the unattributed 350-370/710-800 nm rows).
    TabulatedSpectrum solventAbsorption(const std::string& name) const;
    DyeRecord dye(const std::string& nameOrAlias) const;
    // The dye as a Fluorophore; `extinctionPeak` (M^-1 cm^-1) and `quantumYield` override the table, and
    // are required where dyes.json has no sourced value (null). Throws ConfigError.
    Fluorophore fluorophore(const std::string& nameOrAlias, std::optional<double> extinctionPeak = std::nullopt,
                            std::optional<double> quantumYield = std::nullopt) const;
    std::vector<std::string> dyeIds() const;
    std::vector<std::string> filterNames() const;

    // Resolves "kind:name" references used by scene files: "filter:chroma_ET525-36m", "illuminant:D65",
    // "cie:x|y|z", "dye-excitation:<dye>", "dye-emission:<dye>", "solvent-absorption:water",
    // or a path to a two-column CSV file (wavelength_nm,value). Throws ConfigError with suggestions.
    TabulatedSpectrum resolve(const std::string& reference, const std::filesystem::path& relativeTo = {}) const;

private:
    std::filesystem::path dir_;
};

// Names in `candidates` closest to `name` (edit distance), best first.
std::vector<std::string> closestNames(const std::string& name, const std::vector<std::string>& candidates, size_t count = 3);

}  // namespace fluorosim::spectra
