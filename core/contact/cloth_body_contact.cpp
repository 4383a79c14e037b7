// A cloth against the bodies and the ground (the interface is in cloth_body_contact.h).
//
// The cloth computes its internal forces and new velocities itself (cloth/integrators.h). The
// contacts then make the candidate positions x + dt v respect every body and the ground: a
// cloth point (each vertex, and each edge's quarter points, so that a pole or a box's edge
// cannot slip between vertices) whose candidate lies closer than the cloth's thickness to a
// surface (phi < h, with phi the body's level set at its end-of-step pose) gets the normal
// velocity, relative to the body's point velocity, that brings it exactly to distance h at
// the end of the step:
//     dv_n = (h - phi) / dt   when positive (phi is taken at the candidate, so this is the
//                              change that moves the candidate out to h: inelastic, no bounce)
// and Coulomb friction on the relative tangential velocity, limited by that normal change
// (Bridson, Fedkiw and Anderson 2002): v_T <- max(0, 1 - mu dv_n / |v_T|) v_T. An edge
// point's change is shared by its two vertices in proportion to their weights and inverse
// masses. The cloth's momentum change goes, opposite, to a dynamic body at the contact point,
// so cloth pushes bodies back. A body's corners and points along its edges (a box's, or a
// mesh's sharp ones) are held out of the cloth's triangles the same way
// (contact/body_features.h), so that no body edge pokes through the inside of a triangle,
// and its sharp edges are held h away from the cloth's edges (collide_features). Resting
// contacts against still surfaces are also held inside the cloth's implicit solve
// (contact_constraints, apply_constraint_impulses), and a cloth pinched between two surfaces
// holds them apart (hold_pinched_bodies). The world calls these in its cloth step
// (cloth/cloth_step.cpp), with strain limiting and self-collision in between.
#include "contact/cloth_body_contact.h"

#include "geometry/closest_points.h"
#include "geometry/triangle_intersection.h"
#include "rigid/impulse.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace simbake {

namespace {
constexpr int kGround = -1;                // a contact's body index for the ground
constexpr double kPinchSpeed = 0.25;       // (m/s) the most a pinch pushes its two surfaces apart per step
constexpr double kPinchGap = 3.0;          // x h: the least gap a pinch holds open (two layers)
constexpr double kPinchReach = 6.0;        // x h: the widest gap looked at for layers (up to 5)
constexpr double kWorldBoxSlack = 1e-6;    // (m) a body's world box grown past round-off
constexpr int kPinchSweeps = 4;            // Gauss-Seidel sweeps of the pinches' impulses
constexpr double kEdgeReach = 2.0;         // x h: a cloth edge inside a body within this of a body edge went over it
constexpr double kMaxLever = 4.0;         // a contact moves no cloth vertex faster than this many times its
                                          // point's velocity change (see collide's contact_point)

// the velocity of body b's surface at point p (m/s; b < 0: the ground, at rest)
Vec3 surface_velocity(const ContactBodies& bodies, int b, const Vec3& p) {
  if (b < 0) return Vec3::Zero();
  return bodies.velocity_at(b, p);
}

// the ground (b < 0), a static body or a kinematic one not moving in this step
bool still_surface(const ContactBodies& bodies, int b) { return b < 0 || bodies.body(b).still; }

// a body the pinches may move: dynamic and awake
bool movable_body(const ContactBodies& bodies, int b) { return b >= 0 && !bodies.body(b).kinematic && !bodies.asleep(b); }

// the quick reject: the body's bounding sphere, grown by h, misses the cloth's box `reach`
bool out_of_reach(const ContactBody& body, const Box3& reach, double h) {
  const Vec3 nearest = body.center.cwiseMax(reach.min()).cwiseMin(reach.max());
  return (nearest - body.center).norm() > body.bounding_radius + h;
}
}  // namespace

ClothBodyContact::ClothBodyContact(const Cloth& cloth)
    : friction_(cloth.model().friction), thickness_(cloth.model().thickness) {
  inverse_mass_ = cloth.inverse_masses();
  edges_ = unique_edges(cloth.triangles());  // sorted
  const Triangles& triangles = cloth.triangles();
  triangle_edges_.resize(triangles.rows());
  for (int t = 0; t < triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int i = triangles(t, k), j = triangles(t, (k + 1) % 3);
      const std::array<int, 2> e{std::min(i, j), std::max(i, j)};
      triangle_edges_[t][k] = static_cast<int>(std::lower_bound(edges_.begin(), edges_.end(), e) - edges_.begin());
    }
  }
  nearby_ = ClothNearby(cloth.vertex_count(), edges_, cloth.triangles());
  planes_.resize(cloth.triangles().rows());
  vertex_changed_.assign(cloth.vertex_count(), 0);
  triangle_seen_.assign(triangles.rows(), -1);
  edge_seen_.assign(edges_.size(), -1);
  double total = 0.0;
  for (const auto& e : edges_) total += (cloth.positions().row(e[1]) - cloth.positions().row(e[0])).norm();
  mean_edge_ = total / static_cast<double>(std::max<size_t>(1, edges_.size()));
  touches_ = {std::vector<Vec3>(cloth.vertex_count(), Vec3::Zero()), std::vector<int>(cloth.vertex_count(), -1),
              std::vector<char>(cloth.vertex_count(), 0), std::vector<char>(cloth.vertex_count(), 0), {}};
}

