#include "organfit/fitting/embedded_body.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {

EmbeddedBody::EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference, GlobalMap map,
                           particles::Positions placed, particles::Positions current,
                           double support_mm)
    : EmbeddedBody(std::move(reference),
                   std::make_shared<const Deformation>(std::move(map), std::move(placed),
                                                       std::move(current), support_mm)) {}

EmbeddedBody::EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference,
                           std::shared_ptr<const Deformation> deformation)
    : EmbeddedBody(
          reference,
          reference ? std::make_shared<const geometry::SignedDistance>(*reference, false) : nullptr,
          std::move(deformation)) {}

EmbeddedBody::EmbeddedBody(std::shared_ptr<const geometry::LabelVolume> reference,
                           std::shared_ptr<const geometry::SignedDistance> distance,
                           std::shared_ptr<const Deformation> deformation)
    : reference_(std::move(reference)),
      distance_(std::move(distance)),
      deformation_(std::move(deformation)) {
  if (!reference_ || !distance_) throw std::invalid_argument("embedded body: no reference body");
  if (!deformation_) throw std::invalid_argument("embedded body: no deformation");
}

bool EmbeddedBody::inside(const Eigen::Vector3d& q) const {
  const Eigen::Vector3d r = pull_back(q);
  return r.allFinite() && distance_->at(r) < 0;
}

geometry::Aabb EmbeddedBody::bounds() const {
  const geometry::Aabb b = deformation_->particle_box();
  if (((b.max_mm - b.min_mm).array() > 0).all()) return b;
  // No particles: the reference's box moved by the global map (its corners' images:
  // exact for an affine map).
  const geometry::Aabb r = reference_->geometry.bounds_mm();
  return geometry::image_of_box(
      r, [this](const Eigen::Vector3d& p) { return deformation_->push_forward(p); });
}

namespace {
/// Voxels [lo, hi] (inclusive, each axis) of a grid.
struct Block {
  std::array<int, 3> lo, hi;
};
}  // namespace

geometry::LabelVolume EmbeddedBody::on_grid(const geometry::ImageGeometry& grid) const {
  geometry::LabelVolume out(grid);
  const geometry::IndexRange r = geometry::index_range(grid, bounds());
  if (r.empty()) return out;
  // Blocks of voxels, coarse to fine. A voxel q is inside when D(q) = d(phi^-1(q)) < 0,
  // d the reference's signed distance. Over a block of half-diagonal h (mm) about its
  // centre c, |D(q) - D(c)| <= G (S h + slack), S and slack phi^-1's stretch bound over
  // the grid's part (pull_back_stretch) and G d's gradient bound about phi^-1(c): where
  // |D(c)| exceeds that, every voxel of the block has D(c)'s sign and is set without being
  // evaluated; otherwise the block is halved, down to single voxels, each evaluated as
  // inside() would. The labels are those of evaluating every voxel; the pull-backs are
  // those of a band about the surface.
  const geometry::Aabb part{grid.index_to_physical(Eigen::Vector3d(r.lo[0], r.lo[1], r.lo[2])),
                            grid.index_to_physical(Eigen::Vector3d(r.hi[0], r.hi[1], r.hi[2]))};
  const geometry::Aabb box =
      geometry::image_of_box(part, [](const Eigen::Vector3d& p) { return p; });
  const StretchBound bound = deformation_->pull_back_stretch(box);
  // d's gradient bound, found here on threads rather than by the first block that asks.
  const bool bounded = std::isfinite(bound.stretch) && std::isfinite(bound.slack_mm) &&
                       std::isfinite(distance_->gradient_bound());
  auto half_diagonal = [&grid](const Block& b) {
    Eigen::Vector3d extent;
    for (int d = 0; d < 3; ++d)
      extent[d] = (b.hi[d] - b.lo[d]) * grid.spacing_mm[d];
    return 0.5 * extent.norm();  // the direction matrix is orthonormal
  };
  // Sets block b, or halves it; returns nothing, writes only b's voxels.
  auto classify = [&](const Block& b, auto& self) -> void {
    const Eigen::Vector3d centre = grid.index_to_physical(
        0.5 * Eigen::Vector3d(b.lo[0] + b.hi[0], b.lo[1] + b.hi[1], b.lo[2] + b.hi[2]));
    const Eigen::Vector3d y = pull_back(centre);
    const double d = y.allFinite() ? distance_->at(y) : HUGE_VAL;
    const bool single = b.lo == b.hi;
    if (!single && bounded && std::isfinite(d)) {
      const double h = half_diagonal(b);
      const double reach = bound.stretch * h + bound.slack_mm;
      if (std::abs(d) > distance_->gradient_bound(y, reach) * reach) {
        const std::uint8_t label = d < 0 ? 1 : 0;
        for (int k = b.lo[2]; k <= b.hi[2]; ++k)
          for (int j = b.lo[1]; j <= b.hi[1]; ++j)
            for (int i = b.lo[0]; i <= b.hi[0]; ++i)
              out.at(i, j, k) = label;
        return;
      }
    }
    if (single) {
      out.at(b.lo[0], b.lo[1], b.lo[2]) = d < 0 ? 1 : 0;
      return;
    }
    // Halve each axis longer than a voxel.
    int split[3][2][2];
    int parts[3];
    for (int a = 0; a < 3; ++a) {
      if (b.lo[a] == b.hi[a]) {
        parts[a] = 1, split[a][0][0] = b.lo[a], split[a][0][1] = b.hi[a];
      } else {
        const int mid = (b.lo[a] + b.hi[a]) / 2;
        parts[a] = 2;
        split[a][0][0] = b.lo[a], split[a][0][1] = mid;
        split[a][1][0] = mid + 1, split[a][1][1] = b.hi[a];
      }
    }
    for (int pk = 0; pk < parts[2]; ++pk)
      for (int pj = 0; pj < parts[1]; ++pj)
        for (int pi = 0; pi < parts[0]; ++pi)
          self(Block{{split[0][pi][0], split[1][pj][0], split[2][pk][0]},
                     {split[0][pi][1], split[1][pj][1], split[2][pk][1]}},
               self);
  };
  constexpr int kTop = 16;  // voxels a side of the coarsest blocks
  std::vector<Block> tops;
  for (int k = r.lo[2]; k <= r.hi[2]; k += kTop)
    for (int j = r.lo[1]; j <= r.hi[1]; j += kTop)
      for (int i = r.lo[0]; i <= r.hi[0]; i += kTop)
        tops.push_back(Block{{i, j, k},
                             {std::min(i + kTop - 1, r.hi[0]), std::min(j + kTop - 1, r.hi[1]),
                              std::min(k + kTop - 1, r.hi[2])}});
  const long n = static_cast<long>(tops.size());
#pragma omp parallel for schedule(dynamic, 1)
  for (long t = 0; t < n; ++t)
    classify(tops[static_cast<size_t>(t)], classify);
  return out;
}

