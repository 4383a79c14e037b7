// simbake._core: a thin layer over the C++ core. Converts numpy arrays to Eigen and back,
// releases the GIL while the world steps, and turns C++ exceptions into Python ones
// (std::invalid_argument -> ValueError, std::runtime_error -> RuntimeError). No physics here.
// Every index and number a method takes is checked here or by the core before it is used: a
// bad index is IndexError, a bad number ValueError, never a crash. The settings and the
// descriptions of bodies and cloths are the core's structs, constructed by keyword: their C++
// defaults are the only defaults (pipeline/simbake/_core.pyi lists them for readers).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <string>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "checked_triangles.h"  // before any use of Triangles: its own caster (checked)
#include "geometry/closed_mesh.h"
#include "math/threads.h"
#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "geometry/triangle_intersection.h"
#include "levelset/vdb_levelset.h"
#include "world/quality.h"
#include "world/stages.h"
#include "world/world.h"

namespace py = pybind11;
using namespace simbake;

namespace {

using Quats = Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>;  // (n x 4) [w, x, y, z]

// A signed distance handle for Python; `grid` is set when it is an OpenVDB level set
struct LevelSet {
  SignedDistancePtr distance;
  std::shared_ptr<VdbLevelSet> grid;
};

TriangleMesh to_mesh(const Points& vertices, const Triangles& triangles) {
  if (triangles.size() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= vertices.rows())) {
    throw std::invalid_argument("triangle index out of range");
  }
  return TriangleMesh{vertices, triangles};
}

py::tuple mesh_tuple(const TriangleMesh& mesh) { return py::make_tuple(mesh.vertices, mesh.triangles); }

py::dict mass_dict(const MassProperties& m) {
  py::dict d;
  d["volume"] = m.volume;
  d["center"] = m.center;
  d["inertia"] = m.inertia;
  return d;
}

MassProperties mass_from_dict(const py::dict& d) {
  MassProperties m;
  m.volume = d["volume"].cast<double>();
  m.center = d["center"].cast<Vec3>();
  m.inertia = d["inertia"].cast<Mat3>();
  return m;
}

// `i` as an index into `count` items (negative indices are not Python-style here), or IndexError
int checked_index(long long i, int count, const char* what) {
  if (i < 0 || i >= count) {
    throw py::index_error(std::string(what) + " index " + std::to_string(i) + " out of range (there are " +
                          std::to_string(count) + ")");
  }
  return static_cast<int>(i);
}

// `x` when it is finite and > 0, or ValueError naming it
double positive(double x, const char* name) {
  if (!(x > 0.0 && std::isfinite(x))) {
    char shown[32];
    std::snprintf(shown, sizeof shown, "%g", x);
    throw std::invalid_argument(std::string(name) + " must be a finite number > 0, got " + shown);
  }
  return x;
}

const Vec3& positive(const Vec3& v, const char* name) {
  for (int k = 0; k < 3; ++k) positive(v[k], name);
  return v;
}

Quat quat_wxyz(const Eigen::Vector4d& q) { return Quat(q[0], q[1], q[2], q[3]); }

// An enum's names (the strings Python passes and reads), e.g. kModels
template <class Enum>
using Names = std::initializer_list<std::pair<const char*, Enum>>;

const Names<InPlaneModel> kModels = {{"springs", InPlaneModel::kSprings}, {"membrane", InPlaneModel::kMembrane}};
const Names<CompressionMode> kCompressions = {
    {"subgrid", CompressionMode::kSubgrid}, {"enforce", CompressionMode::kEnforce}, {"none", CompressionMode::kNone}};
const Names<JointType> kJointTypes = {{"fixed", JointType::kFixed},         {"revolute", JointType::kRevolute},
                                      {"prismatic", JointType::kPrismatic}, {"spherical", JointType::kSpherical},
                                      {"distance", JointType::kDistance},   {"d6", JointType::kD6}};
const Names<int> kAxes = {{"x", 0}, {"y", 1}, {"z", 2}};
const Names<int> kDofs = {{"trans_x", kTransX}, {"trans_y", kTransY}, {"trans_z", kTransZ},
                          {"rot_x", kRotX},     {"rot_y", kRotY},     {"rot_z", kRotZ}};
const Names<ClothIntegrator> kIntegrators = {{"implicit", ClothIntegrator::kImplicit}, {"explicit", ClothIntegrator::kExplicit}};
const Names<ClothPreconditioner> kPreconditioners = {{"automatic", ClothPreconditioner::kAutomatic},
                                                     {"block_jacobi", ClothPreconditioner::kBlockJacobi},
                                                     {"multigrid", ClothPreconditioner::kMultigrid}};

// The enum value named by `name`, or ValueError listing the choices
template <class Enum>
Enum choose(const std::string& name, Names<Enum> choices) {
  std::string names;
  for (const auto& [key, value] : choices) {
    if (name == key) return value;
    names += std::string(names.empty() ? "" : ", ") + key;
  }
  throw std::invalid_argument("unknown choice '" + name + "' (choose " + names + ")");
}

template <class Enum>
std::string name_of(Enum value, Names<Enum> choices) {
  for (const auto& [key, choice] : choices) {
    if (choice == value) return key;
  }
  return "";
}

