#pragma once
// Fresnel equations for unpolarized light.
#include <complex>

#include "core/vec3.h"

namespace fluorosim {

// Reflectance at a dielectric interface. cosThetaI > 0 is on the incident side; eta = n_t / n_i.
// Returns 1 under total internal reflection.
double fresnelDielectric(double cosThetaI, double eta);

// Reflectance of a conductor with complex relative index eta + i k.
double fresnelConductor(double cosThetaI, std::complex<double> eta);

// Refracts `wi` (pointing away from the surface) through the interface with normal n, where
// eta = n(side opposite n) / n(side of n). Handles wi on either side; etap receives the relative
// index actually used (eta or 1/eta). Returns false under total internal reflection.
bool refract(const Vec3& wi, const Vec3& n, double eta, Vec3* wt, double* etap = nullptr);

}  // namespace fluorosim
