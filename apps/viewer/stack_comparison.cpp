#include "viewer/stack_comparison.h"

#include <algorithm>
#include <cmath>
#include <regex>

#include "core/errors.h"
#include "core/parallel.h"
#include "optics/filter.h"
#include "optics/ome_tiff.h"
#include "optics/stack_files.h"
#include "viewer/microscope_overlay.h"

namespace fluorosim::viewer {
namespace fs = std::filesystem;
namespace {

// The value of attribute `name` in the first element `<tag ...>` at or after `from`; "" when absent.
std::string attribute(const std::string& xml, const std::string& tag, const std::string& name, size_t from = 0) {
    const size_t open = xml.find("<" + tag + " ", from);
    if (open == std::string::npos) return "";
    const size_t close = xml.find('>', open);
    const std::string element = xml.substr(open, close == std::string::npos ? std::string::npos : close - open);
    std::smatch m;
    if (!std::regex_search(element, m, std::regex("\\s" + name + "=\"([^\"]*)\""))) return "";
    std::string value = m[1].str();
    static const std::pair<std::string, std::string> kEntities[] = {
        {"&lt;", "<"}, {"&gt;", ">"}, {"&quot;", "\""}, {"&apos;", "'"}, {"&amp;", "&"}};
    for (const auto& [entity, text] : kEntities)
        for (size_t at = value.find(entity); at != std::string::npos; at = value.find(entity, at + 1))
            value.replace(at, entity.size(), text);
    return value;
}

double positiveNumber(const std::string& text, const std::string& what, const fs::path& file) {
    try {
        size_t used = 0;
        const double v = std::stod(text, &used);
        if (used == text.size() && std::isfinite(v) && v > 0) return v;
    } catch (const std::exception&) {
    }
    throw ConfigError(file.string() + ": OME-XML " + what + " must be a positive number (got \"" + text + "\")");
}

// Least squares y ≈ a x + b, and the correlation of x and y.
void fitLine(const std::vector<float>& x, const std::vector<float>& y, double& a, double& b, double& r) {
    const double n = static_cast<double>(x.size());
    double sx = 0, sy = 0;
    for (size_t i = 0; i < x.size(); ++i) sx += x[i], sy += y[i];
    const double mx = sx / n, my = sy / n;
    double sxx = 0, syy = 0, sxy = 0;
    for (size_t i = 0; i < x.size(); ++i) {
        const double dx = x[i] - mx, dy = y[i] - my;
        sxx += dx * dx, syy += dy * dy, sxy += dx * dy;
    }
    a = sxx > 0 ? sxy / sxx : 0;
    b = my - a * mx;
    r = sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0;
}

}  // namespace

OmeStackInfo parseOmeXml(const std::string& xml, const fs::path& file) {
    if (xml.find("<OME") == std::string::npos || xml.find("<Pixels ") == std::string::npos)
        throw ConfigError(file.string() + ": not an OME-TIFF (no OME-XML with <Pixels> in the first page)");
    OmeStackInfo info;
    const std::string order = attribute(xml, "Pixels", "DimensionOrder");
    if (order != "XYZCT") throw ConfigError(file.string() + ": DimensionOrder must be XYZCT, as acquire writes it (got \"" + order + "\")");
    auto size = [&](const char* name) {
        const double v = positiveNumber(attribute(xml, "Pixels", name), std::string("Pixels/") + name, file);
        if (v != std::floor(v) || v > 1e6) throw ConfigError(file.string() + ": OME-XML Pixels/" + name + " must be a whole number");
        return static_cast<int>(v);
    };
    info.width = size("SizeX");
    info.height = size("SizeY");
    info.planes = size("SizeZ");
    info.channels = size("SizeC");
    if (size("SizeT") != 1) throw ConfigError(file.string() + ": the viewer shows stacks with one time point (SizeT = 1)");
    info.pixelSizeUm = positiveNumber(attribute(xml, "Pixels", "PhysicalSizeX"), "Pixels/PhysicalSizeX", file);
    const std::string z = attribute(xml, "Pixels", "PhysicalSizeZ");
    info.zStepUm = z.empty() ? 1.0 : positiveNumber(z, "Pixels/PhysicalSizeZ", file);
    info.pixelType = attribute(xml, "Pixels", "Type");
    for (size_t at = xml.find("<Channel "); at != std::string::npos; at = xml.find("<Channel ", at + 1))
        info.channelNames.push_back(attribute(xml, "Channel", "Name", at));
    if (static_cast<int>(info.channelNames.size()) != info.channels)
        throw ConfigError(file.string() + ": OME-XML lists " + std::to_string(info.channelNames.size()) + " channels but SizeC is " +
                          std::to_string(info.channels));
    return info;
}

int truthChannelFor(const optics::MicroscopeChannel& channel, const Specimen& specimen) {
    for (size_t c = 0; c < specimen.channels.size(); ++c)
        if (specimen.channels[c].grid && (specimen.channels[c].name == channel.name || specimen.channels[c].id == channel.name))
            return static_cast<int>(c);
    int best = -1;
    double bestEfficiency = 0;
    for (size_t c = 0; c < specimen.channels.size(); ++c) {
        const DyeChannel& d = specimen.channels[c];
        if (!d.grid || !d.dye) continue;
        const double e = optics::emissionPathEfficiency(channel.filters, d.dye->emission());
        if (e > bestEfficiency) bestEfficiency = e, best = static_cast<int>(c);
    }
    return best;
}

StackComparison loadStackComparison(const fs::path& stack, const Scene& scene, const optics::Microscope& microscope,
                                    const Specimen& specimen) {
    if (!fs::exists(stack)) throw IoError(stack.string() + ": no such file");
    const optics::TiffStackInfo tiff = optics::readTiffStack(stack, true);
    StackComparison s;
    s.file = stack;
    s.info = parseOmeXml(tiff.imageDescription, stack);
    const OmeStackInfo& info = s.info;
    if (tiff.pages != info.planes * info.channels || tiff.width != info.width || tiff.height != info.height)
        throw ConfigError(stack.string() + ": the file holds " + std::to_string(tiff.pages) + " pages of " + std::to_string(tiff.width) +
                          " x " + std::to_string(tiff.height) + " pixels, but its OME-XML describes " + std::to_string(info.planes) +
                          " planes x " + std::to_string(info.channels) + " channels of " + std::to_string(info.width) + " x " +
                          std::to_string(info.height));
    if (info.width != microscope.width || info.height != microscope.height)
        throw ConfigError(stack.string() + ": the stack's planes are " + std::to_string(info.width) + " x " + std::to_string(info.height) +
                          " pixels, but the scene's detector has " + std::to_string(microscope.width) + " x " +
                          std::to_string(microscope.height) + " (a stack of another scene?)");
    const double pixelUm = microscope.pixelSizeMm() * kUmPerMm;
    if (std::abs(info.pixelSizeUm - pixelUm) > 1e-3 * pixelUm)
        throw ConfigError(stack.string() + ": the stack's pixels are " + std::to_string(info.pixelSizeUm) + " um in the sample, but the scene's " +
                          "microscope gives " + std::to_string(pixelUm) + " um (a stack of another scene?)");
    s.counts = tiff.sampleFormat != 3;
    // Name the sibling: the expected stack beside a counts stack, or the counts beside an expected stack.
    const std::string name = stack.filename().string();
    const std::string expectedSuffix = ".expected.ome.tif";
    fs::path sibling;
    if (name.size() > expectedSuffix.size() && name.ends_with(expectedSuffix))
        sibling = stack.parent_path() / (name.substr(0, name.size() - expectedSuffix.size()) + ".ome.tif");
    else if (name.ends_with(".ome.tif"))
        sibling = optics::StackOutputs::forStack(stack).expected;
    if (!sibling.empty() && fs::exists(sibling)) s.sibling = sibling;

    MicroscopeOverlay overlay(scene, microscope, info.planes, info.zStepUm);
    const size_t planePixels = size_t(info.width) * info.height;
    for (int c = 0; c < info.channels; ++c) {
        ChannelComparison cc;
        cc.name = info.channelNames[size_t(c)];
        const optics::MicroscopeChannel& mc = microscope.channels.at(microscope.channelIndex(cc.name));
        const auto first = tiff.pixels.begin() + static_cast<std::ptrdiff_t>(size_t(c) * info.planes * planePixels);
        cc.simulated.assign(first, first + static_cast<std::ptrdiff_t>(size_t(info.planes) * planePixels));
        cc.truthChannel = truthChannelFor(mc, specimen);
        cc.truth.assign(cc.simulated.size(), 0.f);
        if (cc.truthChannel >= 0) {
            const DyeChannel& dye = specimen.channels[size_t(cc.truthChannel)];
            // Supersample the pixel footprint when a pixel spans more than a voxel.
            const double voxelUm = std::abs(dye.worldUmFromIndex.m[0][0]);
            const int n = std::max(1, static_cast<int>(std::ceil(pixelUm / voxelUm)));
            parallelFor(size_t(info.planes) * info.height, 0, [&](size_t row) {
                const int plane = static_cast<int>(row / size_t(info.height)), y = static_cast<int>(row % size_t(info.height));
                const FieldOfView fov = overlay.fieldOfView(plane);
                for (int x = 0; x < info.width; ++x) {
                    double sum = 0;
                    for (int sy = 0; sy < n; ++sy)
                        for (int sx = 0; sx < n; ++sx) {
                            const Vec3 p = fov.pixelCentreUm(x + (sx + 0.5) / n - 0.5, y + (sy + 0.5) / n - 0.5);
                            sum += dye.grid->value(dye.indexFromWorldUm.apply(p), Interpolation::Trilinear);
                        }
                    cc.truth[row * size_t(info.width) + size_t(x)] = static_cast<float>(sum / (n * n));
                }
            });
        }
        fitLine(cc.truth, cc.simulated, cc.fitScale, cc.fitOffset, cc.correlation);
        cc.residual.resize(cc.simulated.size());
        double sum2 = 0;
        for (size_t i = 0; i < cc.residual.size(); ++i) {
            cc.residual[i] = static_cast<float>(cc.simulated[i] - (cc.fitScale * cc.truth[i] + cc.fitOffset));
            sum2 += double(cc.residual[i]) * cc.residual[i];
        }
        cc.residualRms = std::sqrt(sum2 / static_cast<double>(std::max<size_t>(1, cc.residual.size())));
        s.channels.push_back(std::move(cc));
    }
    return s;
}

}  // namespace fluorosim::viewer
