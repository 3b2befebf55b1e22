// Mesh input (io/readers/mesh_reader.h): analytic PLY, OBJ and 3MF cubes written here, detection by
// content, units and scale, malformed files, and the shared models (PLY/OBJ against their STL siblings,
// every file loads or fails with one line naming it).
#include "io/readers/mesh_reader.h"

#include <gtest/gtest.h>
#include <zip.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "core/mesh/mesh_info.h"
#include "io/errors.h"
#include "io/readers/lib3mf_handle.h"
#include "io/readers/ply_reader.h"
#include "io/readers/stl_reader.h"
#include "tests/fixtures/gzip_bytes.h"
#include "tests/fixtures/runners.h"
#include "tests/fixtures/scratch_dir.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;

fs::path modelsDir() {
  return fs::path(TOPOSLICE_MODELS_DIR);
}

bool haveModels() {
  return fs::is_directory(modelsDir());
}

Bytes bytesOf(std::string_view text) {
  Bytes bytes(text.size());
  if (!text.empty()) std::memcpy(bytes.data(), text.data(), text.size());
  return bytes;
}

void writeFile(const fs::path& path, const Bytes& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

using fixtures::gzipped;

// The message of the InputError that `load` throws ("" when it loads, with a test failure).
template <class F>
std::string errorOf(F&& load) {
  try {
    load();
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no InputError";
  return "";
}

BoundingBox bounds(const FacetSoup& soup) {
  return boundsOf(soup.corners);
}

// The unit cube [0,1]^3: 8 corners, 6 quads counter-clockwise seen from outside (PLY/0-based order).
constexpr float kCubeVertices[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                       {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
constexpr int kCubeQuads[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                  {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};

void expectUnitCube(const FacetSoup& soup, double size = 1.0, Point3f origin = {0, 0, 0}) {
  ASSERT_EQ(soup.facetCount(), 12u);
  EXPECT_NEAR(signedVolume(soup.corners), size * size * size, 1e-6 * size * size * size);
  const BoundingBox b = bounds(soup);
  EXPECT_FLOAT_EQ(b.min.x, origin.x);
  EXPECT_FLOAT_EQ(b.min.y, origin.y);
  EXPECT_FLOAT_EQ(b.min.z, origin.z);
  EXPECT_NEAR(b.max.x, origin.x + size, 1e-5 * size);
  EXPECT_NEAR(b.max.z, origin.z + size, 1e-5 * size);
}

std::string asciiPlyCube() {
  std::string text =
      "ply\nformat ascii 1.0\ncomment a unit cube of quads\nelement vertex 8\nproperty float x\n"
      "property float y\nproperty float z\nelement face 6\nproperty list uchar int "
      "vertex_indices\nend_header\n";
  for (const auto& v : kCubeVertices) {
    text += std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + "\n";
  }
  for (const auto& q : kCubeQuads) {
    text += "4 " + std::to_string(q[0]) + " " + std::to_string(q[1]) + " " + std::to_string(q[2]) + " " +
            std::to_string(q[3]) + "\n";
  }
  return text;
}

// Appends `value` in `size` bytes, in the given byte order.
template <class T>
void put(Bytes& out, T value, bool bigEndian) {
  unsigned char raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  if (bigEndian == (std::endian::native == std::endian::little)) std::reverse(raw, raw + sizeof(T));
  for (unsigned char c : raw) out.push_back(std::byte{c});
}

// The cube as binary PLY with an extra element before the vertices, x as double, y as float, z as
// int16, extra vertex properties (a normal, a colour, a list) and extra face properties.
Bytes binaryPlyCube(bool bigEndian) {
  const std::string header =
      std::string("ply\r\nformat ") + (bigEndian ? "binary_big_endian" : "binary_little_endian") +
      " 1.0\r\n"
      "obj_info made by a test\r\n"
      "element material 2\r\nproperty uchar red\r\nproperty list ushort float coefficients\r\n"
      "element vertex 8\r\nproperty double x\r\nproperty float nx\r\nproperty float32 y\r\n"
      "property uint8 red\r\nproperty int16 z\r\nproperty list uchar int16 tags\r\n"
      "element face 6\r\nproperty uchar flags\r\nproperty list ushort uint vertex_indices\r\n"
      "property list uchar float texcoord\r\n"
      "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\nend_header\r\n";
  Bytes out = bytesOf(header);
  for (int m = 0; m < 2; ++m) {
    put<uint8_t>(out, 7, bigEndian);
    put<uint16_t>(out, static_cast<uint16_t>(m + 1), bigEndian);
    for (int k = 0; k <= m; ++k) put<float>(out, 0.5f, bigEndian);
  }
  for (const auto& v : kCubeVertices) {
    put<double>(out, v[0], bigEndian);
    put<float>(out, -1.0f, bigEndian);
    put<float>(out, v[1], bigEndian);
    put<uint8_t>(out, 200, bigEndian);
    put<int16_t>(out, static_cast<int16_t>(v[2]), bigEndian);
    put<uint8_t>(out, 2, bigEndian);
    put<int16_t>(out, 11, bigEndian);
    put<int16_t>(out, 12, bigEndian);
  }
  for (const auto& q : kCubeQuads) {
    put<uint8_t>(out, 1, bigEndian);
    put<uint16_t>(out, 4, bigEndian);
    for (int c : q) put<uint32_t>(out, static_cast<uint32_t>(c), bigEndian);
    put<uint8_t>(out, 0, bigEndian);
  }
  put<int32_t>(out, 0, bigEndian);
  put<int32_t>(out, 1, bigEndian);
  return out;
}

// The cube as OBJ: quads, relative (negative) indices, v//vn and v/vt/vn corners, two groups, a material
// library that does not exist.
std::string objCube() {
  std::string text = "# cube\nmtllib missing.mtl\no cube\n";
  for (const auto& v : kCubeVertices) {
    text += "v " + std::to_string(v[0]) + " " + std::to_string(v[1]) + " " + std::to_string(v[2]) + " 1.0\n";
  }
  text += "vn 0 0 1\nvt 0 0\ng bottom_and_top\nusemtl red\n";
  for (int f = 0; f < 6; ++f) {
    const auto& q = kCubeQuads[f];
    if (f == 2) text += "g sides\ns 1\n";
    text += "f";
    for (int c = 0; c < 4; ++c) {
      if (f % 3 == 0) text += " " + std::to_string(q[c] - 8);  // -8 is the first of the 8 vertices
      if (f % 3 == 1) text += " " + std::to_string(q[c] + 1) + "//1";
      if (f % 3 == 2) text += " " + std::to_string(q[c] + 1) + "/1/1";
    }
    text += "\n";
  }
  return text;
}

TEST(MeshReader, AsciiPlyCubeOfQuads) {
  MeshSource source;
  const FacetSoup soup = parseMesh(bytesOf(asciiPlyCube()), "cube.ply", {}, &source);
  expectUnitCube(soup);
  EXPECT_EQ(source.format, MeshFormat::Ply);
  EXPECT_FALSE(source.binary);
  EXPECT_EQ(source.polygonsTriangulated, 6u);
  // The fan (0, i, i+1) of the first quad (0 3 2 1).
  EXPECT_FLOAT_EQ(soup.corners[1].y, 1.0f);
  EXPECT_FLOAT_EQ(soup.corners[2].x, 1.0f);
  EXPECT_FLOAT_EQ(soup.corners[2].y, 1.0f);
}

TEST(MeshReader, BinaryPlyCubeBothByteOrdersWithExtraPropertiesAndElements) {
  for (const bool bigEndian : {false, true}) {
    SCOPED_TRACE(bigEndian ? "big endian" : "little endian");
    MeshSource source;
    const FacetSoup soup = parseMesh(binaryPlyCube(bigEndian), "cube.ply", {}, &source);
    expectUnitCube(soup);
    EXPECT_TRUE(source.binary);
    EXPECT_EQ(source.polygonsTriangulated, 6u);
  }
}

TEST(MeshReader, PlyErrorsNameTheFaceVertexOrHeaderLine) {
  std::string text = asciiPlyCube();
  const auto replaced = [&](std::string_view from, std::string_view to) {
    std::string copy = text;
    copy.replace(copy.find(from), from.size(), to);
    return bytesOf(copy);
  };
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("4 0 3 2 1", "2 0 3"), "a.ply"); }),
            "a.ply: face 0 (line 19): 2 corners, expected at least 3");
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("4 4 5 6 7", "4 4 5 6 8"), "a.ply"); }),
            "a.ply: face 1 (line 20): vertex index 8 out of range (8 vertices)");
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("property float y", "property floot y"), "a.ply"); }),
            "a.ply: PLY header line 6: unknown property type 'floot'");
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("1.000000 1.000000 1.000000", "nan 1 1"), "a.ply"); }),
            "a.ply: vertex 6 (line 17): non-finite coordinate (NaN or infinity)");
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("end_header\n", "end_header\n0 0"), "a.ply"); }).substr(0, 13),
            "a.ply: line 1");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(text.substr(0, text.size() - 10)), "a.ply"); }),
            "a.ply: line 24: truncated: the data ends inside face 5");
  EXPECT_EQ(errorOf([&] {
              parseMesh(
                  bytesOf("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                          "property float z\nend_header\n"),
                  "a.ply");
            }),
            "a.ply: contains no facets");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("ply\nformat ascii 1.0\nelement vertex 1\n"), "a.ply"); }),
            "a.ply: PLY header: the file ends before 'end_header'");

  // Hostile counts are checked against the bytes left before anything is allocated.
  Bytes binary = binaryPlyCube(false);
  std::string header(reinterpret_cast<const char*>(binary.data()), 400);
  const std::size_t at = header.find("element vertex 8");
  const std::string huge = "element vertex 4000000000";
  Bytes hostile(binary.begin(), binary.begin() + static_cast<std::ptrdiff_t>(at));
  for (char c : huge) hostile.push_back(static_cast<std::byte>(c));
  hostile.insert(hostile.end(), binary.begin() + static_cast<std::ptrdiff_t>(at + 16), binary.end());
  EXPECT_EQ(
      errorOf([&] { parseMesh(hostile, "h.ply"); }),
      "h.ply: truncated: element 'vertex' declares 4000000000 records, more than the data after the header "
      "can hold");
  Bytes cut(binary.begin(), binary.end() - 20);
  EXPECT_EQ(errorOf([&] { parseMesh(cut, "c.ply"); }), "c.ply: truncated: the data ends inside face 5");

  // A face count that is too small left faces unread, silently: the data after the last element is an
  // error, ASCII or binary (the fixed-record reader leaves it to the record reader); trailing blanks are
  // fine in ASCII.
  EXPECT_EQ(errorOf([&] { parseMesh(replaced("element face 6", "element face 5"), "a.ply"); }),
            "a.ply: data after the last element, line 24: the header's element counts do not cover the file");
  EXPECT_NO_THROW(parseMesh(bytesOf(text + "\n \n"), "a.ply"));
  Bytes longer = binary;
  longer.insert(longer.end(), 4, std::byte{0});
  EXPECT_EQ(errorOf([&] { parseMesh(longer, "l.ply"); }),
            "l.ply: 4 bytes after the last element: the header's element counts do not cover the file");
}

