#pragma once
// The memory cap: work whose memory can be estimated before it is allocated (films, voxel blocks, files
// read whole) is refused when the estimate exceeds the cap, with a ConfigError naming the input, the
// estimate and the cap, instead of running for minutes and dying of bad_alloc.
//
// Default: 8 GiB or half the physical memory, whichever is smaller. The CLI sets it from
// --memory-cap or the FLUOROSIM_MEMORY_CAP environment variable (docs/reliability.md).
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace fluorosim {

uint64_t defaultMemoryCapBytes();
uint64_t memoryCapBytes();
void setMemoryCapBytes(uint64_t bytes);  // 0 restores the default

// Throws ConfigError "<what>: needs about 3.2 TiB, over the memory cap of 8 GiB (...)" when
// `bytes` (an estimate; may be huge or infinite) exceeds the cap.
void requireMemory(double bytes, std::string_view what);

// "512 B", "3.5 MiB", "8 GiB".
std::string formatBytes(double bytes);
// "8GiB", "512 MiB", "2G", "1e9" (bytes), "100KB" (decimal); nullopt when malformed, non-positive or
// above 2^62 bytes.
std::optional<uint64_t> parseByteSize(std::string_view text);

}  // namespace fluorosim
