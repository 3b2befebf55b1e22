// 3MF slice stack writer: read back with lib3mf 1.8 (an independent reader: slices, ztop, vertices,
// polygons, mesh object, build item), the package itself unzipped with zlib (entry names, fixed entry
// times, the model text byte for byte on a tiny job), and the OutputFile contract (nothing under the
// final name before finish, overwrite policy, same input same bytes).
#include <gtest/gtest.h>

#include <zlib.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "Model/COM/NMR_DLLInterfaces.h"
#include "core/slicing/contours.h"
#include "io/contours/threemf_writer.h"
#include "io/errors.h"
#include "io/readers/lib3mf_handle.h"
#include "io/readers/stl_writer.h"
#include "tests/fixtures/archives.h"
#include "tests/fixtures/scratch_dir.h"
#include "tests/fixtures/shapes.h"
#include "tests/fixtures/winding.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

using fixtures::readFile;
using fixtures::ScratchDir;

// ---- fixtures -------------------------------------------------------------------------------------

void addLoop(LayerContours& layer, const std::vector<Point2d>& pts, bool closed) {
  for (const Point2d& p : pts) layer.addPoint(p, static_cast<uint32_t>(layer.points.size()));
  layer.endLoop(closed);
}

const std::vector<Point2d> kOuter = {{0, 0}, {10, 0}, {10, 10}, {0, 10}};       // counter-clockwise
const std::vector<Point2d> kHole = {{3, 3}, {3, 7.25}, {7.5, 7.25}, {7.5, 3}};  // clockwise

// A 10 x 10 square with a square hole, as every layer of a box with a square shaft would have.
LayerContours squareWithHole(double z) {
  LayerContours layer;
  layer.clear(z);
  addLoop(layer, kOuter, true);
  addLoop(layer, kHole, true);
  return layer;
}

// Closed, outward-oriented box [0,10]^2 x [0,h] as a facet soup (12 facets, 8 distinct corners).
FacetSoup boxSoup(float h) {
  const auto v = [h](int i) {
    return Point3f{(i & 1) ? 10.f : 0.f, (i & 2) ? 10.f : 0.f, (i & 4) ? h : 0.f};
  };
  const int faces[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                            {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  FacetSoup soup;
  for (const auto& f : faces)
    for (int c = 0; c < 3; ++c) soup.corners.push_back(v(f[c]));
  return soup;
}

ContourJob boxJob(uint32_t layers, float height) {
  ContourJob job;
  job.name = "box";
  job.bounds = {{0, 0, 0}, {10, 10, height}};
  job.layerCount = layers;
  return job;
}

// Writes `layers` through the 3MF writer and commits.
void writeThreeMf(const fs::path& path, const ContourJob& job, const FacetSoup* mesh, double h,
                  const std::vector<LayerContours>& layers) {
  auto sink = makeThreeMfWriter(path, job, mesh, false, h);
  for (uint32_t k = 0; k < layers.size(); ++k) sink->writeLayer(k, layers[k]);
  sink->finish();
}

// ---- zip, read with zlib -------------------------------------------------------------------------

uint32_t le16(const std::string& s, std::size_t at) {
  return uint32_t{static_cast<uint8_t>(s[at])} | uint32_t{static_cast<uint8_t>(s[at + 1])} << 8;
}
uint32_t le32(const std::string& s, std::size_t at) {
  return le16(s, at) | le16(s, at + 2) << 16;
}

struct ZipEntry {
  std::string name;
  uint32_t method = 0, dosTime = 0, dosDate = 0;
  std::string data;  // inflated
};

// Entries in central-directory order. Fails the test on anything unexpected.
std::vector<ZipEntry> readZip(const std::string& zip) {
  std::vector<ZipEntry> entries;
  const std::size_t eocd = zip.rfind(std::string("PK\x05\x06", 4));
  EXPECT_NE(eocd, std::string::npos);
  if (eocd == std::string::npos) return entries;
  const uint32_t count = le16(zip, eocd + 10);
  std::size_t at = le32(zip, eocd + 16);
  for (uint32_t i = 0; i < count; ++i) {
    EXPECT_EQ(le32(zip, at), 0x02014b50u);
    ZipEntry e;
    e.method = le16(zip, at + 10);
    e.dosTime = le16(zip, at + 12);
    e.dosDate = le16(zip, at + 14);
    const uint32_t compressed = le32(zip, at + 20), size = le32(zip, at + 24);
    const uint32_t nameLen = le16(zip, at + 28), extraLen = le16(zip, at + 30),
                   commentLen = le16(zip, at + 32);
    const uint32_t local = le32(zip, at + 42);
    e.name = zip.substr(at + 46, nameLen);
    at += 46 + nameLen + extraLen + commentLen;
    EXPECT_EQ(le32(zip, local), 0x04034b50u);
    const std::size_t data = local + 30 + le16(zip, local + 26) + le16(zip, local + 28);
    e.data.resize(size);
    if (e.method == 0) {
      e.data = zip.substr(data, size);
    } else {
      z_stream z{};
      EXPECT_EQ(inflateInit2(&z, -MAX_WBITS), Z_OK);
      z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(zip.data() + data));
      z.avail_in = compressed;
      z.next_out = reinterpret_cast<Bytef*>(e.data.data());
      z.avail_out = size;
      EXPECT_EQ(inflate(&z, Z_FINISH), Z_STREAM_END) << e.name;
      EXPECT_EQ(z.total_out, size);
      inflateEnd(&z);
    }
    entries.push_back(std::move(e));
  }
  return entries;
}

std::string modelText(const fs::path& path) {
  for (ZipEntry& e : readZip(readFile(path)))
    if (e.name == "3D/3dmodel.model") return std::move(e.data);
  ADD_FAILURE() << "no 3D/3dmodel.model in " << path;
  return {};
}

// ---- lib3mf 1.8 (C interface) -----------------------------------------------------------------------

}  // namespace
}  // namespace toposlice

