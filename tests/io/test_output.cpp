// Field files (HDF5 + XDMF): bit-exact round trip, a well-formed sidecar that points at datasets that
// exist, failing writes that leave nothing behind, clear read errors; atomic text files.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <span>
#include <thread>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "lmeform/delaunay.hpp"
#include "lmeform/node_sets.hpp"
#include "lmeform/output.hpp"

namespace fs = std::filesystem;
using namespace lmeform;

namespace {

// A fresh, empty folder per test under the build tree.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::path(LMEFORM_TEST_TMPDIR) / "scratch" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::vector<std::string> listing(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

bool bit_equal(const std::vector<double>& a, std::span<const double> b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

struct Sample {
  NodeSet nodes;
  BackgroundCells cells;
  std::vector<double> phi, grad, vec3;
};

Sample make_sample(int dim) {
  Sample s;
  if (dim == 2) {
    const Box box{2, {0.0, 0.0, 0.0}, {1.5, 2.0, 0.0}};
    s.nodes = jitter_interior(uniform_grid(box, std::array<int, 3>{9, 12, 1}), box, 0.02, 3);
  } else if (dim == 3) {
    const Box box{3, {0.0, 0.0, 0.0}, {1.0, 1.0, 1.0}};
    s.nodes = jitter_interior(uniform_grid(box, std::array<int, 3>{4, 4, 4}), box, 0.03, 5);
  } else {
    const Box box{1, {0.0, 0.0, 0.0}, {1.0, 0.0, 0.0}};
    s.nodes = uniform_grid(box, std::array<int, 3>{7, 1, 1});
  }
  s.cells = delaunay(s.nodes);
  const std::size_t n = s.nodes.size();
  for (std::size_t i = 0; i < n; ++i) {
    const auto x = s.nodes.point(i);
    // Values that do not print exactly in decimal: the round trip must keep every bit.
    s.phi.push_back(std::tanh((0.5 - x[0]) / 0.07) + 1e-17 * static_cast<double>(i));
    s.grad.push_back(std::sin(x[0]) / 3.0);
    s.grad.push_back(-std::cos(x[0]) / 7.0);
    for (int k = 0; k < 3; ++k) s.vec3.push_back(std::exp(-x[0] * (k + 1)) / 11.0);
  }
  return s;
}

FieldViews views(const Sample& s) { return {{"phi", {s.phi}}, {"grad_phi", {s.grad, 2}}, {"v", {s.vec3, 3}}}; }

// ---- a minimal XML reader: enough to check the sidecar is well-formed and read its DataItems ----

struct Element {
  std::string name;
  std::map<std::string, std::string> attributes;
  std::string text;
  std::vector<Element> children;
};

class MiniXml {
 public:
  explicit MiniXml(std::string s) : s_(std::move(s)) {}

  Element parse() {
    skip_prolog();
    Element root = element();
    skip_space();
    if (pos_ != s_.size()) throw std::runtime_error("trailing content after the root element");
    return root;
  }

 private:
  void skip_space() {
    while (pos_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[pos_]))) ++pos_;
  }
  void skip_prolog() {
    for (;;) {
      skip_space();
      if (s_.compare(pos_, 2, "<?") == 0) {
        pos_ = s_.find("?>", pos_);
        if (pos_ == std::string::npos) throw std::runtime_error("unterminated <?");
        pos_ += 2;
      } else if (s_.compare(pos_, 2, "<!") == 0) {
        pos_ = s_.find('>', pos_);
        if (pos_ == std::string::npos) throw std::runtime_error("unterminated <!");
        pos_ += 1;
      } else {
        return;
      }
    }
  }
  std::string name() {
    const std::size_t start = pos_;
    while (pos_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[pos_])) || s_[pos_] == ':' ||
                                s_[pos_] == '_' || s_[pos_] == '-'))
      ++pos_;
    if (start == pos_) throw std::runtime_error("expected a name at offset " + std::to_string(pos_));
    return s_.substr(start, pos_ - start);
  }
  void expect(char c) {
    if (pos_ >= s_.size() || s_[pos_] != c) {
      throw std::runtime_error(std::string("expected '") + c + "' at offset " + std::to_string(pos_));
    }
    ++pos_;
  }
  static std::string unescape(const std::string& t) {
    std::string out;
    for (std::size_t i = 0; i < t.size(); ++i) {
      if (t[i] != '&') {
        out += t[i];
        continue;
      }
      const std::size_t semi = t.find(';', i);
      if (semi == std::string::npos) throw std::runtime_error("bad entity");
      const std::string ent = t.substr(i + 1, semi - i - 1);
      static const std::map<std::string, char> known{{"amp", '&'}, {"lt", '<'}, {"gt", '>'}, {"quot", '"'}, {"apos", '\''}};
      const auto it = known.find(ent);
      if (it == known.end()) throw std::runtime_error("unknown entity &" + ent + ";");
      out += it->second;
      i = semi;
    }
    return out;
  }
  Element element() {
    expect('<');
    Element e;
    e.name = name();
    for (;;) {
      skip_space();
      if (s_.compare(pos_, 2, "/>") == 0) {
        pos_ += 2;
        return e;
      }
      if (pos_ < s_.size() && s_[pos_] == '>') {
        ++pos_;
        break;
      }
      const std::string key = name();
      expect('=');
      expect('"');
      const std::size_t end = s_.find('"', pos_);
      if (end == std::string::npos) throw std::runtime_error("unterminated attribute value");
      if (!e.attributes.emplace(key, unescape(s_.substr(pos_, end - pos_))).second) {
        throw std::runtime_error("duplicate attribute " + key);
      }
      pos_ = end + 1;
    }
    for (;;) {
      const std::size_t lt = s_.find('<', pos_);
      if (lt == std::string::npos) throw std::runtime_error("unclosed element " + e.name);
      e.text += unescape(s_.substr(pos_, lt - pos_));
      pos_ = lt;
      if (s_.compare(pos_, 2, "</") == 0) {
        pos_ += 2;
        const std::string closing = name();
        if (closing != e.name) throw std::runtime_error("</" + closing + "> closes <" + e.name + ">");
        skip_space();
        expect('>');
        return e;
      }
      e.children.push_back(element());
    }
  }

  std::string s_;
  std::size_t pos_ = 0;
};