// A struct field bound as a string property: `field(object)` is the enum it reads and writes
template <class T, class Field, class Enum>
void enum_field(py::class_<T>& cls, const char* name, Field field, Names<Enum> choices) {
  cls.def_property(name, [field, choices](T& self) { return name_of(field(self), choices); },
                   [field, choices](T& self, const std::string& value) { field(self) = choose(value, choices); });
}

// The fields of a bound struct: its properties, in the order they were bound
std::vector<std::string> field_names(const py::handle& type) {
  const py::object property = py::module_::import("builtins").attr("property");
  std::vector<std::string> names;
  // (a type's __dict__ is a mapping proxy, in definition order)
  for (const py::handle item : type.attr("__dict__").attr("items")()) {
    const py::tuple entry = py::reinterpret_borrow<py::tuple>(item);
    if (py::isinstance(entry[1], property)) names.push_back(py::str(entry[0]));
  }
  return names;
}

// T() with the keyword arguments set as its fields, so that every field not given keeps its
// C++ default; TypeError for a name that is not a field
template <class T>
T from_keywords(const py::kwargs& kwargs) {
  T value;
  const py::object self = py::cast(&value, py::return_value_policy::reference);
  const std::vector<std::string> fields = field_names(py::type::of(self));
  for (const auto& [key, field] : kwargs) {
    const std::string name = py::str(key);
    if (std::find(fields.begin(), fields.end(), name) == fields.end()) {
      throw py::type_error(py::str(py::type::of(self).attr("__name__")).cast<std::string>() + " has no field '" + name + "'");
    }
    py::setattr(self, name.c_str(), field);
  }
  return value;
}

// Binds T's keyword constructor and a repr of its fields
template <class T>
void keyword_struct(py::class_<T>& cls) {
  cls.def(py::init([](const py::kwargs& kwargs) { return from_keywords<T>(kwargs); }));
  cls.def("__repr__", [](const py::object& self) {
    std::string text = py::str(py::type::of(self).attr("__name__"));
    const char* separator = "(";
    for (const std::string& name : field_names(py::type::of(self))) {
      text += separator + name + "=" + py::repr(self.attr(name.c_str())).cast<std::string>();
      separator = ", ";
    }
    return text + ")";
  });
}

// The description given, or one made from its fields (not both)
template <class T>
T given_or_from_keywords(const std::optional<T>& given, const py::kwargs& kwargs, const char* what) {
  if (given && !kwargs.empty()) throw py::type_error(std::string("give ") + what + " or its fields, not both");
  return given ? *given : from_keywords<T>(kwargs);
}

}  // namespace


