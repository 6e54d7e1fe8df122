#include "organfit/fitting/embedded_body.h"

#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "organfit/geometry/image_geometry.h"
#include "organfit/geometry/label_by_blocks.h"
#include "organfit/geometry/mask_ops.h"
#include "organfit/geometry/sample_grid.h"

namespace organfit::fitting {
namespace {
/// A box holding phi(the organ of `mask`) (mm): the centres of the mask's boundary voxels
/// (labelled, with a face on an unlabelled voxel or the grid's edge) moved by M, grown by
/// the largest |u| (phi(r) = M(r) - u(phi(r))) and by 1.5 voxel diagonals stretched by M's
/// affine part (the surface lies within a voxel of those centres; the half for M's
/// nonlinear parts, whose stretch the fit bounds). The image of the surface bounds the
/// image of what it encloses. The mask's own box at rest; nothing for an empty mask.
std::optional<geometry::Aabb> moved_organ_box(const geometry::LabelVolume& mask,
                                              const Deformation& phi) {
  const geometry::ImageGeometry& g = mask.geometry;
  const int nx = g.size[0], ny = g.size[1], nz = g.size[2];
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(HUGE_VAL), hi = -lo;
  const bool moved = !phi.identity();
#pragma omp parallel
  {
    Eigen::Vector3d thread_lo = Eigen::Vector3d::Constant(HUGE_VAL), thread_hi = -thread_lo;
#pragma omp for collapse(2) schedule(static) nowait
    for (int k = 0; k < nz; ++k)
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          if (!mask.at(i, j, k)) continue;
          const bool boundary = i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny ||
                                k + 1 == nz || !mask.at(i - 1, j, k) || !mask.at(i + 1, j, k) ||
                                !mask.at(i, j - 1, k) || !mask.at(i, j + 1, k) ||
                                !mask.at(i, j, k - 1) || !mask.at(i, j, k + 1);
          if (!boundary) continue;
          const Eigen::Vector3d r = g.index_to_physical(Eigen::Vector3d(i, j, k));
          const Eigen::Vector3d q = moved ? phi.map(r) : r;
          thread_lo = thread_lo.cwiseMin(q), thread_hi = thread_hi.cwiseMax(q);
        }
#pragma omp critical(organfit_moved_organ_box)
    lo = lo.cwiseMin(thread_lo), hi = hi.cwiseMax(thread_hi);
  }
  if (!(lo.x() <= hi.x())) return std::nullopt;
  const double stretch =
      moved ? Eigen::JacobiSVD<Eigen::Matrix3d>(phi.global_map().affine.a).singularValues()[0]
            : 1.0;
  const double grow = phi.largest_u_mm() + 1.5 * stretch * g.spacing_mm.norm();
  return geometry::Aabb{lo.array() - grow, hi.array() + grow};
}
}  // namespace

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
  const std::optional<geometry::Aabb> organ = moved_organ_box(*reference_, *deformation_);
  const geometry::Aabb particles = deformation_->particle_box();
  if (!((particles.max_mm - particles.min_mm).array() > 0).all())
    bounds_ = organ.value_or(geometry::Aabb{});
  else if (!organ)
    bounds_ = particles;
  else
    bounds_ = {organ->min_mm.cwiseMin(particles.min_mm), organ->max_mm.cwiseMax(particles.max_mm)};
}

bool EmbeddedBody::inside(const Eigen::Vector3d& q) const {
  const Eigen::Vector3d r = pull_back(q);
  return r.allFinite() && distance_->beyond_level(r) < 0;
}

