// Body features against cloth triangles; the method is at the top of body_features.h.
#include "contact/body_features.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace simbake {

void box_edge_features(const Vec3& half, double spacing, std::vector<Vec3>& points, std::vector<Vec3>& normals,
                       std::vector<FeatureEdge>* edges) {
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
        if (edges) {
          Vec3 a, n1 = Vec3::Zero(), n2 = Vec3::Zero();
          a[j] = sj * half[j];
          a[k] = sk * half[k];
          a[i] = -half[i];
          Vec3 b = a;
          b[i] = half[i];
          n1[j] = sj;
          n2[k] = sk;
          edges->push_back({a, b, n1, n2});
        }
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

double sharp_crease_angle(double thickness, double mean_edge) {
  constexpr double kMostSharp = M_PI / 6.0;  // 30 degrees: a crease past it is always a feature
  if (!(mean_edge > 0.0)) return kMostSharp;
  return std::min(kMostSharp, 2.0 * std::atan(0.5 * thickness / mean_edge));
}

void mesh_edge_features(const Points& vertices, const Triangles& triangles, double spacing, double sharp_angle,
                        std::vector<Vec3>& points, std::vector<Vec3>& normals, std::vector<FeatureEdge>* edges) {
  constexpr double kFlat = 1e-3;  // (rad) creases under this are flat (a face's diagonal, round-off)
  const double sharp = std::max(sharp_angle, kFlat);
  const int nv = static_cast<int>(vertices.rows()), nt = static_cast<int>(triangles.rows());
  const auto vertex = [&](int i) { return Vec3(vertices.row(i).transpose()); };
  // the faces' unit normals (counter-clockwise from outside); a degenerate face has none
  std::vector<Vec3> face_normal(nt);
  for (int t = 0; t < nt; ++t) {
    const Vec3 n = (vertex(triangles(t, 1)) - vertex(triangles(t, 0))).cross(vertex(triangles(t, 2)) - vertex(triangles(t, 0)));
    face_normal[t] = n.norm() > 0.0 ? Vec3(n.normalized()) : Vec3::Zero();
  }
  // each vertex's angle-weighted normal, its angle sum and its faces' largest turn from it
  std::vector<Vec3> vertex_normal(nv, Vec3::Zero());
  std::vector<double> angle_sum(nv, 0.0), turn(nv, 0.0);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int i = triangles(t, k);
      const Vec3 u = vertex(triangles(t, (k + 1) % 3)) - vertex(i), w = vertex(triangles(t, (k + 2) % 3)) - vertex(i);
      const double angle = std::atan2(u.cross(w).norm(), u.dot(w));
      vertex_normal[i] += angle * face_normal[t];
      angle_sum[i] += angle;
    }
  }
  for (int i = 0; i < nv; ++i) {
    if (vertex_normal[i].norm() > 0.0) vertex_normal[i].normalize();
  }
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int i = triangles(t, k);
      const double c = std::clamp(face_normal[t].dot(vertex_normal[i]), -1.0, 1.0);
      turn[i] = std::max(turn[i], std::acos(c));
    }
  }
  // (edge, face) pairs sorted by edge: each edge's faces side by side
  std::vector<std::pair<std::array<int, 2>, int>> sides;
  sides.reserve(3 * nt);
  for (int t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(t, k), b = triangles(t, (k + 1) % 3);
      sides.push_back({{std::min(a, b), std::max(a, b)}, t});
    }
  }
  std::sort(sides.begin(), sides.end());
  std::vector<char> corner(nv, 0);
  for (size_t s = 0; s < sides.size();) {
    size_t e = s;
    while (e < sides.size() && sides[e].first == sides[s].first) ++e;
    const int a = sides[s].first[0], b = sides[s].first[1];
    Vec3 normal = Vec3::Zero();
    for (size_t k = s; k < e; ++k) normal += face_normal[sides[k].second];
    bool feature = e - s != 2;  // a boundary edge (or one shared by more than two faces)
    if (e - s == 2) {
      // a convex crease: the second face's far vertex lies behind the first face's plane
      const int t1 = sides[s].second, t2 = sides[s + 1].second;
      const Vec3& n1 = face_normal[t1];
      const Vec3& n2 = face_normal[t2];
      int far = triangles(t2, 0);
      for (int k = 0; k < 3; ++k) {
        if (triangles(t2, k) != a && triangles(t2, k) != b) far = triangles(t2, k);
      }
      const double angle = std::atan2(n1.cross(n2).norm(), n1.dot(n2));
      feature = angle > sharp && n1.dot(vertex(far) - vertex(a)) < 0.0;
    }
    const size_t s_first = s;
    s = e;
    if (!feature || !(normal.norm() > 0.0)) continue;
    normal.normalize();
    if (edges) {
      const Vec3& n1 = face_normal[sides[s_first].second];
      const Vec3& n2 = face_normal[sides[e - 1].second];
      edges->push_back({vertex(a), vertex(b), n1, n2});
    }
    // the edge's inner points (its ends are corners)
    const Vec3 p = vertex(a), d = vertex(b) - p;
    const int count = std::max(1, static_cast<int>(std::ceil(d.norm() / spacing)));
    for (int q = 1; q < count; ++q) {
      points.push_back(p + d * (static_cast<double>(q) / count));
      normals.push_back(normal);
    }
    corner[a] = corner[b] = 1;
  }
  for (int i = 0; i < nv; ++i) {
    const bool tip = angle_sum[i] < 2.0 * M_PI && turn[i] > 0.5 * sharp;
    if (!(corner[i] || tip) || !(vertex_normal[i].norm() > 0.0)) continue;
    points.push_back(vertex(i));
    normals.push_back(vertex_normal[i]);
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

void TriangleGrid::build(const Points& x, const Triangles& triangles, double cell, double margin,
                         const Box3& region) {
  cell_ = cell;
  entries_.clear();
  for (int t = 0; t < triangles.rows(); ++t) {
    Box3 box;
    for (int v = 0; v < 3; ++v) box.extend(Vec3(x.row(triangles(t, v)).transpose()));
    Vec3 lo = box.min().array() - margin, hi = box.max().array() + margin;
    if (!Box3(lo, hi).intersects(region)) continue;
    // only the cells a query can read: those of points in the region (a triangle stretched
    // far across it, by a vertex flung out of a bad step, would list cells without bound)
    lo = lo.cwiseMax(region.min() - Vec3::Constant(cell));
    hi = hi.cwiseMin(region.max() + Vec3::Constant(cell));
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
