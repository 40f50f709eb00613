#include "optics/stack_files.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>

#include <unistd.h>

#include "core/errors.h"
#include "io/image_io.h"
#include "optics/ome_tiff.h"

namespace fluorosim::optics {
namespace fs = std::filesystem;
namespace {

constexpr const char* kCheckpointMagic = "fluorosim acquire checkpoint 1";

template <class T>
std::vector<T> firstPlanes(const std::vector<T>& data, const Stack& stack, int planes) {
    const size_t plane = static_cast<size_t>(stack.width) * stack.height;
    std::vector<T> out;
    out.reserve(plane * planes * stack.channels.size());
    for (size_t c = 0; c < stack.channels.size(); ++c)
        out.insert(out.end(), data.begin() + static_cast<std::ptrdiff_t>(stack.pixelOffset(c, 0)),
                   data.begin() + static_cast<std::ptrdiff_t>(stack.pixelOffset(c, 0) + plane * planes));
    return out;
}

struct RecordHeader {
    uint32_t slot;
    int32_t plane;
    uint32_t width, height;
};

}  // namespace

StackOutputs StackOutputs::forStack(const fs::path& stack) {
    const std::string text = stack.string(), suffix = ".ome.tif";
    if (text.size() <= suffix.size() || text.compare(text.size() - suffix.size(), suffix.size(), suffix) != 0)
        throw ConfigError(text + ": output must end in .ome.tif");
    const std::string base = text.substr(0, text.size() - suffix.size());
    return {stack, base + ".expected.ome.tif", base + ".stderr.ome.tif", base + ".preview.png"};
}

CameraMetadata cameraMetadata(const DetectorOptions& d) {
    CameraMetadata c;
    c.sensor = d.type == SensorType::Emccd ? "EMCCD" : "sCMOS";
    c.gainElectronsPerAdu = d.gainElectronsPerAdu;
    c.offsetAdu = d.offsetAdu;
    c.readNoiseElectrons = d.readNoiseElectrons;
    c.emGain = d.emGain;
    c.darkCurrentElectronsPerS = d.darkCurrentElectronsPerS;
    c.fullWellElectrons = d.fullWellElectrons;
    c.bitDepth = d.bitDepth;
    return c;
}

void writeStackFiles(const StackOutputs& out, const Stack& stack, const Microscope& m, int planes, const std::string& description) {
    StackMetadata meta;
    meta.pixelSizeUm = m.pixelSizeMm() * 1e3;
    meta.zStepUm = m.stack.stepMm * 1e3;
    meta.exposureS = m.detector.exposureS;
    meta.significantBits = m.detector.bitDepth;
    meta.camera = cameraMetadata(m.detector);
    for (size_t c : stack.channels) meta.channels.push_back({m.channels[c].name, m.channels[c].excitationNm, m.channels[c].emissionNm});
    const int channels = static_cast<int>(stack.channels.size());
    meta.description = description;
    writeOmeTiffUint16(out.counts, stack.width, stack.height, planes, channels, firstPlanes(stack.counts, stack, planes), meta);
    meta.description = description + "; expected photoelectrons (with dark current, before noise)";
    meta.values = "electrons";
    writeOmeTiffFloat32(out.expected, stack.width, stack.height, planes, channels, firstPlanes(stack.expected, stack, planes), meta);
    meta.description = description + "; Monte Carlo standard error of the expected photoelectrons";
    writeOmeTiffFloat32(out.stderrElectrons, stack.width, stack.height, planes, channels, firstPlanes(stack.stderrElectrons, stack, planes),
                        meta);
    writeStackPreview(out.preview, stack, planes, meta.pixelSizeUm, meta.zStepUm);
}

double previewScaleBarUm(double pixelSizeUm, int width) {
    const double limit = 0.2 * width * pixelSizeUm;
    double bar = 0;
    for (int k = -3; k <= 6; ++k)
        for (double m : {1.0, 2.0, 5.0})
            if (m * std::pow(10.0, k) <= limit) bar = m * std::pow(10.0, k);
    return bar;
}

void writeStackPreview(const fs::path& png, const Stack& stack, int planes, double pixelSizeUm, double zStepUm) {
    static const float colours[4][3] = {{0, 1, 0}, {1, 0, 1}, {1, 0, 0}, {0, 1, 1}};
    const int width = stack.width, height = stack.height, gap = 4;
    const int channels = static_cast<int>(stack.channels.size());
    const int panels = channels > 1 ? channels + 1 : channels;
    const int stretch = std::max(1, static_cast<int>(std::lround(zStepUm / pixelSizeUm)));
    const int sliceRows = planes * stretch;
    const bool side = planes > 1 && sliceRows * 10 >= height;
    const int outW = panels * width + (panels - 1) * gap, outH = height + (side ? gap + sliceRows : 0);
    std::vector<float> rgb(static_cast<size_t>(outW) * outH * 3, 0.0f);
    const size_t plane = static_cast<size_t>(width) * height;
    auto put = [&](int x, int y, const float* col, float t) {
        for (int k = 0; k < 3; ++k) rgb[(static_cast<size_t>(y) * outW + x) * 3 + k] += col[k] * std::min(1.0f, t);
    };
    auto percentile = [](std::vector<float> v, double q) {
        std::sort(v.begin(), v.end());
        return v[static_cast<size_t>(q * (v.size() - 1))];
    };
    for (int c = 0; c < channels; ++c) {
        const float* base = stack.expected.data() + stack.pixelOffset(static_cast<size_t>(c), 0);
        std::vector<float> mip(plane, 0.0f);
        for (int k = 0; k < planes; ++k)
            for (size_t i = 0; i < plane; ++i) mip[i] = std::max(mip[i], base[k * plane + i]);
        const float scale = percentile(mip, 0.995);
        if (!(scale > 0)) continue;
        const float* col = colours[c % 4];
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) {
                const float t = mip[static_cast<size_t>(y) * width + x] / scale;
                put(c * (width + gap) + x, y, col, t);
                if (panels > channels) put(channels * (width + gap) + x, y, col, t);
            }
        if (!side) continue;
        // The x-z panel, under the last panel: the maximum over y (a single row misses most neurites), each
        // plane `stretch` rows tall, on its own scale (a maximum over y is brighter than the x-y projection).
        std::vector<float> xz(static_cast<size_t>(planes) * width, 0.0f);
        for (int k = 0; k < planes; ++k)
            for (int x = 0; x < width; ++x)
                for (int y = 0; y < height; ++y)
                    xz[static_cast<size_t>(k) * width + x] = std::max(xz[static_cast<size_t>(k) * width + x], base[k * plane + static_cast<size_t>(y) * width + x]);
        const float sideScale = std::max(percentile(xz, 0.99), 1e-30f);
        for (int k = 0; k < planes; ++k)
            for (int x = 0; x < width; ++x)
                for (int r = 0; r < stretch; ++r)
                    put((panels - 1) * (width + gap) + x, height + gap + k * stretch + r, col, xz[static_cast<size_t>(k) * width + x] / sideScale);
    }
    // Scale bars: 2 rows (at least), a margin of 1/32 of the panel.
    const int barPixels = static_cast<int>(std::lround(previewScaleBarUm(pixelSizeUm, width) / pixelSizeUm));
    const int thick = std::max(2, height / 128), margin = std::max(2, width / 32);
    static const float white[3] = {1, 1, 1};
    for (int p = 0; p < panels && barPixels > 0; ++p)
        for (int y = height - margin - thick; y < height - margin; ++y)
            for (int x = margin; x < margin + barPixels && x < width; ++x) {
                if (y < 0) continue;
                for (int k = 0; k < 3; ++k) rgb[(static_cast<size_t>(y) * outW + p * (width + gap) + x) * 3 + k] = 0;
                put(p * (width + gap) + x, y, white, 1.0f);
            }
    // The PNG writer applies the sRGB curve; these values are already display-scaled in [0, 1].
    writePngPreview(png.string(), outW, outH, rgb, 1.0);
}