// lib3mf 1.8 opens zip entries with zip_fopen_index and never closes them (160 bytes per entry read,
// in COpcPackageReader::openZIPEntryIndexed); without this, a LeakSanitizer build
// (TOPOSLICE_SANITIZE=address) fails every test that reads a 3MF. LSan's default fast unwinder stops
// inside libzip (built without frame pointers), so only the module can be named: this hides leaks of
// libzip allocations in the whole test binary. The binary's only suppression list: define no other.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libzip.so\n";
}

namespace toposlice {
namespace {

struct ReadSlice {
  float ztop = 0;
  std::vector<NMR::MODELSLICEVERTEX> vertices;
  std::vector<std::vector<DWORD>> polygons;  // startv, then every segment's v2
};

// One mesh object as lib3mf reads it, with its slice stack.
struct ReadObject {
  DWORD id = 0, type = 0, sliceStackId = 0;
  std::string name;
  NMR::eModelSlicesMeshResolution resolution = NMR::MODELSLICESMESHRESOLUTION_FULL;
  std::vector<NMR::MODELMESHVERTEX> vertices;
  std::vector<NMR::MODELMESHTRIANGLE> triangles;
  std::vector<ReadSlice> slices;
};

struct ReadModel {
  bool ok = false;
  DWORD readError = 0;  // lib3mf's error code when it refused the file
  std::string readMessage;
  std::vector<DWORD> warningCodes;
  int meshObjects = 0;
  DWORD objectType = 0;
  std::string objectName;
  DWORD sliceStackId = 0;
  NMR::eModelSlicesMeshResolution resolution = NMR::MODELSLICESMESHRESOLUTION_FULL;
  std::vector<NMR::MODELMESHVERTEX> vertices;
  std::vector<NMR::MODELMESHTRIANGLE> triangles;
  std::vector<DWORD> buildObjectIds;
  std::vector<ReadSlice> slices;
  std::vector<ReadObject> objects;  // every mesh object in resource order; the fields above are the first's
};

#define LIB3MF_CHECK(call)                                      \
  do {                                                          \
    const LIB3MFRESULT rc_ = (call);                            \
    if (rc_ != LIB3MF_OK) {                                     \
      ADD_FAILURE() << #call << " failed: " << std::hex << rc_; \
      return result;                                            \
    }                                                           \
  } while (false)

ReadModel readWithLib3mf(const fs::path& path) {
  ReadModel result;
  Lib3mfHandle model, reader;
  LIB3MF_CHECK(NMR::lib3mf_createmodel(model.out()));
  LIB3MF_CHECK(NMR::lib3mf_model_queryreader(model.get(), "3mf", reader.out()));
  if (NMR::lib3mf_reader_readfromfileutf8(reader.get(), path.c_str()) != LIB3MF_OK) {
    DWORD code = 0;
    LPCSTR message = nullptr;
    NMR::lib3mf_getlasterror(reader.get(), &code, &message);
    result.readError = code;
    result.readMessage = message ? message : "";
    return result;
  }
  DWORD warnings = 0;
  LIB3MF_CHECK(NMR::lib3mf_reader_getwarningcount(reader.get(), &warnings));
  for (DWORD i = 0; i < warnings; ++i) {
    DWORD code = 0;
    ULONG needed = 0;
    char text[512] = {};
    LIB3MF_CHECK(NMR::lib3mf_reader_getwarningutf8(reader.get(), i, &code, text, sizeof text, &needed));
    result.warningCodes.push_back(code);
  }

  Lib3mfHandle meshes;
  LIB3MF_CHECK(NMR::lib3mf_model_getmeshobjects(model.get(), meshes.out()));
  BOOL hasNext = false;
  LIB3MF_CHECK(NMR::lib3mf_resourceiterator_movenext(meshes.get(), &hasNext));
  while (hasNext) {
    Lib3mfHandle mesh;
    LIB3MF_CHECK(NMR::lib3mf_resourceiterator_getcurrent(meshes.get(), mesh.out()));
    ++result.meshObjects;
    ReadObject& o = result.objects.emplace_back();
    LIB3MF_CHECK(NMR::lib3mf_resource_getresourceid(mesh.get(), &o.id));
    LIB3MF_CHECK(NMR::lib3mf_object_gettype(mesh.get(), &o.type));
    char name[256] = {};
    ULONG needed = 0;
    LIB3MF_CHECK(NMR::lib3mf_object_getnameutf8(mesh.get(), name, sizeof name, &needed));
    o.name = name;
    LIB3MF_CHECK(NMR::lib3mf_meshobject_getslicestackid(mesh.get(), &o.sliceStackId));
    LIB3MF_CHECK(NMR::lib3mf_meshobject_getslicesmeshresolution(mesh.get(), &o.resolution));
    DWORD nv = 0, nt = 0;
    LIB3MF_CHECK(NMR::lib3mf_meshobject_getvertexcount(mesh.get(), &nv));
    LIB3MF_CHECK(NMR::lib3mf_meshobject_gettrianglecount(mesh.get(), &nt));
    o.vertices.resize(nv);
    o.triangles.resize(nt);
    if (nv > 0) LIB3MF_CHECK(NMR::lib3mf_meshobject_getvertices(mesh.get(), o.vertices.data(), nv, nullptr));
    if (nt > 0)
      LIB3MF_CHECK(NMR::lib3mf_meshobject_gettriangleindices(mesh.get(), o.triangles.data(), nt, nullptr));
    if (o.sliceStackId != 0) {
      Lib3mfHandle stack;
      LIB3MF_CHECK(NMR::lib3mf_model_getslicestackById(model.get(), o.sliceStackId, stack.out()));
      DWORD count = 0;
      LIB3MF_CHECK(NMR::lib3mf_slicestack_getslicecount(stack.get(), &count));
      for (DWORD i = 0; i < count; ++i) {
        Lib3mfHandle slice;
        LIB3MF_CHECK(NMR::lib3mf_slicestack_getslice(stack.get(), i, slice.out()));
        ReadSlice& rs = o.slices.emplace_back();
        LIB3MF_CHECK(NMR::lib3mf_slice_gettopz(slice.get(), &rs.ztop));
        DWORD nsv = 0, np = 0;
        LIB3MF_CHECK(NMR::lib3mf_slice_getvertexcount(slice.get(), &nsv));
        rs.vertices.resize(nsv);
        if (nsv > 0) LIB3MF_CHECK(NMR::lib3mf_slice_getvertices(slice.get(), rs.vertices.data(), nsv));
        LIB3MF_CHECK(NMR::lib3mf_slice_getpolygoncount(slice.get(), &np));
        for (DWORD p = 0; p < np; ++p) {
          DWORD ni = 0;
          LIB3MF_CHECK(NMR::lib3mf_slice_getpolygonindexcount(slice.get(), p, &ni));
          std::vector<DWORD> indices(ni);
          if (ni > 0) LIB3MF_CHECK(NMR::lib3mf_slice_getpolygonindices(slice.get(), p, indices.data(), ni));
          rs.polygons.push_back(std::move(indices));
        }
      }
    }
    LIB3MF_CHECK(NMR::lib3mf_resourceiterator_movenext(meshes.get(), &hasNext));
  }
  if (!result.objects.empty()) {
    const ReadObject& first = result.objects.front();
    result.objectType = first.type;
    result.objectName = first.name;
    result.sliceStackId = first.sliceStackId;
    result.resolution = first.resolution;
    result.vertices = first.vertices;
    result.triangles = first.triangles;
    result.slices = first.slices;
  }

  Lib3mfHandle items;
  LIB3MF_CHECK(NMR::lib3mf_model_getbuilditems(model.get(), items.out()));
  LIB3MF_CHECK(NMR::lib3mf_builditemiterator_movenext(items.get(), &hasNext));
  while (hasNext) {
    Lib3mfHandle item;
    LIB3MF_CHECK(NMR::lib3mf_builditemiterator_getcurrent(items.get(), item.out()));
    DWORD id = 0;
    LIB3MF_CHECK(NMR::lib3mf_builditem_getobjectresourceid(item.get(), &id));
    result.buildObjectIds.push_back(id);
    LIB3MF_CHECK(NMR::lib3mf_builditemiterator_movenext(items.get(), &hasNext));
  }

  result.ok = true;
  return result;
}

// Signed volume of a read mesh (divergence theorem); positive for outward-oriented closed meshes.
template <class Mesh>
double signedVolume(const Mesh& m) {
  double v = 0;
  for (const auto& t : m.triangles) {
    const float* a = m.vertices[t.m_nIndices[0]].m_fPosition;
    const float* b = m.vertices[t.m_nIndices[1]].m_fPosition;
    const float* c = m.vertices[t.m_nIndices[2]].m_fPosition;
    v += (double{a[0]} * (double{b[1]} * c[2] - double{b[2]} * c[1]) -
          double{a[1]} * (double{b[0]} * c[2] - double{b[2]} * c[0]) +
          double{a[2]} * (double{b[0]} * c[1] - double{b[1]} * c[0])) /
         6;
  }
  return v;
}

void expectLoop(const ReadSlice& s, const std::vector<DWORD>& polygon, const std::vector<Point2d>& pts) {
  ASSERT_GE(polygon.size(), pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    ASSERT_LT(polygon[i], s.vertices.size());
    const NMR::MODELSLICEVERTEX& v = s.vertices[polygon[i]];
    EXPECT_EQ(v.m_fPosition[0], static_cast<float>(pts[i].x)) << "point " << i;
    EXPECT_EQ(v.m_fPosition[1], static_cast<float>(pts[i].y)) << "point " << i;
  }
}

// ---- tests --------------------------------------------------------------------------------------------

TEST(ThreeMfWriter, SliceStackReadsBackWithLib3mf) {
  ScratchDir dir;
  const fs::path out = dir / "box.3mf";
  const FacetSoup box = boxSoup(0.3f);
  // h = 0.1 from z0 = 0: planes 0.05, 0.15, 0.25, slab tops 0.1, 0.2, 0.3.
  writeThreeMf(out, boxJob(3, 0.3f), &box, 0.1,
               {squareWithHole(0.05), squareWithHole(0.15), squareWithHole(0.25)});

  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_TRUE(m.warningCodes.empty()) << "first warning " << std::hex << m.warningCodes[0];
  ASSERT_EQ(m.slices.size(), 3u);
  const float tops[3] = {0.1f, 0.2f, 0.3f};
  for (std::size_t k = 0; k < 3; ++k) {
    const ReadSlice& s = m.slices[k];
    EXPECT_EQ(s.ztop, tops[k]) << "slice " << k;
    ASSERT_EQ(s.vertices.size(), 8u);
    ASSERT_EQ(s.polygons.size(), 2u);
    EXPECT_EQ(s.polygons[0], (std::vector<DWORD>{0, 1, 2, 3, 0}));  // closed: back to startv
    EXPECT_EQ(s.polygons[1], (std::vector<DWORD>{4, 5, 6, 7, 4}));
    expectLoop(s, s.polygons[0], kOuter);
    expectLoop(s, s.polygons[1], kHole);
  }

  // The mesh object: the welded box, full resolution, linked to the stack, on the build plate.
  EXPECT_EQ(m.meshObjects, 1);
  EXPECT_EQ(m.objectType, DWORD{NMR::MODELOBJECTTYPE_MODEL});
  EXPECT_EQ(m.objectName, "box");
  EXPECT_NE(m.sliceStackId, 0u);
  EXPECT_EQ(m.resolution, NMR::MODELSLICESMESHRESOLUTION_FULL);
  EXPECT_EQ(m.vertices.size(), 8u);
  EXPECT_EQ(m.triangles.size(), 12u);
  EXPECT_NEAR(signedVolume(m), 10.0 * 10.0 * 0.3, 1e-4);
  ASSERT_EQ(m.buildObjectIds.size(), 1u);

  const std::string text = modelText(out);
  EXPECT_NE(text.find("<s:slicestack id=\"1\" zbottom=\"0\">"), std::string::npos);
  EXPECT_NE(text.find("s:meshresolution=\"fullres\""), std::string::npos);
  EXPECT_EQ(text.find("requiredextensions"), std::string::npos);
}

TEST(ThreeMfWriter, TinyLoopsDroppedEmptyLayersKept) {
  ScratchDir dir;
  const fs::path out = dir / "tiny.3mf";
  LayerContours layer;
  layer.clear(0.5);
  addLoop(layer, {{9, 9}}, true);          // one point: dropped
  addLoop(layer, {{1, 1}, {4, 1}}, true);  // two points: a there-and-back polygon
  addLoop(layer, {}, false);               // no points: dropped
  addLoop(layer, kOuter, true);
  LayerContours empty;
  empty.clear(1.5);
  const FacetSoup box = boxSoup(2);
  writeThreeMf(out, boxJob(2, 2), &box, 1.0, {layer, empty});

  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_TRUE(m.warningCodes.empty());
  ASSERT_EQ(m.slices.size(), 2u);
  const ReadSlice& s = m.slices[0];
  EXPECT_EQ(s.ztop, 1.0f);
  ASSERT_EQ(s.vertices.size(), 2u + 4u);
  ASSERT_EQ(s.polygons.size(), 2u);
  EXPECT_EQ(s.polygons[0], (std::vector<DWORD>{0, 1, 0}));
  EXPECT_EQ(s.polygons[1], (std::vector<DWORD>{2, 3, 4, 5, 2}));
  expectLoop(s, s.polygons[0], {{1, 1}, {4, 1}});
  expectLoop(s, s.polygons[1], kOuter);
  // The empty layer is a slice with its ztop only.
  EXPECT_EQ(m.slices[1].ztop, 2.0f);
  EXPECT_TRUE(m.slices[1].vertices.empty());
  EXPECT_TRUE(m.slices[1].polygons.empty());
  EXPECT_NE(modelText(out).find("<s:slice ztop=\"2\"/>\n"), std::string::npos);
}

TEST(ThreeMfWriter, OpenPolylineIsClosedByASegment) {
  ScratchDir dir;
  const fs::path out = dir / "open.3mf";
  LayerContours layer;
  layer.clear(0.5);
  addLoop(layer, {{1, 1}, {4, 1}, {4, 3}}, false);  // open polyline (defect)
  addLoop(layer, kOuter, true);
  const FacetSoup box = boxSoup(1);
  writeThreeMf(out, boxJob(1, 1), &box, 1.0, {layer});

  const std::string text = modelText(out);
  EXPECT_NE(text.find("<s:polygon startv=\"0\">\n"
                      "<s:segment v2=\"1\"/>\n"
                      "<s:segment v2=\"2\"/>\n"
                      "<s:segment v2=\"0\"/>\n"  // closed back to startv: the spec wants closed polygons
                      "</s:polygon>\n"
                      "<s:polygon startv=\"3\">\n"
                      "<s:segment v2=\"4\"/>\n"
                      "<s:segment v2=\"5\"/>\n"
                      "<s:segment v2=\"6\"/>\n"
                      "<s:segment v2=\"3\"/>\n"
                      "</s:polygon>\n"),
            std::string::npos)
      << text;
  // The extension wants every polygon of a "model" object closed; lib3mf 1.8 reads this one.
  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
}

TEST(ThreeMfWriter, WithoutMeshWritesBoundingBoxAsLowres) {
  ScratchDir dir;
  const fs::path out = dir / "nomesh.3mf";
  ContourJob job = boxJob(1, 0.3f);
  job.bounds = {{-1, -2, -3}, {4, 5, 6}};
  writeThreeMf(out, job, nullptr, 9.0, {squareWithHole(1.5)});

  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_TRUE(m.warningCodes.empty());
  EXPECT_EQ(m.resolution, NMR::MODELSLICESMESHRESOLUTION_LOW);
  EXPECT_EQ(m.vertices.size(), 8u);
  EXPECT_EQ(m.triangles.size(), 12u);
  EXPECT_NEAR(signedVolume(m), 5.0 * 7.0 * 9.0, 1e-4);  // the box, outward-oriented
  ASSERT_EQ(m.slices.size(), 1u);
  EXPECT_EQ(m.slices[0].ztop, 6.0f);  // 1.5 + 9 / 2

  // A mesh whose facets are all degenerate is replaced by the box too.
  const fs::path flat = dir / "flat.3mf";
  FacetSoup degenerate;
  degenerate.corners = {{0, 0, 0}, {0, 0, 0}, {1, 1, 1}};
  writeThreeMf(flat, job, &degenerate, 9.0, {squareWithHole(1.5)});
  const std::string text = modelText(flat);
  EXPECT_NE(text.find("requiredextensions=\"s\""), std::string::npos);  // the extension demands it
  EXPECT_NE(text.find("s:meshresolution=\"lowres\""), std::string::npos);
  EXPECT_NE(text.find("<s:slicestack id=\"1\" zbottom=\"-3\">"), std::string::npos);
}

TEST(ThreeMfWriter, UnevenPlanesPutSlabBoundsHalfway) {
  ScratchDir dir;
  const FacetSoup box = boxSoup(1);
  {
    const fs::path out = dir / "uneven.3mf";
    writeThreeMf(out, boxJob(3, 1), &box, 0.0,
                 {squareWithHole(0.1), squareWithHole(0.2), squareWithHole(0.4)});
    const ReadModel m = readWithLib3mf(out);
    ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
    ASSERT_EQ(m.slices.size(), 3u);
    EXPECT_EQ(m.slices[0].ztop, 0.15f);
    EXPECT_EQ(m.slices[1].ztop, 0.3f);
    EXPECT_EQ(m.slices[2].ztop, 0.5f);
    EXPECT_EQ(m.slices[2].polygons.size(), 2u);  // the body went with its own ztop
    EXPECT_NE(modelText(out).find("zbottom=\"0.05\""), std::string::npos);
  }
  {
    const fs::path out = dir / "single.3mf";  // one plane, no height: from the model's lowest z up
    writeThreeMf(out, boxJob(1, 1), &box, 0.0, {squareWithHole(0.25)});
    const ReadModel m = readWithLib3mf(out);
    ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
    ASSERT_EQ(m.slices.size(), 1u);
    EXPECT_EQ(m.slices[0].ztop, 0.5f);
    EXPECT_EQ(m.slices[0].polygons.size(), 2u);
    EXPECT_NE(modelText(out).find("zbottom=\"0\""), std::string::npos);
  }
  {
    const fs::path out = dir / "none.3mf";  // no layers at all: an empty stack
    writeThreeMf(out, boxJob(0, 1), &box, 0.0, {});
    const ReadModel m = readWithLib3mf(out);
    ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
    EXPECT_TRUE(m.slices.empty());
    EXPECT_EQ(m.triangles.size(), 12u);
  }
}

TEST(ThreeMfWriter, PackageLayoutAndExactModelText) {
  ScratchDir dir;
  const fs::path out = dir / "tiny.3mf";
  LayerContours layer;
  layer.clear(0.025);
  addLoop(layer, {{0, 0}, {1.5, -0.0000001}, {0.333333333, 2}}, true);
  FacetSoup tri;  // one facet: a mesh need not be closed to be written
  tri.corners = {{0, 0, 0}, {1.5f, 0, 0.05f}, {-0.0f, 2, 0.1f}};
  ContourJob job = boxJob(1, 0.05f);
  job.name = "a<b>&\"c\"\x01";
  writeThreeMf(out, job, &tri, 0.05, {layer});

  const std::vector<ZipEntry> entries = readZip(readFile(out));
  ASSERT_EQ(entries.size(), 3u);
  EXPECT_EQ(entries[0].name, "[Content_Types].xml");
  EXPECT_EQ(entries[1].name, "_rels/.rels");
  EXPECT_EQ(entries[2].name, "3D/3dmodel.model");
  for (const ZipEntry& e : entries) {
    EXPECT_EQ(e.method, 8u) << e.name;      // deflated
    EXPECT_EQ(e.dosTime, 0u) << e.name;     // 00:00:00
    EXPECT_EQ(e.dosDate, 0x21u) << e.name;  // 1980-01-01
  }
  EXPECT_NE(entries[0].data.find("<Default Extension=\"model\" "
                                 "ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/>"),
            std::string::npos);
  EXPECT_NE(entries[1].data.find("Target=\"/3D/3dmodel.model\""), std::string::npos);
  EXPECT_NE(entries[1].data.find("Type=\"http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel\""),
            std::string::npos);
  EXPECT_EQ(entries[2].data,
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
            "<model unit=\"millimeter\" xml:lang=\"en-US\" "
            "xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\" "
            "xmlns:s=\"http://schemas.microsoft.com/3dmanufacturing/slice/2015/07\">\n"
            "<metadata name=\"Application\">toposlice</metadata>\n"
            "<resources>\n"
            "<s:slicestack id=\"1\" zbottom=\"0\">\n"
            "<s:slice ztop=\"0.05\">\n"
            "<s:vertices>\n"
            "<s:vertex x=\"0\" y=\"0\"/>\n"
            "<s:vertex x=\"1.5\" y=\"0\"/>\n"
            "<s:vertex x=\"0.333333\" y=\"2\"/>\n"
            "</s:vertices>\n"
            "<s:polygon startv=\"0\">\n"
            "<s:segment v2=\"1\"/>\n"
            "<s:segment v2=\"2\"/>\n"
            "<s:segment v2=\"0\"/>\n"
            "</s:polygon>\n"
            "</s:slice>\n"
            "</s:slicestack>\n"
            "<object id=\"2\" type=\"model\" name=\"a&lt;b&gt;&amp;&quot;c&quot;_\" s:slicestackid=\"1\" "
            "s:meshresolution=\"fullres\">\n"
            "<mesh>\n"
            "<vertices>\n"
            "<vertex x=\"0\" y=\"0\" z=\"0\"/>\n"
            "<vertex x=\"1.5\" y=\"0\" z=\"0.05\"/>\n"
            "<vertex x=\"0\" y=\"2\" z=\"0.1\"/>\n"
            "</vertices>\n"
            "<triangles>\n"
            "<triangle v1=\"0\" v2=\"1\" v3=\"2\"/>\n"
            "</triangles>\n"
            "</mesh>\n"
            "</object>\n"
            "</resources>\n"
            "<build>\n"
            "<item objectid=\"2\"/>\n"
            "</build>\n"
            "</model>\n");
}

TEST(ThreeMfWriter, WeldsCornersAndSkipsDegenerateFacets) {
  ScratchDir dir;
  const fs::path out = dir / "weld.3mf";
  FacetSoup soup = boxSoup(1);
  soup.corners.push_back({1, 1, 0});  // a facet with two equal corners: not a 3MF triangle
  soup.corners.push_back({1, 1, 0});
  soup.corners.push_back({2, 2, 0});
  writeThreeMf(out, boxJob(1, 1), &soup, 1.0, {squareWithHole(0.5)});
  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_EQ(m.triangles.size(), 12u);
  EXPECT_EQ(m.vertices.size(), 10u);  // 8 box corners + the 2 of the skipped facet
  EXPECT_NEAR(signedVolume(m), 100.0, 1e-4);
}

// Signed area of a read polygon (its index list runs back to startv).
double polygonArea(const ReadSlice& s, const std::vector<DWORD>& polygon) {
  std::vector<Point2d> pts;
  for (std::size_t i = 0; i + 1 < polygon.size(); ++i) {
    const NMR::MODELSLICEVERTEX& v = s.vertices.at(polygon[i]);
    pts.push_back({v.m_fPosition[0], v.m_fPosition[1]});
  }
  return signedArea(pts);
}

TEST(ThreeMfWriter, FeaturesAreObjectsOfTheirOwnAndRemovalsAreReversed) {
  // Model: the 10 x 10 box; add-on: a 2 x 2 block beside it; removal: a 2 x 2 shaft inside the model.
  const FacetSoup box = boxSoup(0.2f);
  const std::vector<FacetSoup> features = {fixtures::box(10, 0, 0, 12, 2, 0.2f),
                                           fixtures::box(3, 3, 0, 5, 5, 0.2f)};
  const std::vector<Point2d> add = {{10, 0}, {12, 0}, {12, 2}, {10, 2}};
  const std::vector<Point2d> shaft = {{3, 3}, {5, 3}, {5, 5}, {3, 5}};  // counter-clockwise, as sliced
  ContourJob job = boxJob(2, 0.2f);
  job.features = {{"knob", PartRole::Add}, {"shaft", PartRole::Remove}};
  for (const double h : {0.1, 0.0}) {  // uniform planes, then the same planes without a height
    ScratchDir dir;
    const fs::path out = dir / "f.3mf";
    auto sink = makeThreeMfWriter(out, job, &box, false, h, features);
    for (uint32_t k = 0; k < 2; ++k) {
      std::vector<LayerContours> parts(3);
      for (LayerContours& part : parts) part.clear(0.05 + 0.1 * k);
      addLoop(parts[0], kOuter, true);
      addLoop(parts[1], add, true);
      addLoop(parts[2], shaft, true);
      sink->writeLayer(k, parts);
    }
    sink->finish();

    const ReadModel m = readWithLib3mf(out);
    ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
    EXPECT_TRUE(m.warningCodes.empty()) << "first warning " << std::hex << m.warningCodes[0];
    ASSERT_EQ(m.objects.size(), 3u);
    const std::vector<std::string> names = {"box", "add knob", "remove shaft"};
    const double volumes[3] = {10.0 * 10.0 * 0.2, 2.0 * 2.0 * 0.2, -2.0 * 2.0 * 0.2};  // removal inside out
    for (std::size_t p = 0; p < 3; ++p) {
      const ReadObject& o = m.objects[p];
      EXPECT_EQ(o.name, names[p]);
      EXPECT_EQ(o.type, DWORD{NMR::MODELOBJECTTYPE_MODEL});
      EXPECT_NE(o.sliceStackId, 0u);
      if (p > 0) {
        EXPECT_NE(o.sliceStackId, m.objects[p - 1].sliceStackId);
      }
      EXPECT_EQ(o.resolution, NMR::MODELSLICESMESHRESOLUTION_FULL);
      EXPECT_NEAR(signedVolume(o), volumes[p], 1e-4) << names[p];
      ASSERT_EQ(o.slices.size(), 2u) << names[p];
      for (std::size_t k = 0; k < 2; ++k) {
        EXPECT_EQ(o.slices[k].ztop, m.objects[0].slices[k].ztop) << names[p] << " slice " << k;
        ASSERT_EQ(o.slices[k].polygons.size(), 1u);
        EXPECT_EQ(o.slices[k].polygons[0], (std::vector<DWORD>{0, 1, 2, 3, 0}));
      }
    }
    // Removals are not printed by a consumer of the build. (lib3mf numbers resources itself: the
    // file's ids are checked in the text below.)
    EXPECT_EQ(m.buildObjectIds, (std::vector<DWORD>{m.objects[0].id, m.objects[1].id}));
    const std::string text = modelText(out);
    for (const char* tag : {"<s:slicestack id=\"3\" zbottom=\"0\">", "<s:slicestack id=\"5\" zbottom=\"0\">",
                            "<object id=\"4\" type=\"model\" name=\"add knob\" s:slicestackid=\"3\"",
                            "<object id=\"6\" type=\"model\" name=\"remove shaft\" s:slicestackid=\"5\"",
                            "<build>\n<item objectid=\"2\"/>\n<item objectid=\"4\"/>\n</build>"})
      EXPECT_NE(text.find(tag), std::string::npos) << tag;
    for (std::size_t k = 0; k < 2; ++k) {
      const ReadSlice& removal = m.objects[2].slices[k];
      expectLoop(removal, removal.polygons[0], {shaft[0], shaft[3], shaft[2], shaft[1]});
      // The documented rule: all objects' polygons at one ztop under positive winding; with windings 0
      // and 1 only, the solid's area is the sum of their signed areas.
      double area = 0;
      for (const ReadObject& o : m.objects) area += polygonArea(o.slices[k], o.slices[k].polygons[0]);
      EXPECT_NEAR(area, 100.0 + 4.0 - 4.0, 1e-9) << "slice " << k;
    }
  }
}

// The toposlice program on a box with an add-on half sunk into it and a cylinder removal reaching
// beyond its side (as in cli_tool_test.cpp): the 3MF read back by lib3mf, combined by the documented
// rule, gives the report's (mask) area on every layer.
TEST(ThreeMfWriter, ProgramOutputWithFeaturesCombinesToTheReportArea) {
  ScratchDir dir;
  writeBinaryStl(dir / "model.stl", fixtures::box(0, 0, 0, 20, 10, 5), "model", false);
  writeBinaryStl(dir / "knob.stl", fixtures::box(2, 6, 4, 8, 12, 7), "add-on", false);
  writeBinaryStl(dir / "bore.stl", fixtures::cylinder(19, 5, 2, 32, 2, 6), "removal", false);
  const char* env = std::getenv("TOPOSLICE_BIN");
  const std::string program = env != nullptr && *env != '\0' ? env : TOPOSLICE_BIN_PATH;
  const auto quoted = [](const fs::path& p) { return "'" + p.string() + "'"; };
  const std::string command = "'" + program + "' slice " + quoted(dir / "model.stl") + " --add " +
                              quoted(dir / "knob.stl") + " --remove " + quoted(dir / "bore.stl") +
                              " -H 0.5 -o " + quoted(dir / "f.3mf") + " --masks " + quoted(dir / "masks") +
                              " --resolution 480x300 --pixel 0.05 --report " + quoted(dir / "r.csv") + " -q";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;

  const ReadModel m = readWithLib3mf(dir / "f.3mf");
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_TRUE(m.warningCodes.empty()) << "first warning " << std::hex << m.warningCodes[0];
  ASSERT_EQ(m.objects.size(), 3u);
  EXPECT_EQ(m.objects[1].name, "add knob");
  EXPECT_EQ(m.objects[2].name, "remove bore");
  EXPECT_EQ(m.buildObjectIds, (std::vector<DWORD>{m.objects[0].id, m.objects[1].id}));
  EXPECT_LT(signedVolume(m.objects[2]), 0);  // the removal's mesh is inside out

  std::istringstream report(readFile(dir / "r.csv"));
  std::string row;
  std::getline(report, row);           // header
  constexpr std::size_t kLayers = 14;  // to z 7: the add-on reaches 2 mm above the model
  for (const ReadObject& o : m.objects) ASSERT_EQ(o.slices.size(), kLayers) << o.name;
  for (std::size_t k = 0; k < kLayers; ++k) {
    std::vector<std::vector<Point2d>> loops;
    for (const ReadObject& o : m.objects) {
      const ReadSlice& s = o.slices[k];
      EXPECT_EQ(s.ztop, m.objects[0].slices[k].ztop);
      for (const auto& polygon : s.polygons) {
        std::vector<Point2d>& loop = loops.emplace_back();
        for (std::size_t i = 0; i + 1 < polygon.size(); ++i)
          loop.push_back(
              {s.vertices.at(polygon[i]).m_fPosition[0], s.vertices.at(polygon[i]).m_fPosition[1]});
        if (&o == &m.objects[2]) {
          EXPECT_LT(signedArea(loop), 0) << "a removal's loops are reversed: slice " << k;
        }
      }
    }
    ASSERT_TRUE(std::getline(report, row));
    const std::size_t c1 = row.find(','), c2 = row.find(',', c1 + 1);
    const double reported = std::stod(row.substr(c2 + 1));
    EXPECT_NEAR(fixtures::positiveWindingArea(loops, 0.001), reported, 0.01 * reported) << row;
  }
}

// An outline correction moves the slices off the meshes' cuts: every object's mesh is then low resolution
// (the extension's requiredextensions with it), so a consumer uses the slices, not the meshes (they were
// "fullres": a consumer without the extension printed the uncorrected part).
TEST(ThreeMfWriter, CorrectedOutlinesMakeTheMeshesLowResolution) {
  ScratchDir dir;
  writeBinaryStl(dir / "model.stl", fixtures::box(0, 0, 0, 20, 10, 5), "model", false);
  writeBinaryStl(dir / "knob.stl", fixtures::box(2, 6, 4, 8, 12, 7), "add-on", false);
  const char* env = std::getenv("TOPOSLICE_BIN");
  const std::string program = env != nullptr && *env != '\0' ? env : TOPOSLICE_BIN_PATH;
  const auto quoted = [](const fs::path& p) { return "'" + p.string() + "'"; };
  for (const char* correction : {"--absolute-correction 0.2", "--elefant-foot-compensation 0.1", ""}) {
    const std::string command = "'" + program + "' slice " + quoted(dir / "model.stl") + " --add " +
                                quoted(dir / "knob.stl") + " -H 0.5 -o " + quoted(dir / "c.3mf") +
                                " --force -q " + correction;
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const ReadModel m = readWithLib3mf(dir / "c.3mf");
    ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
    ASSERT_EQ(m.objects.size(), 2u);
    const bool corrected = *correction != '\0';
    for (const ReadObject& o : m.objects) {
      EXPECT_EQ(o.resolution,
                corrected ? NMR::MODELSLICESMESHRESOLUTION_LOW : NMR::MODELSLICESMESHRESOLUTION_FULL)
          << correction << " " << o.name;
      EXPECT_EQ(o.triangles.size(), 12u) << "the part's own mesh, not a stand-in box";
    }
    EXPECT_EQ(modelText(dir / "c.3mf").find("requiredextensions=\"s\"") != std::string::npos, corrected)
        << correction;
  }
}

TEST(ThreeMfWriter, Deterministic) {
  ScratchDir dir;
  const FacetSoup box = boxSoup(0.3f);
  const std::vector<LayerContours> layers = {squareWithHole(0.05), squareWithHole(0.15),
                                             squareWithHole(0.25)};
  writeThreeMf(dir / "a.3mf", boxJob(3, 0.3f), &box, 0.1, layers);
  writeThreeMf(dir / "b.3mf", boxJob(3, 0.3f), &box, 0.1, layers);
  const std::string a = readFile(dir / "a.3mf");
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, readFile(dir / "b.3mf"));
}

TEST(ThreeMfWriter, NothingUnderFinalNameBeforeFinish) {
  ScratchDir dir;
  const FacetSoup box = boxSoup(0.3f);
  {
    auto sink = makeThreeMfWriter(dir / "x.3mf", boxJob(3, 0.3f), &box, false, 0.1);
    sink->writeLayer(0, squareWithHole(0.05));
    sink->writeLayer(1, squareWithHole(0.15));
    const auto names = dir.entries();
    ASSERT_EQ(names.size(), 1u);
    EXPECT_EQ(names[0].rfind("x.3mf.tmp-" + std::to_string(::getpid()) + "-", 0), 0u) << names[0];
    sink->writeLayer(2, squareWithHole(0.25));
    EXPECT_FALSE(fs::exists(dir / "x.3mf"));
    sink->finish();
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"x.3mf"});
  }
  {
    auto sink = makeThreeMfWriter(dir / "y.3mf", boxJob(3, 0.3f), &box, false, 0.1);
    sink->writeLayer(0, squareWithHole(0.05));
  }  // destroyed without finish(): nothing left
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"x.3mf"});
}