// A runner that calls the chunks last first, as if four threads took them in any order: the fixed-record
// PLY reader must give the same soup as the serial runner.
ChunkRunner backwardsRunner() {
  return fixtures::shuffledRunner(true, 4);
}

// A binary PLY of `faces` random triangles over `vertices` points (a fixed seed), with what scanners and
// VTK add: a fixed-size element before the vertices, x as double, normals and a colour, a face flag.
// `faceAt` may change a face's count or corners (count, corners), and `header` the element lines.
struct RandomPly {
  std::size_t vertices = 40000, faces = 70000;
  bool bigEndian = false;
  std::string countType = "uchar", indexType = "int";
  std::function<void(std::size_t, int&, std::vector<int64_t>&)> faceAt;
  std::function<float(std::size_t, int)> coordinate;

  Bytes bytes() const {
    std::string header = std::string("ply\nformat ") +
                         (bigEndian ? "binary_big_endian" : "binary_little_endian") +
                         " 1.0\nelement camera 1\nproperty float focal\nproperty int16 id\n"
                         "element vertex " +
                         std::to_string(vertices) +
                         "\nproperty double x\nproperty float y\nproperty float z\nproperty float nx\n"
                         "property uchar red\nelement face " +
                         std::to_string(faces) + "\nproperty uchar flags\nproperty list " + countType + " " +
                         indexType + " vertex_indices\nend_header\n";
    Bytes out = bytesOf(header);
    put<float>(out, 35.0f, bigEndian);
    put<int16_t>(out, 3, bigEndian);
    uint64_t state = 12345;
    const auto next = [&] {
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      return static_cast<int64_t>(state >> 33);
    };
    for (std::size_t v = 0; v < vertices; ++v) {
      float xyz[3];
      for (int k = 0; k < 3; ++k)
        xyz[k] = coordinate ? coordinate(v, k) : static_cast<float>(next() % 100000) * 0.001f - 50.0f;
      put<double>(out, xyz[0], bigEndian);
      put<float>(out, xyz[1], bigEndian);
      put<float>(out, xyz[2], bigEndian);
      put<float>(out, 0.25f, bigEndian);
      put<uint8_t>(out, 9, bigEndian);
    }
    const auto putTyped = [&](const std::string& type, int64_t value) {
      if (type == "uchar") put<uint8_t>(out, static_cast<uint8_t>(value), bigEndian);
      if (type == "ushort") put<uint16_t>(out, static_cast<uint16_t>(value), bigEndian);
      if (type == "int") put<int32_t>(out, static_cast<int32_t>(value), bigEndian);
      if (type == "uint") put<uint32_t>(out, static_cast<uint32_t>(value), bigEndian);
    };
    std::vector<int64_t> corners;
    for (std::size_t f = 0; f < faces; ++f) {
      int count = 3;
      const auto n = static_cast<int64_t>(vertices);
      corners = {next() % n, next() % n, next() % n};
      if (faceAt) faceAt(f, count, corners);
      put<uint8_t>(out, 1, bigEndian);
      putTyped(countType, count);
      for (const int64_t c : corners) putTyped(indexType, c);
    }
    return out;
  }
};

