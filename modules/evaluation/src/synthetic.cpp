#include "organfit/evaluation/synthetic.h"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace organfit::evaluation {

SampledDisplacement make_sampled_displacement(const geometry::ImageGeometry& grid,
                                              std::vector<float> u_mm) {
  if (!grid.direction.isIdentity(1e-9))
    throw std::invalid_argument("sampled displacement: the grid must be axis-aligned");
  if (grid.voxel_count() < 8 || grid.size[0] < 2 || grid.size[1] < 2 || grid.size[2] < 2 ||
      u_mm.size() != 3 * static_cast<size_t>(grid.voxel_count()))
    throw std::invalid_argument(
        "sampled displacement: 3 values per voxel on a grid of 2^3 or more");
  SampledDisplacement d{grid, std::move(u_mm), 0.0};
  for (size_t v = 0; v < d.u_mm.size(); v += 3) {
    const Eigen::Vector3d u(d.u_mm[v], d.u_mm[v + 1], d.u_mm[v + 2]);
    if (!u.allFinite()) throw std::invalid_argument("sampled displacement: a value is not finite");
    d.largest_mm = std::max(d.largest_mm, u.norm());
  }
  return d;
}

Eigen::Vector3d SampledDisplacement::at(const Eigen::Vector3d& p_mm) const {
  const Eigen::Vector3d index = grid.physical_to_index(p_mm);
  std::array<int, 3> base{};
  Eigen::Vector3d f;
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(index[a], 0.0, static_cast<double>(grid.size[a] - 1));
    base[a] = std::min(static_cast<int>(c), grid.size[a] - 2);
    f[a] = c - base[a];
  }
  Eigen::Vector3d u = Eigen::Vector3d::Zero();
  geometry::for_each_trilinear_corner(f, [&](int di, int dj, int dk, double w) {
    const size_t v =
        3 * static_cast<size_t>(grid.linear_index(base[0] + di, base[1] + dj, base[2] + dk));
    u += w * Eigen::Vector3d(u_mm[v], u_mm[v + 1], u_mm[v + 2]);
  });
  return u;
}

Eigen::Matrix3d SampledDisplacement::gradient(const Eigen::Vector3d& p_mm) const {
  Eigen::Matrix3d g;
  for (int a = 0; a < 3; ++a) {
    const double h = 0.5 * grid.spacing_mm[a];
    const Eigen::Vector3d e = h * Eigen::Vector3d::Unit(a);
    g.col(a) = (at(p_mm + e) - at(p_mm - e)) / (2 * h);
  }
  return g;
}

namespace {

/// x with x + u(x) = q: Newton's method from x = q - u(q), each step at most the largest
/// displacement (a step across a fold of the interpolant would jump).
Eigen::Vector3d invert_field(const SampledDisplacement& field, const Eigen::Vector3d& q) {
  Eigen::Vector3d x = q - field.at(q);
  for (int it = 0; it < 30; ++it) {
    const Eigen::Vector3d r = x + field.at(x) - q;
    if (r.norm() < 1e-5) break;
    Eigen::Vector3d dx = (Eigen::Matrix3d::Identity() + field.gradient(x)).lu().solve(r);
    const double limit = std::max(field.largest_mm, 0.1);
    if (!dx.allFinite()) dx = r;
    if (dx.norm() > limit) dx *= limit / dx.norm();
    x -= dx;
  }
  return x;
}

}  // namespace

Eigen::Vector3d Deformation::apply(const Eigen::Vector3d& p_in) const {
  const Eigen::Vector3d& c = centre_mm;
  const Eigen::Vector3d p = field ? Eigen::Vector3d(p_in + field->at(p_in)) : p_in;
  const double s = stretch, t = 1.0 / std::sqrt(stretch);
  Eigen::Vector3d q = c + Eigen::Vector3d(s, t, t).cwiseProduct(p - c);
  const double u = (q.x() - c.x()) / half_length_mm;
  q.y() += bend_mm * u * u;
  if (twist_rad != 0) {
    const double a = twist_rad * u, ca = std::cos(a), sa = std::sin(a);
    const double y = q.y() - c.y(), z = q.z() - c.z();
    q.y() = c.y() + ca * y - sa * z, q.z() = c.z() + sa * y + ca * z;
  }
  const double two_s2 = 2 * bump_sigma_mm * bump_sigma_mm;
  if (indent_mm != 0)
    q.y() +=
        indent_mm * std::exp(-(std::pow(q.x() - c.x(), 2) + std::pow(q.z() - c.z(), 2)) / two_s2);
  if (push_mm != 0)
    q.z() +=
        push_mm * std::exp(-(std::pow(q.x() - c.x(), 2) + std::pow(q.y() - c.y(), 2)) / two_s2);
  if (!rotation_rad.isZero(0) || !shift_mm.isZero(0)) q = c + rotation() * (q - c) + shift_mm;
  return q;
}

