// 8-bit sRGB PNG previews with libpng.
#include <png.h>

#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "core/errors.h"
#include "io/image_io.h"
#include "spectral/color.h"

namespace fluorosim {
namespace {

// libpng reports errors through a callback that must not return; the reason is kept here for the IoError.
struct PngErrorContext {
    char message[256] = "unknown libpng error";
};

[[noreturn]] void pngError(png_structp png, png_const_charp message) {
    auto* context = static_cast<PngErrorContext*>(png_get_error_ptr(png));
    std::snprintf(context->message, sizeof context->message, "%s", message);
    png_longjmp(png, 1);
}

// Library code never prints; warnings (e.g. about ancillary chunks) do not affect the pixels.
void pngWarning(png_structp, png_const_charp) {}

// Returns false on failure with the reason in `context`. libpng leaves through longjmp, which would skip
// destructors, so this frame holds only trivially destructible objects and the caller owns every buffer.
bool writePngRows(std::FILE* file, png_uint_32 width, png_uint_32 height, const unsigned char* pixels,
                  PngErrorContext& context) {
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &context, pngError, pngWarning);
    if (!png) {
        std::snprintf(context.message, sizeof context.message, "cannot create libpng write struct");
        return false;
    }
    png_infop info = png_create_info_struct(png);
    if (!info) {
        png_destroy_write_struct(&png, nullptr);
        std::snprintf(context.message, sizeof context.message, "cannot create libpng info struct");
        return false;
    }
    // png and info are not modified after setjmp, so they need not be volatile.
    if (setjmp(png_jmpbuf(png))) {
        png_destroy_write_struct(&png, &info);
        return false;
    }
    png_init_io(png, file);
    png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                 PNG_FILTER_TYPE_DEFAULT);
    // Tags the file as sRGB so viewers do not apply a second gamma.
    png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    const std::size_t rowBytes = 3 * static_cast<std::size_t>(width);
    for (png_uint_32 y = 0; y < height; ++y) png_write_row(png, pixels + y * rowBytes);
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    return true;
}

}  // namespace

void writePngPreview(const std::string& path, int width, int height, const std::vector<float>& linearRgb,
                     double exposure) {
    if (width <= 0 || height <= 0)
        throw ConfigError(path + ": PNG size must be positive, got " + std::to_string(width) + "x" +
                          std::to_string(height));
    const std::size_t count = 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    if (linearRgb.size() != count)
        throw ConfigError(path + ": PNG preview has " + std::to_string(linearRgb.size()) + " values, expected " +
                          std::to_string(count) + " (3 x width x height)");
    if (!std::isfinite(exposure) || exposure < 0)
        throw ConfigError(path + ": PNG exposure must be finite and non-negative, got " + std::to_string(exposure));

    std::vector<unsigned char> pixels(count);
    for (std::size_t i = 0; i < count; ++i) {
        const double linear = linearRgb[i];
        // NaN or infinite samples are render failures; black makes them visible without poisoning neighbours.
        const double encoded = std::isfinite(linear) ? srgbEncode(linear * exposure) : 0.0;
        pixels[i] = static_cast<unsigned char>(std::lround(encoded * 255.0));
    }

    std::FILE* file = std::fopen(path.c_str(), "wb");
    if (!file) throw IoError(path + ": cannot write PNG file: " + std::strerror(errno));
    PngErrorContext context;
    const bool written = writePngRows(file, static_cast<png_uint_32>(width), static_cast<png_uint_32>(height),
                                      pixels.data(), context);
    // fclose flushes, so a full disk may only show up here.
    const bool closed = std::fclose(file) == 0;
    if (!written || !closed) {
        const std::string reason = written ? std::string(std::strerror(errno)) : std::string(context.message);
        std::remove(path.c_str());  // a truncated preview would look like a valid but wrong image
        throw IoError(path + ": cannot write PNG file: " + reason);
    }
}

}  // namespace fluorosim