bool sameCorners(const FacetSoup& a, const FacetSoup& b) {
  return a.corners.size() == b.corners.size() &&
         (a.corners.empty() ||  // no memcmp of an empty vector's null data
          std::memcmp(a.corners.data(), b.corners.data(), a.corners.size() * sizeof(Point3f)) == 0);
}

// The fixed-record reader (chunks on a runner) gives the record-by-record soup, bit for bit, in both byte
// orders and with other count and index types; the shared VTK PLYs too.
TEST(MeshReader, BinaryPlyInChunksIsTheRecordByRecordSoup) {
  for (const bool bigEndian : {false, true}) {
    for (const auto& [countType, indexType] : std::vector<std::pair<std::string, std::string>>{
             {"uchar", "int"}, {"uint", "uint"}, {"uchar", "ushort"}}) {
      SCOPED_TRACE(std::string(bigEndian ? "big" : "little") + " " + countType + " " + indexType);
      RandomPly ply;
      ply.bigEndian = bigEndian;
      ply.countType = countType;
      ply.indexType = indexType;
      if (indexType == "ushort") ply.vertices = 60000;
      const Bytes bytes = ply.bytes();
      PlySource fixed, records;
      const FacetSoup a = parsePly(bytes, "r.ply", &fixed, backwardsRunner());
      const FacetSoup b = parsePly(bytes, "r.ply");
      const FacetSoup c = parsePlyRecords(bytes, "r.ply", &records);
      ASSERT_EQ(a.facetCount(), ply.faces);
      EXPECT_TRUE(sameCorners(a, c));
      EXPECT_TRUE(sameCorners(b, c));
      EXPECT_TRUE(fixed.binary && records.binary);
      EXPECT_EQ(fixed.polygonsTriangulated, 0u);
    }
  }
  if (!haveModels()) return;
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(modelsDir())) {
    if (entry.path().extension() != ".ply") continue;
    SCOPED_TRACE(entry.path().filename().string());
    std::ifstream in(entry.path(), std::ios::binary);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const Bytes bytes = bytesOf(text);
    EXPECT_TRUE(
        sameCorners(parsePly(bytes, "m.ply", nullptr, backwardsRunner()), parsePlyRecords(bytes, "m.ply")));
    ++compared;
  }
  EXPECT_GE(compared, 6);
}

// Whatever the fixed records cannot hold is read record by record: a polygon is fanned out, and damage
// in any chunk gives the record-by-record message.
TEST(MeshReader, BinaryPlyInChunksLeavesPolygonsAndDamageToTheRecordReader) {
  const auto both = [](const RandomPly& ply, PlySource* source = nullptr) {
    const Bytes bytes = ply.bytes();
    std::string fixedError, recordError;
    FacetSoup a, b;
    try {
      a = parsePly(bytes, "d.ply", source, backwardsRunner());
    } catch (const InputError& e) {
      fixedError = e.what();
    }
    try {
      b = parsePlyRecords(bytes, "d.ply");
    } catch (const InputError& e) {
      recordError = e.what();
    }
    EXPECT_EQ(fixedError, recordError);
    EXPECT_TRUE(sameCorners(a, b));
    return fixedError;
  };
  RandomPly quad;
  quad.faceAt = [](std::size_t f, int& count, std::vector<int64_t>& c) {
    if (f == 69999) count = 4, c.push_back(7);
  };
  PlySource source;
  EXPECT_EQ(both(quad, &source), "");
  EXPECT_EQ(source.polygonsTriangulated, 1u);
  RandomPly outside;
  outside.faceAt = [](std::size_t f, int&, std::vector<int64_t>& c) {
    if (f == 65600) c[1] = 40000;
  };
  EXPECT_EQ(both(outside), "d.ply: face 65600: vertex index 40000 out of range (40000 vertices)");
  RandomPly negative;
  negative.faceAt = [](std::size_t f, int&, std::vector<int64_t>& c) {
    if (f == 3) c[2] = -1;
  };
  EXPECT_EQ(both(negative), "d.ply: face 3: vertex index -1 out of range (40000 vertices)");
  RandomPly twoCorners;
  twoCorners.faceAt = [](std::size_t f, int& count, std::vector<int64_t>& c) {
    if (f == 40000) count = 2, c.pop_back();
  };
  EXPECT_EQ(both(twoCorners), "d.ply: face 40000: 2 corners, expected at least 3");
  RandomPly notFinite;
  notFinite.coordinate = [](std::size_t v, int k) {
    return v == 39000 && k == 2 ? std::numeric_limits<float>::infinity() : static_cast<float>(v % 97);
  };
  EXPECT_EQ(both(notFinite), "d.ply: vertex 39000: non-finite coordinate (NaN or infinity)");
  RandomPly shortFaces;
  shortFaces.faces = 10;
  Bytes cut = shortFaces.bytes();
  cut.resize(cut.size() - 3);
  std::string fixedError, recordError;
  try {
    parsePly(cut, "t.ply", nullptr, backwardsRunner());
  } catch (const InputError& e) {
    fixedError = e.what();
  }
  EXPECT_EQ(fixedError, "t.ply: truncated: the data ends inside face 9");
}