double EmbeddedBody::volume_mm3(double voxel_mm) const {
  const geometry::Aabb b = bounds();
  if (!((b.max_mm - b.min_mm).array() > 0).all()) return 0;
  return on_grid(geometry::grid_covering(b, voxel_mm, voxel_mm)).volume_mm3(1);
}

double EmbeddedBody::volume_ratio(const geometry::LabelVolume& organ) const {
  const geometry::ImageGeometry& g = organ.geometry;
  double planning = 0;
  long long today = 0;
#pragma omp parallel for collapse(2) reduction(+ : planning, today)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j)
      for (int i = 0; i < g.size[0]; ++i) {
        if (organ.at(i, j, k) != 1) continue;
        ++today;
        planning += 1.0 / deformation_->volume_ratio(g.index_to_physical(Eigen::Vector3d(i, j, k)));
      }
  return planning > 0 ? static_cast<double>(today) / planning : 1.0;
}

SurfaceFeet surface_feet(const particles::Positions& x, const SurfaceSamples& samples,
                         double reach) {
  SurfaceFeet feet;
  feet.offset_mm.resize(3, x.cols());
  feet.normal.resize(3, x.cols());
  const Eigen::Vector3d centroid =
      x.cols() > 0 ? Eigen::Vector3d(x.rowwise().mean()) : Eigen::Vector3d::Zero();
  for (Eigen::Index i = 0; i < x.cols(); ++i) {  // no sample within reach: deep inside
    Eigen::Vector3d away = x.col(i) - centroid;
    away = away.norm() > 1e-12 ? Eigen::Vector3d(away.normalized()) : Eigen::Vector3d::UnitX();
    feet.normal.col(i) = away, feet.offset_mm.col(i) = reach * away;
  }
  if (samples.points.cols() == 0 || !(reach > 0)) return feet;
  const geometry::SampleGrid grid(samples.points);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < x.cols(); ++i) {
    const int nearest = grid.nearest(x.col(i), reach).first;
    if (nearest < 0) continue;
    feet.offset_mm.col(i) = samples.points.col(nearest) - x.col(i);
    feet.normal.col(i) = samples.normals.col(nearest);
  }
  return feet;
}

}  // namespace organfit::fitting
