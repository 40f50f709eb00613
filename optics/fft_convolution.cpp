#include "optics/fft_convolution.h"

#include <fftw3.h>

#include <complex>
#include <mutex>
#include <string>

#include "core/errors.h"

namespace fluorosim::optics {
namespace {

// FFTW's planner is not thread-safe; executing a plan on new arrays is.
std::mutex& plannerMutex() {
    static std::mutex m;
    return m;
}

int fastSize(int n) {
    for (int m = n;; ++m) {
        int r = m;
        for (int p : {2, 3, 5, 7})
            while (r % p == 0) r /= p;
        if (r == 1) return m;
    }
}

struct FftwBuffer {
    explicit FftwBuffer(size_t bytes) : data(fftw_malloc(bytes)) {
        if (!data) throw std::bad_alloc();
    }
    ~FftwBuffer() { fftw_free(data); }
    FftwBuffer(const FftwBuffer&) = delete;
    FftwBuffer& operator=(const FftwBuffer&) = delete;
    void* data;
};

}  // namespace

struct FftConvolution::Impl {
    int width, height, radius, nx, ny;
    size_t spectrumSize;  // ny × (nx/2 + 1) complex values
    fftw_plan forward = nullptr, backward = nullptr;
    std::vector<std::vector<std::complex<double>>> kernels;

