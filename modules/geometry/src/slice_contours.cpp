#include "organfit/geometry/slice_contours.h"

#include <cmath>
#include <map>
#include <utility>

namespace organfit::geometry {
namespace {

using Point = Eigen::Vector2d;

/// Douglas-Peucker on a closed loop (split at its first and farthest point).
std::vector<Point> thin(const std::vector<Point>& loop, double tol) {
  auto dp = [&](auto&& self, const std::vector<Point>& pts, size_t a, size_t b,
                std::vector<char>& keep) -> void {
    double worst = -1;
    size_t at = a;
    const Point ab = pts[b % pts.size()] - pts[a];
    for (size_t i = a + 1; i < b; ++i) {
      const Point ap = pts[i] - pts[a];
      const double d =
          ab.norm() > 0 ? std::abs(ab.x() * ap.y() - ab.y() * ap.x()) / ab.norm() : ap.norm();
      if (d > worst) worst = d, at = i;
    }
    if (worst > tol) {
      keep[at] = 1;
      self(self, pts, a, at, keep);
      self(self, pts, at, b, keep);
    }
  };
  size_t far = 0;
  for (size_t i = 1; i < loop.size(); ++i)
    if ((loop[i] - loop[0]).squaredNorm() > (loop[far] - loop[0]).squaredNorm()) far = i;
  std::vector<char> keep(loop.size(), 0);
  keep[0] = keep[far] = 1;
  dp(dp, loop, 0, far, keep);
  dp(dp, loop, far, loop.size(), keep);
  std::vector<Point> out;
  for (size_t i = 0; i < loop.size(); ++i)
    if (keep[i]) out.push_back(loop[i]);
  return out;
}

}  // namespace

std::vector<SliceContour> slice_contours(const LabelVolume& mask, std::uint8_t label,
                                         int max_points) {
  const ImageGeometry& g = mask.geometry;
  std::vector<SliceContour> out;
  auto in = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && i < g.size[0] && j < g.size[1] && mask.at(i, j, k) == label;
  };
  for (int k = 0; k < g.size[2]; ++k) {
    // Edge midpoints are keyed by (2i+di, 2j+dj) in half-voxel units: unique per edge.
    using Key = std::pair<int, int>;
    std::multimap<Key, Key> links;  // undirected segments, stored both ways
    bool any = false;
    for (int j = -1; j < g.size[1]; ++j)
      for (int i = -1; i < g.size[0]; ++i) {
        const bool a = in(i, j, k), b = in(i + 1, j, k), c = in(i + 1, j + 1, k),
                   d = in(i, j + 1, k);
        const int code = a | (b << 1) | (c << 2) | (d << 3);
        if (code == 0 || code == 15) continue;
        any = true;
        const Key bottom{2 * i + 1, 2 * j}, right{2 * i + 2, 2 * j + 1}, top{2 * i + 1, 2 * j + 2},
            left{2 * i, 2 * j + 1};
        auto seg = [&](Key p, Key q) {
          links.insert({p, q});
          links.insert({q, p});
        };
        switch (code) {
          case 1:
          case 14:
            seg(left, bottom);
            break;
          case 2:
          case 13:
            seg(bottom, right);
            break;
          case 4:
          case 11:
            seg(right, top);
            break;
          case 8:
          case 7:
            seg(top, left);
            break;
          case 3:
          case 12:
            seg(left, right);
            break;
          case 6:
          case 9:
            seg(bottom, top);
            break;
          // Saddles: the two inside corners joined (the organ 8-connected in the slice,
          // as topology_of's pieces are 26-connected): a voxel touching the organ only
          // diagonally is part of its contour, not a contour of its own.
          case 5:
            seg(bottom, right), seg(top, left);
            break;
          case 10:
            seg(left, bottom), seg(right, top);
            break;
        }
      }
    if (!any) continue;
    // Chain the segments into closed loops.
    while (!links.empty()) {
      std::vector<Key> loop{links.begin()->first};
      Key prev = loop[0], cur = links.begin()->second;
      auto erase = [&](Key p, Key q) {
        auto range = links.equal_range(p);
        for (auto it = range.first; it != range.second; ++it)
          if (it->second == q) {
            links.erase(it);
            break;
          }
      };
      erase(prev, cur);
      erase(cur, prev);
      while (cur != loop[0]) {
        loop.push_back(cur);
        auto it = links.find(cur);
        if (it == links.end()) break;  // cannot happen for a closed grid; guard anyway
        const Key next = it->second;
        erase(cur, next);
        erase(next, cur);
        prev = cur;
        cur = next;
      }
      // To continuous voxel indices; drop vertices on straight runs (exact).
      std::vector<Point> pts;
      for (const auto& key : loop)
        pts.emplace_back(0.5 * key.first, 0.5 * key.second);
      std::vector<Point> kept;
      for (size_t p = 0; p < pts.size(); ++p) {
        const Point& a = pts[(p + pts.size() - 1) % pts.size()];
        const Point& b = pts[p];
        const Point& c = pts[(p + 1) % pts.size()];
        if (std::abs((b - a).x() * (c - b).y() - (b - a).y() * (c - b).x()) > 1e-12)
          kept.push_back(b);
      }
      SliceContour contour;
      contour.k = k;
      double tol = 0.05;
      while (static_cast<int>(kept.size()) > max_points) {
        kept = thin(kept, tol);
        contour.thinning_tolerance_mm = tol * g.spacing_mm.head<2>().maxCoeff();
        tol *= 2;
      }
      for (const auto& p : kept)
        contour.points_mm.push_back(g.index_to_physical(Eigen::Vector3d(p.x(), p.y(), k)));
      if (contour.points_mm.size() >= 3) out.push_back(std::move(contour));
    }
  }
  return out;
}

std::vector<ContourCountChange> contour_count_changes(const std::vector<SliceContour>& before,
                                                      const std::vector<SliceContour>& after) {
  std::map<int, int> b, a;
  for (const SliceContour& c : before)
    ++b[c.k];
  for (const SliceContour& c : after)
    ++a[c.k];
  std::vector<ContourCountChange> out;
  for (const auto& [k, count] : a)
    if (const auto it = b.find(k); it != b.end() && it->second != count)
      out.push_back({k, it->second, count});
  return out;
}

}  // namespace organfit::geometry
