// Collective field files (3 ranks): every rank writes the rows it owns through MPI-IO, and the file
// read back equals the one the serial writer makes from the gathered data, bit for bit; a rank that
// owns no rows takes part; a part that does not add up is refused on every rank and leaves nothing
// behind; a time series written collectively lists its steps; fields every rank holds whole are
// written by blocks of rows and give the same file. Read collectively, a file equals its serial read.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"

namespace fs = std::filesystem;
using namespace lmeform;

namespace {

int rank_of_world() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}

int ranks_of_world() {
  int n = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &n);
  return n;
}

// A fresh, empty folder per test, made by rank 0 and seen by all.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "scratch_collective" / name;
  if (rank_of_world() == 0) {
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  return dir;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct Sample {
  NodeSet nodes;
  BackgroundCells cells;
  std::vector<double> phi, grad;  // 1 and dim components per node
};

Sample make_sample(int dim) {
  Sample s;
  const Box box = dim == 2 ? Box{2, {0.0, 0.0, 0.0}, {1.5, 2.0, 0.0}} : Box{3, {0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}};
  s.nodes = jitter_interior(uniform_grid(box, dim == 2 ? std::array<int, 3>{9, 12, 1} : std::array<int, 3>{5, 4, 4}), box, 0.02, 3);
  s.cells = delaunay(s.nodes);
  for (std::size_t i = 0; i < s.nodes.size(); ++i) {
    const auto x = s.nodes.point(i);
    s.phi.push_back(std::tanh((0.5 - x[0]) / 0.07) + 1e-17 * static_cast<double>(i));
    for (int k = 0; k < dim; ++k) s.grad.push_back(std::sin(x[0] * (k + 1)) / 3.0);
  }
  return s;
}

/// This rank's rows as a partition scattered through the node order would give them (METIS does),
/// with the values at them. `skip_rank`: that rank owns nothing.
struct Part {
  std::vector<int> rows;
  std::vector<double> phi, grad;
};

Part part_of(const Sample& s, int rank, int ranks, int skip_rank = -1) {
  Part p;
  const int owners = skip_rank >= 0 ? ranks - 1 : ranks;
  const auto dim = static_cast<std::size_t>(s.nodes.dim);
  for (std::size_t i = 0; i < s.nodes.size(); ++i) {
    int owner = static_cast<int>((i * 7 + 3) % static_cast<std::size_t>(owners));
    if (skip_rank >= 0 && owner >= skip_rank) ++owner;
    if (owner != rank) continue;
    p.rows.push_back(static_cast<int>(i));
    p.phi.push_back(s.phi[i]);
    for (std::size_t k = 0; k < dim; ++k) p.grad.push_back(s.grad[i * dim + k]);
  }
  return p;
}

const OutputAttributes kAttributes{{"step", std::int64_t{4}}, {"load", 0.125}, {"scene", std::string("collective.toml")}};

void expect_same_file(const fs::path& collective, const fs::path& serial) {
  const FieldFile a = read_field_hdf5(collective), b = read_field_hdf5(serial);
  EXPECT_EQ(a.nodes.coords, b.nodes.coords);
  EXPECT_EQ(a.cells.connectivity, b.cells.connectivity);
  ASSERT_EQ(a.fields.size(), b.fields.size());
  for (const auto& [name, field] : b.fields) {
    ASSERT_TRUE(a.fields.contains(name)) << name;
    EXPECT_EQ(a.fields.at(name).components, field.components) << name;
    const auto& x = a.fields.at(name).values;
    ASSERT_EQ(x.size(), field.values.size()) << name;
    EXPECT_EQ(std::memcmp(x.data(), field.values.data(), x.size() * sizeof(double)), 0) << name << ": not bit-equal";
  }
  EXPECT_EQ(a.attributes, b.attributes);
}

void write_both(const fs::path& dir, const Sample& s, const Part& p, const std::string& stem) {
  const int dim = s.nodes.dim;
  write_field_hdf5(MPI_COMM_WORLD, dir / (stem + ".h5"), s.nodes, s.cells,
                   DistributedFields{p.rows, {{"phi", {p.phi}}, {"grad_phi", {p.grad, dim}}}}, kAttributes);
  if (rank_of_world() == 0)
    write_field_hdf5(dir / (stem + "_serial.h5"), s.nodes, s.cells, {{"phi", {s.phi}}, {"grad_phi", {s.grad, dim}}}, kAttributes);
  MPI_Barrier(MPI_COMM_WORLD);
}

TEST(CollectiveOutput, EqualsTheSerialFileIn2DAnd3D) {
  const fs::path dir = scratch("equal");
  for (const int dim : {2, 3}) {
    const Sample s = make_sample(dim);
    const Part p = part_of(s, rank_of_world(), ranks_of_world());
    const std::string stem = "state_" + std::to_string(dim) + "d";
    write_both(dir, s, p, stem);
    if (rank_of_world() != 0) continue;
    expect_same_file(dir / (stem + ".h5"), dir / (stem + "_serial.h5"));
    // The sidecar differs only in the name of the file it points at.
    std::string xmf = slurp(dir / (stem + ".xmf")), serial_xmf = slurp(dir / (stem + "_serial.xmf"));
    for (std::size_t at = 0; (at = serial_xmf.find(stem + "_serial.h5", at)) != std::string::npos;)
      serial_xmf.replace(at, stem.size() + 10, stem + ".h5");
    EXPECT_FALSE(xmf.empty());
    EXPECT_EQ(xmf, serial_xmf);
  }
  if (rank_of_world() == 0) {
    for (const auto& e : fs::directory_iterator(dir)) EXPECT_NE(e.path().extension(), ".tmp") << e.path();
  }
}

// Ranks that hold the whole fields (gathered arrays) write a block each; fewer nodes than ranks
// leave a rank with none.
TEST(CollectiveOutput, ReplicatedFieldsWrittenByBlocksEqualTheSerialFile) {
  const fs::path dir = scratch("replicated");
  for (const int dim : {2, 3}) {
    const Sample s = make_sample(dim);
    const FieldViews whole{{"phi", {s.phi}}, {"grad_phi", {s.grad, dim}}};
    const ReplicatedShare share(MPI_COMM_WORLD, s.nodes.size(), whole);
    const DistributedFields part = share.part();
    long long mine = static_cast<long long>(part.rows.size()), all = 0;
    MPI_Allreduce(&mine, &all, 1, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
    EXPECT_EQ(all, static_cast<long long>(s.nodes.size()));
    EXPECT_LE(mine, static_cast<long long>(s.nodes.size() / static_cast<std::size_t>(ranks_of_world()) + 1));
    const std::string stem = "replicated_" + std::to_string(dim) + "d";
    write_field_hdf5(MPI_COMM_WORLD, dir / (stem + ".h5"), s.nodes, s.cells, part, kAttributes);
    if (rank_of_world() == 0) write_field_hdf5(dir / (stem + "_serial.h5"), s.nodes, s.cells, whole, kAttributes);
    MPI_Barrier(MPI_COMM_WORLD);
    if (rank_of_world() == 0) expect_same_file(dir / (stem + ".h5"), dir / (stem + "_serial.h5"));
  }
  const NodeSet two(2, {0.0, 0.0, 1.0, 0.0});
  const std::vector<double> values{1.5, 2.5};
  const ReplicatedShare tiny(MPI_COMM_WORLD, two.size(), {{"phi", {values}}});
  long long mine = static_cast<long long>(tiny.part().rows.size()), all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  EXPECT_EQ(all, 2);
  EXPECT_THROW(ReplicatedShare(MPI_COMM_WORLD, 3, {{"phi", {values}}}), std::invalid_argument);
}

TEST(CollectiveOutput, ARankWithoutRowsTakesPart) {
  const fs::path dir = scratch("empty_rank");
  const Sample s = make_sample(2);
  const Part p = part_of(s, rank_of_world(), ranks_of_world(), ranks_of_world() - 1);
  if (rank_of_world() == ranks_of_world() - 1) {
    EXPECT_TRUE(p.rows.empty());
  }
  write_both(dir, s, p, "state");
  if (rank_of_world() == 0) expect_same_file(dir / "state.h5", dir / "state_serial.h5");
}

TEST(CollectiveOutput, PartsThatDoNotAddUpAreRefusedEverywhereAndLeaveNothing) {
  const fs::path dir = scratch("refused");
  const Sample s = make_sample(2);
  Part p = part_of(s, rank_of_world(), ranks_of_world());
  if (rank_of_world() == 1) {  // one row lost
    p.rows.pop_back();
    p.phi.pop_back();
    p.grad.resize(p.grad.size() - 2);
  }
  try {
    write_field_hdf5(MPI_COMM_WORLD, dir / "state.h5", s.nodes, s.cells,
                     DistributedFields{p.rows, {{"phi", {p.phi}}, {"grad_phi", {p.grad, 2}}}}, kAttributes);
    ADD_FAILURE() << "accepted on rank " << rank_of_world();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("the ranks hold " + std::to_string(s.nodes.size() - 1) + " rows together"), std::string::npos)
        << e.what();
  }
  // A field whose length does not match the rank's rows: refused on every rank, the culprit named.
  Part q = part_of(s, rank_of_world(), ranks_of_world());
  if (rank_of_world() == 2 % ranks_of_world()) q.phi.push_back(1.0);
  try {
    write_field_hdf5(MPI_COMM_WORLD, dir / "state.h5", s.nodes, s.cells, DistributedFields{q.rows, {{"phi", {q.phi}}}}, kAttributes);
    ADD_FAILURE() << "accepted on rank " << rank_of_world();
  } catch (const std::invalid_argument& e) {
    const bool culprit = rank_of_world() == 2 % ranks_of_world();
    EXPECT_NE(std::string(e.what()).find(culprit ? "rows of this rank" : "another rank's part"), std::string::npos) << e.what();
  }
  MPI_Barrier(MPI_COMM_WORLD);
  if (rank_of_world() == 0) {
    EXPECT_TRUE(fs::is_empty(dir)) << "something was left in " << dir;
  }
}

TEST(CollectiveOutput, ATimeSeriesWrittenCollectivelyListsItsSteps) {
  const fs::path dir = scratch("series");
  const Sample s = make_sample(2);
  const Part p = part_of(s, rank_of_world(), ranks_of_world());
  TimeSeriesWriter series(dir, "run");
  for (int step = 1; step <= 2; ++step)
    series.write(MPI_COMM_WORLD, 0.5 * step, step, s.nodes, s.cells, DistributedFields{p.rows, {{"phi", {p.phi}}}},
                 {{"step", std::int64_t{step}}});
  EXPECT_EQ(series.steps().size(), 2u);
  MPI_Barrier(MPI_COMM_WORLD);
  if (rank_of_world() != 0) return;
  const std::string collection = slurp(dir / "run.xmf");
  EXPECT_NE(collection.find("run_000001.h5"), std::string::npos);
  EXPECT_NE(collection.find("run_000002.h5"), std::string::npos);
  const FieldFile second = read_field_hdf5(dir / series.file_of(2));
  EXPECT_EQ(second.fields.at("phi").values, s.phi);
}

// Every rank reads a block of each dataset's rows and receives the whole file: equal to the serial
// read bit for bit, with more ranks than rows too; what the selection leaves out is not read, a
// named field that is not there is refused on every rank.
TEST(CollectiveInput, EveryRankReadsABlockAndReceivesTheWholeFile) {
  const fs::path dir = scratch("read");
  for (const int dim : {2, 3}) {
    const Sample s = make_sample(dim);
    const std::string stem = "state_" + std::to_string(dim) + "d";
    write_both(dir, s, part_of(s, rank_of_world(), ranks_of_world()), stem);
    const FieldFile serial = read_field_hdf5(dir / (stem + "_serial.h5"));
    const FieldFile all = read_field_hdf5(dir / (stem + ".h5"), MPI_COMM_WORLD);
    EXPECT_EQ(all.nodes.dim, dim);
    EXPECT_EQ(all.nodes.coords, serial.nodes.coords);
    EXPECT_EQ(all.cells.connectivity, serial.cells.connectivity);
    EXPECT_EQ(all.cells.measures, serial.cells.measures);
    ASSERT_EQ(all.fields.size(), 2u);
    for (const auto& [name, field] : serial.fields) {
      EXPECT_EQ(all.fields.at(name).components, field.components) << name;
      EXPECT_EQ(std::memcmp(all.fields.at(name).values.data(), field.values.data(), field.values.size() * sizeof(double)), 0) << name;
    }
    EXPECT_EQ(all.attributes, serial.attributes);

    const FieldFile nodes_only = read_field_hdf5(dir / (stem + ".h5"), MPI_COMM_WORLD, {.cells = false, .fields = std::vector<std::string>{},
                                                                                        .attributes = false});
    EXPECT_EQ(nodes_only.nodes.coords, serial.nodes.coords);
    EXPECT_TRUE(nodes_only.cells.connectivity.empty());
    EXPECT_TRUE(nodes_only.fields.empty());
    EXPECT_TRUE(nodes_only.attributes.empty());
    const FieldFile one = read_field_hdf5(dir / (stem + ".h5"), MPI_COMM_WORLD, {.cells = false, .fields = std::vector<std::string>{"grad_phi"}});
    ASSERT_EQ(one.fields.size(), 1u);
    EXPECT_EQ(one.fields.at("grad_phi").values, serial.fields.at("grad_phi").values);
    try {
      (void)read_field_hdf5(dir / (stem + ".h5"), MPI_COMM_WORLD, {.fields = std::vector<std::string>{"psi"}});
      ADD_FAILURE() << "a missing field read on rank " << rank_of_world();
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("missing dataset /fields/psi"), std::string::npos) << e.what();
    }
  }
  // Two nodes on three ranks: a rank reads no row and still takes part.
  const NodeSet two(2, {0.0, 0.0, 1.0, 0.5});
  const std::vector<double> values{1.5, 2.5};
  if (rank_of_world() == 0) write_field_hdf5(dir / "two.h5", two, BackgroundCells{}, {{"phi", {values}}}, {});
  MPI_Barrier(MPI_COMM_WORLD);
  const FieldFile tiny = read_field_hdf5(dir / "two.h5", MPI_COMM_WORLD);
  EXPECT_EQ(tiny.nodes.coords, two.coords);
  EXPECT_EQ(tiny.fields.at("phi").values, values);
  try {
    (void)read_field_hdf5(dir / "absent.h5", MPI_COMM_WORLD);
    ADD_FAILURE() << "a missing file read on rank " << rank_of_world();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("no such file"), std::string::npos) << e.what();
  }
  // A node set larger than the machine's free memory (declared, never written): every rank refuses
  // it, none is left in a collective read.
  if (rank_of_world() == 0) {
    const hid_t f = H5Fcreate((dir / "huge.h5").c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {hsize_t{1} << 40, 3};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t create = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_alloc_time(create, H5D_ALLOC_TIME_LATE);
    H5Dclose(H5Dcreate2(f, "nodes", H5T_IEEE_F64LE, space, H5P_DEFAULT, create, H5P_DEFAULT));
    H5Pclose(create);
    H5Sclose(space);
    H5Fclose(f);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  try {
    (void)read_field_hdf5(dir / "huge.h5", MPI_COMM_WORLD);
    ADD_FAILURE() << "a 24 TiB node set read on rank " << rank_of_world();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("free for each of the " + std::to_string(ranks_of_world()) + " ranks on this machine"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  ::testing::InitGoogleTest(&argc, argv);
  // Only rank 0 prints gtest's report; every rank's failures still fail the run.
  if (rank_of_world() != 0) delete ::testing::UnitTest::GetInstance()->listeners().Release(
      ::testing::UnitTest::GetInstance()->listeners().default_result_printer());
  int failed = RUN_ALL_TESTS();
  MPI_Allreduce(MPI_IN_PLACE, &failed, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  MPI_Finalize();
  return failed;
}
