#include "core/units.h"

#include <cctype>
#include <charconv>
#include <cmath>

#include "core/errors.h"
#include "core/message.h"

namespace fluorosim {
namespace {

std::string_view trim(std::string_view s) {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
    return s;
}

// "u" for the micro sign (U+00B5) and the Greek mu (U+03BC), which look alike.
std::string asciiMicro(std::string_view unit) {
    std::string out;
    for (size_t i = 0; i < unit.size(); ++i) {
        const std::string_view rest = unit.substr(i);
        if (rest.substr(0, 2) == "\xC2\xB5" || rest.substr(0, 2) == "\xCE\xBC") {
            out += 'u';
            ++i;
        } else {
            out += unit[i];
        }
    }
    return out;
}

std::optional<double> lengthInMm(std::string_view u) {
    if (u == "m") return 1e3;
    if (u == "cm") return 10.0;
    if (u == "mm") return 1.0;
    if (u == "um" || u == "micron") return 1e-3;
    if (u == "nm") return 1e-6;
    return std::nullopt;
}

}  // namespace

const char* dimensionName(Dimension d) {
    switch (d) {
        case Dimension::Length: return "a length (e.g. \"5 mm\")";
        case Dimension::InverseLength: return "a coefficient (e.g. \"90 /cm\")";
        case Dimension::Wavelength: return "a wavelength (e.g. \"550 nm\")";
        case Dimension::Dimensionless: return "a number";
        case Dimension::MolarConcentration: return "a concentration (e.g. \"10 uM\")";
        case Dimension::MassConcentration: return "a mass concentration (e.g. \"0.1 g/L\")";
        case Dimension::MolarMass: return "a molar mass (e.g. \"643.4 g/mol\")";
        case Dimension::Time: return "a time (e.g. \"50 ms\")";
        case Dimension::Power: return "a power (e.g. \"3 mW\")";
    }
    return "?";
}

const char* acceptedUnits(Dimension d) {
    switch (d) {
        case Dimension::Length: return "m, cm, mm, um, nm";
        case Dimension::InverseLength: return "/m, /cm, /mm, /um";
        case Dimension::Wavelength: return "nm, um";
        case Dimension::Dimensionless: return "none";
        case Dimension::MolarConcentration: return "M, mM, uM, nM, pM";
        case Dimension::MassConcentration: return "g/L, mg/mL, mg/L, ug/mL, ug/L";
        case Dimension::MolarMass: return "g/mol, Da, kg/mol, kDa";
        case Dimension::Time: return "s, ms, us, ns, min";
        case Dimension::Power: return "W, mW, uW, nW";
    }
    return "?";
}

std::optional<double> unitScale(std::string_view text, Dimension dim) {
    const std::string ascii = asciiMicro(trim(text));
    const std::string_view unit = ascii;
    switch (dim) {
        case Dimension::Length: return lengthInMm(unit);
        case Dimension::Wavelength: {
            if (unit == "nm") return 1.0;
            if (unit == "um") return 1e3;
            return std::nullopt;
        }
        case Dimension::InverseLength: {
            std::string_view u = unit;
            if (!u.empty() && u.front() == '/') u = trim(u.substr(1));
            else if (u.size() > 2 && u.substr(0, 2) == "1/") u = trim(u.substr(2));
            else if (u.size() > 3 && u.substr(u.size() - 3) == "^-1") u = trim(u.substr(0, u.size() - 3));
            else return std::nullopt;
            const auto l = lengthInMm(u);
            if (!l) return std::nullopt;
            return 1.0 / *l;
        }
        case Dimension::Dimensionless: return unit.empty() ? std::optional<double>(1.0) : std::nullopt;
        case Dimension::MolarConcentration: {
            if (unit == "M" || unit == "mol/L") return 1.0;
            if (unit == "mM" || unit == "mmol/L") return 1e-3;
            if (unit == "uM" || unit == "umol/L") return 1e-6;
            if (unit == "nM" || unit == "nmol/L") return 1e-9;
            if (unit == "pM") return 1e-12;
            return std::nullopt;
        }
        case Dimension::MassConcentration: {
            if (unit == "g/L" || unit == "mg/mL") return 1.0;
            if (unit == "mg/L" || unit == "ug/mL") return 1e-3;
            if (unit == "ug/L") return 1e-6;
            return std::nullopt;
        }
        case Dimension::MolarMass: {
            if (unit == "g/mol" || unit == "Da") return 1.0;
            if (unit == "kg/mol" || unit == "kDa") return 1e3;
            return std::nullopt;
        }
        case Dimension::Time: {
            if (unit == "s") return 1.0;
            if (unit == "ms") return 1e-3;
            if (unit == "us") return 1e-6;
            if (unit == "ns") return 1e-9;
            if (unit == "min") return 60.0;
            return std::nullopt;
        }
        case Dimension::Power: {
            if (unit == "W") return 1e3;
            if (unit == "mW") return 1.0;
            if (unit == "uW") return 1e-3;
            if (unit == "nW") return 1e-6;
            return std::nullopt;
        }
    }
    return std::nullopt;
}

double parseQuantity(std::string_view text, Dimension dim, std::string_view what,
                     std::optional<std::string_view> bareUnit) {
    const std::string_view s = trim(text);
    auto fail = [&](const std::string& why) -> double {
        throw ConfigError(std::string(what) + ": " + why + " (got \"" + excerpt(text) + "\", expected " +
                          dimensionName(dim) + ")");
    };
    double value = 0;
    const char* begin = s.data();
    const char* end = s.data() + s.size();
    // from_chars rejects a leading '+', accept it for convenience.
    if (begin != end && *begin == '+') ++begin;
    const auto [ptr, ec] = std::from_chars(begin, end, value);
    if (ec == std::errc::result_out_of_range) return fail("beyond the range of double precision");
    if (ec != std::errc() || ptr == begin) return fail("not a number");
    if (!std::isfinite(value)) return fail("not finite");
    const std::string_view unit = trim(std::string_view(ptr, static_cast<size_t>(end - ptr)));
    // The product is checked too: "1e308 m" is finite in metres but not in millimetres.
    auto scaled = [&](double scale) {
        const double v = value * scale;
        return std::isfinite(v) ? v : fail("too large: not finite in internal units");
    };
    if (unit.empty()) {
        if (dim == Dimension::Dimensionless) return value;
        if (!bareUnit) return fail("missing unit");
        const auto scale = unitScale(*bareUnit, dim);
        if (!scale) return fail("the default unit \"" + std::string(*bareUnit) + "\" does not fit");
        return scaled(*scale);
    }
    const auto scale = unitScale(unit, dim);
    if (!scale) return fail("unknown or mismatched unit \"" + excerpt(unit) + "\" (units: " + acceptedUnits(dim) + ")");
    return scaled(*scale);
}

}  // namespace fluorosim
