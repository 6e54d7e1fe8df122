#include "organfit/fitting/surface_samples.h"

#include <algorithm>
#include <cstdint>

#include "organfit/geometry/counter_random.h"
#include "organfit/geometry/mask_ops.h"

namespace organfit::fitting {

SurfaceSamples surface_samples(const particles::Positions& x, const std::vector<int>& skin,
                               double radius_mm) {
  const double r0 = 2 * radius_mm;
  const double reach2 = (1.6 * r0) * (1.6 * r0);
  SurfaceSamples out;
  out.points.resize(3, static_cast<Eigen::Index>(skin.size()));
  out.normals.resize(3, static_cast<Eigen::Index>(skin.size()));
  const Eigen::Vector3d body_centre = x.rowwise().mean();
  for (size_t s = 0; s < skin.size(); ++s) {
    const int i = skin[s];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    for (int j = 0; j < x.cols(); ++j) {
      if (j != i && (x.col(j) - x.col(i)).squaredNorm() < reach2) sum += x.col(j), ++count;
    }
    Eigen::Vector3d n =
        count > 0 ? Eigen::Vector3d(x.col(i) - sum / count) : Eigen::Vector3d::Zero();
    if (n.norm() < 1e-6 * r0) n = x.col(i) - body_centre;  // flat spot: point away from the centre
    n.normalize();
    out.normals.col(static_cast<Eigen::Index>(s)) = n;
    out.points.col(static_cast<Eigen::Index>(s)) = x.col(i) + radius_mm * n;
  }
  return out;
}

SurfaceSamples reference_surface(const geometry::LabelVolume& reference, int stride) {
  return reference_surface(reference, geometry::SignedDistance(reference), stride);
}

namespace {
/// Whether voxel `v` is among a deterministic, spatially unbiased 1 in `stride`: by a
/// hash of its index (splitmix64). Counting boundary voxels in raster order aliased: a
/// box's rows each cross two of them, so 1 in 2 kept the -x face and none of the +x face
/// (the samples' centre 4.9 mm off the 30 mm cube's).
bool kept_one_in(int stride, std::uint64_t v) {
  if (stride <= 1) return true;
  return geometry::splitmix64(v) % static_cast<std::uint64_t>(stride) == 0;
}
}  // namespace

SurfaceSamples reference_surface(const geometry::LabelVolume& reference,
                                 const geometry::SignedDistance& distance, int stride) {
  const geometry::ImageGeometry& g = reference.geometry;
  auto sd = [&](int i, int j, int k) { return distance.at_voxel(i, j, k); };
  const std::vector<Eigen::Vector3i> voxels = geometry::surface_voxels(reference);
  // Runs of the surface's voxels on threads, each into its own lists, joined in order: the
  // samples in the voxels' order, as one pass gives them.
  constexpr long long kRun = 4096;
  const long long runs = (static_cast<long long>(voxels.size()) + kRun - 1) / kRun;
  std::vector<std::vector<Eigen::Vector3d>> run_pts(static_cast<size_t>(runs)),
      run_nrm(static_cast<size_t>(runs));
  std::vector<std::vector<std::uint64_t>> run_keys(static_cast<size_t>(runs));
#pragma omp parallel for schedule(dynamic, 1)
  for (long long r = 0; r < runs; ++r) {
    auto& pts = run_pts[static_cast<size_t>(r)];
    auto& nrm = run_nrm[static_cast<size_t>(r)];
    auto& keys = run_keys[static_cast<size_t>(r)];
    const size_t end = std::min(voxels.size(), static_cast<size_t>((r + 1) * kRun));
    for (size_t at = static_cast<size_t>(r * kRun); at < end; ++at) {
      const Eigen::Vector3i& voxel = voxels[at];
      const int i = voxel.x(), j = voxel.y(), k = voxel.z();
      const auto key = static_cast<std::uint64_t>(g.linear_index(i, j, k));
      if (!kept_one_in(stride, key)) continue;
      Eigen::Vector3d grad((sd(i + 1, j, k) - sd(i - 1, j, k)) / (2 * g.spacing_mm.x()),
                           (sd(i, j + 1, k) - sd(i, j - 1, k)) / (2 * g.spacing_mm.y()),
                           (sd(i, j, k + 1) - sd(i, j, k - 1)) / (2 * g.spacing_mm.z()));
      if (grad.norm() < 1e-9) continue;
      grad = g.direction * grad;
      const Eigen::Vector3d n = grad.normalized();
      pts.push_back(g.index_to_physical(voxel.cast<double>()) - sd(i, j, k) * n);
      nrm.push_back(n);
      keys.push_back(key);
    }
  }
  // The runs joined in order, each straight into its columns (and let go).
  std::vector<Eigen::Index> first(static_cast<size_t>(runs) + 1, 0);
  for (long long r = 0; r < runs; ++r)
    first[static_cast<size_t>(r) + 1] =
        first[static_cast<size_t>(r)] +
        static_cast<Eigen::Index>(run_pts[static_cast<size_t>(r)].size());
  SurfaceSamples s;
  s.points.resize(3, first.back());
  s.normals.resize(3, first.back());
  s.keys.resize(static_cast<size_t>(first.back()));
  for (long long r = 0; r < runs; ++r) {
    const auto at = static_cast<size_t>(r);
    for (size_t q = 0; q < run_pts[at].size(); ++q) {
      const Eigen::Index c = first[at] + static_cast<Eigen::Index>(q);
      s.points.col(c) = run_pts[at][q];
      s.normals.col(c) = run_nrm[at][q];
      s.keys[static_cast<size_t>(c)] = run_keys[at][q];
    }
    std::vector<Eigen::Vector3d>().swap(run_pts[at]);
    std::vector<Eigen::Vector3d>().swap(run_nrm[at]);
  }
  return s;
}

SurfaceSamples SurfaceSamples::one_in(int stride) const {
  SurfaceSamples out;
  std::vector<Eigen::Index> kept;
  for (size_t q = 0; q < keys.size(); ++q)
    if (kept_one_in(stride, keys[q])) kept.push_back(static_cast<Eigen::Index>(q));
  out.points.resize(3, static_cast<Eigen::Index>(kept.size()));
  out.normals.resize(3, static_cast<Eigen::Index>(kept.size()));
  for (size_t q = 0; q < kept.size(); ++q) {
    out.points.col(static_cast<Eigen::Index>(q)) = points.col(kept[q]);
    out.normals.col(static_cast<Eigen::Index>(q)) = normals.col(kept[q]);
    out.keys.push_back(keys[static_cast<size_t>(kept[q])]);
  }
  return out;
}

}  // namespace organfit::fitting
