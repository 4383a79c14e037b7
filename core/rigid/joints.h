// The joints stage: impulses that hold every enabled joint at the end of the step, drives,
// limits and breaking (the method is at the top of joints.cpp).
#pragma once

#include "rigid/joint_rows.h"

#include "math/block_sparse_lu.h"

#include <vector>

namespace simbake {

// A connected set of jointed dynamic bodies, solved on its own
struct JointComponent {
  std::vector<int> bodies;            // its dynamic bodies (global indices), ascending
  std::vector<int> joints;            // its enabled joints, ascending
  std::vector<JointRow> rows;         // this step's rows, joint by joint
  std::vector<int> row_begin;         // (njoint of the component + 1) each joint's first row
  std::vector<JointRow> measured;     // the same rows' Jacobians where the bodies end the step
  std::vector<JointFrames> end_frames;        // (njoint of the component) where they end it
  std::vector<JointCoordinates> coordinates;  // (njoint of the component) and there
  std::vector<unsigned> needed;               // (njoint of the component) coordinates its rows measure
  std::vector<BodyPose> start;        // (nlocal) the bodies' poses at the start of the step
  std::vector<BodyPose> candidate;    // (nlocal) and where their velocities now take them
  std::vector<Mat3> inverse_inertia;  // (nlocal) world I^-1 at the start (1/(kg m^2))
  std::vector<Mat3> rotation_response;  // (nlocal) how the candidate turns with L, over h
                                      //   (rotation_response, 1/(kg m^2))
  std::vector<JointFrames> frames;    // (njoint of the component) frames at the start
  std::vector<char> in_solve;         // (nrow) rows in this iteration's solve
  std::vector<double> residual;       // (nrow) the solve's right-hand side (0 off the solve)
  std::vector<Vec3> response;         // (nrow x 2 sides x 2) M^-1 J^T of each row's sides
  std::vector<Vec3> saved_v, saved_l;  // (nlocal) velocities at the best iterate so far
  std::vector<double> saved_impulse;  // (nrow) and the rows' impulses
  std::vector<double> step;           // (nrow) the last Newton step's impulses
  // the system's pattern: a node per joint (its rows), a block per pair of joints sharing
  // a body; analysed again only when the joints or their row counts change
  BlockSparseLU system;
  std::vector<double> assembled;      // the system's values before factoring (with drives)
  bool drives = false;                // a drive row among the rows
  std::vector<double> rhs, delta;     // (nrow) the solve's right-hand side and solution
  std::vector<char> bounded;          // (nrow) drives held at their bound in the solve
  std::vector<int> pattern_joints, pattern_rows;
  double regularization = 0.0;        // of the diagonal, relative (joints.cpp)
  bool loops = false;                 // joints closing loops: redundant rows
  bool factored = false;              // the system holds a factorization of this step's
  std::vector<char> factored_rows;    //   with these rows in the solve
  bool factored_bounded = false;      //   and a drive held at its bound
  std::vector<std::vector<int>> joints_at;    // (nlocal) the component's joints on each body
  std::vector<std::vector<int>> block_at;     // (nlocal) offsets of their blocks, a x b
  double error = 0.0;                 // (m, rad) the largest joint error the step ends at
};

struct JointScratch {
  std::vector<int> parent;            // (nbody) union-find through the joints
  std::vector<int> local;             // (nbody) a body's index in its component, or -1
  std::vector<int> component_of;      // (nbody) its component, or -1
  std::vector<JointComponent> components;
  int count = 0;                      // components this step
  double error = 0.0;                 // (m, rad) the largest joint error any component's
                                      // solve ended this step at (its Newton iterations
                                      // stop at 1e-10; more: they did not converge)
};

// Solves the joints over a step of dt that ends at world time `end_time` (s): every enabled
// joint's rows, component by component in parallel, then the joints whose impulse over the
// step exceeded their break force or torque broken (data.joints)
void solve_joints(const RigidModel& model, RigidData& data, JointScratch& scratch, double dt, double end_time);

// The velocities of the bodies of the last solve's components made tangent to what their
// joints hold where the bodies are now: the least kinetic energy change (an M^-1 J^T
// impulse) that brings every locked coordinate's rate J v to zero. The position step's
// impulses leave the velocities of the step's middle, (x_end - x_start) / dt, whose rate is
// off by O(dt); these are the end's (RATTLE, Andersen 1983, beside the step's SHAKE). The
// next step's solve acts along the same rows and takes the bodies to the same poses, so
// only what the velocities are read for changes (a cache's velocities, kinetic energy, the
// contacts), and the kinetic energy only falls. Components with a body asleep, a broken
// joint or a joint to a moving kinematic body are left as they are. `dt`: the last step's
void project_joint_velocities(const RigidModel& model, RigidData& data, JointScratch& scratch, double dt);

// Each joint's error now: the largest gap between its frames along what it holds (m) and
// the largest angle (rad); zeros for a disabled joint
struct JointError {
  double gap = 0.0;
  double angle = 0.0;
};
JointError joint_error(const RigidModel& model, const RigidData& data, int j);

}  // namespace simbake
