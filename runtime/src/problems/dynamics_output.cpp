// What a dynamics run leaves on disk and reads back: the history of accepted steps, the time
// series (HDF5 + XDMF), and the checkpoint from which --restart continues.
#include <algorithm>
#include <cmath>
#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "dynamics_integrator.hpp"
#include "dynamics_reference.hpp"
#include "lmeform/output.hpp"
#include "membrane_topology.hpp"

namespace lmeform::problems {

namespace fs = std::filesystem;

// `measures`: those of `state` when the caller has them (an accepted step was just checked).
void DynamicsIntegrator::record(Vec state, double energy, int newton, int rejected, double dt_taken,
                                std::optional<DeformationMeasures> measures) {
  DynamicsStep s;
  s.step = step_;
  s.t_star = t_;
  s.dt_star = dt_taken;
  s.energy = energy;
  s.constraints = constraint_values(state);
  for (std::size_t i = 0; i < k_; ++i) s.multipliers.push_back(nu_[i] / ref_->space.constraints[i].scale);
  s.newton_iterations = newton;
  s.rejected = rejected;
  const DeformationMeasures m = measures ? *measures : measures_of(state);
  s.min_jacobian = m.min_jacobian;
  s.distortion = m.max_distortion;
  s.resets = run_.resets;
  s.wall_s = clock_.seconds();
  s.topology = topology_;
  run_.history.push_back(s);
  if (out_ == nullptr) return;
  std::string drift;
  for (std::size_t i = 0; i < k_; ++i)
    drift += fmt::format("  {} {:+.1e}", ref_->space.constraints[i].name,
                         (s.constraints[i] - start_constraints_[i]) / std::max(std::abs(start_constraints_[i]), 1e-300));
  *out_ << fmt::format("step {:5d}  t* {:.4e}  dt* {:.3e}  E {:.8f}  Newton {:2d}  rejected {}  resets {}{}  det F {:.3f}  {:.1f} s{}", s.step,
                       s.t_star, s.dt_star, s.energy, newton, rejected, run_.resets, drift, s.min_jacobian, s.wall_s,
                       s.topology ? "  membrane: " + s.topology->shapes() : std::string())
        << std::endl;
}

void DynamicsIntegrator::write_series(Vec state) {
  if (output_ == nullptr) return;
  // Every rank holds the gathered state and writes its block of rows (collective HDF5).
  const std::vector<double> y = to_original(*ref_->space.disc, state, bs_);
  const auto d = std::size_t(dim_);
  std::vector<double> positions(n_nodes_ * d), displacement(n_nodes_ * d), v(n_nodes_ * d);
  for (std::size_t a = 0; a < n_nodes_; ++a)
    for (std::size_t i = 0; i < d; ++i) {
      const std::size_t s = a * std::size_t(bs_) + std::size_t(offset_) + i;
      positions[a * d + i] = y[s];
      displacement[a * d + i] = y[s] - material_nodes_.point(a)[i];
      v[a * d + i] = velocity_[s];
    }
  FieldViews fields;
  fields.emplace("displacement", FieldView{displacement, dim_});
  fields.emplace("velocity", FieldView{v, dim_});
  for (const auto& [name, values] : scalar_fields_) fields.emplace(name, FieldView{values, 1});
  const ReplicatedShare share(comm_, n_nodes_, fields);
  series_->write(comm_, t_, step_, NodeSet(dim_, positions), run_.cells, share.part(),
                 {{"t_star", t_}, {"step", static_cast<std::int64_t>(step_)}, {"energy", run_.history.back().energy}});
}

nlohmann::json DynamicsIntegrator::history_json() const {
  nlohmann::json js;
  js["scene"] = scene_.name;
  js["method"] = euler_ ? "forward_euler" : "vti";
  js["time_unit"] = settings_.time_unit;
  js["constraints"] = run_.constraint_names;
  js["steps"] = nlohmann::json::array();
  for (const auto& s : run_.history)
    js["steps"].push_back({{"step", s.step},
                           {"t_star", s.t_star},
                           {"dt_star", s.dt_star},
                           {"energy", json_number(s.energy)},
                           {"constraints", s.constraints},
                           {"multipliers", s.multipliers},
                           {"newton_iterations", s.newton_iterations},
                           {"rejected", s.rejected},
                           {"min_jacobian", json_number(s.min_jacobian)},
                           {"distortion", json_number(s.distortion)},
                           {"resets", s.resets},
                           {"wall_s", s.wall_s},
                           {"topology", s.topology ? topology_json(*s.topology) : nlohmann::json()}});
  js["series"] = nlohmann::json::array();
  for (const auto& s : series_ ? series_->steps() : std::vector<TimeSeriesStep>{})
    js["series"].push_back({{"time", s.time}, {"file", s.h5_file.generic_string()}, {"nodes", s.nodes}, {"cells", s.cells}});
  return js;
}

// The state, the counters and the constraint targets, and, once the reference configuration has
// changed, its quadrature (points, weights) with the field jets: what a restart continues from.
void DynamicsIntegrator::write_checkpoint() {
  if (output_ == nullptr) return;
  const std::vector<double> y = to_original(*ref_->space.disc, ref_->u, bs_);
  const auto count = [](int v) { return static_cast<std::int64_t>(v); };
  OutputAttributes attributes{{"step", count(step_)},
                              {"t_star", t_},
                              {"dt_star", dt_},
                              {"target_decrement", target_decrement_},
                              {"accepted", count(run_.accepted)},
                              {"rejected", count(run_.rejected)},
                              {"gradient_evaluations", count(run_.gradient_evaluations)},
                              {"hessian_evaluations", count(run_.hessian_evaluations)},
                              {"resets", count(run_.resets)},
                              {"steps_since_reset", count(steps_since_reset_)},
                              {"remeshes", count(run_.remeshes)},
                              {"steps_since_remesh", count(steps_since_remesh_)},
                              {"scene", scene_.source}};
  for (std::size_t i = 0; i < run_.remesh_changes.size(); ++i) attributes.emplace(fmt::format("remesh_change_{}", i), run_.remesh_changes[i]);
  for (std::size_t i = 0; i < k_; ++i) {
    attributes.emplace(fmt::format("multiplier_{}", i), nu_[i]);
    attributes.emplace(fmt::format("target_{}", i), targets_[i]);
  }
  if (run_.resets > 0 || run_.remeshes > 0) {
    // The quadrature as a point set (no cells) with its weights and jets as point data, every
    // point in the numbering of a carried quadrature (the ranks hold their cells' points).
    const Discretization& disc = *ref_->space.disc;
    const CarriedQuadrature quad = every_point_quadrature(disc, run_.cells);
    std::map<std::string, std::vector<double>, std::less<>> qdata;
    for (const auto& [name, values] : ref_->space.qdata) {
      long size = disc.quadrature().size() > 0 ? long(values.size() / disc.quadrature().size()) : 0;
      MPI_Allreduce(MPI_IN_PLACE, &size, 1, MPI_LONG, MPI_MAX, comm_);
      qdata[name] = every_point_values(disc, values, std::size_t(size));
    }
    FieldViews qfields;
    qfields.emplace("weight", FieldView{quad.quadrature.weights, 1});
    for (const auto& [name, values] : qdata) qfields.emplace("qdata_" + name, FieldView{values, static_cast<int>(values.size() / quad.quadrature.size())});
    BackgroundCells none;
    none.dim = dim_;
    none.vertices_per_cell = dim_ + 1;
    const ReplicatedShare quadrature_share(comm_, quad.quadrature.size(), qfields);
    write_field_hdf5(comm_, quadrature_path_, NodeSet(dim_, quad.quadrature.points), none, quadrature_share.part(),
                     {{"step", count(step_)}, {"points_per_cell", static_cast<std::int64_t>(quad.quadrature.points_per_cell)}});
  }
  if (rank_ == 0) write_text_atomically(history_path_, history_json().dump(1) + "\n");
  // After a re-mesh the material nodes, their triangulation and the projected nodal fields are new.
  FieldViews fields{{"state", FieldView{y, bs_}}, {"velocity", FieldView{velocity_, bs_}}, {"material_nodes", FieldView{material_nodes_.coords, dim_}}};
  for (const auto& [name, values] : scalar_fields_) fields.emplace("field_" + name, FieldView{values, 1});
  const ReplicatedShare share(comm_, n_nodes_, fields);
  write_field_hdf5(comm_, checkpoint_path_, ref_->nodes, run_.cells, share.part(), attributes);
}

namespace {

/// A checkpoint file with its path, for messages about what it lacks.
struct Checkpoint {
  fs::path path;
  FieldFile file;
  [[nodiscard]] const OutputAttribute& attribute(const std::string& name) const {
    const auto it = file.attributes.find(name);
    if (it == file.attributes.end()) throw std::runtime_error(fmt::format("--restart: {} has no attribute '{}'", path.string(), name));
    return it->second;
  }
  [[nodiscard]] int integer(const std::string& name) const { return static_cast<int>(std::get<std::int64_t>(attribute(name))); }
  [[nodiscard]] double number(const std::string& name) const { return std::get<double>(attribute(name)); }
  /// Counts absent from checkpoints written before they were stored take `fallback`.
  [[nodiscard]] int integer_or(const std::string& name, int fallback) const {
    const auto it = file.attributes.find(name);
    return it == file.attributes.end() ? fallback : static_cast<int>(std::get<std::int64_t>(it->second));
  }
  [[nodiscard]] const std::vector<double>& field(const std::string& name) const {
    const auto it = file.fields.find(name);
    if (it == file.fields.end()) throw std::runtime_error(fmt::format("--restart: {} has no field '{}'", path.string(), name));
    return it->second.values;
  }
};

}  // namespace

void DynamicsIntegrator::read_history(const fs::path& path) {
  std::ifstream in(path);
  const nlohmann::json js = nlohmann::json::parse(in);
  auto number_or_nan = [](const nlohmann::json& v) { return v.is_null() ? std::nan("") : v.get<double>(); };
  for (const auto& s : js.at("steps")) {
    if (s.at("step").get<int>() > step_) break;
    DynamicsStep d;
    d.step = s.at("step");
    d.t_star = s.at("t_star");
    d.dt_star = s.at("dt_star");
    d.energy = number_or_nan(s.at("energy"));
    d.constraints = s.at("constraints").get<std::vector<double>>();
    d.multipliers = s.at("multipliers").get<std::vector<double>>();
    d.newton_iterations = s.at("newton_iterations");
    d.rejected = s.at("rejected");
    d.min_jacobian = number_or_nan(s.at("min_jacobian"));
    d.distortion = number_or_nan(s.at("distortion"));
    d.resets = s.at("resets");
    d.wall_s = s.at("wall_s");
    if (s.contains("topology") && !s["topology"].is_null())
      d.topology = topology_from_json(s["topology"], level_set_geometry(dim_, scene_.axisymmetric()));
    run_.history.push_back(d);
  }
  std::vector<TimeSeriesStep> series;
  for (const auto& s : js.at("series")) {
    if (s.at("time").get<double>() > t_) break;
    TimeSeriesStep e;
    e.time = s.at("time");
    e.h5_file = s.at("file").get<std::string>();
    e.dim = dim_;
    e.nodes = s.value("nodes", n_nodes_);  // a re-mesh changes the triangulation
    e.cells = s.value("cells", run_.cells.size());
    e.fields = {{"displacement", dim_}, {"velocity", dim_}};
    for (const auto& [name, values] : scalar_fields_) e.fields.emplace_back(name, 1);
    std::sort(e.fields.begin(), e.fields.end());
    series.push_back(e);
  }
  series_->restore(std::move(series));
}

void DynamicsIntegrator::resume() {
  if (!fs::exists(checkpoint_path_) || !fs::exists(history_path_))
    throw std::runtime_error(fmt::format("--restart: no checkpoint in {} (expected {} and {})", output_->directory.string(),
                                         checkpoint_path_.filename().string(), history_path_.filename().string()));
  const Checkpoint cp{checkpoint_path_, read_field_hdf5(checkpoint_path_, comm_)};
  step_ = cp.integer("step");
  run_.resets = cp.integer("resets");
  run_.remeshes = cp.integer_or("remeshes", 0);
  steps_since_remesh_ = cp.integer_or("steps_since_remesh", step_);
  if (run_.remeshes == 0) {
    if (cp.field("material_nodes") != material_nodes_.coords)
      throw std::runtime_error(fmt::format("--restart: {} was written for other nodes than the scene's", checkpoint_path_.string()));
  } else {  // the nodes, triangulation, boundary sets and nodal fields of the last re-mesh
    material_nodes_ = NodeSet(dim_, cp.field("material_nodes"));
    n_nodes_ = material_nodes_.size();
    run_.cells = cp.file.cells;
    run_.reference_nodes = material_nodes_;
    dirichlet_sets_ = dirichlet_nodes(bound_, material_nodes_);
    for (auto& [name, values] : scalar_fields_) values = cp.field("field_" + name);
    for (int i = 0; i < run_.remeshes; ++i) run_.remesh_changes.push_back(cp.number(fmt::format("remesh_change_{}", i)));
  }
  for (std::size_t i = 0; i < k_; ++i) targets_[i] = cp.number(fmt::format("target_{}", i));
  if (run_.resets > 0 || run_.remeshes > 0) {
    const Checkpoint qf{quadrature_path_, read_field_hdf5(quadrature_path_, comm_)};
    if (qf.integer("step") != step_)
      throw std::runtime_error(fmt::format("--restart: {} belongs to another step than {}", quadrature_path_.string(), checkpoint_path_.string()));
    CarriedQuadrature carried;
    carried.cells = run_.cells;
    carried.quadrature.dim = dim_;
    carried.quadrature.points_per_cell = qf.integer("points_per_cell");
    carried.quadrature.points = qf.file.nodes.coords;
    carried.quadrature.weights = qf.field("weight");
    std::map<std::string, std::vector<double>, std::less<>> qdata;
    for (const auto& [name, f] : qf.file.fields)
      if (name.starts_with("qdata_")) qdata[name.substr(6)] = f.values;
    ref_ = build_reference(cp.file.nodes, cp.field("state"), std::move(carried), std::move(qdata), true, material_fields());
  } else {
    set_from_original(*ref_->space.disc, cp.field("state"), bs_, ref_->u);
  }
  velocity_ = cp.field("velocity");
  t_ = cp.number("t_star");
  dt_ = cp.number("dt_star");
  // A target the scene states is the same at every step of an uninterrupted run: the scene's wins
  // (a restart with a new target applies it); only the automatic one (the first step's decrement)
  // is the checkpoint's.
  if (settings_.energy_decrement <= 0) target_decrement_ = cp.number("target_decrement");
  run_.accepted = cp.integer("accepted");
  run_.rejected = cp.integer("rejected");
  run_.gradient_evaluations = cp.integer_or("gradient_evaluations", 0);
  run_.hessian_evaluations = cp.integer_or("hessian_evaluations", 0);
  steps_since_reset_ = cp.integer("steps_since_reset");
  for (std::size_t i = 0; i < k_; ++i) nu_[i] = cp.number(fmt::format("multiplier_{}", i));
  read_history(history_path_);
  // The membrane as the checkpoint left it, and as the run started (the history's first step).
  if (const auto* field = topology_values()) topology_ = membrane_topology(material_nodes_, run_.cells, *field);
  run_.initial_topology = run_.history.empty() ? topology_ : run_.history.front().topology;
  if (out_ != nullptr)
    *out_ << fmt::format("resumed from {} at step {}, t* {:.6e}, {} resets\n", checkpoint_path_.string(), step_, t_, run_.resets) << std::flush;
}

}  // namespace lmeform::problems
