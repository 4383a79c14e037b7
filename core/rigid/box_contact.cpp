#include "rigid/box_contact.h"

#include <algorithm>
#include <cmath>

namespace simbake {

namespace {

// an edge axis replaces the best face axis only when its overlap is shallower by more than
// this share (and kEdgeSlack): when a box rests flat on another, round-off must not flip the
// contact between a face and one of its edges from one step to the next
constexpr double kEdgePreference = 0.95;
constexpr double kEdgeSlack = 1e-6;     // (m)
constexpr double kParallel = 1e-6;      // |a_i x b_j| below this: parallel edges, no axis

double sign_of(double x) { return x < 0.0 ? -1.0 : 1.0; }

// The corners of the face of `box` whose outward normal is sign * axis k, in order round it
void face_corners(const OrientedBox& box, int k, double sign, std::array<Vec3, 8>& out, int& count) {
  const int u = (k + 1) % 3, v = (k + 2) % 3;
  const Vec3 centre = box.center + sign * box.half[k] * box.rotation.col(k);
  const Vec3 du = box.half[u] * box.rotation.col(u), dv = box.half[v] * box.rotation.col(v);
  out[0] = centre + du + dv;
  out[1] = centre - du + dv;
  out[2] = centre - du - dv;
  out[3] = centre + du - dv;
  count = 4;
}

// Sutherland-Hodgman: keep the part of the polygon where n . x <= offset
void clip(std::array<Vec3, 8>& polygon, int& count, const Vec3& n, double offset) {
  std::array<Vec3, 8> kept;
  int out = 0;
  for (int i = 0; i < count; ++i) {
    const Vec3& p = polygon[i];
    const Vec3& q = polygon[(i + 1) % count];
    const double dp = n.dot(p) - offset, dq = n.dot(q) - offset;
    if (dp <= 0.0 && out < 8) kept[out++] = p;
    if ((dp < 0.0) != (dq < 0.0) && dp != dq && out < 8) kept[out++] = p + (dp / (dp - dq)) * (q - p);
  }
  polygon = kept;
  count = out;
}

// Face contact: `reference` owns the face whose outward normal is `n` (unit, towards the
// other box); the other box's face most opposed to it is clipped to the face's sides, and
// its corners below the face are returned with their depths (positive inside)
void clip_incident_face(const OrientedBox& reference, int axis, const Vec3& n, const OrientedBox& incident,
                        double margin, std::array<Vec3, 8>& points, std::array<double, 8>& depths, int& count) {
  int k = 0;
  double best = -1.0;
  for (int i = 0; i < 3; ++i) {
    const double d = std::abs(incident.rotation.col(i).dot(n));
    if (d > best) best = d, k = i;
  }
  std::array<Vec3, 8> polygon;
  int corners = 0;
  face_corners(incident, k, -sign_of(incident.rotation.col(k).dot(n)), polygon, corners);
  for (int side : {(axis + 1) % 3, (axis + 2) % 3}) {
    const Vec3 s = reference.rotation.col(side);
    const double c = s.dot(reference.center), h = reference.half[side];
    clip(polygon, corners, s, c + h);
    clip(polygon, corners, -s, -c + h);
  }
  const double face = n.dot(reference.center) + reference.half[axis];
  count = 0;
  for (int i = 0; i < corners; ++i) {
    const double depth = face - n.dot(polygon[i]);
    if (depth > -margin) {
      points[count] = polygon[i];
      depths[count++] = depth;
    }
  }
}

// The closest points of segments p + s d (|s| <= hp) and q + t e (|t| <= hq), d and e unit and
// not parallel (Ericson 2005, 5.1.9, for centred segments)
void closest_points(const Vec3& p, const Vec3& d, double hp, const Vec3& q, const Vec3& e, double hq, Vec3& on_p,
                    Vec3& on_q) {
  const Vec3 r = p - q;
  const double b = d.dot(e), c = d.dot(r), f = e.dot(r);
  const double denom = 1.0 - b * b;
  double s = denom > 0.0 ? std::clamp((b * f - c) / denom, -hp, hp) : 0.0;
  double t = std::clamp(b * s + f, -hq, hq);
  s = std::clamp(b * t - c, -hp, hp);
  on_p = p + s * d;
  on_q = q + t * e;
}

// The overlap of the boxes' projections on unit axis L (negative: apart by that much)
double projected_overlap(const OrientedBox& a, const OrientedBox& b, const Vec3& L) {
  double ra = 0.0, rb = 0.0;
  for (int k = 0; k < 3; ++k) {
    ra += a.half[k] * std::abs(L.dot(a.rotation.col(k)));
    rb += b.half[k] * std::abs(L.dot(b.rotation.col(k)));
  }
  return ra + rb - std::abs(L.dot(b.center - a.center));
}

// The 15 candidate axes of two boxes: the shallowest face axis and the shallowest edge axis
struct AxisSearch {
  double best_face = INFINITY;
  int face = -1;                 // 0-2: a's axes, 3-5: b's
  double best_edge = INFINITY;
  int edge_i = -1, edge_j = -1;  // a's and b's edge directions
  double edge_sine = 0.0;        // |a_i x b_j|
  Vec3 edge_axis = Vec3::Zero();
  bool edge_preferred() const { return edge_i >= 0 && best_edge < kEdgePreference * best_face - kEdgeSlack; }
};

// false as soon as an axis separates the boxes by more than `margin`
bool search_axes(const OrientedBox& a, const OrientedBox& b, double margin, AxisSearch& out) {
  for (int k = 0; k < 6; ++k) {
    const double o = projected_overlap(a, b, k < 3 ? a.rotation.col(k) : b.rotation.col(k - 3));
    if (o < -margin) return false;
    if (o < out.best_face) out.best_face = o, out.face = k;
  }
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Vec3 L = a.rotation.col(i).cross(b.rotation.col(j));
      const double length = L.norm();
      if (length < kParallel) continue;
      L /= length;
      const double o = projected_overlap(a, b, L);
      if (o < -margin) return false;
      if (o < out.best_edge) out.best_edge = o, out.edge_i = i, out.edge_j = j, out.edge_axis = L, out.edge_sine = length;
    }
  }
  return true;
}