namespace {

void bind_geometry(py::module_& m) {
  m.def("sphere_mesh", [](double r, int s) { return mesh_tuple(make_sphere_mesh(positive(r, "radius"), s)); },
        py::arg("radius"), py::arg("subdivisions"));
  m.def("box_mesh", [](const Vec3& size, int s) { return mesh_tuple(make_box_mesh(positive(size, "size"), s)); },
        py::arg("size"), py::arg("subdivisions"));
  m.def("vertex_normals", [](const Points& v, const Triangles& t) { return vertex_normals(to_mesh(v, t)); },
        py::arg("vertices"), py::arg("triangles"));
  m.def("surface_samples", [](const Points& v, const Triangles& t, double spacing) {
          // no edge is longer than the box's diagonal: bound the pieces any edge is cut into
          const double diagonal = v.rows() ? (v.colwise().maxCoeff() - v.colwise().minCoeff()).norm() : 0.0;
          if (!(diagonal / positive(spacing, "max_spacing") < 1e6)) {
            throw std::invalid_argument("max_spacing is too small for this mesh (over 1e6 samples per edge)");
          }
          return surface_samples(to_mesh(v, t), spacing);
        }, py::arg("vertices"), py::arg("triangles"), py::arg("max_spacing"),
        "Vertices plus points along every edge longer than max_spacing");
  m.def("intersecting_triangle_pairs", [](const Points& v, const Triangles& t) {
          to_mesh(v, t);
          std::vector<std::pair<int, int>> pairs;
          {
            py::gil_scoped_release release;
            pairs = intersecting_triangle_pairs(v, t, kPairTestBudget);  // length_error past it
          }
          Eigen::Matrix<std::int32_t, Eigen::Dynamic, 2, Eigen::RowMajor> out(pairs.size(), 2);
          for (size_t k = 0; k < pairs.size(); ++k) out.row(k) << pairs[k].first, pairs[k].second;
          return out;
        }, py::arg("vertices"), py::arg("triangles"),
        "Pairs (k, 2), sorted, of triangles that share no vertex and cross each other");
  m.def("closed_mesh_depth", [](const Points& v, const Triangles& t, const Points& points, const Edges& edges, int threads) {
          py::gil_scoped_release release;
          const ClosedMesh mesh(v, t);  // out_of_range (IndexError) for a vertex it does not have
          const ClosedMeshDepth depth = on_threads(threads, [&] { return closed_mesh_depth(mesh, points, edges); });
          return std::make_pair(depth.vertex, depth.edge);
        }, py::arg("vertices"), py::arg("triangles"), py::arg("points"), py::arg("edges"), py::arg("threads") = 0,
        "(deepest point, deepest edge eighth) inside the closed mesh: distance to its surface (0: none inside), "
        "on at most `threads` CPUs (0: all)");
  m.def("is_closed", [](const Points& v, const Triangles& t) { return is_closed(to_mesh(v, t)); },
        py::arg("vertices"), py::arg("triangles"));
  m.def("mass_properties", [](const Points& v, const Triangles& t) { return mass_dict(mass_properties(to_mesh(v, t))); },
        py::arg("vertices"), py::arg("triangles"));
  m.def("sphere_mass_properties", [](double r) { return mass_dict(sphere_mass_properties(positive(r, "radius"))); }, py::arg("radius"));
  m.def("box_mass_properties", [](const Vec3& s) { return mass_dict(box_mass_properties(positive(s, "size"))); }, py::arg("size"));

}

void bind_level_sets(py::module_& m) {
  py::class_<LevelSet>(m, "LevelSet")
      .def_static("sphere", [](double r) { return LevelSet{std::make_shared<SphereDistance>(positive(r, "radius")), nullptr}; })
      .def_static("box", [](const Vec3& size) { return LevelSet{std::make_shared<BoxDistance>(positive(size, "size")), nullptr}; })
      .def_static("bake", [](const Points& v, const Triangles& t, double voxel_size) {
            to_mesh(v, t);
            std::shared_ptr<VdbLevelSet> grid;
            {
              py::gil_scoped_release release;
              grid = VdbLevelSet::bake(v, t, voxel_size);
            }
            return LevelSet{grid, grid};
          }, py::arg("vertices"), py::arg("triangles"), py::arg("voxel_size"))
      .def_static("bake_shell", [](const Points& v, const Triangles& t, double voxel_size, double thickness) {
            to_mesh(v, t);
            std::shared_ptr<VdbLevelSet> grid;
            {
              py::gil_scoped_release release;
              grid = VdbLevelSet::bake_shell(v, t, voxel_size, thickness);
            }
            return LevelSet{grid, grid};
          }, py::arg("vertices"), py::arg("triangles"), py::arg("voxel_size"), py::arg("thickness"),
          "Any triangle soup (open, non-manifold) as a two-sided shell: phi = |d| - thickness (m)")
      .def_static("read", [](const std::string& path) {
            auto grid = VdbLevelSet::read(path);
            return LevelSet{grid, grid};
          }, py::arg("path"))
      .def("write", [](const LevelSet& ls, const std::string& path, const std::map<std::string, std::string>& metadata) {
            if (!ls.grid) throw std::invalid_argument("only baked level sets are written to .vdb");
            ls.grid->write(path, metadata);
          }, py::arg("path"), py::arg("metadata") = std::map<std::string, std::string>(),
          "Write to a .vdb file, with `metadata` (str -> str) stored in the grid")
      .def_property_readonly("metadata", [](const LevelSet& ls) {
            return ls.grid ? ls.grid->metadata() : std::map<std::string, std::string>();
          }, "The grid's string metadata (empty for analytic shapes)")
      .def("phi", [](const LevelSet& ls, const Points& p) {
            Eigen::VectorXd out(p.rows());
            for (Eigen::Index i = 0; i < p.rows(); ++i) out[i] = ls.distance->phi(p.row(i).transpose());
            return out;
          }, py::arg("points"))
      .def("normals", [](const LevelSet& ls, const Points& p) {
            Points out(p.rows(), 3);
            for (Eigen::Index i = 0; i < p.rows(); ++i) {
              Vec3 n;
              ls.distance->phi_and_normal(p.row(i).transpose(), n);
              out.row(i) = n.transpose();
            }
            return out;
          }, py::arg("points"))
      .def_property_readonly("bounds", [](const LevelSet& ls) {
            const Box3 b = ls.distance->bounds();
            return py::make_tuple(Vec3(b.min()), Vec3(b.max()));
          })
      .def_property_readonly("voxel_size", [](const LevelSet& ls) { return ls.grid ? ls.grid->voxel_size() : 0.0; })
      .def_property_readonly("active_voxel_count", [](const LevelSet& ls) { return ls.grid ? ls.grid->active_voxel_count() : 0; })
      .def_property_readonly("memory_bytes", [](const LevelSet& ls) { return ls.grid ? ls.grid->memory_bytes() : 0; });
}

void bind_settings(py::module_& m) {
  py::class_<WorldSettings> settings(m, "WorldSettings", "The world's settings (world/world_settings.h), by keyword");
  settings.def_readwrite("gravity", &WorldSettings::gravity)
      .def_readwrite("collision_sweeps", &WorldSettings::collision_sweeps)
      .def_readwrite("contact_sweeps", &WorldSettings::contact_sweeps)
      .def_readwrite("shock_sweeps", &WorldSettings::shock_sweeps)
      .def_readwrite("sleep_speed", &WorldSettings::sleep_speed)
      .def_readwrite("sleep_time", &WorldSettings::sleep_time)
      .def_readwrite("penetration_slop", &WorldSettings::penetration_slop)
      .def_readwrite("penetration_recovery", &WorldSettings::penetration_recovery)
      .def_readwrite("max_recovery_speed", &WorldSettings::max_recovery_speed)
      .def_readwrite("contact_tolerance", &WorldSettings::contact_tolerance)
      .def_readwrite("speculative_contacts", &WorldSettings::speculative_contacts)
      .def_readwrite("box_contacts", &WorldSettings::box_contacts)
      .def_readwrite("max_substep", &WorldSettings::max_substep)
      .def_readwrite("cloth_contact_substep", &WorldSettings::cloth_contact_substep)
      .def_readwrite("bounce_substep", &WorldSettings::bounce_substep)
      .def_readwrite("cloth_contacts_in_solve", &WorldSettings::cloth_contacts_in_solve)
      .def_readwrite("cloth_max_substep", &WorldSettings::cloth_max_substep)
      .def_readwrite("travel_fraction", &WorldSettings::travel_fraction)
      .def_readwrite("joint_turn", &WorldSettings::joint_turn)
      .def_readwrite("max_substeps", &WorldSettings::max_substeps)
      .def_readwrite("threads", &WorldSettings::threads);
  keyword_struct(settings);
  m.attr("MAX_THREADS") = kMaxThreads;

  py::class_<GroundDef> ground(m, "GroundDef", "The ground plane y = height (rigid/rigid_model.h), by keyword");
  ground.def_readwrite("height", &GroundDef::height)
      .def_readwrite("friction", &GroundDef::friction)
      .def_readwrite("restitution", &GroundDef::restitution);
  keyword_struct(ground);
}

void bind_body_desc(py::module_& m) {
  py::class_<BodyDesc> body(m, "BodyDesc", "A rigid body's description (rigid/rigid_model.h), by keyword");
  body.def_property("shape",
                    [](const BodyDesc& d) -> std::optional<LevelSet> {
                      if (!d.shape) return std::nullopt;
                      return LevelSet{d.shape, std::const_pointer_cast<VdbLevelSet>(std::dynamic_pointer_cast<const VdbLevelSet>(d.shape))};
                    },
                    [](BodyDesc& d, const LevelSet* shape) { d.shape = shape ? shape->distance : nullptr; },
                    "level set in mesh coordinates, or None when nothing can touch the body")
      .def_readwrite("samples", &BodyDesc::samples, "(s, 3) surface samples, mesh coordinates (m)")
      .def_readwrite("mesh_vertices", &BodyDesc::mesh_vertices, "(n, 3) the closed mesh the level set was baked from")
      .def_readwrite("mesh_triangles", &BodyDesc::mesh_triangles, "(m, 3) its triangles")
      .def_property("mass_properties", [](const BodyDesc& d) { return mass_dict(d.unit_mass); },
                    [](BodyDesc& d, const py::dict& props) { d.unit_mass = mass_from_dict(props); },
                    "the shape's at density 1: {volume, center, inertia}")
      .def_readwrite("mass", &BodyDesc::mass, "(kg); ignored for kinematic bodies")
      .def_readwrite("origin", &BodyDesc::origin, "world position of the mesh origin (m)")
      .def_property("orientation",
                    [](const BodyDesc& d) {
                      return Eigen::Vector4d(d.orientation.w(), d.orientation.x(), d.orientation.y(), d.orientation.z());
                    },
                    [](BodyDesc& d, const Eigen::Vector4d& q) { d.orientation = quat_wxyz(q); },
                    "mesh orientation in world [w, x, y, z]")
      .def_readwrite("linear_velocity", &BodyDesc::linear_velocity, "of the centre of mass (m/s)")
      .def_readwrite("angular_velocity", &BodyDesc::angular_velocity, "world (rad/s)")
      .def_readwrite("friction", &BodyDesc::friction)
      .def_readwrite("restitution", &BodyDesc::restitution)
      .def_readwrite("kinematic", &BodyDesc::kinematic);
  keyword_struct(body);
}

void bind_cloth_desc(py::module_& m) {
  py::class_<ClothDesc> cloth(m, "ClothDesc", "A cloth's description (cloth/cloth_model.h), by keyword");
  const auto material = [](const char* name, double ClothMaterial::*field) {
    return std::make_tuple(name, field);
  };
  cloth.def_readwrite("rest", &ClothDesc::rest, "(n, 3) rest positions = initial positions (m)")
      .def_readwrite("triangles", &ClothDesc::triangles, "(m, 3)")
      .def_readwrite("area_density", &ClothDesc::area_density, "(kg/m^2)");
  enum_field(cloth, "model", [](ClothDesc& d) -> InPlaneModel& { return d.material.model; }, kModels);
  for (const auto& [name, field] : {material("stretch_stiffness", &ClothMaterial::stretch_stiffness),
                                    material("poisson_ratio", &ClothMaterial::poisson_ratio),
                                    material("bend_stiffness", &ClothMaterial::bend_stiffness),
                                    material("damping", &ClothMaterial::damping),
                                    material("strain_limit", &ClothMaterial::strain_limit),
                                    material("subgrid_scale", &ClothMaterial::subgrid_scale)}) {
    cloth.def_property(name, [field = field](const ClothDesc& d) { return d.material.*field; },
                       [field = field](ClothDesc& d, double value) { d.material.*field = value; });
  }
  enum_field(cloth, "compression", [](ClothDesc& d) -> CompressionMode& { return d.material.compression; }, kCompressions);
  cloth.def_readwrite("pinned", &ClothDesc::pinned, "vertices held fixed")
      .def_readwrite("attached", &ClothDesc::attached,
                     "vertices attached to a body's surface (World.attach_cloth), carried with it");
  enum_field(cloth, "integrator", [](ClothDesc& d) -> ClothIntegrator& { return d.integrator; }, kIntegrators);
  cloth.def_readwrite("tolerance", &ClothDesc::tolerance, "implicit: the linear solve's relative residual");
  enum_field(cloth, "preconditioner", [](ClothDesc& d) -> ClothPreconditioner& { return d.preconditioner; },
             kPreconditioners);
  cloth.def_readwrite("friction", &ClothDesc::friction, "Coulomb coefficient against bodies and the ground")
      .def_readwrite("thickness", &ClothDesc::thickness, "(m) kept from bodies, the ground and itself")
      .def_readwrite("self_collision", &ClothDesc::self_collision);
  keyword_struct(cloth);
}

// Every body's state now, one array per quantity (n = body count)
py::dict body_states(const World& w) {
  const RigidData& data = w.rigid_data();
  const int n = w.body_count();
  Points x(n, 3), v(n, 3), l(n, 3), omega(n, 3);
  Quats q(n, 4);
  Eigen::Array<bool, Eigen::Dynamic, 1> asleep(n);
  for (int i = 0; i < n; ++i) {
    x.row(i) = data.x[i].transpose();
    v.row(i) = data.v[i].transpose();
    l.row(i) = data.l[i].transpose();
    q.row(i) << data.q[i].w(), data.q[i].x(), data.q[i].y(), data.q[i].z();
    omega.row(i) = angular_velocity(w.body_def(i), data.q[i], data.l[i]).transpose();
    asleep[i] = data.asleep[i] != 0;
  }
  py::dict d;
  d["center_of_mass"] = x;
  d["orientation"] = q;
  d["linear_velocity"] = v;
  d["angular_momentum"] = l;
  d["angular_velocity"] = omega;
  d["asleep"] = asleep;
  return d;
}

py::dict statistics_dict(const StepStatistics& s) {
  py::dict d;
  d["substeps"] = s.substeps;
  d["cloth_steps"] = s.cloth_steps;
  d["max_penetration"] = s.max_penetration;
  d["kinetic_energy"] = s.kinetic_energy;
  d["potential_energy"] = s.potential_energy;
  d["impulses"] = s.impulses;
  d["finite"] = s.finite;
  d["elastic_energy"] = s.elastic_energy;
  d["cloth_penetration"] = s.cloth_penetration;
  d["max_cloth_strain"] = s.max_cloth_strain;
  d["cloth_solver_iterations"] = s.cloth_solver_iterations;
  d["cloth_solver_seconds"] = s.cloth_solver_seconds;
  d["self_repulsions"] = s.self_collision.repulsions;
  d["self_collision_impulses"] = s.self_collision.collisions;
  d["impact_zone_rounds"] = s.self_collision.zone_rounds;
  d["impact_zone_vertices"] = s.self_collision.zone_vertices;
  d["cloth_held_still"] = s.self_collision.stills;
  d["self_collision_searches"] = s.self_collision.searches;
  d["self_collision_candidates"] = s.self_collision.candidates;
  d["self_collision_updates"] = s.self_collision.updates;
  d["self_collision_tests"] = s.self_collision.tests;
  d["self_collision_near_pairs"] = s.self_collision.near_pairs;
  d["self_collision_over_budget"] = s.self_collision.over_budget;
  d["impact_zone_yields"] = s.self_collision.yields;
  d["cloth_let_in"] = s.self_collision.let_in;
  d["cloth_gave"] = s.cloth_gave;
  d["self_collision_candidate_peak"] = s.self_collision.candidate_peak;
  d["self_collision_pass_peak"] = s.self_collision.pass_peak;
  d["impact_zone_round_peak"] = s.self_collision.zone_round_peak;
  return d;
}

py::dict quality_dict(const FrameQuality& q) {
  const auto figure = [](const PenetrationFigure& p) { return py::make_tuple(p.depth, p.a, p.b); };
  py::dict d;
  d["body_penetration"] = figure(q.body_penetration);
  py::list cloths;
  for (const ClothQuality& c : q.cloths) {
    py::dict cd;
    cd["max_strain"] = c.max_strain;
    cd["self_intersections"] = c.self_intersections;
    cd["vertex_penetration"] = figure(c.vertex_penetration);
    cd["edge_penetration"] = figure(c.edge_penetration);
    cloths.append(cd);
  }
  d["cloths"] = cloths;
  return d;
}

// A joint's description and its drives (rigid/joint_model.h)
void bind_joint_desc(py::module_& m) {
  py::class_<JointDrive> drive(m, "JointDrive", "A joint drive (rigid/joint_model.h), by keyword");
  keyword_struct(drive);
  drive.def_readwrite("stiffness", &JointDrive::stiffness, "(N/m or N m/rad; acceleration drives: 1/s^2)")
      .def_readwrite("damping", &JointDrive::damping, "(N s/m or N m s/rad; acceleration drives: 1/s)")
      .def_readwrite("target_position", &JointDrive::target_position, "(m or rad)")
      .def_readwrite("target_velocity", &JointDrive::target_velocity, "(m/s or rad/s)")
      .def_readwrite("max_force", &JointDrive::max_force, "(N or N m)")
      .def_readwrite("acceleration", &JointDrive::acceleration, "false: a force drive");
  py::class_<JointDesc> joint(m, "JointDesc", "A joint's description (rigid/joint_model.h), by keyword");
  keyword_struct(joint);
  enum_field(joint, "type", [](JointDesc& d) -> JointType& { return d.type; }, kJointTypes);
  joint.def_readwrite("body0", &JointDesc::body0, "body index, or -1: the world")
      .def_readwrite("body1", &JointDesc::body1, "body index, or -1: the world")
      .def_readwrite("local_position0", &JointDesc::local_position0, "joint frame in body 0's mesh frame (m)")
      .def_property("local_rotation0", [](const JointDesc& d) {
             return Eigen::Vector4d(d.local_rotation0.w(), d.local_rotation0.x(), d.local_rotation0.y(), d.local_rotation0.z());
           }, [](JointDesc& d, const Eigen::Vector4d& q) { d.local_rotation0 = quat_wxyz(q); }, "[w, x, y, z]")
      .def_readwrite("local_position1", &JointDesc::local_position1, "joint frame in body 1's mesh frame (m)")
      .def_property("local_rotation1", [](const JointDesc& d) {
             return Eigen::Vector4d(d.local_rotation1.w(), d.local_rotation1.x(), d.local_rotation1.y(), d.local_rotation1.z());
           }, [](JointDesc& d, const Eigen::Vector4d& q) { d.local_rotation1 = quat_wxyz(q); }, "[w, x, y, z]");
  enum_field(joint, "axis", [](JointDesc& d) -> int& { return d.axis; }, kAxes);
  joint.def_readwrite("lower_limit", &JointDesc::lower_limit, "revolute (rad), prismatic (m)")
      .def_readwrite("upper_limit", &JointDesc::upper_limit)
      .def_readwrite("cone_angle0", &JointDesc::cone_angle0, "spherical (rad)")
      .def_readwrite("cone_angle1", &JointDesc::cone_angle1)
      .def_readwrite("min_distance", &JointDesc::min_distance, "distance (m)")
      .def_readwrite("max_distance", &JointDesc::max_distance)
      .def_readwrite("dof_lower", &JointDesc::dof_lower, "d6: trans_x .. rot_z (m, rad); lower > upper locks")
      .def_readwrite("dof_upper", &JointDesc::dof_upper)
      .def_property("drives", [](const JointDesc& d) {
             py::dict out;
             for (const auto& [name, dof] : kDofs) {
               if (d.drives[dof].enabled) out[name] = d.drives[dof];
             }
             return out;
           }, [](JointDesc& d, const std::map<std::string, JointDrive>& drives) {
             d.drives = {};
             for (const auto& [name, drive] : drives) {
               d.drives[choose(name, kDofs)] = drive;
               d.drives[choose(name, kDofs)].enabled = true;
             }
           }, "{trans_x .. rot_z: JointDrive}")
      .def_readwrite("break_force", &JointDesc::break_force, "(N)")
      .def_readwrite("break_torque", &JointDesc::break_torque, "(N m)")
      .def_readwrite("enabled", &JointDesc::enabled)
      .def_readwrite("collision_enabled", &JointDesc::collision_enabled);
}

// The joints' state as arrays: enabled (n,), broke_at (n,) (s, NaN while whole), gap (n,) (m),
// angle (n,) (rad), force (n, 3) (N), torque (n, 3) (N m)
py::dict joint_states(const World& w) {
  const int n = w.joint_count();
  Eigen::Array<bool, Eigen::Dynamic, 1> enabled(n);
  Eigen::VectorXd broke(n), gap(n), angle(n);
  Points force(n, 3), torque(n, 3);
  for (int j = 0; j < n; ++j) {
    enabled[j] = w.joint_state().enabled[j] != 0;
    broke[j] = w.joint_state().broke_at[j];
    const JointError e = w.joint_error(j);
    gap[j] = e.gap;
    angle[j] = e.angle;
    force.row(j) = w.joint_state().force[j].transpose();
    torque.row(j) = w.joint_state().torque[j].transpose();
  }
  py::dict d;
  d["enabled"] = enabled;
  d["broke_at"] = broke;
  d["gap"] = gap;
  d["angle"] = angle;
  d["force"] = force;
  d["torque"] = torque;
  return d;
}

// Building a world: its settings, ground, bodies (and their keys) and cloths
void bind_world_building(py::class_<World>& world) {
  world
      .def(py::init([](const std::optional<WorldSettings>& settings, const py::kwargs& kwargs) {
             return World(given_or_from_keywords(settings, kwargs, "settings"));
           }),
           py::arg("settings") = py::none(), "World(settings) or World(**WorldSettings fields)")
      .def_property_readonly("settings", [](const World& w) { return WorldSettings(w.settings()); },
                             "a copy of the world's settings")
      .def("set_ground", [](World& w, const std::optional<GroundDef>& ground, const py::kwargs& kwargs) {
             w.set_ground(given_or_from_keywords(ground, kwargs, "ground"));
           }, py::arg("ground") = py::none(), "set_ground(GroundDef) or set_ground(**GroundDef fields)")
      .def("add_body", [](World& w, const std::optional<BodyDesc>& given, const py::kwargs& kwargs) {
             const BodyDesc desc = given_or_from_keywords(given, kwargs, "desc");
             if ((desc.mesh_vertices.rows() > 0) != (desc.mesh_triangles.rows() > 0)) {
               throw std::invalid_argument("give both mesh_vertices and mesh_triangles, or neither");
             }
             return w.add_body(desc);
           }, py::arg("desc") = py::none(),
           "add_body(BodyDesc) or add_body(**BodyDesc fields): the body's index. mesh_vertices and "
           "mesh_triangles: the closed mesh a baked level-set shape was made from, whose sharp edges and "
           "corners are then held out of cloth triangles")
      .def("add_joint", [](World& w, const std::optional<JointDesc>& given, const py::kwargs& kwargs) {
             const JointDesc desc = given_or_from_keywords(given, kwargs, "desc");
             for (int body : {desc.body0, desc.body1}) {
               if (body != kWorldBody) checked_index(body, w.body_count(), "body");
             }
             return w.add_joint(desc);
           }, py::arg("desc") = py::none(), "add_joint(JointDesc) or add_joint(**JointDesc fields): the joint's index")
      .def("filter_pair", [](World& w, long long a, long long b) {
             w.filter_pair(checked_index(a, w.body_count(), "body"), checked_index(b, w.body_count(), "body"));
           }, py::arg("a"), py::arg("b"), "Bodies a and b never collide")
      .def("set_collision_groups", &World::set_collision_groups, py::arg("members"), py::arg("filters"),
           "Collision groups: members[g] the bodies of group g, filters[g] the groups it does not collide with")
      .def("add_cloth", [](World& w, const std::optional<ClothDesc>& given, const py::kwargs& kwargs) {
             return w.add_cloth(given_or_from_keywords(given, kwargs, "desc"));
           }, py::arg("desc") = py::none(), "add_cloth(ClothDesc) or add_cloth(**ClothDesc fields): the cloth's index")
      .def("attach_cloth", [](World& w, long long cloth, long long body) {
             w.attach_cloth(checked_index(cloth, w.cloth_count(), "cloth"), checked_index(body, w.body_count(), "body"));
           }, py::arg("cloth"), py::arg("body"),
           "Cloth i's attached vertices bound where they are now to body b's nearest surface point and carried with "
           "it (a deforming body's surface set first); a dynamic body takes the reaction")
      .def("set_deforming_frame", [](World& w, long long index, const Points& vertices, const LevelSet& level_set,
                                      double frame_dt) {
             w.set_deforming_frame(checked_index(index, w.body_count(), "body"), vertices, level_set.distance,
                                   positive(frame_dt, "frame_dt"));
           }, py::arg("index"), py::arg("vertices"), py::arg("level_set"), py::arg("frame_dt"),
           "Deforming kinematic body (mesh pose the identity): its surface at the end of the next frame of frame_dt s, "
           "its mesh's vertices (n, 3) in world coordinates and their level set; the first call places it, still")
      .def("set_kinematic_track", [](World& w, long long index, const std::vector<double>& times, const Points& origins,
                                      const Quats& orientations) {
             if (origins.rows() != static_cast<Eigen::Index>(times.size()) || orientations.rows() != origins.rows()) {
               throw std::invalid_argument("keys need one position and one orientation per time");
             }
             const int i = checked_index(index, w.body_count(), "body");
             std::vector<Vec3> o;
             std::vector<Quat> q;
             for (Eigen::Index k = 0; k < origins.rows(); ++k) {
               o.emplace_back(origins.row(k).transpose());
               q.push_back(quat_wxyz(orientations.row(k).transpose()));
             }
             w.set_kinematic_track(i, KinematicTrack(times, o, q));
           }, py::arg("index"), py::arg("times"), py::arg("positions"), py::arg("orientations"),
           "Keyed kinematic body: mesh-origin positions (n, 3) and orientations (n, 4) [w, x, y, z] at times (s)");
}

// Stepping a world
void bind_world_stepping(py::class_<World>& world) {
  world
      .def("step_frame", [](World& w, double frame_dt, int substeps) {
             positive(frame_dt, "frame_dt");
             if (substeps < 0) throw std::invalid_argument("substeps must be >= 0 (0 = automatic), got " + std::to_string(substeps));
             // Signals while the frame steps: between substeps, at most every 50 ms, the GIL is
             // taken back and Python's signal handlers run (PyErr_CheckSignals); one that raises
             // (Ctrl-C's KeyboardInterrupt, the CLI's SIGTERM) stops the frame there and is
             // raised here, so a signal ends a frame of thousands of substeps within 50 ms and a
             // substep. Only time is looked at otherwise: the state is the same bits
             using Clock = std::chrono::steady_clock;
             constexpr auto kSignalPeriod = std::chrono::milliseconds(50);
             Clock::time_point next = Clock::now() + kSignalPeriod;
             bool raised = false;
             const auto stop = [&] {
               if (Clock::now() < next) return false;
               py::gil_scoped_acquire acquire;
               raised = PyErr_CheckSignals() != 0;  // (the exception stays set until raised below)
               next = Clock::now() + kSignalPeriod;
               return raised;
             };
             int taken;
             {
               py::gil_scoped_release release;
               taken = w.step_frame(frame_dt, substeps, stop);
             }
             if (raised) throw py::error_already_set();
             return taken;
           }, py::arg("frame_dt"), py::arg("substeps") = 0,
           "Steps one frame (substeps 0: automatic); returns the substeps taken. A Python signal "
           "handler that raises during the frame (KeyboardInterrupt) stops it part-way and is raised")
      .def("step", [](World& w, double dt) {
             positive(dt, "dt");
             py::gil_scoped_release release;
             w.step(dt);
           }, py::arg("dt"))
      .def("automatic_substeps", [](const World& w, double frame_dt) {
             return w.automatic_substeps(positive(frame_dt, "frame_dt"));
           }, py::arg("frame_dt"))
      .def("automatic_cloth_steps", [](const World& w, double frame_dt) {
             return w.automatic_cloth_steps(positive(frame_dt, "frame_dt"));
           }, py::arg("frame_dt"));
}

// Reading a world's state and figures
void bind_world_reading(py::class_<World>& world) {
  world.def_property_readonly("body_count", &World::body_count)
      .def_property_readonly("cloth_count", &World::cloth_count)
      .def_property_readonly("joint_count", &World::joint_count)
      .def("joint_states", &joint_states,
           "Every joint now: enabled (n,), broke_at (n,) (s, NaN while whole), gap (n,) (m) and angle (n,) "
           "(rad) between its frames, force (n, 3) (N) and torque (n, 3) (N m) on body 1 over the last step")
      .def_property_readonly("sleeping_count", &World::sleeping_count)
      .def_property_readonly("time", &World::time)
      .def("body_states", &body_states,
           "Every body's state now, one array each: center_of_mass (n, 3), orientation (n, 4) [w, x, y, z] "
           "of the principal frame, linear_velocity (n, 3), angular_momentum (n, 3), angular_velocity (n, 3), "
           "asleep (n,)")
      .def("linear_velocities", [](const World& w) {
             Points v(w.body_count(), 3);
             for (int i = 0; i < w.body_count(); ++i) v.row(i) = w.rigid_data().v[i].transpose();
             return v;
           }, "Every body's linear velocity now (n, 3) (m/s): body_states' without the rest")
      .def("mesh_poses", [](const World& w) {
             Points translations(w.body_count(), 3);
             Quats orientations(w.body_count(), 4);
             for (int i = 0; i < w.body_count(); ++i) {
               const Pose pose = w.body_mesh_pose(i);
               translations.row(i) = pose.translation.transpose();
               const Quat q(pose.rotation);
               orientations.row(i) << q.w(), q.x(), q.y(), q.z();
             }
             return py::make_tuple(translations, orientations);
           }, "World pose of each body's mesh origin: translations (n, 3), orientations (n, 4) [w, x, y, z]")
      .def("asleep", [](const World& w, long long i) { return w.asleep(checked_index(i, w.body_count(), "body")); },
           py::arg("index"))
      .def("cloth_state", [](const World& w, long long i) {
             const Cloth& c = w.cloth(checked_index(i, w.cloth_count(), "cloth"));
             return py::make_tuple(c.positions(), c.velocities(), c.vertex_normals());
           }, py::arg("index"), "Positions (n, 3), velocities (n, 3) and vertex normals (n, 3) of cloth i")
      .def("cloth_max_strain", [](const World& w, long long i) {
             return w.cloth(checked_index(i, w.cloth_count(), "cloth")).max_strain();
           }, py::arg("index"))
      .def("statistics", [](const World& w, bool penetrations) { return statistics_dict(w.statistics(penetrations)); },
           py::arg("penetrations") = true, "The world's statistics; penetrations=False leaves the penetration figures NaN")
      .def("quality", [](const World& w) {
             FrameQuality q;
             {
               py::gil_scoped_release release;
               q = measure_quality(w);
             }
             return quality_dict(q);
           }, "Quality figures of the current state (world/quality.h): penetrations as (depth m, inside, "
              "into; -1 = none or the ground), per cloth its largest strain and self-intersections")
      .def("profile", [](const World& w) {
             py::dict d;
             for (int k = 0; k < kStageCount; ++k) d[kStageNames[k]] = w.profile().seconds[k];
             return d;
           }, "Wall seconds spent in each stage since the world was built (world/stages.h)");
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "simbake C++ core: meshes, level sets, rigid bodies and cloths in a world";
  m.attr("__version__") = SIMBAKE_VERSION;
  bind_geometry(m);
  bind_level_sets(m);
  bind_settings(m);
  bind_body_desc(m);
  bind_cloth_desc(m);
  bind_joint_desc(m);
  py::class_<World> world(m, "World");
  bind_world_building(world);
  bind_world_stepping(world);
  bind_world_reading(world);
  py::class_<QualityMeter>(m, "QualityMeter",
                           "World.quality() frame after frame, measuring only what can have changed "
                           "(world/quality.h): the same figures, bit for bit")
      .def(py::init<>())
      .def("measure", [](QualityMeter& meter, const World& w) {
             FrameQuality q;
             {
               py::gil_scoped_release release;
               q = meter.measure(w);
             }
             return quality_dict(q);
           }, py::arg("world"));
}