TEST(MeshReader, ObjCubeWithQuadsNegativeIndicesAndNormals) {
  MeshSource source;
  const FacetSoup soup = parseMesh(bytesOf(objCube()), "cube.obj", {}, &source);
  expectUnitCube(soup);
  EXPECT_EQ(source.format, MeshFormat::Obj);
  EXPECT_EQ(source.polygonsTriangulated, 6u);
  // Same corners, same order as the PLY cube.
  const FacetSoup ply = parseMesh(bytesOf(asciiPlyCube()), "cube.ply");
  EXPECT_EQ(std::memcmp(soup.corners.data(), ply.corners.data(), soup.corners.size() * sizeof(Point3f)), 0);
}

// A UTF-8 byte order mark before the first line: the same mesh (it dropped the first vertex and shifted
// every face onto other corners, silently).
TEST(MeshReader, ObjWithAByteOrderMarkIsTheSameMesh) {
  std::string cube = objCube();
  cube.erase(0, cube.find("\nv ") + 1);  // from the first vertex line on: the mark before a "v" line
  ASSERT_TRUE(cube.starts_with("v ")) << cube.substr(0, 40);
  const FacetSoup plain = parseMesh(bytesOf(cube), "cube.obj");
  const FacetSoup marked = parseMesh(bytesOf("\xEF\xBB\xBF" + cube), "cube.obj");
  ASSERT_EQ(marked.corners.size(), plain.corners.size());
  EXPECT_EQ(std::memcmp(marked.corners.data(), plain.corners.data(), plain.corners.size() * sizeof(Point3f)),
            0);
}

// A comment after a face's corners is no corner (it was read as one, and the face refused).
TEST(MeshReader, ObjCommentsAfterStatementsAreIgnored) {
  const std::string cube = objCube();
  std::string commented;
  for (std::size_t at = 0; at < cube.size();) {
    const std::size_t end = cube.find('\n', at);
    const std::string line = cube.substr(at, end - at);
    commented += line + (line.starts_with("f ") || line.starts_with("v ") ? " # note#2" : "") + "\n";
    at = end + 1;
  }
  const FacetSoup plain = parseMesh(bytesOf(cube), "cube.obj");
  const FacetSoup withComments = parseMesh(bytesOf(commented), "cube.obj");
  ASSERT_EQ(withComments.corners.size(), plain.corners.size());
  EXPECT_EQ(
      std::memcmp(withComments.corners.data(), plain.corners.data(), plain.corners.size() * sizeof(Point3f)),
      0);
}

TEST(MeshReader, ObjErrorsNameTheFaceOrVertex) {
  const std::string cube = objCube();
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2\n"), "a.obj"); }),
            "a.obj: face 6 (line 24): 2 corners, expected at least 3");
  // A bare "f" line was skipped without a word.
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f\n"), "a.obj"); }),
            "a.obj: face 6 (line 24): 0 corners, expected at least 3");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2 9\n"), "a.obj"); }),
            "a.obj: face 6: vertex index 9 out of range (8 vertices)");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2 -9\n"), "a.obj"); }),
            "a.obj: face 6: vertex index -9 out of range (8 vertices before it)");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2 x\n"), "a.obj"); }),
            "a.obj: face 6 (line 24): corner 2: vertex index 'x' is not a whole number");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2 0\n"), "a.obj"); }),
            "a.obj: face 6: corner 2 has vertex index 0 or no number");
  // Indices an int does not hold wrapped to a real vertex (4294967297 to 1) and were accepted.
  for (const char* index : {"4294967297", "-4294967295", "2147483648", "99999999999999999999"})
    EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(cube + "f 1 2/7 " + index + "/1\n"), "a.obj"); }),
              "a.obj: face 6 (line 24): corner 2: vertex index '" + std::string(index) + "' is out of range");
  // A missing coordinate was read as 0 (the mesh flattened, silently).
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("v 0 0 0\nv 1 0 0\nv 0 0 # z?\nf 1 2 3\n"), "a.obj"); }),
            "a.obj: vertex 3 (line 3): expected 3 coordinates, found 2");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("v 0 0 0\nv 1 0 0\nv\nv 0 1 0\nf 1 2 3\n"), "a.obj"); }),
            "a.obj: vertex 3 (line 3): expected 3 coordinates, found 0");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("v 0 0 0\nv 1 0 0\nv 0 1e99 0\nf 1 2 3\n"), "a.obj"); }),
            "a.obj: vertex 3: non-finite coordinate (NaN, infinity or beyond float's range)");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("v 0 0 0\n  v 1 nan 0\nv 0 1 0\nf 1 2 3\n"), "a.obj"); }),
            "a.obj: vertex 2 (line 2): coordinate 'nan' is not a finite number");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("v 0 0 0\nv 1 0 0\nv 0 1,5 0\nf 1 2 3\n"), "a.obj"); }),
            "a.obj: vertex 3 (line 3): coordinate '1,5' is not a finite number");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("# nothing\nv 0 0 0\nvn 0 0 1\n"), "a.obj"); }),
            "a.obj: contains no facets");
  // A face may name vertices defined after it.
  EXPECT_EQ(parseMesh(bytesOf("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"), "a.obj").facetCount(), 1u);
}

// ---- 3MF, written with lib3mf -------------------------------------------------------------------------

NMR::MODELTRANSFORM translation(float x, float y, float z) {
  NMR::MODELTRANSFORM t{};
  for (int r = 0; r < 3; ++r) t.m_fFields[r][r] = 1;
  t.m_fFields[0][3] = x;
  t.m_fFields[1][3] = y;
  t.m_fFields[2][3] = z;
  return t;
}