// Body b's features against the cloth, in the body's coordinates, spaced a quarter of the
// cloth's mean edge: a box's edges and corners, or a mesh's sharp convex edges and corners
// (contact/body_features.h); none for other shapes (a sphere has no edge). Made once per
// (body, cloth), at the first contact pass that reaches the body. A point behind a feature
// counts as inside the body where the body's phi is below 0, or below the level set's own
// phi at the feature, which is above 0 where the grid rounds a sharp edge off (by a fraction
// of a voxel: a cloth point just pierced by the mesh's edge is still outside the rounded
// level set), at most h / 2, so that a layer held at h on the body's far side never counts
const BodyFeatures& ClothBodyContact::body_features(const ContactBodies& bodies, int b) {
  if (body_features_.size() < static_cast<size_t>(bodies.count())) body_features_.resize(bodies.count());
  std::optional<BodyFeatures>& features = body_features_[b];
  if (features) return *features;
  features.emplace();
  const ContactBody& body = bodies.body(b);
  if (body.surface) return *features;  // a deforming surface's edges move: its obstacle keeps them out
  const SignedDistance* shape = body.shape;
  const double h = thickness_, spacing = 0.25 * mean_edge_;
  if (const auto* box = dynamic_cast<const BoxDistance*>(shape)) {
    box_edge_features(box->half(), spacing, features->points, features->normals, &features->edges);
  } else if (shape && body.mesh && body.mesh->triangles.rows() > 0) {
    mesh_edge_features(body.mesh->vertices, body.mesh->triangles, spacing, sharp_crease_angle(h, mean_edge_),
                       features->points, features->normals, &features->edges);
  }
  for (const Vec3& p : features->points) {
    features->inside_below.push_back(std::clamp(shape->phi(p), 0.0, 0.5 * h));
    features->bounds.extend(p);
  }
  return *features;
}

// Body b's features against the cloth's triangles at their candidate positions x + dt v
// (contact/body_features.h), each contact applied before the next feature is looked at; each
// goes to `contact` with the triangle's vertices and weights. The triangle grid is built for
// the body (at the candidates as it reaches the body) over only the triangles near it: those
// whose box, grown by the grid's margin, meets the features' box grown by a cell (a feature's
// query reads only its own cell, so it finds what a grid over the whole cloth would), so
// that a small body's grid costs little
template <class Contact>
bool ClothBodyContact::collide_features(const Cloth& cloth, const ContactBodies& bodies, int b, double dt,
                                        const Contact& contact) {
  const BodyFeatures& features = body_features(bodies, b);
  if (features.points.empty()) return false;
  const SignedDistance& shape = *bodies.body(b).shape;
  const double h = thickness_, edge = mean_edge_;
  const Triangles& triangles = cloth.triangles();
  const Pose& pose = bodies.body(b).pose;
  Box3 region;
  for (int k = 0; k < 8; ++k) region.extend(pose.apply(features.bounds.corner(static_cast<Box3::CornerType>(k))));
  region.min().array() -= edge;
  region.max().array() += edge;
  Box3 reached = region;  // (the triangles whose box grown by the grid's margin may meet the region)
  reached.min().array() -= 2.0 * h;
  reached.max().array() += 2.0 * h;
  grid_.build(candidates_, triangles, edge, 2.0 * h, region, &nearby_.triangles(reached));
  const auto candidate = [&](int k) { return Vec3(candidates_.row(k).transpose()); };
  std::vector<int> near;
  bool touched = false;
  for (size_t f = 0; f < features.points.size(); ++f) {
    const Vec3 p = pose.apply(features.points[f]), nf = pose.rotation * features.normals[f];
    grid_.query(p, near);
    for (int t : near) {
      const int ids[3] = {triangles(t, 0), triangles(t, 1), triangles(t, 2)};
      const Vec3 a = candidate(ids[0]), b = candidate(ids[1]), c = candidate(ids[2]);
      TrianglePlane& plane = planes_[t];
      if (plane.at < pass_stamp_ ||
          plane.at < std::max({vertex_changed_[ids[0]], vertex_changed_[ids[1]], vertex_changed_[ids[2]]})) {
        triangle_plane(a, b, c, plane.winding, plane.twice_area);
        plane.at = stamp_;
      }
      Vec3 w, normal;
      double phi;
      if (!feature_against_plane(p, nf, a, b, c, plane.winding, plane.twice_area, h, edge, w, normal, phi)) continue;
      // a plane behind the feature is the cloth pierced only if its point there is inside the
      // body (not a layer on the body's far side)
      const Vec3 xc = p + phi * normal;
      if (phi < 0.0 && shape.phi(pose.apply_inverse(xc)) >= features.inside_below[f]) continue;
      const double weights[3] = {w[0], w[1], w[2]};
      contact(ids, weights, 3, xc, normal, phi);
      touched = true;
    }
  }
  touched |= collide_feature_edges(cloth, bodies, b, dt, features, contact);
  return touched;
}

