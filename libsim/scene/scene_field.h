#pragma once
// One field of a scene file, with its path and the file it came from, so that every error names file,
// field and value ("scene.json: /microscope/objective/na: must be positive (got -1)"). Modules above
// scene/ (optics reads the "microscope" block) read their part of a scene file through it; the JSON
// library stays inside scene/. Throws ConfigError (IoError from failIo).
#include <filesystem>
#include <initializer_list>
#include <memory>
#include <string>

#include "core/units.h"
#include "core/vec3.h"

namespace fluorosim {

class SceneField {
public:
    // Parses `text` (the whole field) as JSON; `path` is its place in the file, e.g. "/microscope".
    static SceneField parse(const std::string& text, const std::string& path, const std::filesystem::path& file);

    const std::string& path() const { return path_; }
    const std::filesystem::path& file() const;
    [[noreturn]] void fail(const std::string& what) const;        // appends " (got <value>)"
    [[noreturn]] void failQuoted(const std::string& what) const;  // for messages that quote the value
    std::string prefix() const;                                   // "file: /path: "

    bool isObject() const;
    bool isArray() const;
    bool isString() const;
    bool has(const std::string& key) const;
    SceneField at(const std::string& key) const;  // fails naming a missing field
    SceneField at(size_t index) const;
    size_t size() const;
    // Every key must be one of `keys`: a misspelt field is an error, not a silent default.
    void allowOnly(std::initializer_list<const char*> keys) const;

    double number() const;  // finite
    double number(double lo, double hi) const;
    // An integer in [lo, hi]; 2.7, 1e308 and "3" are errors, not casts.
    int64_t integer(int64_t lo, int64_t hi) const;
    std::string str() const;
    bool boolean() const;
    double quantity(Dimension dim) const;  // "0.5 mm" into internal units
    double positiveQuantity(Dimension dim) const;
    // A bare number in the unit the field's name carries ("exposure_s": 0.05), or a string with any unit
    // of the dimension ("50 ms").
    double quantity(Dimension dim, std::string_view bareUnit) const;
    // ["1 mm", "2 mm", "3 mm"] or {"value": [1, 2, 3], "unit": "mm"}; dimensionless: [0, 1, 0].
    Vec3 vec3(Dimension dim) const;

private:
    struct Document;
    SceneField(std::shared_ptr<const Document> doc, const void* node, std::string path);
    std::shared_ptr<const Document> doc_;
    const void* node_;  // a nlohmann::json inside doc_
    std::string path_;
};

}  // namespace fluorosim