Eigen::Matrix3d Deformation::rotation() const {
  const double angle = rotation_rad.norm();
  if (angle == 0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, rotation_rad / angle).toRotationMatrix();
}

namespace {
/// The rigid part undone: c + R^T (p - t - c).
Eigen::Vector3d undo_rigid(const Deformation& d, const Eigen::Vector3d& p) {
  if (d.rotation_rad.isZero(0) && d.shift_mm.isZero(0)) return p;
  return d.centre_mm + d.rotation().transpose() * (p - d.shift_mm - d.centre_mm);
}

/// The largest singular value of a shear I - e_a g^T whose gradient g (of length `g`) is
/// normal to e_a: (g + sqrt(g^2 + 4)) / 2.
double shear_stretch(double g) {
  return 0.5 * (g + std::sqrt(g * g + 4));
}
}  // namespace

Eigen::Vector3d Deformation::inverse(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d& c = centre_mm;
  Eigen::Vector3d q = undo_rigid(*this, p);
  const double two_s2 = 2 * bump_sigma_mm * bump_sigma_mm;
  if (push_mm != 0)
    q.z() -=
        push_mm * std::exp(-(std::pow(q.x() - c.x(), 2) + std::pow(q.y() - c.y(), 2)) / two_s2);
  if (indent_mm != 0)
    q.y() -=
        indent_mm * std::exp(-(std::pow(q.x() - c.x(), 2) + std::pow(q.z() - c.z(), 2)) / two_s2);
  const double u = (q.x() - c.x()) / half_length_mm;
  if (twist_rad != 0) {
    const double a = -twist_rad * u, ca = std::cos(a), sa = std::sin(a);
    const double y = q.y() - c.y(), z = q.z() - c.z();
    q.y() = c.y() + ca * y - sa * z, q.z() = c.z() + sa * y + ca * z;
  }
  q.y() -= bend_mm * u * u;
  const double s = stretch, t = 1.0 / std::sqrt(stretch);
  const Eigen::Vector3d x = c + Eigen::Vector3d(1 / s, 1 / t, 1 / t).cwiseProduct(q - c);
  return field ? invert_field(*field, x) : x;
}

double Deformation::inverse_radius(const Eigen::Vector3d& p, double radius_mm) const {
  if (field) return std::numeric_limits<double>::infinity();
  // The steps of inverse() in its order, each Lipschitz over the ball as carried so far
  // (radius r about the carried centre). The rigid part is an isometry.
  const Eigen::Vector3d& c = centre_mm;
  const Eigen::Vector3d q = undo_rigid(*this, p);
  double r = radius_mm;
  // push and indent: one coordinate moved by a Gaussian bump of the two others, a shear
  // whose gradient is at most |a| e^(-1/2) / sigma (at sigma from the bump's axis).
  for (const double a : {push_mm, indent_mm})
    if (a != 0) r *= shear_stretch(std::abs(a) * std::exp(-0.5) / bump_sigma_mm);
  // The bumps move y and z by at most their heights and leave x.
  const double from_axis =
      std::hypot(q.y() - c.y(), q.z() - c.z()) + std::abs(push_mm) + std::abs(indent_mm) + r;
  // twist: (y, z) turned by an angle of gradient w / L along x: the Jacobian is a rotation
  // with a column (w / L) rho added, as a shear's of that size (rho: the distance from the
  // x axis through c).
  if (twist_rad != 0) r *= shear_stretch(std::abs(twist_rad) / half_length_mm * from_axis);
  // bend: y moved by b u^2, u = (x - c_x) / L: a shear of gradient 2 |b| |x - c_x| / L^2.
  if (bend_mm != 0)
    r *= shear_stretch(2 * std::abs(bend_mm) * (std::abs(q.x() - c.x()) + r) /
                       (half_length_mm * half_length_mm));
  r *= std::max(1 / stretch, std::sqrt(stretch));  // diag(1/s, sqrt(s), sqrt(s))
  return r * (1 + 1e-9) + 1e-9;
}

