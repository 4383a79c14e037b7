// The joints stage: impulses that hold every enabled joint at the end of the step, drives,
// limits and breaking (the method is at the top of joints.cpp).
#pragma once

#include "rigid/joint_rows.h"

#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include <memory>
#include <vector>

namespace simbake {

// A connected set of jointed dynamic bodies, solved on its own
struct JointComponent {
  std::vector<int> bodies;            // its dynamic bodies (global indices), ascending
  std::vector<int> joints;            // its enabled joints, ascending
  std::vector<JointRow> rows;         // this step's rows
  std::vector<JointRow> measured;     // the same rows' Jacobians where the bodies end the step
  std::vector<BodyPose> start;        // (nlocal) the bodies' poses at the start of the step
  std::vector<BodyPose> candidate;    // (nlocal) and where their velocities now take them
  std::vector<Mat3> inverse_inertia;  // (nlocal) world I^-1 at the start (1/(kg m^2))
  std::vector<JointFrames> frames;    // (njoint of the component) frames at the start
  std::vector<int> active;            // rows in this iteration's solve
  std::vector<std::vector<int>> body_rows;  // (nlocal) active rows touching each body
  std::vector<double> residual;       // (nactive) the solve's right-hand side
  std::vector<Vec3> saved_v, saved_l;  // (nlocal) velocities at the best iterate so far
  std::vector<double> saved_impulse;  // (nrow) and the rows' impulses
  std::vector<double> step;           // (nrow) the last Newton step's impulses
  // the sparse LU of the last solve and the pattern it was analysed for: a system with the
  // same pattern (the same active rows, most iterations and steps) is only factored again
  std::unique_ptr<Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>>> lu;
  std::vector<int> pattern_outer, pattern_inner;
};

struct JointScratch {
  std::vector<int> parent;            // (nbody) union-find through the joints
  std::vector<int> local;             // (nbody) a body's index in its component, or -1
  std::vector<int> component_of;      // (nbody) its component, or -1
  std::vector<JointComponent> components;
  int count = 0;                      // components this step
};

// Solves the joints over a step of dt that ends at world time `end_time` (s): every enabled
// joint's rows, component by component in parallel, then the joints whose impulse over the
// step exceeded their break force or torque broken (data.joints)
void solve_joints(const RigidModel& model, RigidData& data, JointScratch& scratch, double dt, double end_time);

// Each joint's error now: the largest gap between its frames along what it holds (m) and
// the largest angle (rad); zeros for a disabled joint
struct JointError {
  double gap = 0.0;
  double angle = 0.0;
};
JointError joint_error(const RigidModel& model, const RigidData& data, int j);

}  // namespace simbake
