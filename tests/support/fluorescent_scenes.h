#pragma once
// Scenes with dyes for the fluorescence tests: dyed spheres under point lights, a dyed layer, and
// dyes built from simple tables.
#include <filesystem>
#include <string>

#include "database.h"
#include "materials/material.h"
#include "render/path_tracer.h"
#include "scene/scene.h"

namespace fluorosim::testing {

inline const spectra::Database& database() {
    static const spectra::Database db(std::filesystem::path(FLUOROSIM_SOURCE_DIR) / "spectra" / "data");
    return db;
}

inline Fluorophore databaseDye(const std::string& name, std::optional<double> qy = std::nullopt) {
    return database().fluorophore(name, std::nullopt, qy);
}

// A dye that absorbs only in [440, 500] nm and emits only in [600, 700] nm (no re-absorption).
inline Fluorophore separatedBandDye(double extinction, double quantumYield) {
    return Fluorophore("test_separated", TabulatedSpectrum({430, 440, 500, 510}, {0, 1, 1, 0}), extinction,
                       TabulatedSpectrum({600, 650, 700}, {0, 1, 0}), quantumYield);
}

inline int addDyedMedium(Scene& scene, const std::string& name, double sigmaA, double sigmaS, double g, double ior,
                         std::vector<DyeComponent> dyes) {
    scene.media.emplace_back(name, Spectrum::constant(sigmaA), Spectrum::constant(sigmaS), g, ior, std::move(dyes));
    return static_cast<int>(scene.media.size()) - 1;
}

inline void addPointLight(Scene& scene, const Vec3& p, Spectrum intensity) { scene.lights.push_back(PointLight{p, std::move(intensity)}); }

// A dyed ball of `radius` at the origin inside vacuum; with `smoothGlass`, its boundary refracts.
inline void addDyedBall(Scene& scene, double radius, int medium, bool smoothGlass) {
    const uint32_t id = scene.geometry.addSphere(Vec3(0, 0, 0), radius);
    ShapeInfo info;
    info.name = "dyed ball";
    info.isInterface = true;
    info.insideMedium = medium;
    info.outsideMedium = kNone;
    if (smoothGlass) {
        scene.materials.push_back(makeDielectric(0.0));
        scene.materialNames.push_back("glass");
        info.material = static_cast<int>(scene.materials.size()) - 1;
    }
    scene.shapes.push_back(info);
    (void)id;
}

// An axis-aligned box [lo, hi] with outward normals, as an interface around `medium`.
inline void addMediumBox(Scene& scene, const Vec3& lo, const Vec3& hi, int medium) {
    TriangleMesh mesh;
    auto face = [&](const Vec3& o, const Vec3& e1, const Vec3& e2) {
        const uint32_t b = static_cast<uint32_t>(mesh.positions.size());
        mesh.positions.insert(mesh.positions.end(), {o, o + e1, o + e1 + e2, o + e2});
        mesh.indices.insert(mesh.indices.end(), {b, b + 1, b + 2, b, b + 2, b + 3});
    };
    const Vec3 d = hi - lo;
    const Vec3 ex(d.x, 0, 0), ey(0, d.y, 0), ez(0, 0, d.z);
    face(lo, ey, ex);            // z = lo, normal -z
    face(lo + ez, ex, ey);       // z = hi, normal +z
    face(lo, ex, ez);            // y = lo, normal -y
    face(lo + ey, ez, ex);       // y = hi, normal +y
    face(lo, ez, ey);            // x = lo, normal -x
    face(lo + ex, ey, ez);       // x = hi, normal +x
    scene.geometry.addMesh(std::move(mesh));
    ShapeInfo info;
    info.name = "dyed box";
    info.isInterface = true;
    info.insideMedium = medium;
    info.outsideMedium = kNone;
    scene.shapes.push_back(info);
}

// A bath of `medium` filling the cube [-half, half]³ with a smooth dielectric surface (vacuum outside):
// where light sheets enter and the immersion objective dips in.
inline void addBath(Scene& scene, double half, int medium) {
    addMediumBox(scene, Vec3(-half, -half, -half), Vec3(half, half, half), medium);
    scene.shapes.back().material = static_cast<int>(scene.materials.size());
    scene.materials.push_back(makeDielectric(0.0));
    scene.materialNames.push_back("bath surface");
}

}  // namespace fluorosim::testing