std::function<bool(const Eigen::Vector3d&)> deformed_inside(const geometry::Shape& shape,
                                                            const Deformation& d) {
  return [shape, d](const Eigen::Vector3d& p) { return shape.inside(d.inverse(p)); };
}

namespace {
/// The body's labels over `range` of out's grid (the rest untouched), as sample_inside
/// samples them.
void sample_inside_range(const InsideTest& body, geometry::LabelVolume& out,
                         const geometry::IndexRange& range) {
  if (range.empty()) return;
  if (body.ball) {
    geometry::label_by_blocks(out, range, body.ball, body.inside);
    return;
  }
  const geometry::ImageGeometry& grid = out.geometry;
#pragma omp parallel for schedule(dynamic, 1) collapse(2)
  for (int k = range.lo[2]; k <= range.hi[2]; ++k)
    for (int j = range.lo[1]; j <= range.hi[1]; ++j)
      for (int i = range.lo[0]; i <= range.hi[0]; ++i)
        out.at(i, j, k) = body.inside(grid.index_to_physical(Eigen::Vector3d(i, j, k)));
}
}  // namespace

geometry::LabelVolume sample_inside(const InsideTest& body, const geometry::ImageGeometry& grid) {
  geometry::LabelVolume out(grid);
  sample_inside_range(body, out, geometry::whole_range(grid));
  return out;
}

InsideTest shape_body(const geometry::Shape& shape) {
  return {[shape](const Eigen::Vector3d& p) { return shape.inside(p); },
          [shape](const Eigen::Vector3d& p, double radius_mm) {
            return shape.inside_ball(p, radius_mm);
          }};
}

InsideTest deformed_body(const geometry::Shape& shape, const Deformation& d) {
  InsideTest body;
  body.inside = deformed_inside(shape, d);
  if (!d.field)
    body.ball = [shape, d](const Eigen::Vector3d& p, double radius_mm) {
      const double r = d.inverse_radius(p, radius_mm);
      return std::isfinite(r) ? shape.inside_ball(d.inverse(p), r) : geometry::BallSide::unknown;
    };
  return body;
}

std::vector<fitting::AttractivePoint> sample_deformed_surface(const geometry::Shape& shape,
                                                              const Deformation& deformation,
                                                              const SamplingOptions& o) {
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  // Rays from a point inside (geometry::ray_origin_mm); from anywhere inside, the surface
  // is within the extents' diagonal.
  const Eigen::Vector3d origin = geometry::ray_origin_mm(shape);
  const double reach = shape.size_mm.norm() + 1.0;
  std::vector<fitting::AttractivePoint> points;
  while (static_cast<int>(points.size()) < o.count) {
    Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
    dir.normalize();
    if (o.half_coverage && dir.y() < 0) dir.y() = -dir.y();
    // March out from the origin to the first exit, then bisect to 0.01 mm.
    double inside_t = 0, outside_t = -1;
    for (double t = 0.25; t <= reach; t += 0.25) {
      if (!shape.inside(origin + t * dir)) {
        outside_t = t;
        break;
      }
      inside_t = t;
    }
    if (outside_t < 0) continue;
    while (outside_t - inside_t > 0.01) {
      const double mid = 0.5 * (inside_t + outside_t);
      (shape.inside(origin + mid * dir) ? inside_t : outside_t) = mid;
    }
    Eigen::Vector3d p = deformation.apply(origin + 0.5 * (inside_t + outside_t) * dir);
    p += o.noise_mm * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
    points.push_back({p, 1.0});
  }
  const int outliers = static_cast<int>(std::lround(o.outlier_fraction * o.count));
  for (int k = 0; k < outliers; ++k) {
    Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
    auto& p = points[static_cast<size_t>(k * o.count / std::max(1, outliers))].p_mm;
    p += (5.0 + 10.0 * uni(rng)) * dir.normalized();
  }
  return points;
}

