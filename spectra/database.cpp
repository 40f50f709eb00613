#include "database.h"

#include <algorithm>
#include <cmath>
#include <cctype>
#include <charconv>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"

#ifndef FLUOROSIM_SPECTRA_DIR
#define FLUOROSIM_SPECTRA_DIR "spectra/data"
#endif

namespace fluorosim::spectra {
namespace fs = std::filesystem;
namespace {

std::string trim(const std::string& s) {
    const auto b = s.find_first_not_of(" \t\r\n");
    if (b == std::string::npos) return {};
    const auto e = s.find_last_not_of(" \t\r\n");
    return s.substr(b, e - b + 1);
}

std::vector<std::string> splitCsv(const std::string& line) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(trim(cell));
    if (!line.empty() && line.back() == ',') cells.emplace_back();
    return cells;
}

std::string numberText(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

std::string lower(std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

// Folds "Alexa Fluor 488", "AF488", "alexa-fluor-488" to one key.
std::string aliasKey(const std::string& name) {
    std::string key;
    for (char c : lower(name))
        if (std::isalnum(static_cast<unsigned char>(c))) key += c;
    if (key.rfind("alexafluor", 0) == 0) key = "af" + key.substr(10);
    if (key.rfind("alexa", 0) == 0) key = "af" + key.substr(5);
    return key;
}

size_t editDistance(const std::string& a, const std::string& b) {
    std::vector<size_t> prev(b.size() + 1), cur(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) prev[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        cur[0] = i;
        for (size_t j = 1; j <= b.size(); ++j)
            cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
        std::swap(prev, cur);
    }
    return prev[b.size()];
}

nlohmann::json loadDyeTable(const fs::path& dir) {
    const fs::path file = dir / "dyes.json";
    std::ifstream in(file);
    if (!in) throw IoError(file.string() + ": cannot open the dye table");
    try {
        return nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        throw ConfigError(file.string() + ": malformed JSON: " + e.what());
    }
}

std::string suggestion(const std::string& name, const std::vector<std::string>& candidates) {
    const auto close = closestNames(name, candidates);
    if (close.empty()) return {};
    std::string s = " (did you mean ";
    for (size_t i = 0; i < close.size(); ++i) s += (i ? ", " : "") + std::string("\"") + close[i] + "\"";
    return s + "?)";
}

// Opens a spectrum file, telling a folder or an oversized file from a missing one. A table's rows
// take about 40 bytes each in memory against at least 4 in the file.
std::ifstream openSpectrumFile(const fs::path& file) {
    std::error_code ec;
    if (fs::is_directory(file, ec)) throw IoError(file.string() + ": is a folder, expected a CSV spectrum file");
    // A device or pipe (/dev/zero) has no size to check and may never end.
    if (fs::exists(file, ec) && !fs::is_regular_file(file, ec))
        throw IoError(file.string() + ": not a regular file, expected a CSV spectrum file");
    std::ifstream in(file, std::ios::binary);
    if (!in) throw IoError(file.string() + ": cannot open spectrum file (" + std::strerror(errno) + ")");
    const auto size = fs::file_size(file, ec);
    if (!ec) requireMemory(10.0 * static_cast<double>(size), file.string() + ": reading a spectrum file of " + formatBytes(static_cast<double>(size)));
    return in;
}

}  // namespace

std::vector<std::string> closestNames(const std::string& name, const std::vector<std::string>& candidates, size_t count) {
    std::vector<std::pair<size_t, std::string>> scored;
    // The edit distance costs length x length: a huge name is compared by its start only.
    const std::string key = aliasKey(name.substr(0, 64));
    for (const auto& c : candidates) scored.emplace_back(editDistance(key, aliasKey(c)), c);
    std::stable_sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<std::string> out;
    for (size_t i = 0; i < scored.size() && i < count; ++i) out.push_back(scored[i].second);
    return out;
}

std::vector<TabulatedSpectrum> readSpectraCsv(const fs::path& file, const std::vector<std::string>& columns) {
    std::ifstream in = openSpectrumFile(file);
    return parseSpectraCsv(in, file.string(), columns);
}

std::vector<TabulatedSpectrum> parseSpectraCsv(std::istream& in, const std::string& file, const std::vector<std::string>& columns) {
    std::string line;
    if (!std::getline(in, line)) throw ConfigError(file + ": empty file, expected a header line");
    const auto header = splitCsv(line);
    auto columnIndex = [&](const std::string& name) {
        const auto it = std::find(header.begin(), header.end(), name);
        if (it == header.end()) throw ConfigError(file + ": missing column \"" + name + "\" in header \"" + excerpt(trim(line)) + "\"");
        return static_cast<size_t>(it - header.begin());
    };
    const size_t lambdaCol = columnIndex("wavelength_nm");
    std::vector<size_t> cols;
    for (const auto& c : columns) cols.push_back(columnIndex(c));
    std::vector<double> lambda;
    std::vector<std::vector<double>> values(columns.size());
    size_t row = 1;
    auto where = [&](const std::string& col) { return file + ":" + std::to_string(row) + ": column \"" + col + "\""; };
    while (std::getline(in, line)) {
        ++row;
        if (trim(line).empty() || trim(line)[0] == '#') continue;
        const auto cells = splitCsv(line);
        auto number = [&](size_t col, const std::string& colName) {
            if (col >= cells.size())
                throw ConfigError(file + ":" + std::to_string(row) + ": missing value in column \"" + colName + "\"");
            double v = 0;
            const std::string& cell = cells[col];
            const auto [ptr, ec] = std::from_chars(cell.data(), cell.data() + cell.size(), v);
            if (ec != std::errc() || ptr != cell.data() + cell.size())
                throw ConfigError(file + ":" + std::to_string(row) + ": column \"" + colName + "\" is not a number: \"" + excerpt(cell) + "\"");
            return v;
        };
        const double l = number(lambdaCol, "wavelength_nm");
        if (!std::isfinite(l) || l <= 0) throw ConfigError(where("wavelength_nm") + ": invalid wavelength " + numberText(l));
        if (!lambda.empty() && !(l > lambda.back()))
            throw ConfigError(where("wavelength_nm") + ": wavelengths must increase strictly, got " + numberText(l) + " nm after " +
                              numberText(lambda.back()) + " nm");
        lambda.push_back(l);
        for (size_t i = 0; i < cols.size(); ++i) {
            const double v = number(cols[i], columns[i]);
            if (!std::isfinite(v) || v < 0) throw ConfigError(where(columns[i]) + ": negative or non-finite value " + numberText(v));
            values[i].push_back(v);
        }
    }
    std::vector<TabulatedSpectrum> out;
    for (size_t i = 0; i < cols.size(); ++i)
        out.emplace_back(lambda, values[i], file + " column \"" + columns[i] + "\"");
    return out;
}

Database::Database(std::optional<fs::path> dataDir) {
    if (dataDir) dir_ = *dataDir;
    else if (const char* env = std::getenv("FLUOROSIM_SPECTRA_DIR")) dir_ = env;
    else dir_ = FLUOROSIM_SPECTRA_DIR;
    if (!fs::is_directory(dir_)) throw IoError(dir_.string() + ": spectral data folder not found (set FLUOROSIM_SPECTRA_DIR)");
}

ColorMatchingFunctions Database::cie1931() const {
    auto s = readSpectraCsv(dir_ / "color/cie1931_2deg_cmf_1nm.csv", {"x_bar", "y_bar", "z_bar"});
    return {s[0], s[1], s[2]};
}

TabulatedSpectrum Database::d65() const {
    return readSpectraCsv(dir_ / "color/cie_d65_1nm.csv", {"relative_spd"})[0];
}

std::vector<std::string> Database::filterNames() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_ / "filters"))
        if (e.path().extension() == ".csv") names.push_back(e.path().stem().string());
    std::sort(names.begin(), names.end());
    return names;
}

