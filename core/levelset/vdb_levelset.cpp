// VdbLevelSet: a closed mesh baked into an OpenVDB FloatGrid signed distance field.
//
// Design:
// - Band: `exterior_band` voxels outside the surface (active voxels with phi < band * h);
//   beyond it the grid returns its background, +band * h. Callers only need exact values
//   near and inside the surface, so a thin exterior band keeps the grid small.
// - Filled interior: the interior band is half the mesh's largest extent (in voxels) + 2,
//   deeper than any interior point can be, so every voxel inside the body holds a real
//   negative distance. Rigid collisions query sample points deep inside other bodies.
// - Queries: trilinear interpolation of the 8 voxel values around the point; the normal is
//   the exact gradient of that trilinear interpolant, normalized. Where the gradient
//   vanishes (outside the band every corner holds the background), the normal falls back to
//   the direction from the centre of the active bounding box to p (+y at the centre).
// - Thread safety: the grid is immutable after bake/read; each query builds its own
//   *unsafe* (unregistered) ValueAccessor on the stack. The default "safe"
//   FloatGrid::ConstAccessor registers itself in the tree's concurrent hash map on
//   construction (a heap allocation and a shared lock per query); registration only serves
//   to clear caches when the tree is modified, which never happens here.
#include "levelset/vdb_levelset.h"

#include <openvdb/openvdb.h>
#include <openvdb/tools/ChangeBackground.h>
#include <openvdb/tools/Interpolation.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <mutex>
#include <stdexcept>
#include <vector>

namespace simbake {

namespace {

using openvdb::Coord;
using openvdb::FloatGrid;
using openvdb::FloatTree;
// unregistered accessor: no allocation, no lock (see the file comment)
using QueryAccessor = openvdb::tree::ValueAccessor<const FloatTree, /*IsSafe=*/false>;

// gradient magnitude (dimensionless for a distance field, ~1 in the band) below which the
// trilinear gradient is treated as zero and the fallback normal is used
constexpr double kMinGradient = 1e-6;

const char* const kGridName = "surface";

void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// 8 corner values around world point p and the fractional position inside that cell
struct Cell {
  float v[2][2][2];  // v[i][j][k]: corner (x0 + i, y0 + j, z0 + k)
  double u, w, t;    // fractional coordinates along x, y, z in [0, 1)
};

inline Cell fetch_cell(const FloatTree& tree, const openvdb::math::Transform& xform,
                       const Vec3& p) {
  const openvdb::Vec3d x = xform.worldToIndex(openvdb::Vec3d(p.x(), p.y(), p.z()));
  const openvdb::Vec3d f(std::floor(x[0]), std::floor(x[1]), std::floor(x[2]));
  Cell c;
  c.u = x[0] - f[0];
  c.w = x[1] - f[1];
  c.t = x[2] - f[2];
  const Coord low = Coord::floor(f);
  QueryAccessor acc(tree);
  // a cell inside one leaf (most: 7 of its 8 rows of cells a side) is read from the leaf's
  // values directly, its corners at offsets +64 (x), +8 (y), +1 (z); the same floats as the
  // accessor's eight lookups, which the other cells keep
  if (((low.x() & 7) != 7) && ((low.y() & 7) != 7) && ((low.z() & 7) != 7)) {
    if (const auto* leaf = acc.probeConstLeaf(low)) {
      const openvdb::Index at = FloatTree::LeafNodeType::coordToOffset(low);
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j)
          for (int k = 0; k < 2; ++k) c.v[i][j][k] = leaf->getValue(at + 64 * i + 8 * j + k);
      return c;
    }
  }
  openvdb::tools::BoxSampler::getValues(c.v, acc, low);
  return c;
}

inline double lerp(double a, double b, double s) { return a + s * (b - a); }

// trilinear interpolant at the cell's fractional position
inline double interpolate(const Cell& c) {
  const double x00 = lerp(c.v[0][0][0], c.v[1][0][0], c.u);
  const double x10 = lerp(c.v[0][1][0], c.v[1][1][0], c.u);
  const double x01 = lerp(c.v[0][0][1], c.v[1][0][1], c.u);
  const double x11 = lerp(c.v[0][1][1], c.v[1][1][1], c.u);
  return lerp(lerp(x00, x10, c.w), lerp(x01, x11, c.w), c.t);
}

}  // namespace

struct VdbLevelSet::Impl {
  FloatGrid::ConstPtr grid;
  const FloatTree* tree = nullptr;
  const openvdb::math::Transform* xform = nullptr;
  const openvdb::math::MapBase* map = nullptr;  // xform's (held by it: baseMap() copies a shared_ptr)
  Box3 active_box;  // world box of the active voxel centres
  Vec3 centre;      // its centre: origin of the fallback normal
  double band = 0;  // background value: the exterior band width (m)
  std::once_flag lipschitz_once;
  double lipschitz = 0.0;