const Element& child(const Element& e, const std::string& name) {
  for (const auto& c : e.children)
    if (c.name == name) return c;
  throw std::runtime_error("<" + e.name + "> has no <" + name + ">");
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  const auto e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}

// Dimensions of a dataset in an HDF5 file, or empty when it does not exist.
std::vector<hsize_t> dataset_dims(const fs::path& h5, const std::string& dataset) {
  std::vector<hsize_t> dims;
  const hid_t file = H5Fopen(h5.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (file < 0) return dims;
  // Check each link on the way: H5Dopen2 on a missing path would print an error stack.
  bool exists = true;
  std::string partial;
  std::istringstream parts(dataset);
  for (std::string part; std::getline(parts, part, '/');) {
    if (part.empty()) continue;
    partial += "/" + part;
    if (H5Lexists(file, partial.c_str(), H5P_DEFAULT) <= 0) {
      exists = false;
      break;
    }
  }
  if (exists) {
    const hid_t set = H5Dopen2(file, dataset.c_str(), H5P_DEFAULT);
    if (set >= 0) {
      const hid_t space = H5Dget_space(set);
      dims.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(space)));
      H5Sget_simple_extent_dims(space, dims.data(), nullptr);
      H5Sclose(space);
      H5Dclose(set);
    }
  }
  H5Fclose(file);
  return dims;
}

std::vector<hsize_t> parse_dims(const std::string& text) {
  std::vector<hsize_t> dims;
  std::istringstream in(text);
  for (unsigned long long d = 0; in >> d;) dims.push_back(static_cast<hsize_t>(d));
  return dims;
}

}  // namespace

// ---- round trip -----------------------------------------------------------------------------------

class RoundTrip : public ::testing::TestWithParam<int> {};