// edge against edge: the edge of a farthest towards b and the edge of b farthest towards a,
// their closest points
void edge_contact(const OrientedBox& a, const OrientedBox& b, const AxisSearch& axes, BoxContact& out) {
  const Vec3 n = -sign_of(axes.edge_axis.dot(b.center - a.center)) * axes.edge_axis;   // from b towards a
  Vec3 pa = a.center, pb = b.center;
  for (int k = 0; k < 3; ++k) {
    if (k != axes.edge_i) pa -= sign_of(a.rotation.col(k).dot(n)) * a.half[k] * a.rotation.col(k);
    if (k != axes.edge_j) pb += sign_of(b.rotation.col(k).dot(n)) * b.half[k] * b.rotation.col(k);
  }
  Vec3 on_a, on_b;
  closest_points(pa, a.rotation.col(axes.edge_i), a.half[axes.edge_i], pb, b.rotation.col(axes.edge_j),
                 b.half[axes.edge_j], on_a, on_b);
  out.normal = n;
  out.depth = axes.best_edge;
  out.edge_edge = true;
  out.edge_sine = axes.edge_sine;
  out.points[0] = {on_a, axes.best_edge};
  out.count = 1;
}

// the face axis's contact: the incident face clipped to the reference face (see box_box_contact)
bool face_contact(const OrientedBox& a, const OrientedBox& b, const AxisSearch& axes, double margin, BoxContact& out) {
  const int face = axes.face;
  const Vec3 d = b.center - a.center;
  std::array<Vec3, 8> points;
  std::array<double, 8> depths;
  int count = 0;
  if (face < 3) {
    // a's face towards b is the reference; b's corners below it are moved back onto it, so
    // that each point is on a's surface
    const Vec3 towards_b = sign_of(a.rotation.col(face).dot(d)) * a.rotation.col(face);
    clip_incident_face(a, face, towards_b, b, margin, points, depths, count);
    out.normal = -towards_b;
    for (int i = 0; i < count; ++i) out.points[i] = {points[i] + depths[i] * towards_b, depths[i]};
  } else {
    const int k = face - 3;
    const Vec3 towards_a = -sign_of(b.rotation.col(k).dot(d)) * b.rotation.col(k);
    clip_incident_face(b, k, towards_a, a, margin, points, depths, count);
    out.normal = towards_a;
    for (int i = 0; i < count; ++i) out.points[i] = {points[i], depths[i]};
  }
  out.depth = axes.best_face;
  out.edge_edge = false;
  out.count = count;
  return count > 0;
}

}  // namespace

bool oriented_box(const SignedDistance* shape, const Pose& pose, OrientedBox& out) {
  const auto* box = dynamic_cast<const BoxDistance*>(shape);
  if (!box) return false;
  out = {pose.translation, pose.rotation, box->half()};
  return true;
}

double box_overlap_depth(const OrientedBox& a, const OrientedBox& b) {
  AxisSearch axes;
  if (!search_axes(a, b, 0.0, axes)) return 0.0;
  return std::max(std::min(axes.best_face, axes.best_edge), 0.0);
}

bool box_edge_contact(const OrientedBox& a, const OrientedBox& b, double margin, BoxContact& out) {
  AxisSearch axes;
  if (!search_axes(a, b, margin, axes) || !axes.edge_preferred()) return false;
  edge_contact(a, b, axes, out);
  return true;
}

bool box_box_contact(const OrientedBox& a, const OrientedBox& b, double margin, BoxContact& out, BoxContact* faces,
                     double point_reach) {
  AxisSearch axes;
  if (!search_axes(a, b, margin, axes)) return false;
  point_reach = std::max(point_reach, margin);
  out.count = 0;
  if (axes.edge_preferred()) {
    edge_contact(a, b, axes, out);
    if (faces != nullptr) {
      faces->count = 0;
      face_contact(a, b, axes, point_reach, *faces);
    }
    return true;
  }
  return face_contact(a, b, axes, point_reach, out);
}

}  // namespace simbake
