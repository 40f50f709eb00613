#include "viewer/colour.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/errors.h"

namespace fluorosim::viewer {
namespace {

const std::pair<const char*, Colour> kNamedColours[] = {
    {"green", {0, 1, 0}},  {"magenta", {1, 0, 1}}, {"cyan", {0, 1, 1}},     {"yellow", {1, 1, 0}},
    {"red", {1, 0, 0}},    {"blue", {0.2, 0.4, 1}}, {"orange", {1, 0.55, 0}}, {"white", {1, 1, 1}},
};

uint8_t toByte(double v) { return static_cast<uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0)); }

}  // namespace

Colour parseColour(const std::string& text, const std::string& what) {
    for (const auto& [name, colour] : kNamedColours)
        if (text == name) return colour;
    if (text.size() == 7 && text[0] == '#' && text.find_first_not_of("0123456789abcdefABCDEF", 1) == std::string::npos) {
        Colour c;
        for (int i = 0; i < 3; ++i) c[size_t(i)] = std::stoi(text.substr(1 + 2 * size_t(i), 2), nullptr, 16) / 255.0;
        return c;
    }
    std::string names;
    for (const auto& [name, colour] : kNamedColours) names += std::string(names.empty() ? "" : ", ") + name;
    throw ConfigError(what + ": unknown colour \"" + text + "\" (use " + names + " or #rrggbb)");
}

Colour defaultChannelColour(int channel) {
    return kNamedColours[size_t(channel) % std::size(kNamedColours)].second;
}

Colour wavelengthColour(double lambdaNm, const ColorMatchingFunctions& cmf) {
    const Rgb rgb = xyzToLinearSrgb({cmf.x(lambdaNm), cmf.y(lambdaNm), cmf.z(lambdaNm)});
    Colour c{std::max(0.0, rgb[0]), std::max(0.0, rgb[1]), std::max(0.0, rgb[2])};
    const double peak = std::max({c[0], c[1], c[2]});
    if (peak <= 0) return {1, 1, 1};  // outside the visible range: show it white
    for (double& v : c) v /= peak;
    return c;
}

double Window::intensity(double v) const {
    if (high <= low) return v >= high ? 1.0 : 0.0;
    return std::clamp((v - low) / (high - low), 0.0, 1.0);
}

Window Window::fromWidthLevel(double width, double level) { return {level - 0.5 * width, level + 0.5 * width}; }

std::vector<uint8_t> Composite::rgb8() const {
    std::vector<uint8_t> out(rgb_.size());
    for (size_t i = 0; i < rgb_.size(); ++i) out[i] = toByte(rgb_[i]);
    return out;
}

std::array<uint8_t, 3> divergingColour(double value, double limit) {
    const double t = limit > 0 ? std::clamp(value / limit, -1.0, 1.0) : 0.0;
    if (t >= 0) return {toByte(t), toByte(0.25 * t), toByte(0.25 * t)};
    return {toByte(-0.25 * t), toByte(-0.45 * t), toByte(-t)};
}

}  // namespace fluorosim::viewer
