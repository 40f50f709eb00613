#include "morphology/swc.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <unordered_map>

#include "core/errors.h"
#include "core/memory_cap.h"
#include "core/message.h"

namespace fluorosim {
namespace {

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
    return s;
}

std::vector<std::string_view> splitFields(std::string_view s) {
    std::vector<std::string_view> out;
    size_t i = 0;
    while (i < s.size()) {
        while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
        const size_t b = i;
        while (i < s.size() && s[i] != ' ' && s[i] != '\t') ++i;
        if (i > b) out.push_back(s.substr(b, i - b));
    }
    return out;
}

class LineParser {
public:
    LineParser(const std::string& source, int line) : source_(source), line_(line) {}

    [[noreturn]] void fail(const std::string& what) const {
        throw ConfigError(source_ + ":" + std::to_string(line_) + ": " + what);
    }
    [[noreturn]] void failField(const char* field, std::string_view value, const std::string& why) const {
        fail(std::string("field \"") + field + "\": " + why + " (got \"" + excerpt(value) + "\")");
    }

    int integer(std::string_view text, const char* field) const {
        int v = 0;
        const char* b = text.data();
        const char* e = text.data() + text.size();
        if (b != e && *b == '+') ++b;
        const auto [ptr, ec] = std::from_chars(b, e, v);
        if (ec == std::errc::result_out_of_range) failField(field, text, "integer out of range");
        if (ec != std::errc() || ptr != e || b == e) failField(field, text, "expected an integer");
        return v;
    }

    double real(std::string_view text, const char* field) const {
        double v = 0;
        const char* b = text.data();
        const char* e = text.data() + text.size();
        if (b != e && *b == '+') ++b;
        const auto [ptr, ec] = std::from_chars(b, e, v);
        if (ec != std::errc() || ptr != e || b == e) failField(field, text, "expected a number");
        if (!std::isfinite(v)) failField(field, text, "not finite");
        return v;
    }

private:
    const std::string& source_;
    int line_;
};

std::string where(const Morphology& m, const SwcSample& s) { return m.source + ":" + std::to_string(s.line) + ": "; }

// Unique ids, known parents, no cycles.
void checkTree(const Morphology& m) {
    std::unordered_map<int, size_t> index;
    for (size_t i = 0; i < m.samples.size(); ++i) {
        const SwcSample& s = m.samples[i];
        const auto [it, inserted] = index.emplace(s.id, i);
        if (!inserted)
            throw ConfigError(where(m, s) + "field \"id\": id " + std::to_string(s.id) + " is already used on line " +
                              std::to_string(m.samples[it->second].line) + " (got \"" + std::to_string(s.id) + "\")");
    }
    for (const SwcSample& s : m.samples) {
        if (s.parent == -1) continue;
        if (!index.count(s.parent))
            throw ConfigError(where(m, s) + "field \"parent\": no sample has id " + std::to_string(s.parent) + " (got \"" +
                              std::to_string(s.parent) + "\"; -1 marks a root)");
    }
    // 0 unvisited, 1 on the current walk, 2 known to reach a root.
    std::vector<char> state(m.samples.size(), 0);
    std::vector<size_t> walk;
    for (size_t start = 0; start < m.samples.size(); ++start) {
        walk.clear();
        size_t i = start;
        while (state[i] == 0) {
            state[i] = 1;
            walk.push_back(i);
            const int parent = m.samples[i].parent;
            if (parent == -1) break;
            i = index.at(parent);
            if (state[i] == 1) {
                std::string cycle;
                const auto first = std::find(walk.begin(), walk.end(), i);
                for (auto it = first; it != walk.end(); ++it) cycle += std::to_string(m.samples[*it].id) + " -> ";
                cycle += std::to_string(m.samples[i].id);
                throw ConfigError(where(m, m.samples[i]) + "field \"parent\": sample " + std::to_string(m.samples[i].id) +
                                  " is its own ancestor (cycle " + cycle + ")");
            }
        }
        for (size_t w : walk) state[w] = 2;
    }
}

}  // namespace