TEST_P(RoundTrip, WriteReadIsBitExact) {
  const int dim = GetParam();
  const Sample s = make_sample(dim);
  const fs::path dir = scratch("roundtrip" + std::to_string(dim));
  const fs::path file = dir / "state.h5";
  write_field_hdf5(file, s.nodes, s.cells, views(s),
                   {{"energy", 9.126570000000001}, {"eps", 0.01}, {"step", 42}, {"scene", "discocyte.toml"},
                    {"tiny", 5e-324}});

  const FieldFile back = read_field_hdf5(file);
  EXPECT_EQ(back.nodes.dim, dim);
  EXPECT_TRUE(bit_equal(back.nodes.coords, s.nodes.coords));
  EXPECT_EQ(back.cells.dim, dim);
  EXPECT_EQ(back.cells.vertices_per_cell, dim + 1);
  EXPECT_EQ(back.cells.connectivity, s.cells.connectivity);
  ASSERT_EQ(back.cells.size(), s.cells.size());
  for (std::size_t c = 0; c < s.cells.size(); ++c) EXPECT_NEAR(back.cells.measures[c], s.cells.measures[c], 1e-15);

  ASSERT_EQ(back.fields.size(), 3U);
  EXPECT_EQ(back.fields.at("phi").components, 1);
  EXPECT_EQ(back.fields.at("grad_phi").components, 2);
  EXPECT_EQ(back.fields.at("v").components, 3);
  EXPECT_TRUE(bit_equal(back.fields.at("phi").values, s.phi));
  EXPECT_TRUE(bit_equal(back.fields.at("grad_phi").values, s.grad));
  EXPECT_TRUE(bit_equal(back.fields.at("v").values, s.vec3));

  ASSERT_EQ(back.attributes.size(), 5U);
  EXPECT_EQ(std::get<double>(back.attributes.at("energy")), 9.126570000000001);
  EXPECT_EQ(std::get<double>(back.attributes.at("eps")), 0.01);
  EXPECT_EQ(std::get<double>(back.attributes.at("tiny")), 5e-324);
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("step")), 42);
  EXPECT_EQ(std::get<std::string>(back.attributes.at("scene")), "discocyte.toml");

  // Nothing but the two results in the folder (no temporaries); no sidecar in 1D.
  if (dim == 1) {
    EXPECT_EQ(listing(dir), (std::vector<std::string>{"state.h5"}));
  } else {
    EXPECT_EQ(listing(dir), (std::vector<std::string>{"state.h5", "state.xmf"}));
  }
}

INSTANTIATE_TEST_SUITE_P(Dimensions, RoundTrip, ::testing::Values(1, 2, 3));

TEST(FieldFile, OverwritesAnEarlierFile) {
  const Sample s = make_sample(2);
  const fs::path file = scratch("overwrite") / "state.h5";
  write_field_hdf5(file, s.nodes, s.cells, views(s), {{"step", 1}});
  std::vector<double> phi2(s.phi.size(), 0.25);
  write_field_hdf5(file, s.nodes, s.cells, {{"phi", {phi2}}}, {{"step", 2}});
  const FieldFile back = read_field_hdf5(file);
  EXPECT_EQ(back.fields.size(), 1U);
  EXPECT_EQ(back.fields.at("phi").values, phi2);
  EXPECT_EQ(std::get<std::int64_t>(back.attributes.at("step")), 2);
}

// ---- the XDMF sidecar ------------------------------------------------------------------------------

class Sidecar : public ::testing::TestWithParam<int> {};

TEST_P(Sidecar, IsWellFormedAndReferencesExistingDatasets) {
  const int dim = GetParam();
  const Sample s = make_sample(dim);
  const fs::path dir = scratch("xdmf" + std::to_string(dim));
  const fs::path file = dir / "vesicle & co.h5";  // a name that needs XML escaping
  write_field_hdf5(file, s.nodes, s.cells, views(s), {{"energy", 1.0}});
  const fs::path xmf = dir / "vesicle & co.xmf";
  EXPECT_EQ(xdmf_sidecar_path(file), xmf);
  ASSERT_TRUE(fs::exists(xmf));

  const Element root = MiniXml(slurp(xmf)).parse();
  EXPECT_EQ(root.name, "Xdmf");
  EXPECT_EQ(root.attributes.at("Version"), "3.0");
  const Element& grid = child(child(root, "Domain"), "Grid");
  const Element& topology = child(grid, "Topology");
  EXPECT_EQ(topology.attributes.at("TopologyType"), dim == 2 ? "Triangle" : "Tetrahedron");
  EXPECT_EQ(topology.attributes.at("NumberOfElements"), std::to_string(s.cells.size()));
  EXPECT_EQ(child(grid, "Geometry").attributes.at("GeometryType"), dim == 2 ? "XY" : "XYZ");

  std::vector<const Element*> items{&child(topology, "DataItem"), &child(child(grid, "Geometry"), "DataItem")};
  std::vector<std::string> field_names;
  for (const auto& c : grid.children) {
    if (c.name != "Attribute") continue;
    EXPECT_EQ(c.attributes.at("Center"), "Node");
    field_names.push_back(c.attributes.at("Name"));
    items.push_back(&child(c, "DataItem"));
  }
  EXPECT_EQ(field_names, (std::vector<std::string>{"grad_phi", "phi", "v"}));

  std::vector<std::string> referenced;
  for (const Element* item : items) {
    EXPECT_EQ(item->attributes.at("Format"), "HDF");
    const std::string ref = trim(item->text);
    const auto colon = ref.find(":/");
    ASSERT_NE(colon, std::string::npos) << ref;
    EXPECT_EQ(ref.substr(0, colon), file.filename().string());  // relative, and not the .tmp name
    const std::string dataset = ref.substr(colon + 1);
    referenced.push_back(dataset);
    const auto dims = dataset_dims(dir / ref.substr(0, colon), dataset);
    ASSERT_FALSE(dims.empty()) << dataset << " does not exist in " << file;
    EXPECT_EQ(dims, parse_dims(item->attributes.at("Dimensions"))) << dataset;
    const bool is_int = item->attributes.at("NumberType") == "Int";
    EXPECT_EQ(is_int, dataset == "/cells") << dataset;
    EXPECT_EQ(item->attributes.at("Precision"), is_int ? "4" : "8");
  }
  EXPECT_EQ(referenced,
            (std::vector<std::string>{"/cells", "/nodes", "/fields/grad_phi", "/fields/phi", "/fields/v"}));
}

