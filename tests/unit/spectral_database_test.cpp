// spectra::Database and readSpectraCsv: the shipped data files load with the expected values, dye
// aliases resolve, and malformed CSV files give messages naming file, row and column.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/errors.h"
#include "database.h"
#include "support/temp_dir.h"

namespace fluorosim {
namespace {

namespace fs = std::filesystem;

const fs::path kDataDir = fs::path(FLUOROSIM_SOURCE_DIR) / "spectra" / "data";

const spectra::Database& db() {
    static const spectra::Database database(kDataDir);
    return database;
}

double argmax(const TabulatedSpectrum& s) {
    const auto& v = s.values();
    return s.wavelengths()[static_cast<size_t>(std::max_element(v.begin(), v.end()) - v.begin())];
}

bool contains(const std::string& haystack, const std::string& needle) { return haystack.find(needle) != std::string::npos; }

using testing::TempDir;

TEST(SpectralDatabase, Cie1931) {
    const auto cmf = db().cie1931();
    EXPECT_NEAR(cmf.y.integral(), 106.86, 0.1);
    EXPECT_NEAR(cmf.x.integral(), 106.86, 0.1);
    EXPECT_NEAR(cmf.z.integral(), 106.89, 0.1);
    EXPECT_DOUBLE_EQ(cmf.y.minLambda(), 360.0);
    EXPECT_DOUBLE_EQ(cmf.y.maxLambda(), 830.0);
    EXPECT_NEAR(cmf.y(555), 1.0, 1e-3);
    EXPECT_NEAR(argmax(cmf.y), 555.0, 1.0);
}

TEST(SpectralDatabase, D65) {
    const auto d65 = db().d65();
    EXPECT_NEAR(d65(560), 100.0, 1e-9);  // D65 is normalized to 100 at 560 nm
    EXPECT_LE(d65.minLambda(), 360.0);
    EXPECT_GE(d65.maxLambda(), 780.0);
    EXPECT_GT(d65(460), d65(700));
}

TEST(SpectralDatabase, Filter) {
    const auto names = db().filterNames();
    ASSERT_NE(std::find(names.begin(), names.end(), "chroma_ET525-36m"), names.end());
    const auto f = db().filter("chroma_ET525-36m");
    EXPECT_GT(f(525), 0.8);
    EXPECT_LE(f.maxValue(), 1.0);
    EXPECT_LT(f(450), 1e-3);
    EXPECT_LT(f(600), 1e-3);
    // Same spectrum through a scene reference.
    const auto r = db().resolve("filter:chroma_ET525-36m");
    EXPECT_EQ(r.values(), f.values());
}

TEST(SpectralDatabase, UnknownFilterSuggestsClosest) {
    try {
        db().filter("chroma_ET525-36");
        FAIL() << "accepted";
    } catch (const ConfigError& e) {
        EXPECT_TRUE(contains(e.what(), "chroma_ET525-36")) << e.what();
        EXPECT_TRUE(contains(e.what(), "chroma_ET525-36m")) << e.what();
    }
}

// Every row of the Pope & Fry file, read independently, appears in the database in 1/mm.
TEST(SpectralDatabase, WaterAbsorptionPerMillimetre) {
    const auto water = db().solventAbsorption("water");
    EXPECT_NEAR(water(500), 0.0204e-3, 1e-12);  // Pope & Fry: 0.0204 1/m at 500 nm
    std::ifstream in(kDataDir / "water" / "water_absorption_pope_fry_1997.csv");
    ASSERT_TRUE(in);
    std::string line;
    std::getline(in, line);
    ASSERT_EQ(line.substr(0, line.find_last_not_of("\r") + 1), "wavelength_nm,absorption_coefficient_per_m");
    int rows = 0;
    bool saw500 = false;
    while (std::getline(in, line)) {
        if (line.empty() || line[0] == '#') continue;
        std::stringstream ss(line);
        std::string a, b;
        std::getline(ss, a, ',');
        std::getline(ss, b, ',');
        const double l = std::stod(a), perM = std::stod(b);
        if (l == 500) {
            saw500 = true;
            EXPECT_DOUBLE_EQ(perM, 0.0204);
        }
        EXPECT_NEAR(water(l), perM * 1e-3, 1e-15 + 1e-12 * perM) << "at " << l << " nm";
        ++rows;
    }
    EXPECT_TRUE(saw500);
    EXPECT_GT(rows, 100);
    // The unattributed extension covers 350-370 nm.
    EXPECT_NEAR(water(350), 0.0204e-3, 1e-12);
    EXPECT_DOUBLE_EQ(water.minLambda(), 350.0);
    EXPECT_NO_THROW(db().solventAbsorption("Water"));
    EXPECT_THROW(db().solventAbsorption("ethanol"), ConfigError);
    EXPECT_NEAR(db().resolve("solvent-absorption:water")(500), 0.0204e-3, 1e-12);
}

TEST(SpectralDatabase, EveryDyePeaksWhereDyesJsonSays) {
    std::ifstream in(kDataDir / "dyes.json");
    ASSERT_TRUE(in);
    const auto table = nlohmann::json::parse(in);
    ASSERT_GE(table.at("dyes").size(), 10u);
    for (const auto& d : table.at("dyes")) {
        const std::string id = d.at("id").get<std::string>();
        SCOPED_TRACE(id);
        const auto rec = db().dye(id);
        EXPECT_EQ(rec.id, id);
        EXPECT_EQ(rec.name, d.at("name").get<std::string>());
        const double ex = d.at("excitation_peak_nm").get<double>(), em = d.at("emission_peak_nm").get<double>();
        EXPECT_NEAR(argmax(rec.excitation), ex, 1.0);
        EXPECT_NEAR(argmax(rec.emission), em, 1.0);
        EXPECT_DOUBLE_EQ(rec.excitationPeakNm, ex);
        EXPECT_DOUBLE_EQ(rec.emissionPeakNm, em);
        EXPECT_NEAR(rec.excitation.maxValue(), 1.0, 1e-6);  // relative, peak 1
        EXPECT_NEAR(rec.emission.maxValue(), 1.0, 1e-6);
        EXPECT_LT(ex, em) << "Stokes shift";
        // The same spectra through scene references.
        EXPECT_EQ(db().resolve("dye-excitation:" + id).values(), rec.excitation.values());
        EXPECT_EQ(db().resolve("dye-emission:" + id).values(), rec.emission.values());
        if (!d.at("quantum_yield").is_null()) {
            ASSERT_TRUE(rec.quantumYield.has_value());
            EXPECT_DOUBLE_EQ(*rec.quantumYield, d.at("quantum_yield").get<double>());
        } else {
            EXPECT_FALSE(rec.quantumYield.has_value());
        }
    }
}

std::vector<std::string> dyeIdsFromJson() {
    std::ifstream in(kDataDir / "dyes.json");
    const auto table = nlohmann::json::parse(in);
    std::vector<std::string> ids;
    for (const auto& d : table.at("dyes")) ids.push_back(d.at("id").get<std::string>());
    return ids;
}

TEST(SpectralDatabase, DyeIdsListsEveryDye) {
    const auto expected = dyeIdsFromJson();
    ASSERT_GE(expected.size(), 10u);
    EXPECT_EQ(db().dyeIds(), expected);
}

TEST(SpectralDatabase, DyeAliases) {
    const auto a = db().dye("AF488"), b = db().dye("Alexa Fluor 488"), c = db().dye("alexa_fluor_488");
    EXPECT_EQ(a.id, "alexa_fluor_488");
    EXPECT_EQ(b.id, "alexa_fluor_488");
    EXPECT_EQ(c.id, "alexa_fluor_488");
    EXPECT_EQ(a.excitation.values(), c.excitation.values());
    EXPECT_EQ(b.emission.values(), c.emission.values());
    EXPECT_EQ(db().dye("alexa-fluor-488").id, "alexa_fluor_488");
    EXPECT_EQ(db().dye("Alexa488").id, "alexa_fluor_488");
}

TEST(SpectralDatabase, UnknownDyeSuggestsClosest) {
    try {
        db().dye("AF489");
        FAIL() << "accepted";
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_TRUE(contains(msg, "AF489")) << msg;
        EXPECT_TRUE(contains(msg, "alexa_fluor_488")) << msg;
        // The best suggestion comes first.
        const auto close = spectra::closestNames("AF489", dyeIdsFromJson());
        ASSERT_FALSE(close.empty());
        EXPECT_EQ(close.front(), "alexa_fluor_488");
    }
}

TEST(SpectralDatabase, ResolveRejectsUnknownReferences) {
    EXPECT_THROW(db().resolve("illuminant:D50"), ConfigError);
    EXPECT_THROW(db().resolve("cie:w"), ConfigError);
    EXPECT_THROW(db().resolve("nonsense:thing"), ConfigError);
    EXPECT_THROW(db().resolve("dye-emission:AF489"), ConfigError);
    try {
        db().resolve("illuminant:D50");
    } catch (const ConfigError& e) {
        EXPECT_TRUE(contains(e.what(), "D50")) << e.what();
    }
}

TEST(SpectralDatabase, ResolvesRelativeCsvPath) {
    const TempDir dir;
    dir.write("mine.csv", "wavelength_nm,transmission\n400,0.5\n500,1\n");
    const auto s = db().resolve("mine.csv", dir.path());
    EXPECT_DOUBLE_EQ(s(450), 0.75);
    try {
        db().resolve("missing.csv", dir.path());
        FAIL() << "accepted";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), "missing.csv")) << e.what();
    }
}