// the body's sharp edges against the cloth's edges: where a cloth edge passes within h of a
// body edge between the ends of both, the cloth edge's point there is pushed out to h, along
// the line joining the two (outside the body: that line leaves the edge on the outer side
// of one of its faces), or along the level set where it is inside. The feature points
// above, and the samples of each cloth edge against the level set, miss this: a cloth edge
// sweeping past a body edge nearly square to it (a box pushed into a sheet lying on the
// ground, its vertical edges crossing the sheet's edges between the points they are
// sampled at) put the body edge through the middle of a cloth triangle whose three
// corners stayed outside. The triangles near an edge come from the grid at points along it
// 2h apart (a cloth edge within h of the body edge has its triangle's box, grown by the
// grid's 2h, over one of them)
template <class Contact>
bool ClothBodyContact::collide_feature_edges(const Cloth& cloth, const ContactBodies& bodies, int b, double dt,
                                             const BodyFeatures& features, const Contact& contact) {
  const SignedDistance& shape = *bodies.body(b).shape;
  const double h = thickness_;
  const Pose& pose = bodies.body(b).pose;
  const auto candidate = [&](int k) { return Vec3(candidates_.row(k).transpose()); };
  std::vector<int> near;
  bool touched = false;
  std::vector<int> cloth_edges;
  for (const FeatureEdge& fe : features.edges) {
    // each triangle and cloth edge once per body edge (marked with a number distinct across
    // body edges, bodies and calls)
    if (edge_mark_ == std::numeric_limits<int>::max()) {
      std::fill(triangle_seen_.begin(), triangle_seen_.end(), -1);
      std::fill(edge_seen_.begin(), edge_seen_.end(), -1);
      edge_mark_ = -1;
    }
    const int mark = ++edge_mark_;
    const Vec3 a = pose.apply(fe.a), ab = pose.apply(fe.b) - a;
    const Vec3 n1 = pose.rotation * fe.n1, n2 = pose.rotation * fe.n2;
    Box3 reach(a);
    reach.extend(Vec3(a + ab));
    reach.min().array() -= h;
    reach.max().array() += h;
    const int samples = std::max(1, static_cast<int>(std::ceil(ab.norm() / (2.0 * h))));
    cloth_edges.clear();
    long long last = 0;
    for (int q = 0; q <= samples; ++q) {
      const Vec3 p = a + ab * (static_cast<double>(q) / samples);
      if (q > 0 && grid_.cell(p) == last) continue;  // the same cell: the same triangles
      last = grid_.cell(p);
      grid_.query(p, near);
      for (int t : near) {
        if (triangle_seen_[t] == mark) continue;
        triangle_seen_[t] = mark;
        for (int k : triangle_edges_[t]) {
          if (edge_seen_[k] == mark) continue;
          edge_seen_[k] = mark;
          cloth_edges.push_back(k);
        }
      }
    }
    for (int k : cloth_edges) {
      const std::array<int, 2>& e = edges_[k];
      const Vec3 c = candidate(e[0]), d = candidate(e[1]);
      Box3 span(c);
      span.extend(d);
      if (!span.intersects(reach)) continue;
      const auto [s, t] = closest_on_segments(a, a + ab, c, d);
      if (!(s > 0.0 && s < 1.0 && t > 0.0 && t < 1.0)) continue;
      const Vec3 xc = c + t * (d - c), across = xc - (a + s * ab);
      const double distance = across.norm();
      if (!(distance > 0.0)) continue;  // on the edge: no direction to go
      Vec3 normal;
      double phi;
      if (across.dot(n1) > 0.0 || across.dot(n2) > 0.0) {
        // outside: out to h along the line from the edge
        if (!(distance < h)) continue;
        normal = across / distance;
        phi = distance;
      } else if (distance < kEdgeReach * h) {
        // inside, just past the edge (it went over the edge this step): back over it, to h
        // on the side it came from (the opposite of an inside direction is outside, the
        // edge being convex), rather than out of the nearest face, which can leave it
        // across the edge still
        normal = -across / distance;
        phi = -distance;
      } else {
        // inside, deeper: out of the nearest face
        Vec3 n_local;
        phi = shape.phi_and_normal(pose.apply_inverse(xc), n_local);
        if (!(phi < h)) continue;
        normal = pose.rotation * n_local;
      }
      const double weights[2] = {1.0 - t, t};
      contact(e.data(), weights, 2, xc, normal, phi);
      touched = true;
    }
  }
  return touched;
}