  explicit Impl(FloatGrid::ConstPtr g) : grid(std::move(g)) {
    tree = &grid->tree();
    xform = &grid->transform();
    map = xform->baseMap().get();
    band = double(grid->background());
    // world box of the active voxels (all eight corners of the index box, for any linear map)
    const openvdb::CoordBBox ibox = grid->evalActiveVoxelBoundingBox();
    active_box.setEmpty();
    if (!ibox.empty()) {
      for (int corner = 0; corner < 8; ++corner) {
        const openvdb::Vec3d ijk((corner & 1 ? ibox.max() : ibox.min()).x(),
                                 (corner & 2 ? ibox.max() : ibox.min()).y(),
                                 (corner & 4 ? ibox.max() : ibox.min()).z());
        const openvdb::Vec3d w = xform->indexToWorld(ijk);
        active_box.extend(Vec3(w[0], w[1], w[2]));
      }
      centre = active_box.center();
    } else {
      centre = Vec3::Zero();
    }
  }
};

VdbLevelSet::VdbLevelSet(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
VdbLevelSet::~VdbLevelSet() = default;

namespace {

// The mesh checked and put in index space (voxel centres at integer coordinates)
struct IndexMesh {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  Vec3 lo, hi;  // bounding box (m)
};

IndexMesh index_mesh(const char* who, const Points& vertices, const Triangles& triangles,
                     double voxel_size, int exterior_band) {
  const std::string w(who);
  if (!(voxel_size > 0.0) || !std::isfinite(voxel_size))
    throw std::invalid_argument(w + ": voxel size must be a positive finite number");
  if (exterior_band < 3)
    throw std::invalid_argument(w + ": exterior band must be at least 3 voxels");
  if (vertices.rows() == 0 || triangles.rows() == 0)
    throw std::invalid_argument(w + ": empty mesh (no vertices or no triangles)");
  if (!vertices.allFinite())
    throw std::invalid_argument(w + ": vertex coordinates must be finite");
  const Eigen::Index n = vertices.rows();
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= n)
    throw std::invalid_argument(w + ": triangle vertex index out of range [0, " +
                                std::to_string(n) + ")");
  IndexMesh m;
  m.lo = vertices.colwise().minCoeff();
  m.hi = vertices.colwise().maxCoeff();
  if (std::max(m.lo.cwiseAbs().maxCoeff(), m.hi.cwiseAbs().maxCoeff()) / voxel_size > 1e7)
    throw std::invalid_argument(w + ": voxel size too small for the mesh extent");
  m.points.resize(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i)
    m.points[i] = openvdb::Vec3s(float(vertices(i, 0) / voxel_size),
                                 float(vertices(i, 1) / voxel_size),
                                 float(vertices(i, 2) / voxel_size));
  m.triangles.resize(static_cast<std::size_t>(triangles.rows()));
  for (Eigen::Index t = 0; t < triangles.rows(); ++t)
    m.triangles[t] = openvdb::Vec3I(openvdb::Index32(triangles(t, 0)), openvdb::Index32(triangles(t, 1)),
                                    openvdb::Index32(triangles(t, 2)));
  return m;
}

}  // namespace

std::shared_ptr<VdbLevelSet> VdbLevelSet::bake(const Points& vertices,
                                               const Triangles& triangles, double voxel_size,
                                               int exterior_band) {
  IndexMesh m = index_mesh("VdbLevelSet::bake", vertices, triangles, voxel_size, exterior_band);
  const Vec3 lo = m.lo, hi = m.hi;
  std::vector<openvdb::Vec3s>& points = m.points;
  std::vector<openvdb::Vec3I>& tris = m.triangles;

  initialize_openvdb();
  const openvdb::math::Transform::Ptr xform =
      openvdb::math::Transform::createLinearTransform(voxel_size);

  // signed distance with a thin exterior band and an interior band deeper than any
  // interior point (half the largest extent bounds the depth), so the interior is filled
  const float interior_band = float(0.5 * (hi - lo).maxCoeff() / voxel_size + 2.0);
  const openvdb::tools::QuadAndTriangleDataAdapter<openvdb::Vec3s, openvdb::Vec3I> mesh(
      points, tris);
  FloatGrid::Ptr grid = openvdb::tools::meshToVolume<FloatGrid>(mesh, *xform,
                                                                float(exterior_band), interior_band);
  grid->setName(kGridName);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  if (grid->activeVoxelCount() == 0)
    throw std::invalid_argument("VdbLevelSet::bake: the mesh produced no voxels (degenerate mesh?)");

  return std::shared_ptr<VdbLevelSet>(new VdbLevelSet(std::make_unique<Impl>(grid)));
}