INSTANTIATE_TEST_SUITE_P(Dimensions, Sidecar, ::testing::Values(2, 3));

// ---- failing writes leave nothing behind ------------------------------------------------------------

TEST(FailingWrite, MissingFolderThrowsWithThePathAndLeavesNothing) {
  const Sample s = make_sample(2);
  const fs::path dir = scratch("fail_missing");
  const fs::path file = dir / "no_such_folder" / "state.h5";
  try {
    write_field_hdf5(file, s.nodes, s.cells, views(s));
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(file.string()), std::string::npos) << what;
    EXPECT_NE(what.find("HDF5"), std::string::npos) << what;
    EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
  }
  EXPECT_TRUE(listing(dir).empty());
}

TEST(FailingWrite, ParentIsAFileThrowsAndLeavesNothing) {
  const Sample s = make_sample(2);
  const fs::path dir = scratch("fail_notdir");
  std::ofstream(dir / "plain") << "x";
  const fs::path file = dir / "plain" / "state.h5";
  try {
    write_field_hdf5(file, s.nodes, s.cells, views(s));
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
  }
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"plain"}));
}

TEST(FailingWrite, RenameFailureRemovesTheTemporaries) {
  // The target name is taken by a folder: both temporaries get written, the final rename fails.
  const Sample s = make_sample(2);
  const fs::path dir = scratch("fail_rename");
  fs::create_directory(dir / "state.h5");
  try {
    write_field_hdf5(dir / "state.h5", s.nodes, s.cells, views(s));
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find((dir / "state.h5").string()), std::string::npos) << what;
    EXPECT_NE(what.find("cannot rename"), std::string::npos) << what;
  }
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"state.h5"}));  // the folder only: no .tmp, no .xmf
  EXPECT_TRUE(fs::is_directory(dir / "state.h5"));
}

TEST(FailingWrite, BadInputLeavesAnEarlierFileUntouched) {
  const Sample s = make_sample(2);
  const fs::path dir = scratch("fail_input");
  const fs::path file = dir / "state.h5";
  write_field_hdf5(file, s.nodes, s.cells, views(s), {{"step", 1}});
  const std::string before = slurp(file);
  const std::vector<double> short_field(s.nodes.size() - 1, 0.0);
  try {
    write_field_hdf5(file, s.nodes, s.cells, {{"phi", {short_field}}});
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("'phi'"), std::string::npos) << what;
    EXPECT_NE(what.find(file.string()), std::string::npos) << what;
  }
  std::vector<int> bad_cells = s.cells.connectivity;
  bad_cells[4] = static_cast<int>(s.nodes.size());
  BackgroundCells broken = s.cells;
  broken.connectivity = bad_cells;
  EXPECT_THROW(write_field_hdf5(file, s.nodes, broken, {}), std::invalid_argument);
  EXPECT_THROW(write_field_hdf5(file, s.nodes, s.cells, {{"a/b", {s.phi}}}), std::invalid_argument);
  EXPECT_EQ(slurp(file), before);
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"state.h5", "state.xmf"}));
}

// ---- reading errors ----------------------------------------------------------------------------------