// the Coulomb coefficient between the cloth and body b (b < 0: the ground): sqrt(mu_a mu_b)
double ClothBodyContact::surface_friction(const ContactBodies& bodies, int b) const {
  return std::sqrt(friction_ * (b < 0 ? bodies.ground()->friction : bodies.body(b).friction));
}

// The contacts the cloth's implicit solve holds (WorldSettings::cloth_contacts_in_solve; Baraff
// and Witkin 1998, 5.3), against still surfaces (the ground, static bodies and kinematic ones
// not moving in this step; still_surface):
// each free vertex a contact pushed in the last step (collide: its own contact, or one of
// an edge point or of a body's feature it shares; or this stage's own hold, when the surface
// pushed), unless the surface had to pull then. Its velocity along the contacts' mean normal
// becomes the surface's; if friction stopped its slip (and the solve's hold needed no more than
// the friction cone allowed), across the normal too (static friction). The rest of the cloth
// then answers to the held vertices inside the solve. Without it, the solve lets a resting
// vertex fall (or slide) with its neighbours, the contacts stop it alone after the solve, and
// its edges stretch by their relative speed times the step, every step: a soft drape without
// strain limiting rests several times more stretched than when held
// (ClothWorld.ContactsHeldInTheSolve... measures it).
// Moving bodies are left to collide: held to a dynamic body's velocity before the body had
// answered, a ball in a hammock keeps bouncing; held to a keyed body's surface velocity at
// the step's start, a cloth on a fast spinning box sinks into it, and static friction and
// landings against a fast keyed body crossing a curtain fling its vertices. Landings are not
// predicted: holding the vertices that would come within h of a surface during the step (at
// x + dt v + dt^2 g) to land at h flings the vertices of a fine drape as its corners hit the
// ground.
void ClothBodyContact::contact_constraints(const Cloth& cloth, const ContactBodies& bodies,
                                           std::vector<ClothContactConstraint>& out) {
  const Points& x = cloth.positions();
  const std::vector<char>& pinned = cloth.pinned();
  const int n = cloth.vertex_count();
  Touches& touches = touches_;
  out.clear();
  touches.constrained_body.clear();
  for (int k = 0; k < n; ++k) {
    const Vec3 sum = touches.normal[k];
    if (pinned[k] || touches.released[k] || !(sum.squaredNorm() > 0.0)) continue;
    const Vec3 normal = sum.normalized();
    const int body = touches.body[k];
    const Vec3 surface = surface_velocity(bodies, body, x.row(k).transpose());
    ClothContactConstraint held;
    held.vertex = k;
    held.normal = normal;
    held.speed = surface.dot(normal);
    held.stick = touches.stuck[k];
    held.surface_velocity = surface;
    out.push_back(held);
    touches.constrained_body.push_back(body);
  }
  forget_touches();
}

void ClothBodyContact::forget_touches() {
  std::fill(touches_.normal.begin(), touches_.normal.end(), Vec3::Zero());
  std::fill(touches_.stuck.begin(), touches_.stuck.end(), 0);
}

// After the solve, for each held vertex: one the surface had to pull is let go in the next
// step. One the surface pushed is held again in the next (it rests there now, so no contact
// after the solve may touch it) and gets Coulomb friction from the solve's normal impulse
// (Bridson, Fedkiw and Anderson 2002, as collide's): a sliding one's slip relative to
// the surface reduced by mu times that impulse over the mass, at most to zero (then it sticks
// in the next step); a sticking one keeps the surface's velocity, and slides from the next
// step on if the solve needed more than mu times the normal impulse across it
void ClothBodyContact::apply_constraint_impulses(Cloth& cloth, const ContactBodies& bodies,
                                                 const std::vector<ClothContactConstraint>& constraints) {
  Touches& touches = touches_;
  std::fill(touches.released.begin(), touches.released.end(), 0);
  for (size_t i = 0; i < constraints.size(); ++i) {
    const ClothContactConstraint& k = constraints[i];
    if (k.impulse < 0.0) {
      touches.released[k.vertex] = 1;
      continue;
    }
    const int b = touches.constrained_body[i];
    touches.normal[k.vertex] += k.normal;
    touches.body[k.vertex] = b;
    const double mu = surface_friction(bodies, b);
    const double m = cloth.masses()[k.vertex];
    auto v = cloth.velocities().row(k.vertex);
    if (k.stick) {
      // (past the cone it slides from the next step on: the rest of the cloth has already
      // answered to it held, so giving the excess back to the vertex alone would hand it the
      // pull of all the cloth it held, and a light corner vertex holding a hanging sheet would
      // fly off)
      touches.stuck[k.vertex] = k.friction.norm() <= mu * k.impulse;
      continue;
    }
    const Vec3 p = cloth.positions().row(k.vertex).transpose();
    const Vec3 relative = Vec3(v.transpose()) - surface_velocity(bodies, b, p);
    const Vec3 slip = relative - relative.dot(k.normal) * k.normal;
    const double speed = slip.norm(), stop = mu * k.impulse / m;
    if (stop >= speed) {
      touches.stuck[k.vertex] = 1;
      v -= slip.transpose();
    } else {
      v -= (stop / speed) * slip.transpose();
    }
  }
}