std::shared_ptr<VdbLevelSet> VdbLevelSet::bake_shell(const Points& vertices,
                                                     const Triangles& triangles, double voxel_size,
                                                     double thickness, int exterior_band) {
  IndexMesh m = index_mesh("VdbLevelSet::bake_shell", vertices, triangles, voxel_size, exterior_band);
  if (!(thickness >= voxel_size) || !std::isfinite(thickness))
    throw std::invalid_argument("VdbLevelSet::bake_shell: thickness must be finite and at least the voxel size");

  initialize_openvdb();
  const openvdb::math::Transform::Ptr xform =
      openvdb::math::Transform::createLinearTransform(voxel_size);

  // unsigned distance |d| in a band of thickness + exterior_band voxels around every triangle
  const float band = float(thickness / voxel_size + exterior_band);
  const openvdb::tools::QuadAndTriangleDataAdapter<openvdb::Vec3s, openvdb::Vec3I> mesh(
      m.points, m.triangles);
  FloatGrid::Ptr grid = openvdb::tools::meshToVolume<FloatGrid>(
      mesh, *xform, band, band, openvdb::tools::UNSIGNED_DISTANCE_FIELD);
  if (grid->activeVoxelCount() == 0)
    throw std::invalid_argument("VdbLevelSet::bake_shell: the mesh produced no voxels (degenerate mesh?)");

  // phi = |d| - thickness, the background too: it stays exterior_band voxels outside the
  // zero level set, as for bake(), so bounds() and exterior_reach() hold unchanged
  const float t = float(thickness);
  for (auto it = grid->beginValueOn(); it; ++it) it.setValue(*it - t);
  openvdb::tools::changeBackground(grid->tree(), grid->background() - t);
  grid->setName(kGridName);
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  return std::shared_ptr<VdbLevelSet>(new VdbLevelSet(std::make_unique<Impl>(grid)));
}

std::shared_ptr<VdbLevelSet> VdbLevelSet::read(const std::string& path) {
  initialize_openvdb();
  // read every grid (no delayed loading: the grid must not depend on the file afterwards,
  // and lazy loading would mutate the tree during const queries); errors name the path
  openvdb::GridPtrVecPtr grids;
  try {
    openvdb::io::File file(path);
    file.open(/*delayLoad=*/false);
    grids = file.getGrids();
    file.close();
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read as a .vdb file (" + e.what() + ")");
  }
  // first FloatGrid in the file
  FloatGrid::Ptr grid;
  for (const openvdb::GridBase::Ptr& g : *grids) {
    grid = openvdb::gridPtrCast<FloatGrid>(g);
    if (grid) break;
  }
  if (!grid) throw std::runtime_error(path + ": no float grid in the file");
  return std::shared_ptr<VdbLevelSet>(new VdbLevelSet(std::make_unique<Impl>(grid)));
}

void VdbLevelSet::write(const std::string& path, const std::map<std::string, std::string>& metadata) const {
  // the tree is shared, not copied; only the metadata of the written copy differs
  FloatGrid::Ptr copy = openvdb::ConstPtrCast<FloatGrid>(impl_->grid)->copy();
  for (const auto& [key, value] : metadata) {
    copy->removeMeta(key);
    copy->insertMeta(key, openvdb::StringMetadata(value));
  }
  const openvdb::GridCPtrVec grids{copy};
  openvdb::io::File file(path);
  // blosc when this OpenVDB build has it (Debian's does), zip otherwise
  file.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK |
                      (openvdb::io::Archive::hasBloscCompression() ? openvdb::io::COMPRESS_BLOSC
                                                                   : openvdb::io::COMPRESS_ZIP));
  try {
    file.write(grids);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot write .vdb file (" + e.what() + ")");
  }
  file.close();
}

std::map<std::string, std::string> VdbLevelSet::metadata() const {
  std::map<std::string, std::string> out;
  for (auto it = impl_->grid->beginMeta(); it != impl_->grid->endMeta(); ++it) {
    if (it->second && it->second->typeName() == openvdb::StringMetadata::staticTypeName()) {
      out[it->first] = it->second->str();
    }
  }
  return out;
}

double VdbLevelSet::phi(const Vec3& p) const {
  return interpolate(fetch_cell(*impl_->tree, *impl_->xform, p));
}

