// Template files (.topo): round trip of real tables, and every kind of malformed file rejected with a
// clear InputError (truncation, flipped bytes, wrong version, trailing bytes, invalid tables behind a
// valid checksum, random mutations).
#include "io/jobs/template_file.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/mesh/weld.h"
#include "io/errors.h"
#include "io/readers/stl_reader.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

// The shared meshes through the project's STL reader (io/readers/stl_reader.h).
FacetSoup loadBinaryStl(const fs::path& path) {
  return readStl(path);
}

fs::path model(const char* name) {
  return fs::path(TOPOSLICE_MODELS_DIR) / name;
}

// Table of the welded mesh, built the way the slicer builds it.
TemplateTable tableOf(const FacetSoup& soup) {
  return buildTemplateTable(weldCorners(soup.corners));
}

// A closed tetrahedron, outward facets: 4 facets, every entry >= 0.
FacetSoup tetrahedron() {
  const Point3f a{0, 0, 0}, b{1, 0, 0}, c{0, 1, 0}, d{0, 0, 1};
  return FacetSoup{{a, c, b, a, b, d, a, d, c, b, c, d}};
}

std::vector<std::byte> readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> chars((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> bytes(chars.size());
  std::memcpy(bytes.data(), chars.data(), chars.size());
  return bytes;
}

void writeBytes(const fs::path& path, std::span<const std::byte> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

// Recomputes the trailing checksum after a deliberate patch, so that later checks are reached.
void fixChecksum(std::vector<std::byte>& bytes) {
  const std::size_t body = bytes.size() - kTemplateChecksumSize;
  const uint64_t sum = templateChecksum(std::span<const std::byte>(bytes).first(body));
  std::memcpy(bytes.data() + body, &sum, sizeof sum);
}

// Expects readTemplateFile(path) to throw an InputError whose message starts with the path and contains
// every one of `parts`.
void expectRejected(const fs::path& path, std::initializer_list<const char*> parts) {
  try {
    readTemplateFile(path);
    ADD_FAILURE() << path << " was accepted";
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind(path.string() + ": ", 0), 0u) << message;
    for (const char* part : parts)
      EXPECT_NE(message.find(part), std::string::npos) << message << " lacks " << part;
  }
}

// Symmetry and range, checked independently of the code under test.
bool validTable(const TemplateTable& t) {
  if (t.adjacency.size() != std::size_t{3} * t.facetCount) return false;
  for (std::size_t e = 0; e < t.adjacency.size(); ++e) {
    const int32_t k = t.adjacency[e];
    if (k == -1) continue;
    if (k < 0 || static_cast<uint32_t>(k) >= t.facetCount || static_cast<std::size_t>(k) == e / 3)
      return false;
    const auto i = static_cast<int32_t>(e / 3);
    if (std::count(t.adjacency.begin() + 3 * k, t.adjacency.begin() + 3 * k + 3, i) !=
        std::count(t.adjacency.begin() + static_cast<std::ptrdiff_t>(e - e % 3),
                   t.adjacency.begin() + static_cast<std::ptrdiff_t>(e - e % 3 + 3), k)) {
      return false;
    }
  }
  return true;
}

class TemplateFile : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("toposlice_template_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
            "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The femur template's table and its file bytes, written once per test.
  const TemplateTable& femur() {
    if (femur_.facetCount == 0) femur_ = tableOf(loadBinaryStl(model("knee_femur_ssm_S001.stl")));
    return femur_;
  }
  std::vector<std::byte> femurBytes() {
    const fs::path p = dir_ / "femur_reference.topo";
    if (!fs::exists(p)) writeTemplateFile(p, femur(), false);
    return readBytes(p);
  }
  fs::path save(const char* name, std::span<const std::byte> bytes) {
    writeBytes(dir_ / name, bytes);
    return dir_ / name;
  }

  fs::path dir_;
  TemplateTable femur_;
};

TEST_F(TemplateFile, RoundTripFemur) {
  const TemplateTable& table = femur();
  ASSERT_EQ(table.facetCount, 14622u);
  EXPECT_EQ(table.vertexCount, 7313u);
  EXPECT_TRUE(std::none_of(table.adjacency.begin(), table.adjacency.end(), [](int32_t k) { return k < 0; }))
      << "the femur is closed and 2-manifold";
  EXPECT_TRUE(validTable(table));

  const fs::path path = dir_ / "femur.topo";
  writeTemplateFile(path, table, false);
  EXPECT_EQ(fs::file_size(path), 40 + 12 * std::uintmax_t{table.facetCount});
  const TemplateTable loaded = readTemplateFile(path);
  EXPECT_EQ(loaded, table);

  const std::vector<std::byte> bytes = readBytes(path);
  EXPECT_EQ(parseTemplate(bytes, "memory"), table);
  EXPECT_EQ(std::memcmp(bytes.data(), "TOPOSLC\0", 8), 0);

  // buildTemplateTable is the same table.
  EXPECT_EQ(buildTemplateTable(weldCorners(loadBinaryStl(model("knee_femur_ssm_S001.stl")).corners)), table);
}

TEST_F(TemplateFile, EmptyAndTinyTablesRoundTrip) {
  const TemplateTable empty;
  writeTemplateFile(dir_ / "empty.topo", empty, false);
  EXPECT_EQ(fs::file_size(dir_ / "empty.topo"), 40u);
  EXPECT_EQ(readTemplateFile(dir_ / "empty.topo"), empty);

  const TemplateTable tet = tableOf(tetrahedron());
  ASSERT_TRUE(validTable(tet));
  ASSERT_EQ(tet.facetCount, 4u);
  EXPECT_TRUE(std::none_of(tet.adjacency.begin(), tet.adjacency.end(), [](int32_t k) { return k < 0; }));
  writeTemplateFile(dir_ / "tet.topo", tet, false);
  EXPECT_EQ(readTemplateFile(dir_ / "tet.topo"), tet);
}

TEST_F(TemplateFile, WriteHonoursOverwriteAndLeavesNoTemporary) {
  const TemplateTable tet = tableOf(tetrahedron());
  const fs::path path = dir_ / "tet.topo";
  writeTemplateFile(path, tet, false);
  EXPECT_THROW(writeTemplateFile(path, tet, false), OutputError);
  EXPECT_EQ(readTemplateFile(path), tet) << "a refused write leaves the old file";
  TemplateTable other = tet;
  other.fingerprint ^= 1;
  writeTemplateFile(path, other, true);
  EXPECT_EQ(readTemplateFile(path), other);
  EXPECT_THROW(writeTemplateFile(dir_ / "no_such_folder" / "x.topo", tet, true), OutputError);
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir_)) ++files;
  EXPECT_EQ(files, 1u) << "no temporary left behind";
}