TabulatedSpectrum Database::filter(const std::string& name) const {
    const fs::path file = dir_ / "filters" / (name + ".csv");
    if (!fs::exists(file)) throw ConfigError("unknown filter \"" + excerpt(name) + "\"" + suggestion(name, filterNames()));
    return readSpectraCsv(file, {"transmission"})[0];
}

TabulatedSpectrum Database::solventAbsorption(const std::string& name) const {
    if (lower(name) != "water") throw ConfigError("unknown solvent \"" + excerpt(name) + "\" (known: \"water\")");
    const auto core = readSpectraCsv(dir_ / "water/water_absorption_pope_fry_1997.csv", {"absorption_coefficient_per_m"})[0];
    const auto ext = readSpectraCsv(dir_ / "water/water_absorption_extension_unattributed.csv", {"absorption_coefficient_per_m"})[0];
    std::vector<std::pair<double, double>> rows;
    for (size_t i = 0; i < ext.wavelengths().size(); ++i) rows.emplace_back(ext.wavelengths()[i], ext.values()[i]);
    for (size_t i = 0; i < core.wavelengths().size(); ++i) rows.emplace_back(core.wavelengths()[i], core.values()[i]);
    std::sort(rows.begin(), rows.end());
    std::vector<double> l, v;
    for (auto [a, b] : rows) {
        l.push_back(a);
        v.push_back(b * 1e-3);  // 1/m -> 1/mm
    }
    return TabulatedSpectrum(l, v, "water absorption");
}

