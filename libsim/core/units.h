#pragma once
// Quantities with units. Internal units (docs/units.md): length in mm, coefficients in 1/mm,
// wavelength in nm, time in s, power in mW.
#include <optional>
#include <string>
#include <string_view>

namespace fluorosim {

// Internal units: mm, 1/mm, nm, s, mW; concentrations in mol/L, mass concentrations in g/L, molar masses in g/mol.
enum class Dimension { Length, InverseLength, Wavelength, Dimensionless, MolarConcentration, MassConcentration, MolarMass, Time, Power };

const char* dimensionName(Dimension d);
// The units a dimension accepts, for error messages ("m, cm, mm, um, nm").
const char* acceptedUnits(Dimension d);

// Parses "5 mm", "0.2mm", "90 /cm", "9/mm", "550 nm", "1.5um" into internal units.
// A bare number is accepted only when bareUnit is given (e.g. "cm" for MCML-style CLI options);
// otherwise it is an error. Throws ConfigError naming `what` and the text.
double parseQuantity(std::string_view text, Dimension dim, std::string_view what,
                     std::optional<std::string_view> bareUnit = std::nullopt);

// Scale from a unit name to internal units, or nullopt when the unit does not fit the dimension. The
// micro prefix may be written u, µ (micro sign) or μ (Greek mu).
std::optional<double> unitScale(std::string_view unit, Dimension dim);

}  // namespace fluorosim