// A unit cube in `unit`, placed by a build item translated by `offset`; optionally a second build item of
// type support (skipped by the reader) and a mirrored components object.
void writeThreeMfCube(const fs::path& path, DWORD unit, NMR::MODELTRANSFORM offset, bool withSupport) {
  Lib3mfHandle model, mesh, item, writer;
  ASSERT_EQ(NMR::lib3mf_createmodel(model.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_setunit(model.get(), unit), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_addmeshobject(model.get(), mesh.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_object_setnameutf8(mesh.get(), "cube"), LIB3MF_OK);
  std::vector<NMR::MODELMESHVERTEX> vertices(8);
  for (int v = 0; v < 8; ++v) {
    for (int k = 0; k < 3; ++k) vertices[v].m_fPosition[k] = kCubeVertices[v][k];
  }
  std::vector<NMR::MODELMESHTRIANGLE> triangles;
  for (const auto& q : kCubeQuads) {
    triangles.push_back({{DWORD(q[0]), DWORD(q[1]), DWORD(q[2])}});
    triangles.push_back({{DWORD(q[0]), DWORD(q[2]), DWORD(q[3])}});
  }
  ASSERT_EQ(NMR::lib3mf_meshobject_setgeometry(mesh.get(), vertices.data(), 8, triangles.data(), 12),
            LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_addbuilditem(model.get(), mesh.get(), &offset, item.out()), LIB3MF_OK);
  if (withSupport) {
    Lib3mfHandle support, supportItem, assembly, component, assemblyItem;
    ASSERT_EQ(NMR::lib3mf_model_addmeshobject(model.get(), support.out()), LIB3MF_OK);
    ASSERT_EQ(NMR::lib3mf_meshobject_setgeometry(support.get(), vertices.data(), 8, triangles.data(), 12),
              LIB3MF_OK);
    ASSERT_EQ(NMR::lib3mf_object_settype(support.get(), NMR::MODELOBJECTTYPE_SUPPORT), LIB3MF_OK);
    ASSERT_EQ(NMR::lib3mf_model_addbuilditem(model.get(), support.get(), nullptr, supportItem.out()),
              LIB3MF_OK);
    // The cube again, mirrored in x by a component transform and moved to x in [-3, -2] by its build item.
    ASSERT_EQ(NMR::lib3mf_model_addcomponentsobject(model.get(), assembly.out()), LIB3MF_OK);
    NMR::MODELTRANSFORM mirror = translation(0, 0, 0);
    mirror.m_fFields[0][0] = -1;
    ASSERT_EQ(NMR::lib3mf_componentsobject_addcomponent(assembly.get(), mesh.get(), &mirror, component.out()),
              LIB3MF_OK);
    NMR::MODELTRANSFORM place = translation(-2, 0, 0);
    ASSERT_EQ(NMR::lib3mf_model_addbuilditem(model.get(), assembly.get(), &place, assemblyItem.out()),
              LIB3MF_OK);
  }
  ASSERT_EQ(NMR::lib3mf_model_querywriter(model.get(), "3mf", writer.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_writer_writetofileutf8(writer.get(), path.c_str()), LIB3MF_OK);
}

TEST(MeshReader, ThreeMfCubeInCentimetresComesBackInMillimetres) {
  fixtures::ScratchDir dir;
  writeThreeMfCube(dir / "cube.3mf", NMR::MODELUNIT_CENTIMETER, translation(2, 3, 4), false);
  MeshSource source;
  const FacetSoup soup = readMesh(dir / "cube.3mf", {}, &source);
  expectUnitCube(soup, 10.0, {20, 30, 40});
  EXPECT_EQ(source.format, MeshFormat::ThreeMf);
  EXPECT_EQ(source.fileUnit, "centimeter");
  EXPECT_EQ(source.name, "cube");

  MeshReadOptions scaled;
  scaled.scale = 2;
  expectUnitCube(readMesh(dir / "cube.3mf", scaled), 20.0, {40, 60, 80});

  MeshReadOptions units;
  units.unitMm = 25.4;
  const std::string name = (dir / "cube.3mf").string();
  EXPECT_EQ(errorOf([&] { readMesh(dir / "cube.3mf", units); }),
            name + ": 3MF files state their unit (centimeter); --units does not apply");
}

TEST(MeshReader, ThreeMfSkipsSupportsAndResolvesMirroredComponents) {
  fixtures::ScratchDir dir;
  writeThreeMfCube(dir / "parts.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), true);
  const FacetSoup soup = readMesh(dir / "parts.3mf");
  ASSERT_EQ(soup.facetCount(), 24u);  // the cube and its mirror image; the support is skipped
  EXPECT_NEAR(signedVolume(soup.corners), 2.0, 1e-9);  // the mirrored copy still faces outwards
  const BoundingBox b = bounds(soup);
  EXPECT_FLOAT_EQ(b.min.x, -3);
  EXPECT_FLOAT_EQ(b.max.x, 1);
}

// Components place an object again and again: a few kilobytes can expand to more facets than the
// adjacency's int32 indices hold (or than memory does). The reader counts the expansion, each object
// once, before placing anything: a 1,000-facet mesh placed 1,000 times by an object that is placed 3,000
// times (3e9 facets) is refused.
TEST(MeshReader, ThreeMfComponentsExpandingPastTheFacetLimitAreRefused) {
  fixtures::ScratchDir dir;
  Lib3mfHandle model, mesh, assembly, outer, item, writer;
  ASSERT_EQ(NMR::lib3mf_createmodel(model.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_addmeshobject(model.get(), mesh.out()), LIB3MF_OK);
  constexpr DWORD kTriangles = 1000;
  std::vector<NMR::MODELMESHVERTEX> vertices(kTriangles + 2);
  for (DWORD v = 0; v < kTriangles + 2; ++v) {
    vertices[v].m_fPosition[0] = static_cast<float>(v / 2);
    vertices[v].m_fPosition[1] = static_cast<float>(v % 2);
    vertices[v].m_fPosition[2] = 0;
  }
  std::vector<NMR::MODELMESHTRIANGLE> triangles(kTriangles);  // a strip
  for (DWORD t = 0; t < kTriangles; ++t) triangles[t] = {{t, t + 1, t + 2}};
  ASSERT_EQ(NMR::lib3mf_meshobject_setgeometry(mesh.get(), vertices.data(), kTriangles + 2, triangles.data(),
                                               kTriangles),
            LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_addcomponentsobject(model.get(), assembly.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_addcomponentsobject(model.get(), outer.out()), LIB3MF_OK);
  for (int i = 0; i < 3000; ++i) {
    Lib3mfHandle component;
    NMR::MODELTRANSFORM at = translation(0, 0, static_cast<float>(i));
    if (i < 1000) {
      ASSERT_EQ(NMR::lib3mf_componentsobject_addcomponent(assembly.get(), mesh.get(), &at, component.out()),
                LIB3MF_OK);
    }
    Lib3mfHandle placed;
    ASSERT_EQ(NMR::lib3mf_componentsobject_addcomponent(outer.get(), assembly.get(), &at, placed.out()),
              LIB3MF_OK);
  }
  ASSERT_EQ(NMR::lib3mf_model_addbuilditem(model.get(), outer.get(), nullptr, item.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_model_querywriter(model.get(), "3mf", writer.out()), LIB3MF_OK);
  ASSERT_EQ(NMR::lib3mf_writer_writetofileutf8(writer.get(), (dir / "many.3mf").c_str()), LIB3MF_OK);
  const std::string name = (dir / "many.3mf").string();
  EXPECT_EQ(errorOf([&] { readMesh(dir / "many.3mf"); }),
            name +
                ": its build items expand through their components to more than 2147483647 facets, more "
                "than toposlice slices");
}

// Rewrites the model part of the 3MF package at `path` with `edit` (libzip, not lib3mf, which writes
// only what it understands).
void editThreeMfModel(const fs::path& path, const std::function<void(std::string&)>& edit,
                      const char* part = "3D/3dmodel.model") {
  int err = 0;
  zip_t* zip = zip_open(path.c_str(), 0, &err);
  ASSERT_NE(zip, nullptr);
  zip_stat_t st;
  zip_stat_init(&st);
  ASSERT_EQ(zip_stat(zip, part, 0, &st), 0);
  std::string model(st.size, '\0');
  zip_file_t* entry = zip_fopen(zip, part, 0);
  ASSERT_NE(entry, nullptr);
  ASSERT_EQ(zip_fread(entry, model.data(), st.size), static_cast<zip_int64_t>(st.size));
  zip_fclose(entry);
  edit(model);
  zip_source_t* source = zip_source_buffer(zip, model.data(), model.size(), 0);
  ASSERT_GE(zip_file_add(zip, part, source, ZIP_FL_OVERWRITE), 0);
  ASSERT_EQ(zip_close(zip), 0);
}

// lib3mf reads a unit it does not know as millimetres, silently (unit="parsec" came out 1:1): refused.
TEST(MeshReader, ThreeMfUnknownUnitIsRefused) {
  fixtures::ScratchDir dir;
  for (const std::string stated : {"parsec", ""}) {  // unit="" was read as millimetres
    writeThreeMfCube(dir / "cube.3mf", NMR::MODELUNIT_INCH, translation(0, 0, 0), false);
    // The same package with the model's unit attribute rewritten.
    editThreeMfModel(dir / "cube.3mf", [&](std::string& model) {
      const std::size_t unit = model.find("unit=\"inch\"");
      ASSERT_NE(unit, std::string::npos) << model.substr(0, 300);
      model.replace(unit, 11, "unit=\"" + stated + "\"");
    });
    const std::string name = (dir / "cube.3mf").string();
    EXPECT_EQ(errorOf([&] { readMesh(dir / "cube.3mf"); }),
              name + ": unknown 3MF unit '" + stated +
                  "' (a 3MF states micron, millimeter, centimeter, inch, foot or meter)");
  }
}

// A package whose model requires an extension toposlice does not honour (its geometry in beams, or a mesh
// that stands in for slices) is refused naming it; lib3mf read both as plain meshes. The extensions that
// carry no geometry toposlice would lose (materials) or that it reads (production) are accepted.
TEST(MeshReader, ThreeMfUnsupportedRequiredExtensionIsRefused) {
  fixtures::ScratchDir dir;
  const std::string beam = "http://schemas.microsoft.com/3dmanufacturing/beamlattice/2017/02";
  const std::string slice = "http://schemas.microsoft.com/3dmanufacturing/slice/2015/07";
  const std::string other = "http://example.com/3dmanufacturing/unknown/2030/01";
  const std::string production = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06";
  const std::string material = "http://schemas.microsoft.com/3dmanufacturing/material/2015/02";
  const auto require = [&](const std::string& declarations, const std::string& required) {
    writeThreeMfCube(dir / "cube.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
    editThreeMfModel(dir / "cube.3mf", [&](std::string& model) {
      const std::size_t tag = model.find("<model ");
      ASSERT_NE(tag, std::string::npos) << model.substr(0, 300);
      model.insert(tag + 7, declarations + " requiredextensions=\"" + required + "\" ");
    });
  };
  const auto refusal = [&](const std::string& declarations, const std::string& required) {
    require(declarations, required);
    return errorOf([&] { readMesh(dir / "cube.3mf"); });
  };
  const std::string name = (dir / "cube.3mf").string();
  EXPECT_EQ(refusal("xmlns:b=\"" + beam + "\"", "b"), name + ": its model requires the 3MF extension " +
                                                          beam +
                                                          " (beam lattices), which toposlice does not read");
  EXPECT_EQ(
      refusal("xmlns:p='" + production + "' xmlns:s=\"" + slice + "\"", " p  s "),
      name + ": its model requires the 3MF extension " + slice +
          " (slice stacks; its mesh may be only a low-resolution stand-in), which toposlice does not read");
  EXPECT_EQ(refusal("xmlns:q=\"" + other + "\"", "q"),
            name + ": its model requires the 3MF extension " + other +
                " (an extension toposlice does not know), which toposlice does not read");
  // Read: the cube's 12 facets.
  require("xmlns:p=\"" + production + "\" xmlns:m=\"" + material + "\"", "p m");
  EXPECT_EQ(readMesh(dir / "cube.3mf").facetCount(), 12u);
}

// lib3mf's messages name no element: a model part cut short read as "contains no facets", a triangle
// naming a vertex its mesh lacks as "Invalid model node index". Both are said as they are.
TEST(MeshReader, ThreeMfBrokenModelPartsAreNamed) {
  fixtures::ScratchDir dir;
  writeThreeMfCube(dir / "cut.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
  editThreeMfModel(dir / "cut.3mf", [](std::string& model) { model.resize(model.find("<triangles>") + 30); });
  const std::string cut = errorOf([&] { readMesh(dir / "cut.3mf"); });
  EXPECT_EQ(
      cut.rfind((dir / "cut.3mf").string() +
                    ": not a valid 3MF file: its model part 3D/3dmodel.model is cut short (its XML ends "
                    "before </model>)",
                0),
      0u)
      << cut;
  writeThreeMfCube(dir / "index.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
  editThreeMfModel(dir / "index.3mf", [](std::string& model) {
    const std::size_t triangle = model.find("<triangle ", model.find("<triangle ") + 1);  // the second
    const std::size_t v3 = model.find("v3=\"", triangle);
    ASSERT_NE(v3, std::string::npos);
    model.replace(v3 + 4, model.find('"', v3 + 4) - v3 - 4, "9");
  });
  const std::string what = errorOf([&] { readMesh(dir / "index.3mf"); });
  EXPECT_NE(what.find("triangle 1: v3=\"9\" is no vertex of its mesh (it has 8)"), std::string::npos) << what;
  // Well-formed XML the scan must read as lib3mf does: white space around '=' and around a number.
  writeThreeMfCube(dir / "spaced.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
  const FacetSoup plain = readMesh(dir / "spaced.3mf");
  editThreeMfModel(dir / "spaced.3mf", [](std::string& model) {
    for (std::size_t at = model.find("<vertex x=\""); at != std::string::npos;
         at = model.find("<vertex x=\"", at))
      model.replace(at, 11, "<vertex x = \" ");
    for (std::size_t at = model.find(" v1=\""); at != std::string::npos; at = model.find(" v1=\"", at + 1))
      model.replace(at, 5, " v1 =\" ");
  });
  const FacetSoup spaced = readMesh(dir / "spaced.3mf");
  ASSERT_EQ(spaced.corners.size(), plain.corners.size());
  EXPECT_EQ(std::memcmp(spaced.corners.data(), plain.corners.data(), plain.corners.size() * sizeof(Point3f)),
            0);
  // A relationship to a part the package does not hold (PrusaSlicer's headless export names a thumbnail
  // it leaves out; lib3mf refused the package: "Could not create OPC Part"): the model is read all the same.
  writeThreeMfCube(dir / "thumb.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
  editThreeMfModel(
      dir / "thumb.3mf",
      [](std::string& rels) {
        const std::size_t end = rels.rfind("</Relationships>");
        ASSERT_NE(end, std::string::npos) << rels;
        rels.insert(end,
                    "<Relationship Target=\"/Metadata/thumbnail.png\" Id=\"rel-2\" "
                    "Type=\"http://schemas.openxmlformats.org/package/2006/relationships/metadata/"
                    "thumbnail\"/>");
      },
      "_rels/.rels");
  const FacetSoup thumb = readMesh(dir / "thumb.3mf");
  ASSERT_EQ(thumb.corners.size(), plain.corners.size());
  EXPECT_EQ(std::memcmp(thumb.corners.data(), plain.corners.data(), plain.corners.size() * sizeof(Point3f)),
            0);
  // A coordinate that is not a number, which lib3mf reads as what it can of it (0, or 1 of "1,5").
  for (const char* value : {"abc", "1,5", ""}) {
    writeThreeMfCube(dir / "x.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
    editThreeMfModel(dir / "x.3mf", [&](std::string& model) {
      const std::size_t x = model.find("x=\"", model.find("<vertex "));
      model.replace(x + 3, model.find('"', x + 3) - x - 3, value);
    });
    const std::string bad = errorOf([&] { readMesh(dir / "x.3mf"); });
    EXPECT_NE(bad.find(std::string("vertex 0: x=\"") + value + "\" is not a number"), std::string::npos)
        << bad;
  }
}

// A package holding two parts of one name (or of names OPC takes as one: case is ignored) does not say
// what its model is: libzip and lib3mf read the first, other readers the last. It was read as the first.
TEST(MeshReader, ThreeMfPartsNamedTwiceAreRefused) {
  fixtures::ScratchDir dir;
  const auto withPart = [&](const char* added) {
    writeThreeMfCube(dir / "two.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
    int err = 0;
    zip_t* zip = zip_open((dir / "two.3mf").c_str(), 0, &err);
    ASSERT_NE(zip, nullptr);
    static const char kOther[] = "<?xml version=\"1.0\"?><model unit=\"millimeter\"/>";
    zip_source_t* source = zip_source_buffer(zip, kOther, sizeof kOther - 1, 0);
    ASSERT_GE(zip_file_add(zip, added, source, 0), 0);
    ASSERT_EQ(zip_close(zip), 0);
  };
  const std::string name = (dir / "two.3mf").string();
  withPart("3D/3DMODEL.MODEL");
  EXPECT_EQ(errorOf([&] { readMesh(dir / "two.3mf"); }),
            name +
                ": not a valid 3MF file: its package holds two parts named 3D/3DMODEL.MODEL, and readers "
                "differ in which one they read");
  // The same name byte for byte: libzip cannot write it, so the added part's name is changed in the bytes.
  withPart("3D/3dmodel.modeX");
  std::string bytes = fixtures::readFile(dir / "two.3mf");
  std::size_t renamed = 0;
  for (std::size_t at = bytes.find("3D/3dmodel.modeX"); at != std::string::npos;
       at = bytes.find("3D/3dmodel.modeX", at + 1), ++renamed)
    bytes[at + 15] = 'l';
  ASSERT_EQ(renamed, 2u);  // the local header and the central directory
  writeFile(dir / "two.3mf", bytesOf(bytes));
  EXPECT_EQ(errorOf([&] { readMesh(dir / "two.3mf"); }),
            name +
                ": not a valid 3MF file: its package holds two parts named 3D/3dmodel.model, and readers "
                "differ in which one they read");
  withPart("3D/other.model");  // another part beside the model is fine
  EXPECT_EQ(readMesh(dir / "two.3mf").facetCount(), 12u);
}

TEST(MeshReader, ThreeMfDamagedPackage) {
  fixtures::ScratchDir dir;
  writeThreeMfCube(dir / "cube.3mf", NMR::MODELUNIT_MILLIMETER, translation(0, 0, 0), false);
  std::ifstream in(dir / "cube.3mf", std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string message =
      errorOf([&] { parseMesh(bytesOf(bytes.substr(0, bytes.size() / 2)), "half.3mf"); });
  EXPECT_EQ(message.rfind("half.3mf: not a valid 3MF file: ", 0), 0u) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos);
}

// ---- Detection by content ---------------------------------------------------------------------------

TEST(MeshReader, FormatComesFromTheContentNotTheName) {
  fixtures::ScratchDir dir;
  writeFile(dir / "x.stl", bytesOf(asciiPlyCube()));
  writeFile(dir / "y.ply", bytesOf(objCube()));
  writeFile(dir / "z.stl.gz", gzipped(binaryPlyCube(true)));
  MeshSource source;
  expectUnitCube(readMesh(dir / "x.stl", {}, &source));
  EXPECT_EQ(source.format, MeshFormat::Ply);
  expectUnitCube(readMesh(dir / "y.ply", {}, &source));
  EXPECT_EQ(source.format, MeshFormat::Obj);
  expectUnitCube(readMesh(dir / "z.stl.gz", {}, &source));
  EXPECT_EQ(source.format, MeshFormat::Ply);
  EXPECT_TRUE(source.gzip);
  EXPECT_TRUE(source.binary);
  EXPECT_STREQ(meshFormatName(source.format), "PLY");
}

TEST(MeshReader, TextThatIsNoMeshSaysSo) {
  const std::string expected =
      "notes.stl: not a mesh file (toposlice reads STL, PLY, OBJ and 3MF, recognised by content)";
  const std::string text =
      "Dear lab,\nplease print the attached crown by Friday.\nThe shade is A2.\nRegards\n" +
      std::string(300, '.');
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(text), "notes.stl"); }), expected);
  EXPECT_EQ(errorOf([&] { parseMesh(gzipped(bytesOf(text)), "notes.stl"); }), expected);
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf("# only a comment\n"), "notes.stl"); }), expected);
  // STL's own messages stay: whitespace, a short binary file, a damaged binary STL.
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(" \n\t"), "w.stl"); }), "w.stl: empty file (only whitespace)");
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(std::string("\x01\x02\x00", 3)), "b.stl"); }),
            "b.stl: not an STL file: 3 bytes, too short for a binary STL, and not ASCII text starting with "
            "'solid'");
  Bytes damaged(184, std::byte{0});
  damaged[80] = std::byte{9};
  EXPECT_EQ(errorOf([&] { parseMesh(damaged, "d.stl"); }),
            "d.stl: truncated: expected 9 facets (534 bytes), file has 184 bytes (binary facet count does "
            "not match "
            "the file length)");
}