TEST_F(TemplateFile, FingerprintFollowsConnectivityNotPositions) {
  const TemplateTable& s001 = femur();
  const TemplateTable s002 = tableOf(loadBinaryStl(model("knee_femur_ssm_S002.stl")));
  const TemplateTable tibia = tableOf(loadBinaryStl(model("knee_tibia_ssm_S001.stl")));
  EXPECT_EQ(s001.fingerprint, s002.fingerprint) << "two instances of one shape model";
  EXPECT_EQ(s001.adjacency, s002.adjacency);
  EXPECT_NE(s001.fingerprint, tibia.fingerprint);

  IndexedMesh mesh = weldCorners(tetrahedron().corners);
  const uint64_t original = connectivityFingerprint(mesh.facetVertices);
  std::swap(mesh.facetVertices[0], mesh.facetVertices[1]);
  EXPECT_NE(connectivityFingerprint(mesh.facetVertices), original);
  EXPECT_NE(connectivityFingerprint(std::span<const uint32_t>(mesh.facetVertices).first(11)), original);
  EXPECT_NE(connectivityFingerprint({}), original);
}

// The hash is part of the file format (docs/FORMATS.md gives a reference implementation): these values
// must never change, or files written by earlier builds stop loading.
TEST_F(TemplateFile, HashValuesArePinned) {
  EXPECT_EQ(connectivityFingerprint({}), 0x672d6f35bd706edbull);
  const uint32_t triangle[] = {0, 1, 2};
  EXPECT_EQ(connectivityFingerprint(triangle), 0xa9150f27f875d907ull);
  std::vector<uint32_t> squares;
  for (uint32_t i = 0; i < 30; ++i) squares.push_back(i * i);  // 120 bytes: three blocks and a partial one
  EXPECT_EQ(connectivityFingerprint(squares), 0x11562b44b65e54f7ull);
  EXPECT_EQ(templateChecksum({}), 0x8c7a2c4d5a1c587eull);

  writeTemplateFile(dir_ / "tet.topo", tableOf(tetrahedron()), false);
  const std::vector<std::byte> bytes = readBytes(dir_ / "tet.topo");
  ASSERT_EQ(bytes.size(), 88u);
  uint64_t stored = 0;
  std::memcpy(&stored, bytes.data() + 80, 8);
  EXPECT_EQ(stored, 0xac20ae4d7534847bull);
}