double VdbLevelSet::lipschitz() const {
  std::call_once(impl_->lipschitz_once, [this] {
    // The cells with a voxel of a leaf as a corner are those whose low corner lies in the
    // leaf's 8^3 voxels grown by one below: 9^3 cells, whose corners are the 10^3 values from
    // one below the leaf's origin to one past its end. The leaf's own values are read from it,
    // the shell around them through the accessor (tiles, the background, other leaves)
    QueryAccessor acc(*impl_->tree);
    constexpr int kSide = FloatTree::LeafNodeType::DIM + 2;
    std::array<float, kSide * kSide * kSide> values;
    auto at = [](int x, int y, int z) { return (x * kSide + y) * kSide + z; };
    double steepest = 0.0;  // (index space: per voxel)
    for (auto leaf = impl_->tree->cbeginLeaf(); leaf; ++leaf) {
      const Coord below = leaf->origin() - Coord(1, 1, 1);
      for (int x = 0; x < kSide; ++x) {
        for (int y = 0; y < kSide; ++y) {
          for (int z = 0; z < kSide; ++z) {
            const bool own = x >= 1 && y >= 1 && z >= 1 && x < kSide - 1 && y < kSide - 1 && z < kSide - 1;
            values[at(x, y, z)] = own ? leaf->getValue(static_cast<openvdb::Index>(64 * (x - 1) + 8 * (y - 1) + (z - 1)))
                                      : acc.getValue(below + Coord(x, y, z));
          }
        }
      }
      for (int x = 0; x + 1 < kSide; ++x) {
        for (int y = 0; y + 1 < kSide; ++y) {
          for (int z = 0; z + 1 < kSide; ++z) {
            // the gradient at corner (i, j, k) is its three edges' differences, and anywhere
            // in the cell the corners' gradients blended by the trilinear weights
            for (int i = 0; i < 2; ++i) {
              for (int j = 0; j < 2; ++j) {
                for (int k = 0; k < 2; ++k) {
                  const double gx = static_cast<double>(values[at(x + 1, y + j, z + k)]) - values[at(x, y + j, z + k)];
                  const double gy = static_cast<double>(values[at(x + i, y + 1, z + k)]) - values[at(x + i, y, z + k)];
                  const double gz = static_cast<double>(values[at(x + i, y + j, z + 1)]) - values[at(x + i, y + j, z)];
                  steepest = std::max(steepest, std::sqrt(gx * gx + gy * gy + gz * gz));
                }
              }
            }
          }
        }
      }
    }
    impl_->lipschitz = std::max(1.0, steepest / voxel_size()) * (1.0 + 1e-6);
  });
  return impl_->lipschitz;
}

double VdbLevelSet::phi_and_normal(const Vec3& p, Vec3& normal) const {
  const Cell c = fetch_cell(*impl_->tree, *impl_->xform, p);
  const auto& v = c.v;
  // partial derivatives of the trilinear interpolant in index space
  const double gx = lerp(lerp(v[1][0][0] - v[0][0][0], v[1][1][0] - v[0][1][0], c.w),
                         lerp(v[1][0][1] - v[0][0][1], v[1][1][1] - v[0][1][1], c.w), c.t);
  const double gy = lerp(lerp(v[0][1][0] - v[0][0][0], v[1][1][0] - v[1][0][0], c.u),
                         lerp(v[0][1][1] - v[0][0][1], v[1][1][1] - v[1][0][1], c.u), c.t);
  const double gz = lerp(lerp(v[0][0][1] - v[0][0][0], v[1][0][1] - v[1][0][0], c.u),
                         lerp(v[0][1][1] - v[0][1][0], v[1][1][1] - v[1][1][0], c.u), c.w);
  // to world space (inverse Jacobian transpose; a plain 1/h for our uniform transforms)
  const openvdb::Vec3d g = impl_->map->applyIJT(openvdb::Vec3d(gx, gy, gz));
  const Vec3 grad(g[0], g[1], g[2]);
  const double len = grad.norm();
  if (len > kMinGradient) {
    normal = grad / len;
  } else {
    // flat region (outside the band): point away from the centre of the grid
    const Vec3 d = p - impl_->centre;
    const double dn = d.norm();
    normal = dn > 0.0 ? Vec3(d / dn) : Vec3::UnitY();
  }
  return interpolate(c);
}

Box3 VdbLevelSet::bounds() const {
  // The outermost active voxel centre lies between (band - 1) and band voxels outside the
  // surface, so shrinking by band - 1 voxels still contains the zero level set.
  if (impl_->active_box.isEmpty()) return impl_->active_box;
  const double shrink = std::max(0.0, impl_->band - voxel_size());
  Box3 b(impl_->active_box.min().array() + shrink, impl_->active_box.max().array() - shrink);
  if (b.isEmpty()) b = Box3(impl_->centre, impl_->centre);
  return b;
}

// (the grid's interpolant is exact while all eight corners of a cell lie in the band)
double VdbLevelSet::exterior_reach() const { return std::max(0.0, impl_->band - voxel_size()); }

double VdbLevelSet::voxel_size() const { return impl_->xform->voxelSize()[0]; }

std::size_t VdbLevelSet::active_voxel_count() const {
  return static_cast<std::size_t>(impl_->grid->activeVoxelCount());
}

std::size_t VdbLevelSet::memory_bytes() const {
  return static_cast<std::size_t>(impl_->grid->memUsage());
}

}  // namespace simbake