TEST(MeshReader, UnitsAndScaleMultiplyCoordinates) {
  EXPECT_EQ(parseUnits("mm"), 1.0);
  EXPECT_EQ(parseUnits("cm"), 10.0);
  EXPECT_EQ(parseUnits("m"), 1000.0);
  EXPECT_EQ(parseUnits("in"), 25.4);
  EXPECT_EQ(errorOf([] { parseUnits("ft"); }), "--units 'ft': expected mm, cm, m or in");

  MeshReadOptions options;
  options.unitMm = parseUnits("in");
  expectUnitCube(parseMesh(bytesOf(asciiPlyCube()), "cube.ply", options), 25.4);
  options.scale = 0.5;
  expectUnitCube(parseMesh(bytesOf(objCube()), "cube.obj", options), 12.7);
  options.scale = 0;
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(objCube()), "cube.obj", options); }),
            "cube.obj: --scale 0.000000: expected a positive number");
  options.scale = 1e38;
  EXPECT_EQ(errorOf([&] { parseMesh(bytesOf(objCube()), "cube.obj", options); }),
            "cube.obj: facet 0: coordinate beyond float's range after --units/--scale");
}

// ---- Shared models ----------------------------------------------------------------------------------

// Facet i of `a` and of `b` have the same corners within `tolerance` (relative to the model's size).
bool sameMesh(const FacetSoup& a, const FacetSoup& b, double tolerance) {
  if (a.corners.size() != b.corners.size()) return false;
  for (std::size_t i = 0; i < a.corners.size(); ++i) {
    const Point3f& p = a.corners[i];
    const Point3f& q = b.corners[i];
    if (std::abs(p.x - q.x) > tolerance || std::abs(p.y - q.y) > tolerance ||
        std::abs(p.z - q.z) > tolerance) {
      return false;
    }
  }
  return true;
}