// one contact of a point of the cloth (a vertex, or a point along an edge: vertices `ids`
// with weights `w`): push the point out to distance h, friction on its relative slip,
// shared by its vertices in proportion to weight and inverse mass (pinned ones take none),
// and the opposite momentum to the body (body < 0: the ground)
void ClothBodyContact::contact_point(const Points& x, Points& v, ContactBodies& bodies, double dt, const int* ids,
                                     const double* w, int count, int body, const Vec3& xc, const Vec3& normal,
                                     double phi, double mu) {
  const double h = thickness_;
  const Eigen::VectorXd& inverse_mass = inverse_mass_;
  Touches& touches = touches_;
  // a moving keyed body passes through the vertices the cloth let into it (let_in), and
  // through those that were inside it at the step's start while a still surface holds them
  // (the ground it presses the cloth into: the cloth cannot be in two places). Pushed out of
  // its nearest face, they would be flung up. One the cloth alone holds, by its pins, is
  // pushed: a keyed ball crossing a curtain pushes it aside
  if (body >= 0 && bodies.body(body).kinematic && !bodies.body(body).still) {
    const ContactBody& passing = bodies.body(body);
    for (int i = 0; i < count; ++i) {
      const int k = ids[i];
      if (passing.let_in && (*passing.let_in)[k]) return;
      if (touches.normal[k].squaredNorm() > 0.0 &&
          passing.shape->phi(passing.start_pose.apply_inverse(Vec3(x.row(k).transpose()))) < 0.0) {
        return;
      }
    }
  }
  double denom = 0.0, weight = 0.0, lever = 0.0;
  Vec3 point_velocity = Vec3::Zero();
  for (int i = 0; i < count; ++i) {
    denom += w[i] * w[i] * inverse_mass[ids[i]];
    if (inverse_mass[ids[i]] > 0.0) weight += w[i];
    point_velocity += w[i] * v.row(ids[i]).transpose();
  }
  if (denom <= 0.0) return;
  // how much faster than the point its fastest vertex must move: 1 for a vertex or a point
  // of a free triangle, 3 at the centroid of a triangle with two pinned vertices, and
  // without bound as the point nears a pinned vertex (a lever about the pins: a pole's corner
  // on a triangle by the pins would fling its free vertex). Past kMaxLever the
  // pins hold the point: scaling the push down instead only spread the blow-up over the
  // strain-collision passes, each pushing again while the point stays inside
  for (int i = 0; i < count; ++i) lever = std::max(lever, w[i] * inverse_mass[ids[i]] / denom);
  if (lever > kMaxLever) return;
  const Vec3 relative = point_velocity - surface_velocity(bodies, body, xc);
  const double vn = relative.dot(normal);
  const double dvn = (h - phi) / dt;
  if (dvn <= 0.0) return;
  Vec3 slip = relative - vn * normal;
  const double slip_speed = slip.norm();
  const bool stuck = mu * dvn >= slip_speed;
  if (slip_speed > 0.0) slip *= std::max(0.0, 1.0 - mu * dvn / slip_speed);
  const Vec3 change = (vn + dvn) * normal + slip - relative;  // of the point's velocity
  for (int i = 0; i < count; ++i) {
    v.row(ids[i]) += (w[i] * inverse_mass[ids[i]] / denom) * change.transpose();
    candidates_.row(ids[i]) = x.row(ids[i]) + dt * v.row(ids[i]);
    nearby_.moved(ids[i]);
    vertex_changed_[ids[i]] = ++stamp_;
    if (w[i] > 0.0 && inverse_mass[ids[i]] > 0.0 && still_surface(bodies, body)) {
      touches.normal[ids[i]] += w[i] * normal;
      touches.body[ids[i]] = body;
      touches.stuck[ids[i]] = stuck;
    }
  }
  if (body >= 0 && !bodies.body(body).kinematic && !bodies.asleep(body)) {
    const Vec3 J = (weight / denom) * change;  // the cloth's momentum change; the body takes -J
    bodies.apply_impulse(body, xc, -J);
  }
}

