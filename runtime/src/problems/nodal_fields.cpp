// Node sets and nodal fields of a bound scene: the initial nodes, the nodes of boundary parts, the
// values of [initial] and [coefficients] entries at the nodes.
#include <algorithm>
#include <exception>
#include <set>

#include <fmt/ranges.h>

#include <fmt/format.h>

#include "lmeform/collective_error.hpp"
#include "lmeform/convex_hull.hpp"
#include "lmeform/cvt.hpp"
#include "lmeform/domain.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"
#include "lmeform/stopwatch.hpp"
#include "node_adaptation.hpp"
#include "problem_space.hpp"

namespace lmeform::problems {

namespace {

/// The values of a field read from a previous run's output, which must hold the same nodes.
void read_field_file(MPI_Comm comm, const BoundNodalField& f, const UnknownField& u, const NodeSet& nodes, std::size_t per_node,
                     std::vector<double>& state) {
  FieldFile file;
  try {
    // Only the nodes (to check them) and this field.
    file = read_field_hdf5(f.file, comm, {.cells = false, .fields = std::vector<std::string>{f.dataset}, .attributes = false});
  } catch (const std::runtime_error& e) {
    throw SceneError(fmt::format("{}: field '{}': {}", f.where, f.dataset, e.what()));
  }
  const auto it = file.fields.find(f.dataset);
  if (it->second.components != u.components)
    throw SceneError(fmt::format("{}: field '{}' of {} has {} components, '{}' has {}", f.where, f.dataset, f.file.string(),
                                 it->second.components, u.name, u.components));
  if (file.nodes.size() != nodes.size() || file.nodes.coords != nodes.coords)
    throw SceneError(fmt::format("{}: {} was computed on other nodes ({} nodes); a field is read back on the node set it was "
                                 "written with (same [nodes])",
                                 f.where, f.file.string(), file.nodes.size()));
  for (std::size_t a = 0; a < nodes.size(); ++a)
    for (int c = 0; c < u.components; ++c)
      state[a * per_node + std::size_t(u.offset + c)] = it->second.values[a * std::size_t(u.components) + std::size_t(c)];
}

/// Values at the nodes (original order, interleaved as in `layout`) of the entries that set a field
/// of the layout: numbers, expressions or fields of a previous run's output on the same nodes.
std::vector<double> nodal_values(const BoundScene& b, const std::vector<BoundNodalField>& entries, const StateLayout& layout,
                                 const NodeSet& nodes) {
  const auto bs = static_cast<std::size_t>(layout.dofs_per_node);
  std::vector<double> state(nodes.size() * bs, 0.0);
  std::vector<double> value(3);
  for (const BoundNodalField& f : entries) {
    if (!layout.has(f.name)) continue;
    const UnknownField& u = layout.field(f.name);
    if (!f.file.empty()) {
      read_field_file(b.comm, f, u, nodes, bs, state);
      continue;
    }
    for (std::size_t a = 0; a < nodes.size(); ++a) {
      if (f.value.is_expression()) b.expressions->evaluate(f.value.expression, nodes.point(a), value);
      else std::fill(value.begin(), value.end(), f.value.number);
      for (int c = 0; c < u.components; ++c) state[a * bs + std::size_t(u.offset + c)] = value[std::size_t(c)];
    }
  }
  return state;
}

NodeSet cvt_nodes(const Scene& scene, std::ostream* log) {
  const Stopwatch clock;
  CvtOptions cvt;
  cvt.iterations = scene.nodes.lloyd_iterations;
  CvtReport report;
  NodeSet nodes = uniform_cvt(scene.domain, static_cast<std::size_t>(scene.nodes.count), cvt, &report);
  if (log != nullptr)
    *log << fmt::format("uniform CVT of {} nodes: {} Lloyd iterations{}, {} s\n", nodes.size(), report.iterations.size(),
                        report.iterations.empty()
                            ? std::string()
                            : fmt::format(", last mean move {} h", report.iterations.back().mean_displacement / report.h_bar),
                        clock.seconds());
  return nodes;
}

/// Every node of a previous run inside the domain (a point file is checked line by line).
void check_inside(const Scene& scene, const NodeSet& nodes) {
  if (scene.geometry.is_box()) return;
  const double tol = 1e-9 * scene.geometry.diameter();
  for (std::size_t a = 0; a < nodes.size(); ++a)
    if (!scene.geometry.contains(nodes.point(a), tol))
      throw std::runtime_error(fmt::format("point {} ({}) lies outside the domain (by {:.3g})", a + 1, fmt::join(nodes.point(a), ", "),
                                           -scene.geometry.depth(nodes.point(a))));
}

NodeSet file_nodes(const Scene& scene, MPI_Comm comm) {
  try {
    // A previous run's output (HDF5): its nodes, so that its fields can be read back on them. The
    // ranks read a block of rows each; the file's cells and fields are not read.
    if (scene.nodes.file.extension() == ".h5") {
      NodeSet nodes =
          read_field_hdf5(scene.nodes.file, comm, {.cells = false, .fields = std::vector<std::string>{}, .attributes = false}).nodes;
      if (nodes.dim != scene.dim())
        throw std::runtime_error(fmt::format("{} holds {}D nodes, the scene is {}D", scene.nodes.file.string(), nodes.dim, scene.dim()));
      check_inside(scene, nodes);
      return nodes;
    }
    // A text file: parsed by one rank and sent to the others.
    int rank = 0;
    MPI_Comm_rank(comm, &rank);
    NodeSet nodes;
    std::exception_ptr failure;
    if (rank == 0) {
      try {
        nodes = scene.geometry.is_box() ? read_points(scene.nodes.file, scene.dim(), &scene.domain)
                                        : read_points(scene.nodes.file, scene.dim(), scene.geometry);
      } catch (...) {
        failure = std::current_exception();
      }
    }
    throw_on_every_rank(comm, failure);
    unsigned long long count = nodes.coords.size();
    MPI_Bcast(&count, 1, MPI_UNSIGNED_LONG_LONG, 0, comm);
    nodes.dim = scene.dim();
    nodes.coords.resize(static_cast<std::size_t>(count));
    // In pieces: one broadcast carries at most 2^31 values.
    constexpr std::size_t piece = std::size_t{1} << 30;
    for (std::size_t at = 0; at < nodes.coords.size(); at += piece)
      MPI_Bcast(nodes.coords.data() + at, static_cast<int>(std::min(piece, nodes.coords.size() - at)), MPI_DOUBLE, 0, comm);
    return nodes;
  } catch (const std::runtime_error& e) {
    throw SceneError(fmt::format("{}: key 'nodes.file': {}", scene.source, e.what()));
  }
}

}  // namespace

NodeSet initial_nodes(const Scene& scene, MPI_Comm comm, std::ostream* log) {
  switch (scene.nodes.kind) {
    case SceneNodes::Kind::spacing:
      // A box without refinement keeps its uniform grid; anything else is generated for the domain.
      if (scene.geometry.is_box() && scene.nodes.refine.empty() && !scene.nodes.adapt) return uniform_grid(scene.domain, scene.nodes.spacing);
      if (scene.nodes.sampling == SceneNodes::Sampling::nested_grids) return scene_grids(scene, scene_spacing(scene));
      return domain_nodes(scene.geometry, scene_spacing(scene));
    case SceneNodes::Kind::counts: return uniform_grid(scene.domain, scene.nodes.counts);
    case SceneNodes::Kind::count: return cvt_nodes(scene, log);
    case SceneNodes::Kind::file: return file_nodes(scene, comm);
  }
  throw std::logic_error("unknown node kind");
}

std::vector<int> boundary_nodes(const Domain& geometry, const NodeSet& nodes, const std::string& part) {
  if (part == "hull") return hull_boundary_nodes(nodes);
  return geometry.nodes_on(nodes, part);
}

std::vector<int> boundary_nodes(const Domain& geometry, const NodeSet& nodes, const std::string& part,
                                const std::map<std::string, std::vector<int>, std::less<>>& part_nodes) {
  if (const auto it = part_nodes.find(part); it != part_nodes.end()) return it->second;
  return boundary_nodes(geometry, nodes, part);
}

std::vector<std::vector<int>> dirichlet_nodes(const BoundScene& b, const NodeSet& nodes,
                                              const std::map<std::string, std::vector<int>, std::less<>>& part_nodes) {
  std::vector<std::vector<int>> out;
  for (const BoundDirichlet& d : b.dirichlet) {
    std::set<int> on;
    for (const auto& part : d.parts)
      for (const int n : boundary_nodes(b.geometry, nodes, part, part_nodes)) on.insert(n);
    if (on.empty()) throw SceneError(fmt::format("{}: no node lies on the boundary parts given in key 'boundary'", d.where));
    out.emplace_back(on.begin(), on.end());
  }
  return out;
}

std::vector<double> coefficient_values(const BoundScene& b, const std::string& name, int components, const NodeSet& nodes) {
  if (std::none_of(b.coefficients.begin(), b.coefficients.end(), [&](const BoundNodalField& f) { return f.name == name; }))
    throw SceneError(fmt::format("{}: [coefficients] gives no field '{}'", b.source, name));
  return nodal_values(b, b.coefficients, {{{name, components, 0}}, components}, nodes);
}

std::vector<double> initial_state(const BoundScene& b, const NodeSet& nodes) {
  return nodal_values(b, b.initial, b.layout, nodes);
}

StateLayout kernel_coefficient_layout(const kernel::FormKernels& k) {
  StateLayout layout;
  for (int i = 0; i < k.n_coefficients; ++i) {
    layout.fields.push_back({k.coefficients[i].name, k.coefficients[i].components, layout.dofs_per_node});
    layout.dofs_per_node += k.coefficients[i].components;
  }
  return layout;
}

/// Values of every coefficient field a kernel reads, in the kernel's own layout.
std::vector<double> kernel_coefficient_values(const BoundScene& b, const kernel::FormKernels& k, const NodeSet& nodes,
                                              const std::map<std::string, std::vector<double>, std::less<>>& given) {
  const StateLayout layout = kernel_coefficient_layout(k);
  std::vector<double> values = nodal_values(b, b.coefficients, layout, nodes);
  for (const auto& field : layout.fields) {
    const auto it = given.find(field.name);
    if (it == given.end() || field.components != 1) continue;
    for (std::size_t n = 0; n < nodes.size(); ++n) values[n * std::size_t(layout.dofs_per_node) + std::size_t(field.offset)] = it->second.at(n);
  }
  return values;
}

}  // namespace lmeform::problems