KnownBody::KnownBody(std::function<bool(const Eigen::Vector3d&)> inside,
                     const geometry::Aabb& bounds, double voxel_mm)
    : KnownBody(InsideTest{std::move(inside), {}}, bounds, voxel_mm) {}

KnownBody::KnownBody(InsideTest body, const geometry::Aabb& bounds, double voxel_mm)
    : body_(std::move(body)), bounds_(bounds), voxel_mm_(voxel_mm) {
  if (!(voxel_mm > 0) || !std::isfinite(voxel_mm))
    throw std::invalid_argument("known body: voxel size must be > 0 mm");
  if (!bounds.min_mm.allFinite() || !bounds.max_mm.allFinite())
    throw std::invalid_argument("known body: bounds must be finite");
  // The sampled part grows until no inside voxel lies on its faces: a connected truth is
  // then whole within it, whatever its stated bounds missed, and outside it is outside.
  constexpr double kMostVoxels = 1e9;
  geometry::ImageGeometry part = lattice_covering(bounds_, 2 * voxel_mm_);
  for (;;) {
    cover(part);
    const geometry::ImageGeometry& s = sampled_.geometry;
    const std::array<std::array<bool, 2>, 3> touched = faces_touched();
    geometry::Aabb grown = s.bounds_mm();
    bool any = false;
    for (size_t d = 0; d < 3; ++d) {
      const double step = std::max(8.0, 0.25 * s.size[d]) * voxel_mm_;
      if (touched[d][0]) grown.min_mm[static_cast<Eigen::Index>(d)] -= step, any = true;
      if (touched[d][1]) grown.max_mm[static_cast<Eigen::Index>(d)] += step, any = true;
    }
    if (!any) break;
    part = lattice_covering(grown, 0);
    if (1.0 * part.size[0] * part.size[1] * part.size[2] > kMostVoxels)
      throw std::invalid_argument(
          "known body: the truth reaches past 1e9 voxels of its lattice (is it bounded?)");
  }
  inside_voxels_ = sampled_.count(1);
  surface_ = std::make_unique<geometry::MaskSurface>(sampled_);
}

geometry::ImageGeometry KnownBody::lattice_covering(const geometry::Aabb& box,
                                                    double margin_mm) const {
  // The lattice's phase: the fractional parts of the golden ratio's multiples, so that
  // its centres meet neither the centres nor the midpoints of a scanner's grid (those
  // lie on round millimetres): a mask's inside test is exactly 0.5 there, and a lattice
  // on them measured a CT mask's surface half a voxel out.
  static const Eigen::Vector3d phase(0.6180339887498949, 0.2360679774997898, 0.8541019662496847);
  geometry::ImageGeometry g;
  g.spacing_mm = Eigen::Vector3d::Constant(voxel_mm_);
  for (int d = 0; d < 3; ++d) {
    const double lo = std::floor((box.min_mm[d] - margin_mm) / voxel_mm_ - phase[d]);
    const double hi = std::ceil((box.max_mm[d] + margin_mm) / voxel_mm_ - phase[d]);
    g.origin_mm[d] = (lo + phase[d]) * voxel_mm_;
    g.size[d] = static_cast<int>(hi - lo) + 1;
  }
  return g;
}

namespace {
/// Where lattice part `g`'s voxel (0, 0, 0) lies in part `of` (both on one lattice).
Eigen::Vector3i offset_in(const geometry::ImageGeometry& g, const geometry::ImageGeometry& of) {
  return ((g.origin_mm - of.origin_mm) / g.spacing_mm.x()).array().round().cast<int>();
}

/// Voxel (i, j, k) of `of`, 0 where that lies outside it.
std::uint8_t label_at(const geometry::LabelVolume& of, int i, int j, int k) {
  const auto& n = of.geometry.size;
  return i >= 0 && j >= 0 && k >= 0 && i < n[0] && j < n[1] && k < n[2] ? of.at(i, j, k) : 0;
}
}  // namespace