// The cloth's points, edge points and the body's features against body b
void ClothBodyContact::collide_with_body(Cloth& cloth, ContactBodies& bodies, int b, const Box3& reach, double dt) {
  const Points& x = cloth.positions();
  Points& v = cloth.velocities();
  const std::vector<char>& pinned = cloth.pinned();
  const double h = thickness_;
  const int n = cloth.vertex_count();
  auto contact_point = [&](const int* ids, const double* w, int count, int body, const Vec3& xc, const Vec3& normal,
                           double phi, double mu) {
    this->contact_point(x, v, bodies, dt, ids, w, count, body, xc, normal, phi, mu);
  };
  auto contact = [&](int k, int body, const Vec3& xc, const Vec3& normal, double phi, double mu) {
    const double one = 1.0;
    contact_point(&k, &one, 1, body, xc, normal, phi, mu);
  };
  const ContactBody& body = bodies.body(b);
  if (!body.shape) return;
  const Pose& pose = body.pose;
  Box3 local = body.shape->bounds();
  local.min().array() -= h;
  local.max().array() += h;
  if (out_of_reach(body, reach, h)) return;
  const double mu = surface_friction(bodies, b);
  // the world box of `local` at the pose (grown by far more than round-off): a point outside
  // it is outside `local` in the body's frame, told without turning it into that frame
  const Vec3 centre = pose.apply(local.center()), half = 0.5 * local.sizes();
  const Vec3 spread = pose.rotation.cwiseAbs() * half + Vec3::Constant(kWorldBoxSlack);
  const Box3 around(centre - spread, centre + spread);
  bool touched = false;
  for (int k : nearby_.vertices(around)) {
    if (pinned[k]) continue;
    const Vec3 xc = candidates_.row(k).transpose();
    if (!around.contains(xc)) continue;
    const Vec3 p = pose.apply_inverse(xc);
    if (!local.contains(p)) continue;
    Vec3 n_local;
    const double phi = body.shape->phi_and_normal(p, n_local);
    if (phi >= h) continue;
    contact(k, b, xc, pose.rotation * n_local, phi, mu);
    touched = true;
  }
  // points along the edges (a pole or a box's edge between vertices), at their quarters
  nearby_.begin_edges(around);
  for (int next; (next = nearby_.next_edge()) >= 0;) {
    const std::array<int, 2>& e = edges_[next];
    if (pinned[e[0]] && pinned[e[1]]) continue;
    const Vec3 a = candidates_.row(e[0]).transpose();
    const Vec3 d = Vec3(candidates_.row(e[1]).transpose()) - a;
    for (double s : {0.25, 0.5, 0.75}) {
      const Vec3 xc = a + s * d;
      if (!around.contains(xc)) continue;
      const Vec3 p = pose.apply_inverse(xc);
      if (!local.contains(p)) continue;
      Vec3 n_local;
      const double phi = body.shape->phi_and_normal(p, n_local);
      if (phi >= h) continue;
      const double w[2] = {1.0 - s, s};
      contact_point(e.data(), w, 2, b, xc, pose.rotation * n_local, phi, mu);
      touched = true;
    }
  }
  // the body's corners and edges against the cloth's triangles
  touched |= collide_features(cloth, bodies, b, dt,
                              [&](const int* ids, const double* w, int count, const Vec3& xc, const Vec3& normal,
                                  double phi) { contact_point(ids, w, count, b, xc, normal, phi, mu); });
  if (touched && bodies.asleep(b)) bodies.wake(b);
}

void ClothBodyContact::collide(Cloth& cloth, ContactBodies& bodies, double dt) {
  const Points& x = cloth.positions();
  Points& v = cloth.velocities();
  const std::vector<char>& pinned = cloth.pinned();
  const double h = thickness_;
  const int n = cloth.vertex_count();

  candidates_ = x + dt * v;
  nearby_.begin(candidates_);
  pass_stamp_ = ++stamp_;
  // the cloth's box over the step, to skip bodies it cannot reach
  Box3 reach;
  for (int k = 0; k < n; ++k) {
    reach.extend(Vec3(x.row(k).transpose()));
    reach.extend(Vec3(candidates_.row(k).transpose()));
  }
  reach.min().array() -= h;
  reach.max().array() += h;

  for (int b = 0; b < bodies.count(); ++b) collide_with_body(cloth, bodies, b, reach, dt);
  if (const ContactGround* ground = bodies.ground()) {
    const double mu = surface_friction(bodies, -1);
    for (int k = 0; k < n; ++k) {
      if (pinned[k]) continue;
      const Vec3 xc = candidates_.row(k).transpose();
      const double phi = xc.y() - ground->height;
      if (phi < h) {
        const double one = 1.0;
        contact_point(x, v, bodies, dt, &k, &one, 1, -1, xc, Vec3::UnitY(), phi, mu);
      }
    }
  }
}

