#pragma once
// Real spherical harmonics up to degree 3 in the ordering of 3D Gaussian splatting (the
// Condon-Shortley phase folded in: Y_1 = (-C1 y, C1 z, -C1 x), ...), evaluated at a unit
// direction; templated so that a dual number gives the Jacobian; host and device code.

#include "host_device.hpp"

namespace hanzo::fusion::neural::detail {

inline constexpr double kShC0 = 0.28209479177387814;

/// basis[k] for k < (degree + 1)^2 at the unit direction (x, y, z).
template <typename T>
HANZO_HD void sh_basis(int degree, const T& x, const T& y, const T& z, T* basis) {
  constexpr double kShC1 = 0.4886025119029199;
  constexpr double kShC2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396};
  constexpr double kShC3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                               -0.4570457994644658, 1.445305721320277, -0.5900435899266435};
  basis[0] = T(kShC0);
  if (degree < 1) return;
  basis[1] = T(-kShC1) * y;
  basis[2] = T(kShC1) * z;
  basis[3] = T(-kShC1) * x;
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  basis[4] = T(kShC2[0]) * xy;
  basis[5] = T(kShC2[1]) * yz;
  basis[6] = T(kShC2[2]) * (T(2.0) * zz - xx - yy);
  basis[7] = T(kShC2[3]) * xz;
  basis[8] = T(kShC2[4]) * (xx - yy);
  if (degree < 3) return;
  basis[9] = T(kShC3[0]) * y * (T(3.0) * xx - yy);
  basis[10] = T(kShC3[1]) * xy * z;
  basis[11] = T(kShC3[2]) * y * (T(4.0) * zz - xx - yy);
  basis[12] = T(kShC3[3]) * z * (T(2.0) * zz - T(3.0) * xx - T(3.0) * yy);
  basis[13] = T(kShC3[4]) * x * (T(4.0) * zz - xx - yy);
  basis[14] = T(kShC3[5]) * z * (xx - yy);
  basis[15] = T(kShC3[6]) * x * (xx - T(3.0) * yy);
}

}  // namespace hanzo::fusion::neural::detail