TEST(SpectralDatabase, MissingDataFolderIsIoError) {
    const fs::path nowhere = fs::temp_directory_path() / ("fluorosim_no_such_dir_" + std::to_string(::getpid()));
    try {
        spectra::Database bad(nowhere);
        FAIL() << "accepted";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), nowhere.string())) << e.what();
    }
}

TEST(ReadSpectraCsv, ReadsNamedColumns) {
    const TempDir dir;
    const auto f = dir.write("ok.csv", "wavelength_nm, a ,b\n400,1,0\n# a comment\n\n500,3,2\n600,0,4\n");
    const auto s = spectra::readSpectraCsv(f, {"b", "a"});
    ASSERT_EQ(s.size(), 2u);
    EXPECT_EQ(s[0].values(), (std::vector<double>{0, 2, 4}));
    EXPECT_EQ(s[1].values(), (std::vector<double>{1, 3, 0}));
    EXPECT_EQ(s[1].wavelengths(), (std::vector<double>{400, 500, 600}));
}

// Expects ConfigError naming the file and each of `parts`.
void expectCsvRejected(const fs::path& file, const std::vector<std::string>& columns, const std::vector<std::string>& parts) {
    try {
        spectra::readSpectraCsv(file, columns);
        ADD_FAILURE() << "accepted " << file;
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_TRUE(contains(msg, file.string())) << msg;
        for (const auto& p : parts) EXPECT_TRUE(contains(msg, p)) << "no \"" << p << "\" in: " << msg;
    }
}

