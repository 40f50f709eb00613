#include "scene/scene_field.h"

#include <cmath>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "core/errors.h"

namespace fluorosim {
namespace {

using json = nlohmann::json;

std::string shortDump(const json& j) {
    std::string s = j.dump();
    return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

std::string fmt(double v) {
    std::ostringstream os;
    os << v;
    return os.str();
}

}  // namespace

struct SceneField::Document {
    json root;
    std::filesystem::path file;
};

SceneField::SceneField(std::shared_ptr<const Document> doc, const void* node, std::string path)
    : doc_(std::move(doc)), node_(node), path_(std::move(path)) {}

SceneField SceneField::parse(const std::string& text, const std::string& path, const std::filesystem::path& file) {
    auto doc = std::make_shared<Document>();
    doc->file = file;
    try {
        doc->root = json::parse(text);
    } catch (const json::exception& e) {
        throw ConfigError(file.string() + ": " + (path.empty() ? "/" : path) + ": not valid JSON (" + e.what() + ")");
    }
    const void* node = &doc->root;
    return SceneField(std::move(doc), node, path);
}

static const json& node(const void* p) { return *static_cast<const json*>(p); }

const std::filesystem::path& SceneField::file() const { return doc_->file; }
std::string SceneField::prefix() const { return doc_->file.string() + ": " + (path_.empty() ? "/" : path_) + ": "; }
void SceneField::fail(const std::string& what) const { throw ConfigError(prefix() + what + " (got " + shortDump(node(node_)) + ")"); }
void SceneField::failQuoted(const std::string& what) const { throw ConfigError(prefix() + what); }

bool SceneField::isObject() const { return node(node_).is_object(); }
bool SceneField::isArray() const { return node(node_).is_array(); }
bool SceneField::isString() const { return node(node_).is_string(); }
bool SceneField::has(const std::string& key) const { return isObject() && node(node_).contains(key); }
size_t SceneField::size() const { return node(node_).size(); }

SceneField SceneField::at(const std::string& key) const {
    if (!isObject()) fail("expected an object");
    if (!node(node_).contains(key)) failQuoted("missing required field \"" + key + "\"");
    return SceneField(doc_, &node(node_).at(key), path_ + "/" + key);
}

SceneField SceneField::at(size_t index) const {
    if (!isArray() || index >= size()) fail("expected an array with an element " + std::to_string(index));
    return SceneField(doc_, &node(node_).at(index), path_ + "/" + std::to_string(index));
}

void SceneField::allowOnly(std::initializer_list<const char*> keys) const {
    if (!isObject()) fail("expected an object");
    const std::set<std::string> allowed(keys.begin(), keys.end());
    for (auto it = node(node_).begin(); it != node(node_).end(); ++it)
        if (!allowed.count(it.key())) {
            std::string list;
            for (const auto& k : allowed) list += (list.empty() ? "" : ", ") + k;
            SceneField(doc_, &it.value(), path_ + "/" + it.key()).failQuoted("unknown field \"" + it.key() + "\" (allowed: " + list + ")");
        }
}

double SceneField::number() const {
    if (!node(node_).is_number()) fail("expected a number");
    const double v = node(node_).get<double>();
    if (!std::isfinite(v)) fail("expected a finite number");
    return v;
}

double SceneField::number(double lo, double hi) const {
    const double v = number();
    if (v < lo || v > hi) fail("must lie in [" + fmt(lo) + ", " + fmt(hi) + "]");
    return v;
}

int64_t SceneField::integer(int64_t lo, int64_t hi) const {
    const json& j = node(node_);
    // JSON has one number type: 3.0 is an integer, 2.7 and 1e308 are not.
    if (!j.is_number()) fail("expected an integer");
    const double d = j.get<double>();
    if (!(std::floor(d) == d)) fail("expected an integer");
    if (d < static_cast<double>(lo) || d > static_cast<double>(hi))
        fail("must lie in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return j.is_number_integer() ? j.get<int64_t>() : static_cast<int64_t>(d);
}

std::string SceneField::str() const {
    if (!isString()) fail("expected a string");
    return node(node_).get<std::string>();
}

bool SceneField::boolean() const {
    if (!node(node_).is_boolean()) fail("expected true or false");
    return node(node_).get<bool>();
}

double SceneField::quantity(Dimension dim) const {
    if (!isString()) fail(std::string("expected a string with a unit, ") + dimensionName(dim));
    try {
        return parseQuantity(str(), dim, "value");
    } catch (const ConfigError& e) {
        failQuoted(e.what());
    }
}

double SceneField::quantity(Dimension dim, std::string_view bareUnit) const {
    if (node(node_).is_number()) return number() * *unitScale(bareUnit, dim);
    if (!isString()) fail(std::string("expected a number (in ") + std::string(bareUnit) + ") or a string with a unit, " + dimensionName(dim));
    try {
        return parseQuantity(str(), dim, "value", bareUnit);
    } catch (const ConfigError& e) {
        failQuoted(e.what());
    }
}

double SceneField::positiveQuantity(Dimension dim) const {
    const double v = quantity(dim);
    if (!(v > 0)) fail("must be positive");
    return v;
}

Vec3 SceneField::vec3(Dimension dim) const {
    if (isObject()) {
        allowOnly({"value", "unit"});
        const SceneField v = at("value");
        const std::string unit = at("unit").str();
        const auto scale = unitScale(unit, dim);
        if (!scale) at("unit").fail(std::string("unit does not fit ") + dimensionName(dim));
        if (!v.isArray() || v.size() != 3) v.fail("expected 3 numbers");
        return Vec3(v.at(size_t{0}).number(), v.at(1).number(), v.at(2).number()) * *scale;
    }
    if (!isArray() || size() != 3) fail("expected an array of 3 values");
    Vec3 r;
    for (size_t i = 0; i < 3; ++i) r[static_cast<int>(i)] = dim == Dimension::Dimensionless ? at(i).number() : at(i).quantity(dim);
    if (!isFinite(r)) fail("expected finite values");
    return r;
}

}  // namespace fluorosim
