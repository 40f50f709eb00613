#include "render/checkpoint.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <streambuf>
#include <vector>
#include <type_traits>

#include "core/errors.h"

namespace fluorosim {
namespace {

constexpr char kMagic[16] = "FLUOROSIM-CKPT";
constexpr uint32_t kVersion = 2;
// PathStats is stored as its bytes; a build whose PathStats differs reads it as another version.
static_assert(std::is_trivially_copyable_v<PathStats>);

template <class T>
void put(std::ostream& out, const T& v) {
    out.write(reinterpret_cast<const char*>(&v), sizeof(T));
}

template <class T>
T get(std::istream& in, const std::string& path) {
    T v{};
    in.read(reinterpret_cast<char*>(&v), sizeof(T));
    if (!in) throw IoError(path + ": checkpoint is truncated");
    return v;
}

// Passes writes through to a file while hashing them, so the film is not copied to form the checksum.
class HashingBuf : public std::streambuf {
public:
    explicit HashingBuf(std::streambuf* inner) : inner_(inner) {}
    uint64_t hash = fnv1a64(nullptr, 0);

protected:
    std::streamsize xsputn(const char* s, std::streamsize n) override {
        hash = fnv1a64(s, static_cast<size_t>(n), hash);
        return inner_->sputn(s, n);
    }
    int_type overflow(int_type c) override {
        if (traits_type::eq_int_type(c, traits_type::eof())) return traits_type::not_eof(c);
        const char ch = traits_type::to_char_type(c);
        return xsputn(&ch, 1) == 1 ? c : traits_type::eof();
    }

private:
    std::streambuf* inner_;
};

}  // namespace

uint64_t fnv1a64(const void* data, size_t bytes, uint64_t hash) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < bytes; ++i) {
        hash ^= p[i];
        hash *= 0x100000001b3ull;
    }
    return hash;
}

void writeCheckpoint(const std::string& path, const RenderCheckpoint& c, const Film& film) {
    const std::string tmp = path + ".partial";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) throw IoError(tmp + ": cannot write the checkpoint (" + std::strerror(errno) + ")");
        HashingBuf hashing(out.rdbuf());
        std::ostream body(&hashing);
        body.write(kMagic, sizeof kMagic);
        put(body, kVersion);
        put(body, static_cast<uint32_t>(sizeof(PathStats)));
        put(body, c.sceneHash);
        put(body, c.seed);
        put(body, static_cast<uint32_t>(c.fluorescence.size()));
        body.write(c.fluorescence.data(), static_cast<std::streamsize>(c.fluorescence.size()));
        put(body, static_cast<uint32_t>(c.integrator.size()));
        body.write(c.integrator.data(), static_cast<std::streamsize>(c.integrator.size()));
        put(body, static_cast<int32_t>(c.sppDone));
        put(body, static_cast<int32_t>(c.sppTarget));
        put(body, c.seconds);
        put(body, c.stats);
        film.writeState(body);
        put(out, hashing.hash);
        out.close();
        if (!body || !out) throw IoError(tmp + ": cannot write the checkpoint (disk full?)");
    }
    std::error_code ec;
    std::filesystem::rename(tmp, path, ec);
    if (ec) throw IoError(path + ": cannot write the checkpoint: " + ec.message());
}

RenderCheckpoint readCheckpoint(const std::string& path, Film& film) {
    std::error_code ec;
    if (std::filesystem::is_directory(path, ec)) throw IoError(path + ": is a folder, expected a render checkpoint");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IoError(path + ": cannot open the checkpoint (" + std::strerror(errno) + ")");
    const uint64_t size = std::filesystem::file_size(path, ec);
    char magic[sizeof kMagic] = {};
    in.read(magic, sizeof magic);
    if (ec || !in || size < sizeof kMagic + sizeof(uint64_t) || std::memcmp(magic, kMagic, sizeof kMagic) != 0)
        throw IoError(path + ": not a fluorosim render checkpoint");
    // The checksum first, so a damaged file is reported as such rather than by whichever field broke.
    {
        uint64_t hash = fnv1a64(magic, sizeof magic);
        std::vector<char> buf(1 << 16);
        for (uint64_t left = size - sizeof magic - sizeof(uint64_t); left > 0;) {
            const auto n = static_cast<std::streamsize>(std::min<uint64_t>(left, buf.size()));
            in.read(buf.data(), n);
            if (!in) throw IoError(path + ": checkpoint is truncated");
            hash = fnv1a64(buf.data(), static_cast<size_t>(n), hash);
            left -= static_cast<uint64_t>(n);
        }
        if (get<uint64_t>(in, path) != hash) throw IoError(path + ": checkpoint is damaged (checksum mismatch)");
    }
    in.seekg(sizeof kMagic);
    const auto version = get<uint32_t>(in, path);
    const auto statsSize = get<uint32_t>(in, path);
    if (version != kVersion || statsSize != sizeof(PathStats))
        throw IoError(path + ": checkpoint written by another version of fluorosim (format " + std::to_string(version) + ")");
    RenderCheckpoint c;
    c.sceneHash = get<uint64_t>(in, path);
    c.seed = get<uint64_t>(in, path);
    const auto nameLength = get<uint32_t>(in, path);
    if (nameLength > 64) throw IoError(path + ": checkpoint is damaged (model name)");
    c.fluorescence.resize(nameLength);
    in.read(c.fluorescence.data(), nameLength);
    const auto integratorLength = get<uint32_t>(in, path);
    if (integratorLength > 64) throw IoError(path + ": checkpoint is damaged (integrator name)");
    c.integrator.resize(integratorLength);
    in.read(c.integrator.data(), integratorLength);
    c.sppDone = get<int32_t>(in, path);
    c.sppTarget = get<int32_t>(in, path);
    c.seconds = get<double>(in, path);
    c.stats = get<PathStats>(in, path);
    if (c.sppDone < 1 || c.sppTarget < c.sppDone) throw IoError(path + ": checkpoint is damaged (sample counts)");
    try {
        film.readState(in);
    } catch (const ConfigError& e) {
        throw ConfigError(path + ": " + e.what());
    } catch (const IoError& e) {
        throw IoError(path + ": " + e.what());
    }
    return c;
}

}  // namespace fluorosim