// The row of a problem is the line number in the file (the header is line 1), as an editor shows it.
bool namesLine(const std::string& msg, const fs::path& file, int line) {
    const std::string n = std::to_string(line);
    return contains(msg, file.string() + ":" + n + ":") || contains(msg, "row " + n) || contains(msg, "line " + n);
}

void expectCsvRejectedAtLine(const fs::path& file, const std::vector<std::string>& columns, int line,
                             const std::vector<std::string>& parts) {
    try {
        spectra::readSpectraCsv(file, columns);
        ADD_FAILURE() << "accepted " << file;
    } catch (const ConfigError& e) {
        const std::string msg = e.what();
        EXPECT_TRUE(contains(msg, file.string())) << msg;
        EXPECT_TRUE(namesLine(msg, file, line)) << "does not name line " << line << " of the file: " << msg;
        for (const auto& p : parts) EXPECT_TRUE(contains(msg, p)) << "no \"" << p << "\" in: " << msg;
    }
}

TEST(ReadSpectraCsv, RejectsMissingColumn) {
    const TempDir dir;
    const auto f = dir.write("missing_column.csv", "wavelength_nm,excitation\n400,1\n500,2\n");
    expectCsvRejected(f, {"excitation", "emission"}, {"emission"});
    const auto g = dir.write("no_wavelength.csv", "lambda,excitation\n400,1\n500,2\n");
    expectCsvRejected(g, {"excitation"}, {"wavelength_nm"});
}

TEST(ReadSpectraCsv, RejectsNonIncreasingWavelengths) {
    const TempDir dir;
    // Line 4 (450 nm after 500 nm) is the bad one.
    const auto f = dir.write("non_increasing.csv", "wavelength_nm,value\n400,1\n500,1\n450,1\n600,1\n");
    expectCsvRejectedAtLine(f, {"value"}, 4, {"450"});
    const auto g = dir.write("repeated.csv", "wavelength_nm,value\n400,1\n400,1\n");
    expectCsvRejectedAtLine(g, {"value"}, 3, {"400"});
}

TEST(ReadSpectraCsv, RejectsNegativeValue) {
    const TempDir dir;
    const auto f = dir.write("negative.csv", "wavelength_nm,value\n400,1\n500,-0.25\n600,1\n");
    expectCsvRejectedAtLine(f, {"value"}, 3, {"-0.25", "value"});
}

TEST(ReadSpectraCsv, RejectsNonNumericCell) {
    const TempDir dir;
    const auto f = dir.write("non_numeric.csv", "wavelength_nm,value\n400,1\n500,abc\n600,1\n");
    expectCsvRejectedAtLine(f, {"value"}, 3, {"abc", "value"});
    const auto g = dir.write("trailing.csv", "wavelength_nm,value\n400,1\n500,2x\n");
    expectCsvRejectedAtLine(g, {"value"}, 3, {"2x"});
    const auto h = dir.write("missing_cell.csv", "wavelength_nm,a,b\n400,1,2\n500,3\n");
    expectCsvRejectedAtLine(h, {"a", "b"}, 3, {"b"});
}

TEST(ReadSpectraCsv, RejectsTooFewRows) {
    const TempDir dir;
    const auto f = dir.write("one_row.csv", "wavelength_nm,value\n400,1\n");
    expectCsvRejected(f, {"value"}, {});
    const auto g = dir.write("empty.csv", "");
    expectCsvRejected(g, {"value"}, {});
}

TEST(ReadSpectraCsv, MissingFileIsIoError) {
    const TempDir dir;
    const fs::path f = dir.path() / "does_not_exist.csv";
    try {
        spectra::readSpectraCsv(f, {"value"});
        FAIL() << "accepted";
    } catch (const IoError& e) {
        EXPECT_TRUE(contains(e.what(), f.string())) << e.what();
    }
}

}  // namespace
}  // namespace fluorosim
