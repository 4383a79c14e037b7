// simbake._core: a thin layer over the C++ core. Converts numpy arrays to Eigen and back,
// releases the GIL while the world steps, and turns C++ exceptions into Python ones
// (std::invalid_argument -> ValueError, std::runtime_error -> RuntimeError). No physics here.
// Every index and number a method takes is checked here before it reaches the core (which
// trusts its callers): a bad index is IndexError, a bad number ValueError, never a crash.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "checked_triangles.h"  // before any use of Triangles: its own caster (checked)
#include "geometry/mass_properties.h"
#include "geometry/mesh.h"
#include "geometry/triangle_intersection.h"
#include "levelset/vdb_levelset.h"
#include "world/quality.h"
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

// The enum value named by `name`, or ValueError listing the choices
template <class Enum>
Enum choose(const std::string& name, std::initializer_list<std::pair<const char*, Enum>> choices) {
  std::string names;
  for (const auto& [key, value] : choices) {
    if (name == key) return value;
    names += std::string(names.empty() ? "" : ", ") + key;
  }
  throw std::invalid_argument("unknown choice '" + name + "' (choose " + names + ")");
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "simbake C++ core: meshes, level sets, rigid-body world";
  m.attr("__version__") = SIMBAKE_VERSION;

  // geometry
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
  m.def("is_closed", [](const Points& v, const Triangles& t) { return is_closed(to_mesh(v, t)); },
        py::arg("vertices"), py::arg("triangles"));
  m.def("mass_properties", [](const Points& v, const Triangles& t) { return mass_dict(mass_properties(to_mesh(v, t))); },
        py::arg("vertices"), py::arg("triangles"));
  m.def("sphere_mass_properties", [](double r) { return mass_dict(sphere_mass_properties(positive(r, "radius"))); }, py::arg("radius"));
  m.def("box_mass_properties", [](const Vec3& s) { return mass_dict(box_mass_properties(positive(s, "size"))); }, py::arg("size"));

  // level sets
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

  // the world
  py::class_<World>(m, "World")
      .def(py::init([](const Vec3& gravity, int collision_sweeps, int contact_sweeps, double max_substep,
                       double travel_fraction, int max_substeps, int threads, double cloth_max_substep,
                       bool speculative_contacts, double contact_tolerance, bool box_contacts, int shock_sweeps,
                       bool cloth_contacts_in_solve) {
             WorldSettings s;
             s.gravity = gravity;
             s.collision_sweeps = collision_sweeps;
             s.contact_sweeps = contact_sweeps;
             s.max_substep = max_substep;
             s.travel_fraction = travel_fraction;
             s.max_substeps = max_substeps;
             s.threads = threads;
             s.cloth_max_substep = positive(cloth_max_substep, "cloth_max_substep");
             s.speculative_contacts = speculative_contacts;
             s.box_contacts = box_contacts;
             if (shock_sweeps < 0) throw std::invalid_argument("shock_sweeps must be >= 0");
             s.shock_sweeps = shock_sweeps;
             s.cloth_contacts_in_solve = cloth_contacts_in_solve;
             s.contact_tolerance = positive(contact_tolerance, "contact_tolerance");
             positive(max_substep, "max_substep");
             positive(travel_fraction, "travel_fraction");
             return World(s);
           }),
           py::arg("gravity") = WorldSettings().gravity,
           py::arg("collision_sweeps") = WorldSettings().collision_sweeps,
           py::arg("contact_sweeps") = WorldSettings().contact_sweeps,
           py::arg("max_substep") = WorldSettings().max_substep,
           py::arg("travel_fraction") = WorldSettings().travel_fraction,
           py::arg("max_substeps") = WorldSettings().max_substeps,
           py::arg("threads") = WorldSettings().threads,
           py::arg("cloth_max_substep") = WorldSettings().cloth_max_substep,
           py::arg("speculative_contacts") = WorldSettings().speculative_contacts,
           py::arg("contact_tolerance") = WorldSettings().contact_tolerance,
           py::arg("box_contacts") = WorldSettings().box_contacts,
           py::arg("shock_sweeps") = WorldSettings().shock_sweeps,
           py::arg("cloth_contacts_in_solve") = WorldSettings().cloth_contacts_in_solve)
      .def("set_ground", [](World& w, double height, double friction, double restitution) {
             w.set_ground(GroundDef{height, friction, restitution});
           }, py::arg("height") = 0.0, py::arg("friction") = 0.5, py::arg("restitution") = 0.0)
      .def("add_body", [](World& w, const LevelSet* shape, const Points& samples, const py::dict& mass_properties,
                          double mass, const Vec3& origin, const Eigen::Vector4d& orientation,
                          const Vec3& linear_velocity, const Vec3& angular_velocity, double friction,
                          double restitution, bool kinematic, const std::optional<Points>& mesh_vertices,
                          const std::optional<Triangles>& mesh_triangles) {
             BodyDesc d;
             if (shape) d.shape = shape->distance;
             d.samples = samples;
             if (mesh_vertices.has_value() != mesh_triangles.has_value()) {
               throw std::invalid_argument("give both mesh_vertices and mesh_triangles, or neither");
             }
             if (mesh_vertices) {
               to_mesh(*mesh_vertices, *mesh_triangles);
               d.mesh_vertices = *mesh_vertices;
               d.mesh_triangles = *mesh_triangles;
             }
             d.unit_mass = mass_from_dict(mass_properties);
             d.mass = mass;
             d.origin = origin;
             d.orientation = quat_wxyz(orientation);
             d.linear_velocity = linear_velocity;
             d.angular_velocity = angular_velocity;
             d.friction = friction;
             d.restitution = restitution;
             d.kinematic = kinematic;
             return w.add_body(d);
           },
           py::arg("shape"), py::arg("samples"), py::arg("mass_properties"), py::arg("mass"),
           py::arg("origin"), py::arg("orientation"), py::arg("linear_velocity") = Vec3::Zero(),
           py::arg("angular_velocity") = Vec3::Zero(), py::arg("friction") = 0.5,
           py::arg("restitution") = 0.0, py::arg("kinematic") = false,
           py::arg("mesh_vertices") = py::none(), py::arg("mesh_triangles") = py::none(),
           "mesh_vertices (n, 3) and mesh_triangles (m, 3): the closed mesh a baked level-set shape was "
           "made from, whose sharp edges and corners are then held out of cloth triangles")
      .def("add_cloth", [](World& w, const Points& rest, const Triangles& triangles, double area_density,
                           const std::string& model, double stretch_stiffness, double poisson_ratio,
                           double bend_stiffness, double damping, double strain_limit, const std::string& compression,
                           const std::vector<int>& pinned, const std::string& integrator, double friction,
                           double thickness, double tolerance, bool self_collision, const std::string& preconditioner) {
             ClothDesc d;
             d.rest = rest;
             d.triangles = triangles;
             d.area_density = area_density;
             d.material.model = choose<InPlaneModel>(model, {{"springs", InPlaneModel::kSprings}, {"membrane", InPlaneModel::kMembrane}});
             d.material.stretch_stiffness = stretch_stiffness;
             d.material.poisson_ratio = poisson_ratio;
             d.material.bend_stiffness = bend_stiffness;
             d.material.damping = damping;
             d.material.strain_limit = strain_limit;
             d.material.compression = choose<CompressionMode>(compression, {{"subgrid", CompressionMode::kSubgrid},
                                                                            {"enforce", CompressionMode::kEnforce},
                                                                            {"none", CompressionMode::kNone}});
             d.pinned = pinned;
             d.integrator = choose<ClothIntegrator>(integrator, {{"implicit", ClothIntegrator::kImplicit}, {"explicit", ClothIntegrator::kExplicit}});
             d.tolerance = tolerance;
             d.preconditioner = choose<ClothPreconditioner>(preconditioner, {{"automatic", ClothPreconditioner::kAutomatic},
                                                                             {"block_jacobi", ClothPreconditioner::kBlockJacobi},
                                                                             {"multigrid", ClothPreconditioner::kMultigrid}});
             return w.add_cloth(d, friction, thickness, self_collision);
           },
           py::arg("rest"), py::arg("triangles"), py::arg("area_density") = 0.1, py::arg("model") = "springs",
           py::arg("stretch_stiffness") = 1000.0, py::arg("poisson_ratio") = 0.3, py::arg("bend_stiffness") = 1e-4,
           py::arg("damping") = 0.01, py::arg("strain_limit") = 0.1, py::arg("compression") = "subgrid",
           py::arg("pinned") = std::vector<int>(), py::arg("integrator") = "implicit", py::arg("friction") = 0.3,
           py::arg("thickness") = 0.005, py::arg("tolerance") = ClothDesc().tolerance,
           py::arg("self_collision") = true, py::arg("preconditioner") = "automatic")
      .def_property_readonly("cloth_count", &World::cloth_count)
      .def("cloth_state", [](const World& w, long long i) {
             const Cloth& c = w.cloth(checked_index(i, w.cloth_count(), "cloth"));
             return py::make_tuple(c.positions(), c.velocities(), c.vertex_normals());
           }, py::arg("index"), "Positions (n, 3), velocities (n, 3) and vertex normals (n, 3) of cloth i")
      .def("cloth_max_strain", [](const World& w, long long i) {
             return w.cloth(checked_index(i, w.cloth_count(), "cloth")).max_strain();
           }, py::arg("index"))
      .def("set_kinematic_track", [](World& w, long long index, const std::vector<double>& times, const Points& origins,
                                      const Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>& orientations) {
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
           "Keyed kinematic body: mesh-origin positions (n, 3) and orientations (n, 4) [w, x, y, z] at times (s)")
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
           }, py::arg("frame_dt"))
      .def_property_readonly("body_count", &World::body_count)
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
      .def("body_state", [](const World& w, long long index) {
             const int i = checked_index(index, w.body_count(), "body");
             const RigidBodyState& s = w.body_state(i);
             py::dict d;
             d["center_of_mass"] = s.x;
             d["orientation"] = Eigen::Vector4d(s.q.w(), s.q.x(), s.q.y(), s.q.z());
             d["linear_velocity"] = s.v;
             d["angular_momentum"] = s.l;
             d["angular_velocity"] = angular_velocity(w.body_def(i), s);
             return d;
           }, py::arg("index"))
      .def("asleep", [](const World& w, long long i) { return w.asleep(checked_index(i, w.body_count(), "body")); },
           py::arg("index"))
      .def_property_readonly("sleeping_count", &World::sleeping_count)
      .def_property_readonly("time", &World::time)
      .def("statistics", [](const World& w) {
             const StepStatistics& s = w.statistics();
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
           })
      .def("quality", [](const World& w) {
             FrameQuality q;
             {
               py::gil_scoped_release release;
               q = measure_quality(w);
             }
             const auto figure = [](const PenetrationFigure& p) {
               return py::make_tuple(p.depth, p.a, p.b);
             };
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
           }, "Quality figures of the current state (world/quality.h): penetrations as (depth m, inside, "
              "into; -1 = none or the ground), per cloth its largest strain and self-intersections")
      .def("profile", [](const World& w) {
             const StageProfile& p = w.profile();
             py::dict d;
             d["broad_phase"] = p.broad_phase;
             d["collisions"] = p.collisions;
             d["velocities"] = p.velocities;
             d["contacts"] = p.contacts;
             d["shock_propagation"] = p.shock_propagation;
             d["positions"] = p.positions;
             d["sleeping"] = p.sleeping;
             d["cloths"] = p.cloths;
             d["cloth_forces"] = p.cloth_forces;
             d["cloth_contacts"] = p.cloth_contacts;
             d["cloth_strain"] = p.cloth_strain;
             d["cloth_self_collision"] = p.cloth_self_collision;
             d["statistics"] = p.statistics;
             return d;
           });
}
