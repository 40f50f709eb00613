// Uses the installed library: the spectral database from the installed data, a dye's absorption, and
// a light sheet's peak irradiance from optics. Prints them; exits non-zero on any error.
#include <cstdio>
#include <exception>

#include "database.h"
#include "optics/light_sheet.h"

int main() {
    try {
        const fluorosim::spectra::Database db(SPECTRA_DIR);
        const fluorosim::Fluorophore af488 = db.fluorophore("AF488");
        fluorosim::LightSheetSpec sheet;
        sheet.wavelengthNm = 488;
        sheet.waistMm = 0.002;
        sheet.heightMm = 0.3;
        sheet.powerMw = 5;
        const auto profile = fluorosim::optics::makeLightSheet(sheet);
        std::printf("AF488 quantum yield %.2f; sheet irradiance at its waist %.4g W/mm^2\n", af488.quantumYield(),
                    profile->irradiance(fluorosim::Vec3(0, 0, 0), 0, 488.0));
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "consumer: %s\n", e.what());
        return 1;
    }
}