    ~Impl() {
        const std::lock_guard<std::mutex> lock(plannerMutex());
        if (forward) fftw_destroy_plan(forward);
        if (backward) fftw_destroy_plan(backward);
    }
};

FftConvolution::FftConvolution(int width, int height, int kernelRadius) : impl_(std::make_unique<Impl>()) {
    if (width < 1 || height < 1 || kernelRadius < 0)
        throw ConfigError("FFT convolution needs a positive image size and a non-negative kernel radius, got " + std::to_string(width) + " x " +
                          std::to_string(height) + ", radius " + std::to_string(kernelRadius));
    Impl& m = *impl_;
    m.width = width;
    m.height = height;
    m.radius = kernelRadius;
    m.nx = fastSize(width + kernelRadius);
    m.ny = fastSize(height + kernelRadius);
    m.spectrumSize = static_cast<size_t>(m.ny) * (m.nx / 2 + 1);
    FftwBuffer real(sizeof(double) * m.nx * m.ny), complex(sizeof(fftw_complex) * m.spectrumSize);
    const std::lock_guard<std::mutex> lock(plannerMutex());
    m.forward = fftw_plan_dft_r2c_2d(m.ny, m.nx, static_cast<double*>(real.data), static_cast<fftw_complex*>(complex.data), FFTW_ESTIMATE);
    m.backward = fftw_plan_dft_c2r_2d(m.ny, m.nx, static_cast<fftw_complex*>(complex.data), static_cast<double*>(real.data), FFTW_ESTIMATE);
    if (!m.forward || !m.backward) throw NumericError("FFTW could not plan a " + std::to_string(m.nx) + " x " + std::to_string(m.ny) + " transform");
}

FftConvolution::~FftConvolution() = default;
FftConvolution::FftConvolution(FftConvolution&&) noexcept = default;
FftConvolution& FftConvolution::operator=(FftConvolution&&) noexcept = default;

int FftConvolution::kernelCount() const { return static_cast<int>(impl_->kernels.size()); }

int FftConvolution::addKernel(const std::vector<double>& kernel) {
    Impl& m = *impl_;
    const int side = 2 * m.radius + 1;
    if (kernel.size() != static_cast<size_t>(side) * side)
        throw ConfigError("FFT convolution kernel has " + std::to_string(kernel.size()) + " values, expected " + std::to_string(side * side));
    FftwBuffer real(sizeof(double) * m.nx * m.ny), complex(sizeof(fftw_complex) * m.spectrumSize);
    double* r = static_cast<double*>(real.data);
    std::fill(r, r + static_cast<size_t>(m.nx) * m.ny, 0.0);
    for (int dy = -m.radius; dy <= m.radius; ++dy)
        for (int dx = -m.radius; dx <= m.radius; ++dx) {
            const int x = (dx + m.nx) % m.nx, y = (dy + m.ny) % m.ny;
            r[static_cast<size_t>(y) * m.nx + x] = kernel[static_cast<size_t>(dy + m.radius) * side + (dx + m.radius)];
        }
    fftw_execute_dft_r2c(m.forward, r, static_cast<fftw_complex*>(complex.data));
    const auto* c = static_cast<const std::complex<double>*>(complex.data);
    m.kernels.emplace_back(c, c + m.spectrumSize);
    return static_cast<int>(m.kernels.size()) - 1;
}

std::vector<double> FftConvolution::convolveSum(const std::vector<std::vector<double>>& images) const {
    const Impl& m = *impl_;
    if (images.size() > m.kernels.size())
        throw ConfigError("FFT convolution got " + std::to_string(images.size()) + " images for " + std::to_string(m.kernels.size()) + " kernels");
    const size_t realSize = static_cast<size_t>(m.nx) * m.ny;
    FftwBuffer real(sizeof(double) * realSize), complex(sizeof(fftw_complex) * m.spectrumSize);
    std::vector<std::complex<double>> sum(m.spectrumSize, 0.0);
    double* r = static_cast<double*>(real.data);
    auto* c = static_cast<std::complex<double>*>(complex.data);
    bool any = false;
    for (size_t b = 0; b < images.size(); ++b) {
        const std::vector<double>& image = images[b];
        if (image.empty()) continue;
        if (image.size() != static_cast<size_t>(m.width) * m.height)
            throw ConfigError("FFT convolution image " + std::to_string(b) + " has " + std::to_string(image.size()) + " values, expected " +
                              std::to_string(m.width * m.height));
        std::fill(r, r + realSize, 0.0);
        for (int y = 0; y < m.height; ++y)
            std::copy(image.begin() + static_cast<std::ptrdiff_t>(y) * m.width, image.begin() + static_cast<std::ptrdiff_t>(y + 1) * m.width,
                      r + static_cast<size_t>(y) * m.nx);
        fftw_execute_dft_r2c(m.forward, r, reinterpret_cast<fftw_complex*>(c));
        const std::vector<std::complex<double>>& k = m.kernels[b];
        for (size_t i = 0; i < m.spectrumSize; ++i) sum[i] += c[i] * k[i];
        any = true;
    }
    std::vector<double> out(static_cast<size_t>(m.width) * m.height, 0.0);
    if (!any) return out;
    std::copy(sum.begin(), sum.end(), c);
    fftw_execute_dft_c2r(m.backward, reinterpret_cast<fftw_complex*>(c), r);
    const double scale = 1.0 / static_cast<double>(realSize);
    for (int y = 0; y < m.height; ++y)
        for (int x = 0; x < m.width; ++x) out[static_cast<size_t>(y) * m.width + x] = r[static_cast<size_t>(y) * m.nx + x] * scale;
    return out;
}

std::vector<double> FftConvolution::correlate(const std::vector<double>& image, int kernel) const {
    const Impl& m = *impl_;
    if (kernel < 0 || static_cast<size_t>(kernel) >= m.kernels.size())
        throw ConfigError("FFT correlation: kernel " + std::to_string(kernel) + " of " + std::to_string(m.kernels.size()));
    if (image.size() != static_cast<size_t>(m.width) * m.height)
        throw ConfigError("FFT correlation image has " + std::to_string(image.size()) + " values, expected " + std::to_string(m.width * m.height));
    const size_t realSize = static_cast<size_t>(m.nx) * m.ny;
    FftwBuffer real(sizeof(double) * realSize), complex(sizeof(fftw_complex) * m.spectrumSize);
    double* r = static_cast<double*>(real.data);
    auto* c = static_cast<std::complex<double>*>(complex.data);
    std::fill(r, r + realSize, 0.0);
    for (int y = 0; y < m.height; ++y)
        std::copy(image.begin() + static_cast<std::ptrdiff_t>(y) * m.width, image.begin() + static_cast<std::ptrdiff_t>(y + 1) * m.width,
                  r + static_cast<size_t>(y) * m.nx);
    fftw_execute_dft_r2c(m.forward, r, reinterpret_cast<fftw_complex*>(c));
    // Correlation is convolution with the mirrored kernel, whose transform is the conjugate (real kernel).
    const std::vector<std::complex<double>>& k = m.kernels[static_cast<size_t>(kernel)];
    for (size_t i = 0; i < m.spectrumSize; ++i) c[i] *= std::conj(k[i]);
    fftw_execute_dft_c2r(m.backward, reinterpret_cast<fftw_complex*>(c), r);
    std::vector<double> out(static_cast<size_t>(m.width) * m.height);
    const double scale = 1.0 / static_cast<double>(realSize);
    for (int y = 0; y < m.height; ++y)
        for (int x = 0; x < m.width; ++x) out[static_cast<size_t>(y) * m.width + x] = r[static_cast<size_t>(y) * m.nx + x] * scale;
    return out;
}

}  // namespace fluorosim::optics