TEST(MeshReaderModels, PlyAndObjMatchTheirStlSiblings) {
  if (!haveModels()) GTEST_SKIP() << "no " << modelsDir();
  int compared = 0;
  for (const auto& entry : fs::directory_iterator(modelsDir())) {
    const fs::path path = entry.path();
    if (path.extension() != ".ply" && path.extension() != ".obj") continue;
    fs::path stl = path;
    stl.replace_extension(".stl");
    if (!fs::exists(stl)) continue;
    SCOPED_TRACE(path.filename().string());
    MeshSource source;
    const FacetSoup indexed = readMesh(path, {}, &source);
    const FacetSoup reference = readStl(stl);
    EXPECT_EQ(source.format, path.extension() == ".ply" ? MeshFormat::Ply : MeshFormat::Obj);
    ASSERT_EQ(indexed.facetCount(), reference.facetCount());
    // The STL siblings were exported from these files facet by facet (../shared/models/SOURCES.md).
    const BoundingBox b = bounds(reference);
    const double size = std::max({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
    EXPECT_TRUE(sameMesh(indexed, reference, 1e-6 * size));
    const double volume = signedVolume(reference.corners);
    EXPECT_NEAR(signedVolume(indexed.corners), volume, 1e-6 * std::abs(volume));
    const BoundingBox c = bounds(indexed);
    EXPECT_FLOAT_EQ(c.min.x, b.min.x);
    EXPECT_FLOAT_EQ(c.max.y, b.max.y);
    EXPECT_FLOAT_EQ(c.max.z, b.max.z);
    ++compared;
  }
  EXPECT_GE(compared, 8);
}

TEST(MeshReaderModels, SmplBodiesInMetresHaveAHumanVolume) {
  if (!haveModels()) GTEST_SKIP() << "no " << modelsDir();
  for (const char* file : {"human_body_smpl_female.obj", "human_body_smpl_male.obj"}) {
    SCOPED_TRACE(file);
    MeshReadOptions options;
    options.unitMm = parseUnits("m");
    const FacetSoup soup = readMesh(modelsDir() / file, options);
    const double litres = std::abs(signedVolume(soup.corners)) / 1e6;
    EXPECT_GT(litres, 30.0);
    EXPECT_LT(litres, 150.0);
    const BoundingBox b = bounds(soup);
    EXPECT_GT(b.max.y - b.min.y, 1500.0);  // mm: a standing adult
    EXPECT_LT(b.max.y - b.min.y, 2100.0);
  }
}

TEST(MeshReaderModels, EveryFileLoadsOrFailsWithOneLineNamingIt) {
  if (!haveModels()) GTEST_SKIP() << "no " << modelsDir();
  int loaded = 0, failed = 0;
  for (const fs::path& dir : {modelsDir(), modelsDir() / "stl_parser_edge_cases"}) {
    for (const auto& entry : fs::directory_iterator(dir)) {
      if (!entry.is_regular_file()) continue;
      const fs::path path = entry.path();
      SCOPED_TRACE(path.string());
      try {
        const FacetSoup soup = readMesh(path);
        EXPECT_GT(soup.facetCount(), 0u);
        ++loaded;
      } catch (const InputError& e) {
        const std::string message = e.what();
        EXPECT_EQ(message.rfind(path.string() + ": ", 0), 0u) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
        ++failed;
        // An STL file fails with the STL reader's own message.
        if (path.extension() == ".stl") {
          EXPECT_EQ(message, errorOf([&] { readStl(path); }));
        }
      }
    }
  }
  EXPECT_GT(loaded, 30);
  EXPECT_GT(failed, 5);
}

}  // namespace
}  // namespace toposlice
