#pragma once
// A map's images of surface samples and its parts' largest moves: what the plausibility of
// a map, its shape change and its nearest-sample RMS are measured on (global_map.cpp,
// global_fit.cpp). Internal to the fitting module.
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "organfit/fitting/global_map.h"

namespace organfit::fitting {

/// A map's images of the surface samples (mm) after every part, and how far its shears,
/// fields and flow each move a sample at most. Each candidate's samples are mapped once for
/// the questions asked of it (plausible, point_to_plane_rms, shape change). The images
/// after each part are not kept, only their largest moves: every candidate of the global
/// stage holds its MappedSamples until the choice (22 on a liver, 3 x n doubles each).
struct MappedSamples {
  Eigen::Matrix3Xd full;  ///< mm
  LargestMoves moves;
};

inline MappedSamples map_samples(const GlobalMap& map, const SurfaceSamples& surface) {
  const Eigen::Index n = surface.points.cols();
  MappedSamples m{Eigen::Matrix3Xd(3, n), {}};
  double shears = 0, fields = 0, flow = 0;
#pragma omp parallel for schedule(static) reduction(max : shears, fields, flow)
  for (Eigen::Index j = 0; j < n; ++j) {
    const Eigen::Vector3d affine = map.affine.a * surface.points.col(j) + map.affine.t;
    const Eigen::Vector3d sheared = map.shears.apply(affine);
    const Eigen::Vector3d fielded = map.fields.apply(sheared);
    m.full.col(j) = map.flow.apply(fielded);
    shears = std::max(shears, (sheared - affine).norm());
    fields = std::max(fields, (fielded - sheared).norm());
    flow = std::max(flow, (m.full.col(j) - fielded).norm());
  }
  m.moves = {shears, fields, flow};
  return m;
}

/// RMS displacement (mm) of `moved` from `original` about its mean displacement.
inline double shape_change_of(const Eigen::Matrix3Xd& moved, const Eigen::Matrix3Xd& original) {
  const Eigen::Matrix3Xd d = moved - original;
  const Eigen::Vector3d mean = d.rowwise().mean();
  return std::sqrt((d.colwise() - mean).colwise().squaredNorm().mean());
}

}  // namespace organfit::fitting