Morphology parseSwc(std::string_view text, const std::string& source) {
    Morphology m;
    m.source = source;
    int lineNo = 0;
    size_t pos = 0;
    while (pos < text.size()) {
        size_t end = text.find('\n', pos);
        if (end == std::string_view::npos) end = text.size();
        std::string_view line = text.substr(pos, end - pos);
        pos = end + 1;
        ++lineNo;
        const size_t hash = line.find('#');
        if (hash != std::string_view::npos) line = line.substr(0, hash);
        line = trim(line);
        if (line.empty()) continue;
        const LineParser p(source, lineNo);
        const auto f = splitFields(line);
        if (f.size() != 7)
            p.fail("expected 7 fields \"id type x y z radius parent\", got " + std::to_string(f.size()) + " (\"" + excerpt(line) + "\")");
        SwcSample s;
        s.line = lineNo;
        s.id = p.integer(f[0], "id");
        if (s.id < 0) p.failField("id", f[0], "must be non-negative");
        s.type = p.integer(f[1], "type");
        if (s.type < 0) p.failField("type", f[1], "must be non-negative");
        s.positionUm = Vec3(p.real(f[2], "x"), p.real(f[3], "y"), p.real(f[4], "z"));
        s.radiusUm = p.real(f[5], "radius");
        if (!(s.radiusUm > 0)) p.failField("radius", f[5], "must be positive");
        s.parent = p.integer(f[6], "parent");
        if (s.parent < -1) p.failField("parent", f[6], "must be -1 (root) or a sample id");
        if (s.parent == s.id) p.failField("parent", f[6], "a sample cannot be its own parent");
        m.samples.push_back(s);
    }
    if (m.samples.empty()) throw ConfigError(source + ": no samples (expected lines \"id type x y z radius parent\")");
    checkTree(m);
    return m;
}

Morphology readSwc(const std::string& path) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (fs::is_directory(path, ec)) throw IoError(path + ": is a folder, expected an SWC file");
    // A device or pipe (/dev/zero) has no size to check and may never end.
    if (fs::exists(path, ec) && !fs::is_regular_file(path, ec)) throw IoError(path + ": not a regular file, expected an SWC file");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IoError(path + ": cannot open SWC file (" + std::strerror(errno) + ")");
    // The text, the samples (56 bytes for a line of at least 14) and the tree check's index.
    const auto size = fs::file_size(path, ec);
    if (!ec) requireMemory(10.0 * static_cast<double>(size), path + ": reading an SWC file of " + formatBytes(static_cast<double>(size)));
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw IoError(path + ": cannot read SWC file");
    return parseSwc(ss.str(), path);
}