// Cloth pinched between two surfaces (two bodies, or a body and the ground): a vertex
// between two surfaces facing each other whose gap along it is under the spacer below cannot
// be pushed out of either without going into the other or into a layer of itself (a sheet
// falling, folded, into the gap between a resting sphere and a box: the box's contacts,
// after the sphere's, and self-collision's last word leave it inside the sphere), and its
// light vertices' momentum cannot push a heavy body away. The rigid solver does not see the
// cloth, so here the pinch acts on the two bodies as a rigid spacer of width (L + 1) h for
// the L layers of cloth between the two surfaces there (h from each surface and between
// layers), and at least kPinchGap h (3h, two layers, as where a sheet folds into a gap; a 2h
// spacer for one layer still leaves it inside). L counts the vertex's own layer and the
// cloth triangles the segment between the two surfaces through the vertex crosses: with 3h
// whatever lay there, a body resting on three layers of a fold presses them thinner than the
// thickness, and its edges go through the top one (self-collision, holding the layers apart,
// has the last word over the body's contacts). Gauss-Seidel
// sweeps of equal and opposite impulses (split below into a real and a pseudo part) at the
// vertex along n = (n_a - n_b) / |n_a - n_b| (n_a, n_b the surfaces' outward normals),
// each bringing the bodies' relative velocity there, along n, to the speed that opens the
// gap phi_a + phi_b to the spacer over the step, at most kPinchSpeed (a deep start is
// cleared over a few steps). Immovable surfaces (the ground, kinematic or sleeping bodies)
// take nothing; a pinch between two of them is left alone. A dynamic body resting on a
// single fold of cloth on the ground so rests 3h above the ground, on L layers (L + 1) h.
void ClothBodyContact::hold_pinched_bodies(const Cloth& cloth, ContactBodies& bodies, double dt) {
  const Points& x = cloth.positions();
  const Points& v = cloth.velocities();
  const double h = thickness_;
  const int n = cloth.vertex_count();
  // the bodies the cloth may touch, and whether any of them can move
  Box3 reach;
  for (int k = 0; k < n; ++k) reach.extend(Vec3((x.row(k) + dt * v.row(k)).transpose()));
  reach.min().array() -= h;
  reach.max().array() += h;
  std::vector<int> near;
  bool any_movable = false;
  for (int b = 0; b < bodies.count(); ++b) {
    const ContactBody& body = bodies.body(b);
    if (!body.shape) continue;
    if (out_of_reach(body, reach, h)) continue;
    near.push_back(b);
    any_movable = any_movable || movable_body(bodies, b);
  }
  if (!any_movable) return;
  const std::vector<Pinch> pinches = find_pinches(cloth, bodies, dt, near, reach);
  if (pinches.empty()) return;
  separate_pinches(bodies, dt, near, pinches);
}

// The pinches of the cloth's vertices between the bodies `near` (and the ground), at the
// candidates: pairs of surfaces facing each other whose gap along the vertex is under the
// spacer the layers between them need
std::vector<ClothBodyContact::Pinch> ClothBodyContact::find_pinches(const Cloth& cloth, const ContactBodies& bodies,
                                                                    double dt, const std::vector<int>& near,
                                                                    const Box3& reach) {
  const Points& x = cloth.positions();
  const Points& v = cloth.velocities();
  const double h = thickness_;
  const int n = cloth.vertex_count();
  const ContactGround* ground = bodies.ground();
  struct Touch {
    int body;  // kGround for the ground
    Vec3 normal;
    double phi;
  };
  // the cloth's triangles at the candidates, for counting layers: each registered in the
  // cells its box grown by half the widest gap looked at meets, so that a triangle crossing
  // a segment of length under kPinchReach h is found from the segment's middle (built at
  // the first pair that needs it)
  const Triangles& triangles = cloth.triangles();
  const Points candidates = x + dt * v;
  bool grid_built = false;
  std::vector<int> crossed;
  // the layers between the surface points pa and pb through vertex k: k's own and the
  // triangles not of k's that the segment crosses
  const auto layers = [&](int k, const Vec3& pa, const Vec3& pb) {
    if (!grid_built) {
      grid_.build(candidates, triangles, mean_edge_ + 0.5 * kPinchReach * h, 0.5 * kPinchReach * h, reach);
      grid_built = true;
    }
    grid_.query(0.5 * (pa + pb), crossed);
    int count = 1;
    for (int t : crossed) {
      const int i = triangles(t, 0), j = triangles(t, 1), l = triangles(t, 2);
      if (i == k || j == k || l == k) continue;
      count += segment_crosses_triangle(pa, pb, candidates.row(i).transpose(), candidates.row(j).transpose(),
                                        candidates.row(l).transpose(), 0.0);
    }
    return count;
  };
  std::vector<Pinch> pinches;
  std::vector<Touch> touches;
  for (int k = 0; k < n; ++k) {
    if (cloth.pinned()[k]) continue;
    const Vec3 xc = candidates.row(k).transpose();
    touches.clear();
    for (size_t i = 0; i < near.size(); ++i) {
      const ContactBody& body = bodies.body(near[i]);
      const Vec3 p = body.pose.apply_inverse(xc);
      Box3 local = body.shape->bounds();
      local.min().array() -= kPinchReach * h;
      local.max().array() += kPinchReach * h;
      if (!local.contains(p)) continue;
      Vec3 n_local;
      const double phi = body.shape->phi_and_normal(p, n_local);
      if (phi < kPinchReach * h) touches.push_back({near[i], body.pose.rotation * n_local, phi});
    }
    if (touches.empty()) continue;
    if (ground && xc.y() - ground->height < kPinchReach * h) {
      touches.push_back({kGround, Vec3::UnitY(), xc.y() - ground->height});
    }
    // a pair is a pinch where the two surfaces face each other and the gap between them
    // along the vertex is under the spacer (no need for the vertex to be closer than h to
    // either: cloth resting exactly at h on the ground under a box then switched the pinch
    // off and on, and the box jittered and walked at 1.3 cm/s)
    for (size_t i = 0; i < touches.size(); ++i) {
      for (size_t j = i + 1; j < touches.size(); ++j) {
        const Touch& a = touches[i];
        const Touch& b = touches[j];
        if (!movable_body(bodies, a.body) && !movable_body(bodies, b.body)) continue;
        if (a.phi + b.phi >= kPinchReach * h || a.normal.dot(b.normal) >= 0.0) continue;
        const double width =
            std::max(kPinchGap, layers(k, xc - a.phi * a.normal, xc - b.phi * b.normal) + 1.0) * h;
        if (a.phi + b.phi >= width) continue;
        pinches.push_back({xc, a.body, b.body, (a.normal - b.normal).normalized(), a.phi + b.phi, width});
      }
    }
  }
  return pinches;
}

