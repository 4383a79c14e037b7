// A deforming collider's surface over one frame (a character's skin, a breathing belly): its
// triangle mesh's vertices in world coordinates at the frame's start and end, and the level
// sets baked from those two meshes. The pipeline sets each frame's end (the start is the last
// frame's end); inside the frame every vertex runs on the line between its two positions at
// its own constant velocity, x(s) = (1 - s) x0 + s x1 with s = (t - t0) / T, and the level set
// is the blend of the two (levelset/signed_distance.h, BlendedDistance).
//
// The cloth sees the mesh's moving vertices as an obstacle of its self-collision (per-vertex
// start position and velocity: contact/cloth_obstacles.h) so that the body's edges and
// corners cannot pass through the cloth, the level set in its contacts, and the surface's own
// velocity for friction: the velocity of the mesh vertex nearest the contact point. Rigid
// bodies meet the level set in their collisions and contacts, and the same surface velocity
// (rigid/impulse_stage.h, point_velocity).
#pragma once

#include "levelset/signed_distance.h"
#include "math/types.h"

#include <vector>

namespace simbake {

class DeformingSurface {
 public:
  // The first frame: the surface still at `vertices` (n x 3, world, m), with its level set
  // `shape` (world coordinates)
  DeformingSurface(const Points& vertices, SignedDistancePtr shape, double time);
  // The next frame: from where the last one ended (at `time`, s) to `vertices` and `shape`
  // over `duration` (s > 0); the vertices keep their count
  void set_frame(const Points& vertices, SignedDistancePtr shape, double time, double duration);

  int vertex_count() const { return static_cast<int>(end_.rows()); }
  // where in the frame time t (s) is: 0 at its start, 1 at its end (clamped)
  double blend(double time) const;
  Vec3 vertex(int k, double s) const { return ((1.0 - s) * start_.row(k) + s * end_.row(k)).transpose(); }
  Vec3 vertex_velocity(int k) const { return velocity_.row(k).transpose(); }  // (m/s)
  // the velocity of the surface near world point p: its nearest vertex's (m/s)
  Vec3 velocity_at(const Vec3& p) const;
  // the level set at blend s (a new object: shared with whoever holds it)
  SignedDistancePtr shape_at(double s) const;
  // the farthest any vertex is from `center` over the frame (m)
  double reach(const Vec3& center) const;
  // the fastest of the vertices whose line over the frame may meet `box` (its bounding box
  // does) (m/s), 0 if none
  double fastest_in(const Box3& box) const;
  // the affine field v = A x + c nearest (least squares over the vertices, at blend s) to the
  // vertices' velocities: the motion of the cloth's impact zones that hold the surface's
  // vertices (cloth/self_collision.h, ObstacleMotion); exact for a surface that swells, turns
  // and moves as a whole
  void affine_motion(double s, Mat3& A, Vec3& c) const;

 private:
  Points start_, end_;                  // (n x 3) world (m) at the frame's start and end
  Points velocity_;                     // (n x 3) (end - start) / duration (m/s)
  SignedDistancePtr start_shape_, end_shape_;
  double start_time_ = 0.0, duration_ = 0.0;  // (s)
  // the vertices at the frame's end binned on a grid of cells of `cell_` (m), the cell of x at
  // floor(x / cell_) (whole multiples), from cell corner_ on, extent_ cells a side: cell c's
  // vertices are cell_vertex_[cell_start_[c] .. cell_start_[c + 1]) (velocity_at's search)
  double cell_ = 1.0;
  Eigen::Vector3i corner_ = Eigen::Vector3i::Zero(), extent_ = Eigen::Vector3i::Ones();
  std::vector<int> cell_start_, cell_vertex_;
  Eigen::Vector3i cell_of(const Vec3& p) const;
  void bin();
};

}  // namespace simbake