TEST_F(TemplateFile, RejectsMissingFileAndFolder) {
  expectRejected(dir_ / "missing.topo", {"cannot open"});
  expectRejected(dir_, {"directory"});
}

TEST_F(TemplateFile, RejectsTruncatedFiles) {
  const std::vector<std::byte> bytes = femurBytes();
  const std::span<const std::byte> all(bytes);
  expectRejected(save("t0.topo", all.first(0)), {"empty file", "not a toposlice template"});
  expectRejected(save("t4.topo", all.first(4)), {"truncated", "4 bytes", "header"});
  expectRejected(save("t12.topo", all.first(12)), {"truncated", "12 bytes", "header"});
  expectRejected(save("t31.topo", all.first(31)), {"truncated", "header"});
  expectRejected(save("t32.topo", all.first(32)), {"truncated", "14622 facets needs 175504"});
  expectRejected(save("tmid.topo", all.first(bytes.size() / 2)), {"truncated", "14622 facets"});
  expectRejected(save("tlast.topo", all.first(bytes.size() - 1)), {"truncated", "175503 bytes"});
  for (std::size_t size = 0; size < bytes.size(); size += 997) {
    EXPECT_THROW(parseTemplate(all.first(size), "cut"), InputError) << size;
  }
}

TEST_F(TemplateFile, RejectsFlippedBytes) {
  const std::vector<std::byte> good = femurBytes();
  struct Case {
    std::size_t offset;
    const char* what;  // expected part of the message
  };
  const std::size_t payload = kTemplateHeaderSize + 12 * 7000 + 5;
  const Case cases[] = {
      {0, "not a toposlice template"},
      {7, "not a toposlice template"},
      {8, "unsupported template version"},
      {11, "unsupported template version"},
      {12, "facets needs"},
      {15, "facets needs"},
      {16, "corrupt: checksum mismatch"},
      {20, "corrupt: checksum mismatch"},
      {24, "corrupt: checksum mismatch"},
      {31, "corrupt: checksum mismatch"},
      {32, "corrupt: checksum mismatch"},
      {payload, "corrupt: checksum mismatch"},
      {good.size() - 9, "corrupt"},
      {good.size() - 8, "corrupt"},
      {good.size() - 1, "corrupt"},
  };
  for (const Case& c : cases) {
    for (const std::byte flip : {std::byte{0x01}, std::byte{0x80}}) {
      std::vector<std::byte> bad = good;
      bad[c.offset] ^= flip;
      expectRejected(save("flipped.topo", bad), {c.what});
    }
  }
}

TEST_F(TemplateFile, RejectsWrongVersion) {
  std::vector<std::byte> bytes = femurBytes();
  bytes[8] = std::byte{2};
  expectRejected(save("v2.topo", bytes), {"unsupported template version 2", "reads version 1"});
  fixChecksum(bytes);
  expectRejected(save("v2fixed.topo", bytes), {"unsupported template version 2"});
  bytes[8] = std::byte{0};
  fixChecksum(bytes);
  expectRejected(save("v0.topo", bytes), {"unsupported template version 0"});
}

TEST_F(TemplateFile, RejectsTrailingGarbage) {
  std::vector<std::byte> bytes = femurBytes();
  bytes.push_back(std::byte{0});
  expectRejected(save("trail1.topo", bytes), {"175505 bytes", "trailing data"});
  bytes.insert(bytes.end(), 1000, std::byte{0x5a});
  expectRejected(save("trail1000.topo", bytes), {"trailing data"});
  std::vector<std::byte> twice = femurBytes();
  const std::vector<std::byte> once = twice;
  twice.insert(twice.end(), once.begin(), once.end());
  expectRejected(save("twice.topo", twice), {"trailing data"});
}