TEST(ReadFieldFile, ErrorsNameThePathAndWhatIsMissing) {
  const fs::path dir = scratch("read_errors");
  const auto message = [](const fs::path& p) {
    try {
      (void)read_field_hdf5(p);
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  const std::string missing = message(dir / "absent.h5");
  EXPECT_NE(missing.find((dir / "absent.h5").string()), std::string::npos) << missing;
  EXPECT_NE(missing.find("no such file"), std::string::npos) << missing;

  std::ofstream(dir / "text.h5") << "not hdf5\n";
  EXPECT_NE(message(dir / "text.h5").find("not an HDF5 file"), std::string::npos);

  // A file with /nodes only.
  const fs::path partial = dir / "partial.h5";
  {
    const hid_t f = H5Fcreate(partial.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {3, 2};
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t set = H5Dcreate2(f, "nodes", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    const double xy[6] = {0, 0, 1, 0, 0, 1};
    H5Dwrite(set, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, xy);
    H5Dclose(set);
    H5Sclose(space);
    H5Fclose(f);
  }
  const std::string no_cells = message(partial);
  EXPECT_NE(no_cells.find(partial.string()), std::string::npos) << no_cells;
  EXPECT_NE(no_cells.find("missing dataset /cells"), std::string::npos) << no_cells;
}

// A node set larger than the memory left on this machine: refused with the sizes before anything is
// allocated, not a crash. The dataset's extent is declared but never written, so the file is small.
TEST(ReadFieldFile, ADatasetLargerThanTheFreeMemoryIsRefusedBeforeItIsAllocated) {
  const fs::path dir = scratch("too_large");
  const fs::path huge = dir / "huge.h5";
  {
    const hid_t f = H5Fcreate(huge.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    const hsize_t dims[2] = {hsize_t{1} << 40, 3};  // 24 TiB of coordinates
    const hid_t space = H5Screate_simple(2, dims, nullptr);
    const hid_t create = H5Pcreate(H5P_DATASET_CREATE);
    H5Pset_alloc_time(create, H5D_ALLOC_TIME_LATE);
    const hid_t set = H5Dcreate2(f, "nodes", H5T_IEEE_F64LE, space, H5P_DEFAULT, create, H5P_DEFAULT);
    ASSERT_GE(set, 0);
    H5Dclose(set);
    H5Pclose(create);
    H5Sclose(space);
    H5Fclose(f);
  }
  ASSERT_LT(fs::file_size(huge), std::uintmax_t{1} << 20);
  try {
    (void)read_field_hdf5(huge);
    ADD_FAILURE() << "a 24 TiB node set was read";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(huge.string()), std::string::npos) << what;
    EXPECT_NE(what.find("/nodes holds 2.46e+04 GiB, more than the"), std::string::npos) << what;
    EXPECT_NE(what.find("every rank holds a file's nodes and fields whole"), std::string::npos) << what;
  }
}

// ---- atomic text files -----------------------------------------------------------------------------

TEST(AtomicText, WritesAndReplaces) {
  const fs::path dir = scratch("text");
  const fs::path file = dir / "run.json";
  write_text_atomically(file, "{\"energy\": 1}\n");
  EXPECT_EQ(slurp(file), "{\"energy\": 1}\n");
  write_text_atomically(file, "{\"energy\": 2}\n");
  EXPECT_EQ(slurp(file), "{\"energy\": 2}\n");
  write_text_atomically(dir / "empty.csv", "");
  EXPECT_EQ(slurp(dir / "empty.csv"), "");
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"empty.csv", "run.json"}));
}

// Two runs filling one JIT cache wrote the same generated form at once; with one temporary name per
// path the second rename found its temporary gone ("cannot rename ... No such file or directory").
TEST(AtomicText, ConcurrentWritersOfOnePathAllSucceed) {
  const fs::path dir = scratch("text_concurrent");
  const fs::path file = dir / "shared.form";
  std::vector<std::thread> writers;
  std::atomic<int> failures{0};
  for (int t = 0; t < 8; ++t)
    writers.emplace_back([&, t] {
      for (int k = 0; k < 50; ++k) {
        try {
          write_text_atomically(file, "writer " + std::to_string(t) + "\n");
        } catch (const std::exception&) {
          ++failures;
        }
      }
    });
  for (auto& w : writers) w.join();
  EXPECT_EQ(failures.load(), 0);
  const std::string content = slurp(file);
  EXPECT_EQ(content.rfind("writer ", 0), 0u) << content;
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"shared.form"})) << "no temporary left behind";
}

TEST(AtomicText, FailureNamesThePathAndLeavesNothing) {
  const fs::path dir = scratch("text_fail");
  const fs::path file = dir / "missing" / "run.json";
  try {
    write_text_atomically(file, "x");
    FAIL() << "expected an exception";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(file.string()), std::string::npos) << what;
    EXPECT_NE(what.find("No such file or directory"), std::string::npos) << what;
  }
  fs::create_directory(dir / "taken");  // rename onto a folder fails after the temporary was written
  EXPECT_THROW(write_text_atomically(dir / "taken", "x"), std::runtime_error);
  EXPECT_EQ(listing(dir), (std::vector<std::string>{"taken"}));
}
