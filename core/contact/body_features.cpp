// Body features against cloth triangles; the method is at the top of body_features.h.
#include "contact/body_features.h"

#include <algorithm>
#include <cmath>

namespace simbake {

void box_edge_features(const Vec3& half, double spacing, std::vector<Vec3>& points, std::vector<Vec3>& normals) {
  // each edge runs along axis i, at signs (s1, s2) of the two other axes; its interior points
  // first, then the corners once each
  for (int i = 0; i < 3; ++i) {
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    const int count = std::max(1, static_cast<int>(std::ceil(2.0 * half[i] / spacing)));
    for (double sj : {-1.0, 1.0}) {
      for (double sk : {-1.0, 1.0}) {
        Vec3 normal = Vec3::Zero();
        normal[j] = sj;
        normal[k] = sk;
        normal.normalize();
        for (int q = 1; q < count; ++q) {
          Vec3 p;
          p[i] = -half[i] + 2.0 * half[i] * q / count;
          p[j] = sj * half[j];
          p[k] = sk * half[k];
          points.push_back(p);
          normals.push_back(normal);
        }
      }
    }
  }
  for (double sx : {-1.0, 1.0}) {
    for (double sy : {-1.0, 1.0}) {
      for (double sz : {-1.0, 1.0}) {
        points.push_back(Vec3(sx * half.x(), sy * half.y(), sz * half.z()));
        normals.push_back(Vec3(sx, sy, sz).normalized());
      }
    }
  }
}

bool feature_against_triangle(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                              double h, double band, Vec3& w, Vec3& normal, double& phi) {
  // the plane's unit normal, turned towards the feature's outside
  normal = (b - a).cross(c - a);
  const double twice_area = normal.norm();
  if (!(twice_area > 0.0)) return false;
  normal /= twice_area;
  const Vec3 winding = normal;  // (b - a) x (c - a), unit
  if (normal.dot(nf) < 0.0) normal = -normal;
  phi = (a - f).dot(normal);
  if (!(phi < h && phi > -band)) return false;
  // the projection's barycentric weights (sub-triangle areas along the winding's normal)
  const Vec3 p = f + phi * normal;
  w[0] = (b - p).cross(c - p).dot(winding) / twice_area;
  w[1] = (c - p).cross(a - p).dot(winding) / twice_area;
  w[2] = 1.0 - w[0] - w[1];
  return w.minCoeff() >= 0.0;
}

long long TriangleGrid::key(const Vec3& p) const {
  // 21 bits per axis, wrapped: distinct cells may share a key, which only adds candidates
  long long k = 0;
  for (int a = 0; a < 3; ++a) {
    const long long i = static_cast<long long>(std::floor(p[a] / cell_)) & ((1 << 21) - 1);
    k = (k << 21) | i;
  }
  return k;
}

void TriangleGrid::build(const Points& x, const Triangles& triangles, double cell, double margin) {
  cell_ = cell;
  entries_.clear();
  for (int t = 0; t < triangles.rows(); ++t) {
    Box3 box;
    for (int v = 0; v < 3; ++v) box.extend(Vec3(x.row(triangles(t, v)).transpose()));
    const Vec3 lo = box.min().array() - margin, hi = box.max().array() + margin;
    for (double gx = std::floor(lo.x() / cell) * cell; gx <= hi.x(); gx += cell) {
      for (double gy = std::floor(lo.y() / cell) * cell; gy <= hi.y(); gy += cell) {
        for (double gz = std::floor(lo.z() / cell) * cell; gz <= hi.z(); gz += cell) {
          entries_.push_back({key(Vec3(gx, gy, gz) + Vec3::Constant(0.5 * cell)), t});
        }
      }
    }
  }
  std::sort(entries_.begin(), entries_.end());
  entries_.erase(std::unique(entries_.begin(), entries_.end()), entries_.end());
}

void TriangleGrid::query(const Vec3& p, std::vector<int>& out) const {
  out.clear();
  const long long k = key(p);
  auto it = std::lower_bound(entries_.begin(), entries_.end(), std::make_pair(k, -1));
  for (; it != entries_.end() && it->first == k; ++it) out.push_back(it->second);
}

}  // namespace simbake