StackCheckpoint::StackCheckpoint(fs::path path, const std::string& fingerprint) : path_(std::move(path)) {
    std::ofstream f(path_, std::ios::binary | std::ios::trunc);
    f << kCheckpointMagic << '\n' << fingerprint << '\n';
    f.flush();
    if (!f) throw IoError(path_.string() + ": cannot write the checkpoint");
}

StackCheckpoint StackCheckpoint::resume(fs::path path, const std::string& fingerprint, Stack& stack, const Microscope& m, uint64_t seed) {
    std::ifstream f(path, std::ios::binary);
    if (!f) throw IoError(path.string() + ": no checkpoint to resume from");
    std::string magic, stored;
    std::getline(f, magic);
    std::getline(f, stored);
    if (magic != kCheckpointMagic) throw ConfigError(path.string() + ": not a Fluorosim acquisition checkpoint");
    if (stored != fingerprint)
        throw ConfigError(path.string() + ": the checkpoint was written for another scene, seed or options; run without --resume to start over");
    std::streamoff good = f.tellg();
    while (true) {
        RecordHeader h{};
        if (!f.read(reinterpret_cast<char*>(&h), sizeof h)) break;
        if (h.slot >= stack.channels.size() || h.plane < 0 || h.plane >= stack.planes || static_cast<int>(h.width) != stack.width ||
            static_cast<int>(h.height) != stack.height)
            throw ConfigError(path.string() + ": a record does not fit the stack (corrupt checkpoint)");
        PlaneImage image;
        image.width = stack.width;
        image.height = stack.height;
        const size_t n = static_cast<size_t>(stack.width) * stack.height;
        image.electrons.resize(n);
        image.stderrElectrons.resize(n);
        if (!f.read(reinterpret_cast<char*>(image.electrons.data()), static_cast<std::streamsize>(n * sizeof(double))) ||
            !f.read(reinterpret_cast<char*>(image.stderrElectrons.data()), static_cast<std::streamsize>(n * sizeof(double))))
            break;  // a record cut short: the plane is rendered again
        storePlane(stack, m, h.slot, h.plane, image, seed);
        good = f.tellg();
    }
    f.close();
    fs::resize_file(path, static_cast<uintmax_t>(good));
    return StackCheckpoint(std::move(path));
}

void StackCheckpoint::append(size_t slot, int plane, const PlaneImage& image) {
    FILE* f = std::fopen(path_.c_str(), "ab");
    if (!f) throw IoError(path_.string() + ": cannot append to the checkpoint");
    const RecordHeader h{static_cast<uint32_t>(slot), plane, static_cast<uint32_t>(image.width), static_cast<uint32_t>(image.height)};
    bool ok = std::fwrite(&h, sizeof h, 1, f) == 1;
    ok = ok && std::fwrite(image.electrons.data(), sizeof(double), image.electrons.size(), f) == image.electrons.size();
    ok = ok && std::fwrite(image.stderrElectrons.data(), sizeof(double), image.stderrElectrons.size(), f) == image.stderrElectrons.size();
    ok = ok && std::fflush(f) == 0 && ::fsync(fileno(f)) == 0;
    ok = (std::fclose(f) == 0) && ok;
    if (!ok) throw IoError(path_.string() + ": cannot write to the checkpoint");
}

}  // namespace fluorosim::optics
