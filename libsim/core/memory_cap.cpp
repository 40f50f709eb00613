#include "core/memory_cap.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>

#include "core/errors.h"

namespace fluorosim {
namespace {

std::atomic<uint64_t> gCap{0};  // 0: the default

}  // namespace

uint64_t defaultMemoryCapBytes() {
    constexpr uint64_t kEightGiB = uint64_t(8) << 30;
    const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGESIZE);
    if (pages <= 0 || pageSize <= 0) return kEightGiB;
    return std::min(kEightGiB, static_cast<uint64_t>(pages) * static_cast<uint64_t>(pageSize) / 2);
}

uint64_t memoryCapBytes() {
    const uint64_t c = gCap.load();
    return c ? c : defaultMemoryCapBytes();
}

void setMemoryCapBytes(uint64_t bytes) { gCap.store(bytes); }

void requireMemory(double bytes, std::string_view what) {
    const double cap = static_cast<double>(memoryCapBytes());
    if (bytes <= cap) return;  // NaN is refused too
    throw ConfigError(std::string(what) + ": needs about " + formatBytes(bytes) + ", over the memory cap of " + formatBytes(cap) +
                      " (raise it with --memory-cap or FLUOROSIM_MEMORY_CAP if the machine has the memory)");
}

std::string formatBytes(double bytes) {
    if (!std::isfinite(bytes)) return "more than 10^308 bytes";
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    int u = 0;
    while (bytes >= 1024 && u < 6) bytes /= 1024, ++u;
    char buf[64];
    if (u == 6 && bytes >= 1024) std::snprintf(buf, sizeof buf, "%.3g EiB", bytes);
    else if (u == 0 || bytes >= 100 || bytes == std::floor(bytes)) std::snprintf(buf, sizeof buf, "%.0f %s", bytes, units[u]);
    else std::snprintf(buf, sizeof buf, "%.1f %s", bytes, units[u]);
    return buf;
}

std::optional<uint64_t> parseByteSize(std::string_view text) {
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.front()))) text.remove_prefix(1);
    while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
    double v = 0;
    const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
    if (ec != std::errc() || ptr == text.data() || !std::isfinite(v) || !(v > 0)) return std::nullopt;
    std::string unit(ptr, static_cast<size_t>(text.data() + text.size() - ptr));
    while (!unit.empty() && unit.front() == ' ') unit.erase(0, 1);
    double scale = 0;
    if (unit.empty() || unit == "B") scale = 1;
    else if (unit == "KiB" || unit == "K") scale = 1024.0;
    else if (unit == "MiB" || unit == "M") scale = 1024.0 * 1024;
    else if (unit == "GiB" || unit == "G") scale = 1024.0 * 1024 * 1024;
    else if (unit == "TiB" || unit == "T") scale = 1024.0 * 1024 * 1024 * 1024;
    else if (unit == "kB" || unit == "KB") scale = 1e3;
    else if (unit == "MB") scale = 1e6;
    else if (unit == "GB") scale = 1e9;
    else if (unit == "TB") scale = 1e12;
    else return std::nullopt;
    const double bytes = v * scale;
    if (!(bytes >= 1) || bytes > 4.6e18) return std::nullopt;
    return static_cast<uint64_t>(bytes);
}

}  // namespace fluorosim
