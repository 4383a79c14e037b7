// A closed triangle mesh baked into an OpenVDB FloatGrid signed distance field (or any
// triangle soup into a two-sided shell of a given thickness, bake_shell).
//
// This is the only header of the core that knows OpenVDB exists (the grid lives behind a
// pimpl). The grid is a narrow band outside the surface and filled all the way through the
// interior, so a point anywhere inside the body gets a valid (negative) distance: rigid
// collisions query sample points deep inside other bodies. Outside the band phi is clamped to
// the band width; the normal there falls back to the direction from the grid's centre.
#pragma once

#include "levelset/signed_distance.h"

#include <map>
#include <memory>
#include <string>

namespace simbake {

class VdbLevelSet final : public SignedDistance {
 public:
  // Bake a closed mesh (vertices (n x 3) in metres, triangles (m x 3)) at voxel size h (m).
  // exterior_band: width of the band outside the surface, in voxels (>= 3).
  static std::shared_ptr<VdbLevelSet> bake(const Points& vertices, const Triangles& triangles,
                                           double voxel_size, int exterior_band = 3);
  // Bake any triangle soup (open, non-manifold, self-intersecting: a single-quad ground) as a
  // two-sided shell: phi = |d| - thickness, d the unsigned distance to the nearest triangle
  // (m). Negative only within `thickness` of the surface; thickness >= voxel_size so that
  // the trilinear interpolant of |d| (off by up to h/2 at the surface) stays negative there.
  static std::shared_ptr<VdbLevelSet> bake_shell(const Points& vertices, const Triangles& triangles,
                                                 double voxel_size, double thickness,
                                                 int exterior_band = 3);
  // Read the first FloatGrid of a .vdb file written by write() (or any level-set .vdb)
  static std::shared_ptr<VdbLevelSet> read(const std::string& path);
  // Write the grid (named "surface", class level set) to a .vdb file any OpenVDB reader opens,
  // with `metadata` added to the grid's own (string values; e.g. what the grid was baked from)
  void write(const std::string& path, const std::map<std::string, std::string>& metadata = {}) const;
  // The grid's string metadata (what write() was given, or another writer's)
  std::map<std::string, std::string> metadata() const;

  ~VdbLevelSet() override;

  // trilinear interpolation of phi (m)
  double phi(const Vec3& p) const override;
  // trilinear phi and the normalized gradient of the trilinear interpolant
  double phi_and_normal(const Vec3& p, Vec3& normal) const override;
  // of the trilinear interpolant: in a cell its gradient is the blend, by the trilinear
  // weights, of its gradients at the corners (each the three differences along the corner's
  // edges), so at most the steepest corner's over the voxel size; over every cell that has a
  // voxel of the tree's leaves as a corner (tiles are constant and meet only tiles of their
  // own sign; found on the first call)
  double lipschitz() const override;
  // box containing the zero level set (the active voxels shrunk by the band less one voxel)
  Box3 bounds() const override;
  double exterior_reach() const override;

  double voxel_size() const;
  std::size_t active_voxel_count() const;
  std::size_t memory_bytes() const;

 private:
  struct Impl;
  explicit VdbLevelSet(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace simbake