TEST_F(TemplateFile, RejectsInvalidTablesBehindValidChecksum) {
  const TemplateTable& good = femur();
  const int32_t t = static_cast<int32_t>(good.facetCount);
  const auto written = [&](const char* name, const std::function<void(TemplateTable&)>& edit) {
    TemplateTable bad = good;
    edit(bad);
    writeTemplateFile(dir_ / name, bad, false);  // written as given, with a valid checksum
    return dir_ / name;
  };
  // Facet 0 edge 0 names another facet that does not name facet 0 back.
  expectRejected(
      written("asym.topo", [&](TemplateTable& b) { b.adjacency[0] = (b.adjacency[0] + t / 2) % t; }),
      {"facet 0 edge 0", "not symmetric"});
  // One side of a pair erased: the neighbour still names the facet.
  const std::size_t e = 3 * 5000 + 2;
  expectRejected(written("oneside.topo", [&](TemplateTable& b) { b.adjacency[e] = -1; }), {"not symmetric"});
  // Entries whose old neighbour has a higher index, so that the edited entry is the first one found bad
  // (its old neighbour, now unmatched, comes later in the scan).
  std::vector<std::size_t> upward;
  for (std::size_t i = 3 * 77; upward.size() < 3; ++i) {
    if (good.adjacency[i] > static_cast<int32_t>(i / 3)) upward.push_back(i);
  }
  const auto where = [](std::size_t entry) {
    return "facet " + std::to_string(entry / 3) + " edge " + std::to_string(entry % 3) + ": neighbour ";
  };
  expectRejected(written("range.topo", [&](TemplateTable& b) { b.adjacency[upward[0]] = t; }),
                 {where(upward[0]).c_str(), "14622 is out of range"});
  expectRejected(written("minus2.topo", [&](TemplateTable& b) { b.adjacency[upward[1]] = -2; }),
                 {where(upward[1]).c_str(), "-2 is out of range"});
  expectRejected(
      written("self.topo",
              [&](TemplateTable& b) { b.adjacency[upward[2]] = static_cast<int32_t>(upward[2] / 3); }),
      {where(upward[2]).c_str(), "its own facet"});
  expectRejected(written("vertices.topo", [&](TemplateTable& b) { b.vertexCount = 3 * b.facetCount + 1; }),
                 {"vertex count", "impossible"});

  // Unknown flags behind a valid checksum: written by a newer format revision.
  std::vector<std::byte> bytes = femurBytes();
  bytes[20] = std::byte{1};
  fixChecksum(bytes);
  expectRejected(save("flags.topo", bytes), {"flags"});
}

TEST_F(TemplateFile, RandomMutationsNeverYieldAWrongTable) {
  const TemplateTable tet = tableOf(tetrahedron());
  writeTemplateFile(dir_ / "tet.topo", tet, false);
  const std::vector<std::byte> good = readBytes(dir_ / "tet.topo");
  std::mt19937 rng(1234);
  for (int round = 0; round < 4000; ++round) {
    std::vector<std::byte> bytes = good;
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int k = 0; k < edits; ++k) {
      switch (rng() % 4) {
        case 0:  // flip bits of one byte
          bytes[rng() % bytes.size()] ^= std::byte(static_cast<unsigned char>(1 + rng() % 255));
          break;
        case 1:  // cut
          bytes.resize(rng() % (bytes.size() + 1));
          break;
        case 2:  // append
          bytes.push_back(std::byte(static_cast<unsigned char>(rng())));
          break;
        default:  // rewrite one entry to a random small value, as a buggy writer would
          if (bytes.size() == good.size()) {
            const int32_t v = static_cast<int32_t>(rng() % 8) - 2;
            std::memcpy(bytes.data() + kTemplateHeaderSize + 4 * (rng() % 12), &v, 4);
          }
      }
      if (bytes.empty()) break;
    }
    const bool fixed = bytes.size() == good.size() && rng() % 2 == 0;
    if (fixed) fixChecksum(bytes);
    try {
      const TemplateTable loaded = parseTemplate(bytes, "mutant");
      EXPECT_TRUE(validTable(loaded)) << "round " << round;
      if (!fixed) {
        EXPECT_EQ(loaded, tet) << "round " << round;
      }
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("mutant: ", 0), 0u);
    }
  }
}

}  // namespace
}  // namespace toposlice