std::vector<MorphologyPiece> morphologyPieces(const Morphology& m) {
    const auto& s = m.samples;
    std::unordered_map<int, size_t> index;
    for (size_t i = 0; i < s.size(); ++i) index.emplace(s[i].id, i);
    auto isSoma = [&](size_t i) { return s[i].type == kSwcSomaType; };
    auto parentOf = [&](size_t i) { return s[i].parent == -1 ? s.size() : index.at(s[i].parent); };

    std::vector<size_t> soma;
    std::vector<char> hasSomaChild(s.size(), 0);
    for (size_t i = 0; i < s.size(); ++i) {
        if (!isSoma(i)) continue;
        soma.push_back(i);
        const size_t p = parentOf(i);
        if (p < s.size() && isSoma(p)) hasSomaChild[p] = 1;
    }

    // NeuroMorpho's standardised (CNG) files: centre, then the points at +r and -r along y. The file
    // rounds to 0.01 µm, hence the tolerance.
    bool threePoint = false;
    if (soma.size() == 3) {
        const SwcSample &c = s[soma[0]], &u = s[soma[1]], &v = s[soma[2]];
        const double tol = 0.02 + 0.01 * c.radiusUm;
        auto near = [&](const Vec3& d, double dy) {
            return std::abs(d.x) <= tol && std::abs(d.z) <= tol && std::abs(d.y - dy) <= tol;
        };
        const Vec3 du = u.positionUm - c.positionUm, dv = v.positionUm - c.positionUm;
        threePoint = u.parent == c.id && v.parent == c.id && std::abs(u.radiusUm - c.radiusUm) <= tol &&
                     std::abs(v.radiusUm - c.radiusUm) <= tol &&
                     ((near(du, c.radiusUm) && near(dv, -c.radiusUm)) || (near(du, -c.radiusUm) && near(dv, c.radiusUm)));
    }

    std::vector<MorphologyPiece> pieces;
    auto sphere = [&](const Vec3& c, double r) { pieces.push_back({c, c, r, r, true}); };
    auto cone = [&](const Vec3& a, double ra, const Vec3& b, double rb) { pieces.push_back({a, b, ra, rb, false}); };
    if (threePoint) sphere(s[soma[0]].positionUm, s[soma[0]].radiusUm);

    for (size_t i = 0; i < s.size(); ++i) {
        const size_t p = parentOf(i);
        const bool parentSoma = p < s.size() && isSoma(p);
        if (isSoma(i)) {
            if (threePoint) {
                if (!parentSoma && p < s.size()) cone(s[p].positionUm, s[p].radiusUm, s[i].positionUm, s[i].radiusUm);
                continue;
            }
            if (!parentSoma && !hasSomaChild[i]) sphere(s[i].positionUm, s[i].radiusUm);
            if (p < s.size()) cone(s[p].positionUm, s[p].radiusUm, s[i].positionUm, s[i].radiusUm);
            continue;
        }
        if (p == s.size()) continue;
        if (parentSoma) {
            const SwcSample& centre = threePoint ? s[soma[0]] : s[p];
            const Vec3 d = s[i].positionUm - centre.positionUm;
            const double dist = length(d);
            if (dist <= centre.radiusUm) continue;  // inside the soma: covered by it
            cone(centre.positionUm + d * (centre.radiusUm / dist), s[i].radiusUm, s[i].positionUm, s[i].radiusUm);
            continue;
        }
        cone(s[p].positionUm, s[p].radiusUm, s[i].positionUm, s[i].radiusUm);
    }
    return pieces;
}

double analyticVolumeUm3(const Morphology& m) {
    double v = 0;
    for (const MorphologyPiece& p : morphologyPieces(m)) {
        if (p.sphere) {
            v += 4.0 / 3.0 * std::numbers::pi * p.raUm * p.raUm * p.raUm;
        } else {
            const double l = length(p.bUm - p.aUm);
            v += std::numbers::pi * l / 3.0 * (p.raUm * p.raUm + p.raUm * p.rbUm + p.rbUm * p.rbUm);
        }
    }
    return v;
}

double medianRadiusUm(const Morphology& m) {
    std::vector<double> r;
    for (const SwcSample& s : m.samples)
        if (s.type != kSwcSomaType) r.push_back(s.radiusUm);
    if (r.empty())
        for (const SwcSample& s : m.samples) r.push_back(s.radiusUm);
    if (r.empty()) return 0;
    std::sort(r.begin(), r.end());
    const size_t n = r.size();
    return n % 2 ? r[n / 2] : 0.5 * (r[n / 2 - 1] + r[n / 2]);
}

void place(Morphology& m, const Placement& p) {
    if (m.samples.empty()) return;
    Vec3 pivot = m.samples.front().positionUm;
    for (const SwcSample& s : m.samples)
        if (s.parent == -1) {
            pivot = s.positionUm;
            break;
        }
    for (SwcSample& s : m.samples) {
        Vec3 v = s.positionUm - pivot;
        for (const auto& [axis, degrees] : p.rotationsDeg) {
            const double a = degrees * std::numbers::pi / 180, c = std::cos(a), sn = std::sin(a);
            if (axis == 'x') v = Vec3(v.x, c * v.y - sn * v.z, sn * v.y + c * v.z);
            else if (axis == 'y') v = Vec3(c * v.x + sn * v.z, v.y, -sn * v.x + c * v.z);
            else v = Vec3(c * v.x - sn * v.y, sn * v.x + c * v.y, v.z);
        }
        s.positionUm = pivot + v + p.offsetUm;
    }
}

}  // namespace fluorosim