std::vector<std::string> Database::dyeIds() const {
    std::vector<std::string> ids;
    const auto table = loadDyeTable(dir_);  // keep the table alive across the loop
    for (const auto& d : table.at("dyes")) ids.push_back(d.at("id").get<std::string>());
    return ids;
}

DyeRecord Database::dye(const std::string& nameOrAlias) const {
    const auto table = loadDyeTable(dir_);
    const std::string key = aliasKey(nameOrAlias);
    std::vector<std::string> ids;
    for (const auto& d : table.at("dyes")) {
        const std::string id = d.at("id").get<std::string>();
        ids.push_back(id);
        if (aliasKey(id) != key && aliasKey(d.at("name").get<std::string>()) != key) continue;
        DyeRecord rec;
        rec.id = id;
        rec.name = d.at("name").get<std::string>();
        auto spectra = readSpectraCsv(dir_ / d.at("spectrum_file").get<std::string>(), {"excitation", "emission"});
        rec.excitation = spectra[0];
        rec.emission = spectra[1];
        const auto& ec = d.at("extinction_coefficient_M-1cm-1");
        if (!ec.is_null()) rec.extinctionPeak = ec.get<double>();
        const auto& qy = d.at("quantum_yield");
        if (!qy.is_null()) rec.quantumYield = qy.get<double>();
        rec.excitationPeakNm = d.at("excitation_peak_nm").get<double>();
        rec.emissionPeakNm = d.at("emission_peak_nm").get<double>();
        return rec;
    }
    throw ConfigError("unknown dye \"" + excerpt(nameOrAlias) + "\"" + suggestion(nameOrAlias, ids));
}

Fluorophore Database::fluorophore(const std::string& nameOrAlias, std::optional<double> extinctionPeak,
                                  std::optional<double> quantumYield) const {
    const DyeRecord rec = dye(nameOrAlias);
    const std::optional<double> ec = extinctionPeak ? extinctionPeak : rec.extinctionPeak;
    const std::optional<double> qy = quantumYield ? quantumYield : rec.quantumYield;
    if (!ec)
        throw ConfigError("dye \"" + rec.id + "\" has no sourced peak extinction coefficient in dyes.json; give \"extinction_peak_M-1cm-1\"");
    if (!qy) throw ConfigError("dye \"" + rec.id + "\" has no sourced quantum yield in dyes.json; give \"quantum_yield\"");
    return Fluorophore(rec.id, rec.excitation, *ec, rec.emission, *qy);
}

TabulatedSpectrum Database::resolve(const std::string& reference, const fs::path& relativeTo) const {
    const auto colon = reference.find(':');
    const std::string kind = colon == std::string::npos ? "" : reference.substr(0, colon);
    const std::string name = colon == std::string::npos ? reference : reference.substr(colon + 1);
    if (kind == "filter") return filter(name);
    if (kind == "illuminant") {
        if (lower(name) != "d65") throw ConfigError("unknown illuminant \"" + excerpt(name) + "\" (known: \"D65\")");
        return d65();
    }
    if (kind == "cie") {
        const auto cmf = cie1931();
        if (name == "x") return cmf.x;
        if (name == "y") return cmf.y;
        if (name == "z") return cmf.z;
        throw ConfigError("unknown CIE function \"" + excerpt(name) + "\" (known: x, y, z)");
    }
    if (kind == "dye-excitation") return dye(name).excitation;
    if (kind == "dye-emission") return dye(name).emission;
    if (kind == "solvent-absorption") return solventAbsorption(name);
    if (!kind.empty())
        throw ConfigError("unknown spectrum kind \"" + excerpt(kind) + "\" in \"" + excerpt(reference) +
                          "\" (known: filter, illuminant, cie, dye-excitation, dye-emission, solvent-absorption)");
    fs::path file = reference;
    if (file.is_relative() && !relativeTo.empty()) file = relativeTo / file;
    std::ifstream in = openSpectrumFile(file);
    std::string header;
    std::getline(in, header);
    const auto cells = splitCsv(header);
    if (cells.size() != 2 || cells[0] != "wavelength_nm")
        throw ConfigError(file.string() + ": expected a header \"wavelength_nm,<value>\", got \"" + excerpt(trim(header)) + "\"");
    return readSpectraCsv(file, {cells[1]})[0];
}

}  // namespace fluorosim::spectra
