#pragma once
// Ray-surface intersection over triangle meshes and analytic spheres. Embree is included only in
// geometry.cpp; this header exposes the project's own types.
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "core/vec3.h"

namespace fluorosim {

struct TriangleMesh {
    std::vector<Vec3> positions;
    std::vector<uint32_t> indices;  // 3 per triangle
};

struct SurfaceHit {
    double t = 0;
    Vec3 p;
    Vec3 n;            // unit geometric normal, pointing outward (sphere) or by winding (mesh)
    uint32_t shape = 0;
    uint32_t prim = 0;
    double epsilon = 0;  // safe distance for spawning rays off this hit (see rayEpsilon)
};

class Geometry {
public:
    Geometry();
    ~Geometry();
    Geometry(Geometry&&) noexcept;
    Geometry& operator=(Geometry&&) noexcept;

    // Returns the shape id. Throws ConfigError for degenerate input.
    uint32_t addMesh(TriangleMesh mesh);
    uint32_t addSphere(const Vec3& center, double radius);
    void commit();

    // Nearest hit with t in (tMin, tMax).
    std::optional<SurfaceHit> intersect(const Ray& ray, double tMin, double tMax) const;

    size_t shapeCount() const;
    bool isSphere(uint32_t shape) const;
    const TriangleMesh& mesh(uint32_t shape) const;
    Vec3 sphereCenter(uint32_t shape) const;
    double sphereRadius(uint32_t shape) const;
    double area(uint32_t shape) const;
    // Bounding box of everything, for scene-scale epsilons.
    double extent() const;

private:
    std::optional<SurfaceHit> intersectImpl(const Ray& ray, double tMin, double tMax, bool retry) const;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Offset for spawning rays off a triangle at p without self-intersection (float-precision Embree).
// Spheres are intersected in double precision and use a much smaller, scale-relative offset, so that
// sub-micrometre beads far from the origin are still crossed correctly.
double rayEpsilon(const Vec3& p);
double sphereRayEpsilon(const Vec3& p);

// Loads OBJ or PLY triangles through Assimp. Throws IoError/ConfigError naming the file.
TriangleMesh loadMesh(const std::string& file);

}  // namespace fluorosim