// Equal and opposite impulses between the two surfaces of each pinch (see above), real and
// pseudo, in Gauss-Seidel sweeps; the pseudo part then displaces the bodies
void ClothBodyContact::separate_pinches(ContactBodies& bodies, double dt, const std::vector<int>& near,
                                        const std::vector<Pinch>& pinches) {
  // two parts (split impulses): a real one that stops the surfaces closing in on the
  // vertex (inelastic: no bounce off the cloth), and a pseudo-velocity one, applied to the
  // bodies' positions only, that opens the gap: a body is put in place, not thrown
  const int body_count = bodies.count();
  std::vector<Vec3> pseudo_v(body_count, Vec3::Zero()), pseudo_w(body_count, Vec3::Zero());
  std::vector<Mat3> inverse_inertia(body_count, Mat3::Zero());
  for (int b : near) {
    if (movable_body(bodies, b)) inverse_inertia[b] = bodies.inverse_inertia(b);
  }
  const auto pseudo_at = [&](int b, const Vec3& p) -> Vec3 {
    return b < 0 ? Vec3::Zero() : Vec3(pseudo_v[b] + pseudo_w[b].cross(p - bodies.body(b).center));
  };
  const auto k_normal = [&](const Pinch& pinch) {
    Mat3 K = Mat3::Zero();
    for (int b : {pinch.a, pinch.b}) {
      if (movable_body(bodies, b)) {
        K += impulse_matrix(bodies.body(b).inverse_mass, inverse_inertia[b], pinch.point - bodies.body(b).center);
      }
    }
    return pinch.normal.dot(K * pinch.normal);
  };
  std::vector<char> moved(body_count, 0);
  for (int sweep = 0; sweep < kPinchSweeps; ++sweep) {
    for (const Pinch& pinch : pinches) {
      const double kn = k_normal(pinch);
      if (!(kn > 0.0)) continue;
      // real: the surfaces stop closing in (relative normal velocity >= 0)
      const double closing =
          -(surface_velocity(bodies, pinch.b, pinch.point) - surface_velocity(bodies, pinch.a, pinch.point))
               .dot(pinch.normal);
      // pseudo: the gap opens to the spacer's width over the step, at most kPinchSpeed
      const double target = std::min((pinch.width - pinch.gap) / dt, kPinchSpeed);
      const double opening = (pseudo_at(pinch.b, pinch.point) - pseudo_at(pinch.a, pinch.point)).dot(pinch.normal);
      const double real = std::max(0.0, closing) / kn, pseudo = std::max(0.0, target - opening) / kn;
      if (real <= 0.0 && pseudo <= 0.0) continue;
      for (const auto& [b, sign] : {std::pair<int, double>{pinch.b, 1.0}, std::pair<int, double>{pinch.a, -1.0}}) {
        if (!movable_body(bodies, b)) continue;
        const Vec3 r = pinch.point - bodies.body(b).center;
        const Vec3 J = sign * real * pinch.normal, P = sign * pseudo * pinch.normal;  // to body b
        bodies.apply_impulse(b, pinch.point, J);
        pseudo_v[b] += bodies.body(b).inverse_mass * P;
        pseudo_w[b] += inverse_inertia[b] * r.cross(P);
        moved[b] = 1;
      }
    }
  }
  for (int b : near) {
    if (!moved[b]) continue;
    bodies.displace(b, pseudo_v[b], pseudo_w[b], dt);
  }
}

}  // namespace simbake