TEST(ThreeMfWriter, ExistingFileNeedsOverwrite) {
  ScratchDir dir;
  const fs::path out = dir / "old.3mf";
  const std::string older = fixtures::zipToposliceWrote(" an older 3MF");
  std::ofstream(out) << older;
  const FacetSoup box = boxSoup(0.3f);
  EXPECT_THROW(makeThreeMfWriter(out, boxJob(1, 0.3f), &box, false, 0.3), OutputError);
  EXPECT_EQ(readFile(out), older);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"old.3mf"});

  // Another program's 3MF (a zip without our comment, a user's CAD model) is never replaced.
  const fs::path cad = dir / "cad.3mf";
  std::ofstream(cad) << "PK\x03\x04 a CAD model's 3MF";
  EXPECT_THROW(makeThreeMfWriter(cad, boxJob(1, 0.3f), &box, true, 0.3), OutputError);
  EXPECT_EQ(readFile(cad), "PK\x03\x04 a CAD model's 3MF");
  fs::remove(cad);

  auto sink = makeThreeMfWriter(out, boxJob(1, 0.3f), &box, true, 0.3);
  sink->writeLayer(0, squareWithHole(0.15));
  EXPECT_EQ(readFile(out), older);  // untouched until finish()
  sink->finish();
  const ReadModel m = readWithLib3mf(out);
  ASSERT_TRUE(m.ok) << std::hex << m.readError << " " << m.readMessage;
  EXPECT_EQ(m.slices.size(), 1u);
}

}  // namespace
}  // namespace toposlice
