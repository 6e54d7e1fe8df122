#pragma once
// A map's images of surface samples, after each of its parts: what the plausibility of a
// map, its shape change and its largest moves are measured on (global_map.cpp,
// global_fit.cpp). Internal to the fitting module.
#include <Eigen/Core>
#include <cmath>

#include "organfit/fitting/global_map.h"

namespace organfit::fitting {

/// A map's images of the surface samples: after its affine part, its shears, its fields,
/// and in full (after its flow). Each candidate's samples are mapped once for the three
/// questions asked of it (plausible, point_to_plane_rms, shape change).
struct MappedSamples {
  Eigen::Matrix3Xd affine, sheared, fielded, full;  ///< mm
};

inline MappedSamples map_samples(const GlobalMap& map, const SurfaceSamples& surface) {
  const Eigen::Index n = surface.points.cols();
  MappedSamples m{Eigen::Matrix3Xd(3, n), Eigen::Matrix3Xd(3, n), Eigen::Matrix3Xd(3, n),
                  Eigen::Matrix3Xd(3, n)};
#pragma omp parallel for schedule(static)
  for (Eigen::Index j = 0; j < n; ++j) {
    m.affine.col(j) = map.affine.a * surface.points.col(j) + map.affine.t;
    m.sheared.col(j) = map.shears.apply(m.affine.col(j));
    m.fielded.col(j) = map.fields.apply(m.sheared.col(j));
    m.full.col(j) = map.flow.apply(m.fielded.col(j));
  }
  return m;
}

/// RMS displacement (mm) of `moved` from `original` about its mean displacement.
inline double shape_change_of(const Eigen::Matrix3Xd& moved, const Eigen::Matrix3Xd& original) {
  const Eigen::Matrix3Xd d = moved - original;
  const Eigen::Vector3d mean = d.rowwise().mean();
  return std::sqrt((d.colwise() - mean).colwise().squaredNorm().mean());
}

/// largest_moves (global_fit.h) of samples already mapped.
inline LargestMoves largest_moves_of(const MappedSamples& mapped) {
  auto largest_move = [](const Eigen::Matrix3Xd& to, const Eigen::Matrix3Xd& from) {
    return to.cols() > 0 ? (to - from).colwise().norm().maxCoeff() : 0.0;
  };
  return {largest_move(mapped.sheared, mapped.affine), largest_move(mapped.fielded, mapped.sheared),
          largest_move(mapped.full, mapped.fielded)};
}

}  // namespace organfit::fitting
