// Body features against cloth triangles; the method is at the top of body_features.h.
#include "contact/body_features.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

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

bool triangle_plane(const Vec3& a, const Vec3& b, const Vec3& c, Vec3& winding, double& twice_area) {
  winding = (b - a).cross(c - a);
  twice_area = winding.norm();
  if (!(twice_area > 0.0)) return false;
  winding /= twice_area;
  return true;
}

bool feature_against_plane(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                           const Vec3& winding, double twice_area, double h, double band, Vec3& w, Vec3& normal,
                           double& phi) {
  if (!(twice_area > 0.0)) return false;
  // the plane's unit normal, turned towards the feature's outside
  normal = winding;
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

bool feature_against_triangle(const Vec3& f, const Vec3& nf, const Vec3& a, const Vec3& b, const Vec3& c,
                              double h, double band, Vec3& w, Vec3& normal, double& phi) {
  Vec3 winding;
  double twice_area;
  if (!triangle_plane(a, b, c, winding, twice_area)) return false;
  return feature_against_plane(f, nf, a, b, c, winding, twice_area, h, band, w, normal, phi);
}

long long TriangleGrid::key(const Vec3& p) const {
  // 21 bits per axis, wrapped
  long long k = 0;
  for (int a = 0; a < 3; ++a) k = (k << 21) | (index(p[a]) & kWrap);
  return k;
}

long long TriangleGrid::dense_cell(const std::array<long long, 3>& i) const {
  long long c = 0;
  for (int a = 0; a < 3; ++a) {
    // the block's cell named as i is named (its extent is under the wrap, so there is at most one)
    const long long offset = (i[a] - base_[a]) & kWrap;
    if (offset >= size_[a]) return -1;
    c = c * size_[a] + offset;
  }
  return c;
}

void TriangleGrid::build(const Points& x, const Triangles& triangles, double cell, double margin,
                         const Box3& region, const std::vector<int>* consider, bool dense) {
  cell_ = cell;
  entries_.clear();
  kept_.clear();
  indices_.clear();
  spans_.clear();
  // each triangle's cells, axis by axis: a cell's index is that of its centre, stepping a cell
  // at a time from the one at the box's low corner
  std::array<long long, 3> low{}, high{};
  low.fill(std::numeric_limits<long long>::max());
  high.fill(std::numeric_limits<long long>::min());
  long long entries = 0;
  const int listed = consider ? static_cast<int>(consider->size()) : static_cast<int>(triangles.rows());
  for (int c = 0; c < listed; ++c) {
    const int t = consider ? (*consider)[c] : c;
    Box3 box;
    for (int v = 0; v < 3; ++v) box.extend(Vec3(x.row(triangles(t, v)).transpose()));
    Vec3 lo = box.min().array() - margin, hi = box.max().array() + margin;
    if (!Box3(lo, hi).intersects(region)) continue;
    // only the cells a query can read: those of points in the region (a triangle stretched
    // far across it, by a vertex flung out of a bad step, would list cells without bound)
    lo = lo.cwiseMax(region.min() - Vec3::Constant(cell));
    hi = hi.cwiseMin(region.max() + Vec3::Constant(cell));
    std::array<int, 4> span;
    long long count = 1;
    for (int a = 0; a < 3; ++a) {
      span[a] = static_cast<int>(indices_.size());
      for (double g = std::floor(lo[a] / cell) * cell; g <= hi[a]; g += cell) {
        const long long i = index(g + 0.5 * cell);
        indices_.push_back(i);
        low[a] = std::min(low[a], i);
        high[a] = std::max(high[a], i);
      }
      count *= static_cast<long long>(indices_.size()) - span[a];
    }
    span[3] = static_cast<int>(indices_.size());
    entries += count;
    kept_.push_back(t);
    spans_.push_back(span);
  }
  // a dense block of the cells listed, when it is small beside the entries and its extent
  // along each axis is under the wrap (then the wrapped names are unique in it)
  double volume = 1.0;
  dense_ = dense && !kept_.empty();
  for (int a = 0; a < 3 && dense_; ++a) {
    base_[a] = low[a];
    size_[a] = high[a] - low[a] + 1;
    dense_ = size_[a] <= kWrap;
    volume *= static_cast<double>(size_[a]);
  }
  dense_ = dense_ && volume <= static_cast<double>(kDenseCellsPerEntry * entries + 64);
  const auto each_cell = [&](size_t k, auto&& f) {
    const std::array<int, 4>& s = spans_[k];
    for (int ix = s[0]; ix < s[1]; ++ix) {
      for (int iy = s[1]; iy < s[2]; ++iy) {
        for (int iz = s[2]; iz < s[3]; ++iz) f(std::array<long long, 3>{indices_[ix], indices_[iy], indices_[iz]});
      }
    }
  };
  if (!dense_) {
    for (size_t k = 0; k < kept_.size(); ++k) {
      each_cell(k, [&](const std::array<long long, 3>& i) {
        entries_.push_back({((i[0] & kWrap) << 42) | ((i[1] & kWrap) << 21) | (i[2] & kWrap), kept_[k]});
      });
    }
    std::sort(entries_.begin(), entries_.end());
    entries_.erase(std::unique(entries_.begin(), entries_.end()), entries_.end());
    return;
  }
  // counting: each bucket's size, its start, then the triangles in increasing order (a
  // triangle listed twice in a cell, once)
  const size_t cells = static_cast<size_t>(volume);
  starts_.assign(cells + 1, 0);
  for (size_t k = 0; k < kept_.size(); ++k) each_cell(k, [&](const std::array<long long, 3>& i) { ++starts_[dense_cell(i) + 1]; });
  for (size_t c = 0; c < cells; ++c) starts_[c + 1] += starts_[c];
  ends_.assign(starts_.begin(), starts_.end() - 1);
  items_.resize(starts_[cells]);
  for (size_t k = 0; k < kept_.size(); ++k) {
    const int t = kept_[k];
    each_cell(k, [&](const std::array<long long, 3>& i) {
      const long long c = dense_cell(i);
      if (ends_[c] == starts_[c] || items_[ends_[c] - 1] != t) items_[ends_[c]++] = t;
    });
  }
}

void TriangleGrid::query(const Vec3& p, std::vector<int>& out) const {
  out.clear();
  if (dense_) {
    const long long c = dense_cell({index(p.x()), index(p.y()), index(p.z())});
    if (c >= 0) out.assign(items_.begin() + starts_[c], items_.begin() + ends_[c]);
    return;
  }
  const long long k = key(p);
  auto it = std::lower_bound(entries_.begin(), entries_.end(), std::make_pair(k, -1));
  for (; it != entries_.end() && it->first == k; ++it) out.push_back(it->second);
}

}  // namespace simbake
