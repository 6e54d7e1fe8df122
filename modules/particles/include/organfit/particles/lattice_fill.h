#pragma once
// Filling a body with particles on a face-centred cubic (close-packed) lattice.
//
// With a cutoff, the fcc lattice is not in equilibrium at nearest-neighbour distance
// r0: the attraction of the shells inside r_c compresses it (0.9758 r0 for 12-6 at
// r_c = 2.5 r0). We build at the relaxed spacing computed by fcc_equilibrium_spacing(),
// so the interior starts at zero pressure and only the surface relaxes.
#include <Eigen/Core>
#include <functional>

#include "organfit/geometry/image_geometry.h"
#include "organfit/particles/cohesion.h"
#include "organfit/particles/state.h"

namespace organfit::particles {

/// The four sites of the fcc cubic cell, in units of the cube edge (a_nn sqrt(2)).
inline constexpr double kFccBasis[4][3] = {{0, 0, 0}, {0.5, 0.5, 0}, {0.5, 0, 0.5}, {0, 0.5, 0.5}};

/// Nearest-neighbour distance (mm) of an infinite fcc lattice in equilibrium under
/// `law` with its cutoff (zero virial), found by minimising the lattice energy.
double fcc_equilibrium_spacing(const LennardJones& law);

/// Volume per particle of an fcc lattice with nearest-neighbour distance a (mm^3): a^3/sqrt(2).
inline double fcc_volume_per_particle(double a_nn_mm) {
  return a_nn_mm * a_nn_mm * a_nn_mm / std::sqrt(2.0);
}

/// fcc lattice points with nearest-neighbour distance `a_nn_mm`, one of them at
/// `centre_mm`, that lie in `box` and satisfy `inside`. Order: the Z-order (Morton) curve
/// of the lattice's cubic cells, each cell's basis sites in kFccBasis order.
Positions fcc_lattice_points(const geometry::Aabb& box, const Eigen::Vector3d& centre_mm,
                             double a_nn_mm,
                             const std::function<bool(const Eigen::Vector3d&)>& inside);

/// A box of `size_mm` centred at `centre_mm`.
Positions fill_box(const Eigen::Vector3d& size_mm, const Eigen::Vector3d& centre_mm,
                   double a_nn_mm);
/// An ellipsoid with full axis lengths `size_mm` (diameters) centred at `centre_mm`.
Positions fill_ellipsoid(const Eigen::Vector3d& size_mm, const Eigen::Vector3d& centre_mm,
                         double a_nn_mm);
/// The voxels of `mask` equal to `label` (nearest-voxel test in patient mm, any direction matrix).
Positions fill_mask(const geometry::LabelVolume& mask, std::uint8_t label, double a_nn_mm);

}  // namespace organfit::particles
