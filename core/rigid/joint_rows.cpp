// A joint's frames, coordinates and rows (joint_rows.h).
//
// Jacobians. For a translation coordinate C = (p1 - p0).u with u = frame 0's axis k (turning
// with body 0), p_i = X_i + r_i:
//     dC/dt = u.(v1 + w1 x r1) - u.(v0 + w0 x r0) + (p1 - p0).(w0 x u)
// so body 1's row is (u, r1 x u) and body 0's is (-u, -(r0 + d) x u), d = p1 - p0. A rotation
// coordinate about the world direction n (small turns of frame 1 against frame 0) has rate
// (w1 - w0).n: rows (0, n) and (0, -n). The Jacobian is taken once, at the start of the step;
// the coordinates are measured exactly at any pose (the solver's Newton iterations).
#include "rigid/joint_rows.h"

#include <algorithm>
#include <cmath>

namespace simbake {

namespace {

double wrapped(double angle) {
  angle = std::remainder(angle, 2.0 * M_PI);  // in [-pi, pi]
  return angle;
}

// A row of joint j's coordinate (on its axis) between the bodies `side`, its Jacobian unset
JointRow empty_row(int j, RowCoordinate coordinate, int axis, const int side[2]) {
  JointRow row;
  row.joint = j;
  row.coordinate = coordinate;
  row.axis = axis;
  row.side[0] = side[0];
  row.side[1] = side[1];
  return row;
}

// A row of one coordinate with its Jacobian for a translation along u (body 1: +u)
JointRow translation_row(int j, RowCoordinate coordinate, int axis, const JointFrames& f, const Vec3& u,
                         const int side[2]) {
  JointRow row = empty_row(j, coordinate, axis, side);
  const Vec3 d = f.p1 - f.p0;
  row.linear[0] = -u;
  row.angular[0] = -(f.r0 + d).cross(u);
  row.linear[1] = u;
  row.angular[1] = f.r1.cross(u);
  return row;
}

JointRow rotation_row(int j, RowCoordinate coordinate, int axis, const Vec3& n, const int side[2]) {
  JointRow row = empty_row(j, coordinate, axis, side);
  row.linear[0] = row.linear[1] = Vec3::Zero();
  row.angular[0] = -n;
  row.angular[1] = n;
  return row;
}

// The rows of one coordinate: locked, limited (a row per finite bound), driven
void push_coordinate_rows(const JointRow& base, const DofLimit& limit, const JointDrive& drive,
                          std::vector<JointRow>& rows) {
  JointRow row = base;
  if (limit.motion == DofMotion::kLocked) {
    row.kind = RowKind::kEquality;
    row.target = 0.0;
    rows.push_back(row);
    return;
  }
  if (limit.motion == DofMotion::kLimited) {
    if (std::isfinite(limit.lower)) {
      row.kind = RowKind::kLower;
      row.target = limit.lower;
      rows.push_back(row);
    }
    if (std::isfinite(limit.upper)) {
      row.kind = RowKind::kUpper;
      row.target = limit.upper;
      rows.push_back(row);
    }
  }
  if (drive.enabled && (drive.stiffness > 0.0 || drive.damping > 0.0) && drive.max_force > 0.0) {
    row.kind = RowKind::kDrive;
    rows.push_back(row);
  }
}

}  // namespace

JointFrames joint_frames(const JointDef& def, const BodyPose& pose0, const BodyPose& pose1) {
  JointFrames f;
  f.r0 = pose0.q * def.anchor0;
  f.r1 = pose1.q * def.anchor1;
  f.p0 = pose0.x + f.r0;
  f.p1 = pose1.x + f.r1;
  f.f0 = (pose0.q * def.frame0).normalized();
  f.f1 = (pose1.q * def.frame1).normalized();
  f.axes0 = f.f0.toRotationMatrix();
  return f;
}

namespace {
constexpr unsigned bit(RowCoordinate coordinate) { return 1u << static_cast<unsigned>(coordinate); }
}  // namespace

JointCoordinates joint_coordinates(const JointFrames& f, unsigned needed) {
  JointCoordinates c;
  const Vec3 d = f.p1 - f.p0;
  c.offset = f.axes0.transpose() * d;
  c.distance = d.norm();
  constexpr unsigned kTurns = bit(RowCoordinate::kRotation) | bit(RowCoordinate::kAlignment) | bit(RowCoordinate::kTwist) |
                              bit(RowCoordinate::kSwing) | bit(RowCoordinate::kCone);
  if (!(needed & kTurns)) return c;
  Quat rel = (f.f0.conjugate() * f.f1).normalized();
  if (rel.w() < 0.0) rel.coeffs() = -rel.coeffs();
  if (needed & bit(RowCoordinate::kRotation)) c.rotation = rotation_vector_from_quat(rel);
  if (needed & bit(RowCoordinate::kAlignment)) c.alignment = Vec3::UnitX().cross(rel * Vec3::UnitX());
  if (!(needed & (bit(RowCoordinate::kTwist) | bit(RowCoordinate::kSwing) | bit(RowCoordinate::kCone)))) return c;
  // swing-twist: rel = swing twist, twist about X
  const double norm = std::hypot(rel.w(), rel.x());
  const Quat twist = norm > 1e-12 ? Quat(rel.w() / norm, rel.x() / norm, 0.0, 0.0) : Quat::Identity();
  c.twist = norm > 1e-12 ? 2.0 * std::atan2(rel.x(), rel.w()) : 0.0;
  c.swing = rotation_vector_from_quat(rel * twist.conjugate());
  c.swing.x() = 0.0;
  return c;
}

unsigned needed_coordinates(const JointRow* rows, int count) {
  unsigned needed = 0;
  for (int r = 0; r < count; ++r) needed |= bit(rows[r].coordinate);
  return needed;
}

void set_row_jacobian(const JointFrames& f, const JointCoordinates& c, JointRow& row) {
  const auto translation = [&](const Vec3& u) {
    const Vec3 d = f.p1 - f.p0;
    row.linear[0] = -u;
    row.angular[0] = -(f.r0 + d).cross(u);
    row.linear[1] = u;
    row.angular[1] = f.r1.cross(u);
  };
  switch (row.coordinate) {
    case RowCoordinate::kTrans:
      translation(f.axes0.col(row.axis));
      return;
    case RowCoordinate::kDistance: {
      const Vec3 n = c.distance > 1e-12 ? Vec3((f.p1 - f.p0) / c.distance) : Vec3(f.f0 * Vec3::UnitX());
      translation(n);
      row.angular[0] = -f.r0.cross(n);  // (d along n)
      return;
    }
    case RowCoordinate::kRotation:
    case RowCoordinate::kAlignment:
    case RowCoordinate::kTwist:
    case RowCoordinate::kSwing: {
      const Vec3 n = f.axes0.col(row.axis);
      row.linear[0] = row.linear[1] = Vec3::Zero();
      row.angular[0] = -n;
      row.angular[1] = n;
      return;
    }
    case RowCoordinate::kCone:
      return;
  }
}

double row_coordinate(const JointRow& row, const JointCoordinates& c) {
  switch (row.coordinate) {
    case RowCoordinate::kTrans: return c.offset[row.axis];
    case RowCoordinate::kRotation: return c.rotation[row.axis];
    case RowCoordinate::kAlignment: return c.alignment[row.axis];
    case RowCoordinate::kTwist: return c.twist;
    case RowCoordinate::kSwing: return c.swing[row.axis];
    case RowCoordinate::kCone: return c.swing.norm();
    case RowCoordinate::kDistance: return c.distance;
  }
  return 0.0;
}

// The cone's half-angle along the swing axis (0, sy, sz): the ellipse (theta_z / cone0)^2 +
// (theta_y / cone1)^2 <= 1 in the swing's rotation vector
double cone_limit(const JointDef& def, const Vec3& swing) {
  const double s = swing.norm();
  if (s < 1e-12) return std::min(def.cone0, def.cone1);
  const auto term = [](double component, double cone) { return component == 0.0 ? 0.0 : component / cone; };
  const double a = term(swing.z() / s, def.cone0), b = term(swing.y() / s, def.cone1);
  const double inverse = std::sqrt(a * a + b * b);
  return inverse > 0.0 ? 1.0 / inverse : kUnlimited;
}

void append_joint_rows(const JointDef& def, int j, const JointFrames& f, const JointCoordinates& start,
                       const int side[2], std::vector<JointRow>& rows) {
  const std::size_t first = rows.size();
  // translations: along frame 0's axes, or the distance between the origins
  if (def.distance) {
    const Vec3 d = f.p1 - f.p0;
    const Vec3 n = start.distance > 1e-12 ? Vec3(d / start.distance) : Vec3(f.f0 * Vec3::UnitX());
    JointRow row = translation_row(j, RowCoordinate::kDistance, 0, f, n, side);
    row.angular[0] = -f.r0.cross(n);  // (d along n)
    push_coordinate_rows(row, {DofMotion::kLimited, def.min_distance > 0.0 ? def.min_distance : -kUnlimited,
                               def.max_distance}, {}, rows);
  } else {
    for (int k = 0; k < 3; ++k) {
      const JointRow row = translation_row(j, RowCoordinate::kTrans, k, f, f.axes0.col(k), side);
      push_coordinate_rows(row, def.dofs[kTransX + k], def.drives[kTransX + k], rows);
    }
  }
  // rotations: all locked; a hinge about X; or twist about X and swing
  int locked = 0;
  for (int k = 0; k < 3; ++k) locked += def.dofs[kRotX + k].motion == DofMotion::kLocked;
  if (locked == 3) {
    for (int k = 0; k < 3; ++k) {
      push_coordinate_rows(rotation_row(j, RowCoordinate::kRotation, k, f.axes0.col(k), side),
                           def.dofs[kRotX + k], {}, rows);
    }
  } else {
    const bool hinge = locked == 2;
    push_coordinate_rows(rotation_row(j, RowCoordinate::kTwist, 0, f.axes0.col(0), side), def.dofs[kRotX],
                         def.drives[kRotX], rows);
    for (int k = 1; k < 3; ++k) {
      const RowCoordinate coordinate = hinge ? RowCoordinate::kAlignment : RowCoordinate::kSwing;
      push_coordinate_rows(rotation_row(j, coordinate, k, f.axes0.col(k), side), def.dofs[kRotX + k],
                           hinge ? JointDrive{} : def.drives[kRotX + k], rows);
    }
    if (def.cone) {
      // aimed along the swing when the solver first measures it (aim_cone_row)
      JointRow row = rotation_row(j, RowCoordinate::kCone, 0, f.f0 * Vec3::UnitY(), side);
      row.kind = RowKind::kUpper;
      row.target = cone_limit(def, start.swing);
      rows.push_back(row);
    }
  }
  for (std::size_t r = first; r < rows.size(); ++r) rows[r].start = row_coordinate(rows[r], start);
}

void aim_cone_row(const JointDef& def, const JointFrames& start, const JointCoordinates& at, JointRow& row) {
  const double s = at.swing.norm();
  if (s < 1e-12) return;
  const Vec3 n = start.f0 * Vec3(at.swing / s);
  row.angular[0] = -n;
  row.angular[1] = n;
  row.target = cone_limit(def, at.swing);
}

double measured_coordinate(const JointRow& row, const JointCoordinates& c) {
  const double value = row_coordinate(row, c);
  return row.coordinate == RowCoordinate::kTwist ? row.start + wrapped(value - row.start) : value;
}

void set_drive_compliance(const JointDrive& drive, double k, double h, JointRow& row) {
  // implicit spring-damper: impulse = h (ks (x* - x0 - h u) + kd (v* - u)), u the rate at the
  // end of the step; with u = u_free + k impulse this is (k + gamma) impulse = rate - u_free,
  // gamma = 1 / (h (h ks + kd)), rate = (ks (x* - x0) + kd v*) / (h ks + kd)
  const double mass = drive.acceleration ? 1.0 / k : 1.0;
  const double ks = drive.stiffness * mass, kd = drive.damping * mass;
  const double denominator = h * ks + kd;
  double to_target = drive.target_position - row.start;
  if (row.coordinate == RowCoordinate::kTwist) to_target = wrapped(to_target);
  row.compliance = 1.0 / (h * denominator);
  row.rate = (ks * to_target + kd * drive.target_velocity) / denominator;
  row.max_impulse = drive.max_force * h;
}

}  // namespace simbake