std::array<std::array<bool, 2>, 3> KnownBody::faces_touched() const {
  const geometry::ImageGeometry& g = sampled_.geometry;
  std::array<std::array<bool, 2>, 3> touched{};
  for (int d = 0; d < 3; ++d) {
    const int a = (d + 1) % 3, b = (d + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      bool found = false;
#pragma omp parallel for collapse(2) reduction(|| : found)
      for (int v = 0; v < g.size[b]; ++v)
        for (int u = 0; u < g.size[a]; ++u) {
          int idx[3];
          idx[d] = side ? g.size[d] - 1 : 0, idx[a] = u, idx[b] = v;
          found = found || sampled_.at(idx[0], idx[1], idx[2]) != 0;
        }
      touched[static_cast<size_t>(d)][static_cast<size_t>(side)] = found;
    }
  }
  return touched;
}

void KnownBody::cover(const geometry::ImageGeometry& g) {
  if (sampled_.labels.empty()) {
    sampled_ = sample_inside(body_, g);
    return;
  }
  // The union of what is sampled and g: the sampled part copied, the rest sampled (up to
  // six slabs about it): a truth that outgrew its stated bounds is not sampled twice.
  const geometry::Aabb s = sampled_.geometry.bounds_mm(), b = g.bounds_mm();
  geometry::LabelVolume u(
      lattice_covering({s.min_mm.cwiseMin(b.min_mm), s.max_mm.cwiseMax(b.max_mm)}, 0));
  const geometry::ImageGeometry& ug = u.geometry;
  const Eigen::Vector3i o = offset_in(sampled_.geometry, ug);
  const auto& n = sampled_.geometry.size;
#pragma omp parallel for collapse(2) schedule(static)
  for (int k = 0; k < n[2]; ++k)
    for (int j = 0; j < n[1]; ++j)
      std::copy_n(&sampled_.at(0, j, k), n[0], &u.at(o.x(), j + o.y(), k + o.z()));
  // The slabs: below and above the old part along z, then along y within its z, then
  // along x within its y and z.
  geometry::IndexRange rest = geometry::whole_range(ug);
  for (int d = 2; d >= 0; --d) {
    geometry::IndexRange below = rest, above = rest;
    below.hi[static_cast<size_t>(d)] = o[d] - 1;
    above.lo[static_cast<size_t>(d)] = o[d] + n[d];
    sample_inside_range(body_, u, below);
    sample_inside_range(body_, u, above);
    rest.lo[static_cast<size_t>(d)] = o[d], rest.hi[static_cast<size_t>(d)] = o[d] + n[d] - 1;
  }
  sampled_ = std::move(u);
}

LatticeBody KnownBody::on_lattice(geometry::LabelVolume whole) const {
  LatticeBody out;
  out.voxel_mm = voxel_mm_;
  const geometry::IndexRange r = whole.range(1);
  const geometry::ImageGeometry& w = whole.geometry;
  bool on_face = false;
  for (int d = 0; d < 3; ++d)
    on_face = on_face || (!r.empty() && (r.lo[d] == 0 || r.hi[d] == w.size[d] - 1));
  if (!on_face) {
    // No inside voxel on the faces: its surface voxels are those of any larger part.
    out.inside = r;
    out.labels = std::move(whole);
  } else {
    // The part about the inside voxels, 2 voxels wide, 0 beyond `whole`: what lies beyond
    // the part it was sampled over is outside.
    const Eigen::Vector3d lo = w.index_to_physical(Eigen::Vector3d(r.lo[0], r.lo[1], r.lo[2]));
    const Eigen::Vector3d hi = w.index_to_physical(Eigen::Vector3d(r.hi[0], r.hi[1], r.hi[2]));
    out.labels = geometry::LabelVolume(lattice_covering(geometry::Aabb{lo, hi}, 2 * voxel_mm_));
    const geometry::ImageGeometry& g = out.labels.geometry;
    const Eigen::Vector3i o = offset_in(g, w);
#pragma omp parallel for collapse(2) schedule(static)
    for (int k = 0; k < g.size[2]; ++k)
      for (int j = 0; j < g.size[1]; ++j)
        for (int i = 0; i < g.size[0]; ++i)
          out.labels.at(i, j, k) = label_at(whole, i + o.x(), j + o.y(), k + o.z());
    out.inside = out.labels.range(1);
  }
  const geometry::IndexRange& in = out.inside;
  long long n = 0;
  if (!in.empty()) {
#pragma omp parallel for collapse(2) reduction(+ : n)
    for (int k = in.lo[2]; k <= in.hi[2]; ++k)
      for (int j = in.lo[1]; j <= in.hi[1]; ++j)
        for (int i = in.lo[0]; i <= in.hi[0]; ++i)
          n += out.labels.at(i, j, k) != 0;
  }
  out.inside_voxels = n;
  out.surface = std::make_unique<geometry::MaskSurface>(out.labels);
  return out;
}

