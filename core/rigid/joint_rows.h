// The joints stage's rows: one scalar constraint of a joint each (a locked, limited or driven
// degree of freedom, a cone or a distance limit), with its Jacobian at the start of the step
// and the joint's coordinates measured at any pose of its bodies (the method is at the top
// of joints.cpp).
#pragma once

#include "rigid/rigid_data.h"

#include <vector>

namespace simbake {

// A body's pose as the joints see it (the world: the origin, unturned)
struct BodyPose {
  Vec3 x = Vec3::Zero();        // centre of mass, world (m)
  Quat q = Quat::Identity();    // principal frame -> world
};

// A joint's frames in the world at given poses of its bodies
struct JointFrames {
  Vec3 p0, p1;                  // frame origins, world (m)
  Quat f0, f1;                  // frame axes -> world
  Mat3 axes0;                   // f0 as a matrix: frame 0's axes in the world, as columns
  Vec3 r0, r1;                  // lever arms from each body's centre of mass (m)
};

JointFrames joint_frames(const JointDef& def, const BodyPose& pose0, const BodyPose& pose1);

// A joint's coordinates: what its rows hold, each in frame 0's axes
struct JointCoordinates {
  Vec3 offset = Vec3::Zero();   // p1 - p0 (m)
  double distance = 0.0;        // |p1 - p0| (m)
  Vec3 rotation = Vec3::Zero(); // rotation vector of f0^-1 f1 (rad)
  Vec3 alignment = Vec3::Zero();  // x0 cross x1 (their X axes; sine of the angle between them)
  double twist = 0.0;           // turn of frame 1 about X, in (-pi, pi] (rad)
  Vec3 swing = Vec3::Zero();    // rotation vector of the swing (f0^-1 f1 = swing twist), x = 0
};

// Which coordinates to measure (bits of 1 << RowCoordinate); all by default
JointCoordinates joint_coordinates(const JointFrames& frames, unsigned needed = ~0u);

// What a row holds
enum class RowKind : int {
  kEquality,   // coordinate == target
  kLower,      // coordinate >= target (impulse >= 0)
  kUpper,      // coordinate <= target (impulse <= 0)
  kDrive       // a spring-damper toward the drive's targets, impulse within +-max_force dt
};

// Which coordinate a row measures
enum class RowCoordinate : int { kTrans, kRotation, kAlignment, kTwist, kSwing, kCone, kDistance };

struct JointRow {
  int joint = 0;
  RowKind kind = RowKind::kEquality;
  RowCoordinate coordinate = RowCoordinate::kTrans;
  int axis = 0;                 // frame 0 axis of the coordinate (0 X, 1 Y, 2 Z)
  int side[2] = {-1, -1};       // the component's local body index of each side (-1: immovable)
  Vec3 linear[2];               // Jacobian of each side: the coordinate's rate is
  Vec3 angular[2];              //   sum over sides of linear.v + angular.omega
  double target = 0.0;          // (m, rad) the limit or the locked value
  double start = 0.0;           // (m, rad) the coordinate at the start of the step
  double compliance = 0.0;      // drives: gamma (1/(kg s) in the row's units)
  double rate = 0.0;            // drives: the rate the drive asks for
  double max_impulse = 0.0;     // drives: +- bound of the step's impulse
  double impulse = 0.0;         // the step's impulse so far (N s, or N m s)
  bool active = false;          // in this iteration's solve
  bool clamped = false;         // a drive at its bound, or a limit let go: out of the solve
};

// The coordinate a row measures, out of a joint's coordinates (m, rad)
double row_coordinate(const JointRow& row, const JointCoordinates& c);

// Appends joint j's rows at the start of the step (coordinates `start` at frames `frames`)
// with the sides' local indices. Drive rows need the row's effective mass, set later
// (set_drive_compliance). Rows of a degree of freedom that is free and undriven are not made
void append_joint_rows(const JointDef& def, int j, const JointFrames& frames, const JointCoordinates& start,
                       const int side[2], std::vector<JointRow>& rows);

// The coordinates a joint's rows measure (the bits joint_coordinates takes)
unsigned needed_coordinates(const JointRow* rows, int count);

// Row `row`'s Jacobian (linear, angular) at frames `frames` with coordinates `c` (the
// rows append_joint_rows would make there): how the Newton iterations' measured
// coordinates move. A cone row keeps its own (aimed at the start, aim_cone_row)
void set_row_jacobian(const JointFrames& frames, const JointCoordinates& c, JointRow& row);

// The cone's half-angle along a swing (rad)
double cone_limit(const JointDef& def, const Vec3& swing);

// A cone row aimed along the swing measured at `at` (frame 0's axes at the start: `start`)
void aim_cone_row(const JointDef& def, const JointFrames& start, const JointCoordinates& at, JointRow& row);

// A drive row's compliance, rate and bound from its effective inverse mass k (= J M^-1 J^T)
// and the step h (s)
void set_drive_compliance(const JointDrive& drive, double k, double h, JointRow& row);

// The row's coordinate at `c`, a twist unwrapped to within half a turn of its start (m, rad)
double measured_coordinate(const JointRow& row, const JointCoordinates& c);

}  // namespace simbake