geometry::LabelVolume EmbeddedBody::on_grid(const geometry::ImageGeometry& grid) const {
  geometry::LabelVolume out(grid);
  const geometry::IndexRange r = geometry::index_range(grid, bounds());
  if (r.empty()) return out;
  // A voxel q is inside when D(q) = d(phi^-1(q)) - level(phi^-1(q)) < 0, d the reference's
  // signed distance. Over a ball of radius h about c, |D(q) - D(c)| <= G (S h + slack), S and
  // slack phi^-1's stretch bound (the global map's over the grid's part, u's gradient's over
  // the ball: Deformation::map_inverse_stretch) and G d's gradient bound about phi^-1(c)
  // plus the level's slope across slices (SignedDistance::volume_level_slope):
  // where |D(c)| exceeds that, the whole ball has D(c)'s sign (geometry/label_by_blocks.h).
  // The labels are those of evaluating every voxel; the pull-backs are those of a band
  // about the surface.
  const geometry::Aabb part{grid.index_to_physical(Eigen::Vector3d(r.lo[0], r.lo[1], r.lo[2])),
                            grid.index_to_physical(Eigen::Vector3d(r.hi[0], r.hi[1], r.hi[2]))};
  const geometry::Aabb box =
      geometry::image_of_box(part, [](const Eigen::Vector3d& p) { return p; });
  const StretchBound bound = deformation_->map_inverse_stretch(box);
  // d's gradient bound, found here on threads rather than by the first block that asks.
  const bool bounded = std::isfinite(bound.stretch) && std::isfinite(bound.slack_mm) &&
                       std::isfinite(distance_->gradient_bound());
  const double level_slope = distance_->volume_level_slope();
  auto ball = [&](const Eigen::Vector3d& centre, double h) {
    if (!bounded) return geometry::BallSide::unknown;
    const Eigen::Vector3d y = pull_back(centre);
    const double d = y.allFinite() ? distance_->beyond_level(y) : HUGE_VAL;
    if (!std::isfinite(d)) return geometry::BallSide::unknown;
    const Eigen::Vector3d half = Eigen::Vector3d::Constant(h);
    const double stretch =
        bound.stretch * (1 + deformation_->u_gradient_bound({centre - half, centre + half}));
    const double reach = stretch * h + bound.slack_mm;
    if (std::abs(d) > (distance_->gradient_bound(y, reach) + level_slope) * reach)
      return d < 0 ? geometry::BallSide::inside : geometry::BallSide::outside;
    return geometry::BallSide::unknown;
  };
  geometry::label_by_blocks(out, r, ball, [&](const Eigen::Vector3d& p) { return inside(p); });
  return out;
}

double EmbeddedBody::volume_mm3(double voxel_mm) const {
  const geometry::Aabb b = bounds();
  if (!((b.max_mm - b.min_mm).array() > 0).all()) return 0;
  return on_grid(geometry::grid_covering(b, voxel_mm, voxel_mm)).volume_mm3(1);
}

namespace {
/// The radical inverse of i in `base`: the i-th Halton coordinate, in [0, 1).
double radical_inverse(int i, int base) {
  double scale = 1, value = 0;
  for (; i > 0; i /= base) {
    scale /= base;
    value += scale * (i % base);
  }
  return value;
}
}  // namespace

std::vector<double> EmbeddedBody::volumes_on_shifted_grids(const geometry::ImageGeometry& grid,
                                                           int count) const {
  return on_shifted_grids(grid, count,
                          [](const geometry::LabelVolume& body) { return body.volume_mm3(1); });
}

std::vector<double> EmbeddedBody::on_shifted_grids(
    const geometry::ImageGeometry& grid, int count,
    const std::function<double(const geometry::LabelVolume&)>& measure) const {
  if (count < 0) throw std::invalid_argument("shifted grids: the count must be >= 0");
  std::vector<double> values;
  for (int s = 1; s <= count; ++s) {
    const Eigen::Vector3d move_voxels(radical_inverse(s, 2) - 0.5, radical_inverse(s, 3) - 0.5,
                                      radical_inverse(s, 5) - 0.5);
    geometry::ImageGeometry shifted = grid;
    shifted.origin_mm += grid.direction * move_voxels.cwiseProduct(grid.spacing_mm);
    values.push_back(measure(on_grid(shifted)));
  }
  return values;
}

double EmbeddedBody::volume_ratio(const geometry::LabelVolume& organ) const {
  const geometry::ImageGeometry& g = organ.geometry;
  double planning = 0;
  long long today = 0;
#pragma omp parallel for collapse(2) reduction(+ : planning, today)
  for (int k = 0; k < g.size[2]; ++k)
    for (int j = 0; j < g.size[1]; ++j) {
      Deformation::CellCache cell;  // the row's voxels in order
      for (int i = 0; i < g.size[0]; ++i) {
        if (organ.at(i, j, k) != 1) continue;
        ++today;
        planning +=
            1.0 / deformation_->volume_ratio(g.index_to_physical(Eigen::Vector3d(i, j, k)), cell);
      }
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