geometry::SurfaceComparison KnownBody::compare(const LatticeBody& body) const {
  if (body.voxel_mm != voxel_mm_ || !body.surface)
    throw std::invalid_argument("known body: a body sampled on another lattice");
  // The truth, whole within the sampled part, is outside wherever that part does not
  // reach: nothing more is sampled.
  const geometry::ImageGeometry& g = body.labels.geometry;
  const geometry::IndexRange& in = body.inside;
  const Eigen::Vector3i o = offset_in(g, sampled_.geometry);
  long long inter = 0;
  if (!in.empty()) {
    // Row by row over the part of the body's inside range the sampled part covers.
    const auto& n = sampled_.geometry.size;
    const int i0 = std::max(in.lo[0], -o.x()), i1 = std::min(in.hi[0], n[0] - 1 - o.x());
#pragma omp parallel for collapse(2) reduction(+ : inter)
    for (int k = in.lo[2]; k <= in.hi[2]; ++k)
      for (int j = in.lo[1]; j <= in.hi[1]; ++j) {
        const int jj = j + o.y(), kk = k + o.z();
        if (jj < 0 || kk < 0 || jj >= n[1] || kk >= n[2] || i0 > i1) continue;
        const std::uint8_t* a = body.labels.labels.data() + g.linear_index(i0, j, k);
        const std::uint8_t* b =
            sampled_.labels.data() + sampled_.geometry.linear_index(i0 + o.x(), jj, kk);
        long long row = 0;
        for (int i = 0; i <= i1 - i0; ++i)
          row += (a[i] != 0) & (b[i] != 0);
        inter += row;
      }
  }
  geometry::SurfaceComparison r;
  geometry::surface_distances(*body.surface, *surface_, r);
  const double vox = g.voxel_volume_mm3();
  const long long na = body.inside_voxels;
  r.volume_a_mm3 = static_cast<double>(na) * vox;
  r.volume_b_mm3 = static_cast<double>(inside_voxels_) * vox;
  r.dice = na + inside_voxels_ > 0 ? 2.0 * inter / static_cast<double>(na + inside_voxels_) : 1.0;
  return r;
}

LatticeBody KnownBody::sample(const fitting::EmbeddedBody& organ) const {
  return on_lattice(organ.on_grid(lattice_covering(organ.bounds(), 2 * voxel_mm_)));
}

LatticeBody KnownBody::sample(const Eigen::Matrix3Xd& particles, double radius_mm) const {
  const geometry::Aabb box = particles.cols() > 0 ? geometry::Aabb{particles.rowwise().minCoeff(),
                                                                   particles.rowwise().maxCoeff()}
                                                  : bounds_;
  return on_lattice(geometry::closed_body(particles, radius_mm, radius_mm,
                                          lattice_covering(box, 2 * radius_mm + 2 * voxel_mm_)));
}

geometry::SurfaceComparison compare_with_body(
    const Eigen::Matrix3Xd& particles, double radius_mm,
    const std::function<bool(const Eigen::Vector3d&)>& inside, const geometry::Aabb& body_bounds,
    double voxel_mm) {
  return KnownBody(inside, body_bounds, voxel_mm).compare(particles, radius_mm);
}

geometry::SurfaceComparison compare_with_body(
    const fitting::EmbeddedBody& organ, const std::function<bool(const Eigen::Vector3d&)>& inside,
    const geometry::Aabb& body_bounds, double voxel_mm) {
  return KnownBody(inside, body_bounds, voxel_mm).compare(organ);
}

}  // namespace organfit::evaluation
