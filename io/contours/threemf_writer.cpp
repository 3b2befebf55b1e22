// 3MF slice stack writer.
//
// Sources: 3MF Core Specification 1.x (package parts, content types, relationship type, <model>,
// <object>/<mesh>, <build>, requiredextensions) and the 3MF Slice Extension 1.0 (namespace
// http://schemas.microsoft.com/3dmanufacturing/slice/2015/07; <slicestack id zbottom>, <slice ztop>,
// <vertices>/<vertex x y>, <polygon startv> with <segment v2>; object attributes slicestackid and
// meshresolution fullres|lowres; "lowres" requires the extension in requiredextensions; polygons of
// "model" objects must be closed; a slicestack must be defined before the object that references it).
// Checked against lib3mf 1.8 as a reader (tests/threemf_writer_test.cpp).
#include "io/contours/threemf_writer.h"

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <charconv>
#include <climits>
#include <cstdio>
#include <cstring>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include <fcntl.h>
#include <minizip/zip.h>
#include <sys/stat.h>
#include <unistd.h>

#include "core/mesh/mesh_info.h"
#include "core/mesh/weld.h"
#include "io/coders/zip_stream.h"
#include "io/contours/xml_text.h"
#include "io/errors.h"
#include "io/output_file.h"
#include "io/text_buffer.h"

namespace toposlice {
namespace {

constexpr int kDeflateLevel = 1;  // level 6: about 13% smaller, nearly twice the time
constexpr std::size_t kFlushBytes = std::size_t{1} << 20;  // text goes to deflate in ~1 MiB pieces
constexpr double kLoneSlabHalf = 0.0005;                   // mm; see the header
// Part p (0 the model, then job.features) has slice stack 2p + 1 and object 2p + 2.
constexpr uint32_t sliceStackId(std::size_t p) {
  return static_cast<uint32_t>(2 * p + 1);
}
constexpr uint32_t objectId(std::size_t p) {
  return static_cast<uint32_t>(2 * p + 2);
}

constexpr std::string_view kContentTypes =
    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    "<Types xmlns=\"http://schemas.openxmlformats.org/package/2006/content-types\">\n"
    "<Default Extension=\"rels\" ContentType=\"application/vnd.openxmlformats-package.relationships+xml\"/>\n"
    "<Default Extension=\"model\" ContentType=\"application/vnd.ms-package.3dmanufacturing-3dmodel+xml\"/>\n"
    "</Types>\n";

constexpr std::string_view kRootRels =
    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    "<Relationships xmlns=\"http://schemas.openxmlformats.org/package/2006/relationships\">\n"
    "<Relationship Target=\"/3D/3dmodel.model\" Id=\"rel0\" "
    "Type=\"http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel\"/>\n"
    "</Relationships>\n";

// The 3MF writer's text: TextBuffer plus the format's number forms.
class Text : public TextBuffer {
 public:
  // Fixed notation with at most 6 decimals (correctly rounded), trailing zeros and a bare point
  // dropped, never "-0".
  void appendDecimal(double v) {
    constexpr std::size_t kMax = 1 + 309 + 1 + 6;
    char* p = reserveMore(kMax);
    char* end = std::to_chars(p, p + kMax, v, std::chars_format::fixed, 6).ptr;
    while (end[-1] == '0') --end;
    if (end[-1] == '.') --end;
    setEnd(dropMinusZero(p, end));
  }
  // The shortest fixed-notation text that reads back as exactly `v` (float32), never "-0".
  void appendFloat(float v) {
    constexpr std::size_t kMax = 64;  // widest float in shortest fixed form: 39 digits or "0." + 45
    char* p = reserveMore(kMax);
    setEnd(dropMinusZero(p, std::to_chars(p, p + kMax, v, std::chars_format::fixed).ptr));
  }

 private:
  static char* dropMinusZero(char* p, char* end) {
    if (end - p == 2 && p[0] == '-' && p[1] == '0') {
      p[0] = '0';
      return p + 1;
    }
    return end;
  }
};

// XML attribute text: printable ASCII, escaped; other bytes become '_'; "part" when empty.
std::string xmlName(const std::string& name) {
  std::string out;
  appendXmlEscaped(
      out, name, [](unsigned char c) { return c >= 0x20 && c < 0x7f; }, '_');
  return out.empty() ? std::string("part") : out;
}

// A facet 3MF accepts as a triangle: three distinct vertices once welded. Welding merges bit-identical
// floats and -0 with +0, which for the finite coordinates of a soup is float ==.
bool hasDistinctCorners(const Point3f* c) {
  const auto same = [](const Point3f& a, const Point3f& b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  return !same(c[0], c[1]) && !same(c[1], c[2]) && !same(c[0], c[2]);
}

bool hasProperFacet(const FacetSoup& soup) {
  for (std::size_t c = 0; c + 2 < soup.corners.size(); c += 3) {
    if (hasDistinctCorners(&soup.corners[c])) return true;
  }
  return false;
}

// Point i of a loop of n points in the order it is written: a removal's loops reversed, a closed loop
// keeping its first point (p0, p(n-1), ..., p1), an open polyline from its last point to its first.
std::size_t writtenIndex(std::size_t i, std::size_t n, bool closed, bool reversed) {
  if (!reversed) return i;
  if (closed) return i == 0 ? 0 : n - i;
  return n - 1 - i;
}

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

uint64_t getLE(const uint8_t* p, int bytes) {
  uint64_t v = 0;
  for (int i = bytes - 1; i >= 0; --i) v = v << 8 | p[i];
  return v;
}

// minizip 1.1 writes "version needed to extract" 45 into the local header of a Zip64-ready entry but
// always 20 into its central header; libzip, and lib3mf through it, report that mismatch as
// NMR_ERROR_ZIPCONTAINSINCONSISTENCIES. This copies each local header's value into its central header
// (APPNOTE 4.3.7, 4.3.12, 4.3.14-4.3.16). The archive has 3 entries, all local headers near its start.
void alignCentralVersions(const std::filesystem::path& file, const std::filesystem::path& shownName) {
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  const auto fail = [&shownName, fd](const char* what) {
    const std::string reason = errno != 0 ? std::generic_category().message(errno) : "unexpected zip layout";
    if (fd >= 0) ::close(fd);
    throw OutputError(shownName.string() + ": cannot complete the zip directory: " + what + ": " + reason);
  };
  if (fd < 0) fail("reopen");
  const auto readAt = [fd](uint8_t* buf, std::size_t size, uint64_t at) {
    errno = 0;
    return ::pread(fd, buf, size, static_cast<off_t>(at)) == static_cast<ssize_t>(size);
  };
  struct stat st {};
  if (::fstat(fd, &st) != 0 || st.st_size < static_cast<off_t>(42 + kZipComment.size())) fail("stat");
  // The end record, then toposlice's archive comment, close the file.
  const uint64_t size = static_cast<uint64_t>(st.st_size) - kZipComment.size();
  uint8_t eocd[22];
  if (!readAt(eocd, 22, size - 22) || getLE(eocd, 4) != 0x06054b50u) fail("end record");
  const uint64_t entries = getLE(eocd + 10, 2);
  uint64_t at = getLE(eocd + 16, 4);
  if (at == 0xFFFFFFFFu) {  // past 4 GiB: the Zip64 end record holds the central directory's offset
    uint8_t locator[20], zip64[56];
    if (!readAt(locator, 20, size - 42) || getLE(locator, 4) != 0x07064b50u ||
        !readAt(zip64, 56, getLE(locator + 8, 8)) || getLE(zip64, 4) != 0x06064b50u) {
      fail("Zip64 end record");
    }
    at = getLE(zip64 + 48, 8);
  }
  for (uint64_t i = 0; i < entries; ++i) {
    uint8_t central[46], local[6];
    if (!readAt(central, 46, at) || getLE(central, 4) != 0x02014b50u ||
        !readAt(local, 6, getLE(central + 42, 4)) || getLE(local, 4) != 0x04034b50u) {
      fail("entry header");
    }
    if (getLE(central + 6, 2) < getLE(local + 4, 2)) {
      errno = 0;
      if (::pwrite(fd, local + 4, 2, static_cast<off_t>(at + 6)) != 2) fail("write");
    }
    at += 46 + getLE(central + 28, 2) + getLE(central + 30, 2) + getLE(central + 32, 2);
  }
  errno = 0;
  if (::close(fd) != 0) {
    throw OutputError(shownName.string() + ": cannot write: " + std::generic_category().message(errno));
  }
}

// Closes an archive abandoned before finish() (an error, a cancelled run).
struct ZipCloser {
  void operator()(zipFile zip) const { zipClose(zip, nullptr); }
};

std::string zipErrorText(int code) {
  return code == ZIP_ERRNO ? std::generic_category().message(errno) : "zip error " + std::to_string(code);
}

// One part's slice stack while it is written, and what its object needs.
struct Part {
  const FacetSoup* mesh = nullptr;  // may be null
  bool box = true;                  // no mesh with a proper facet: a bounding box stands in
  bool lowres = true;               // the mesh is not what the slices were cut from (a box, or corrected)
  bool reversed = false;            // a removal: loops and triangles written reversed
  Text body;                        // the current layer's <s:vertices> and <s:polygon>s
  Text pending;                     // without a layer height: the previous layer's body, waiting for its ztop
  Text text;                        // a feature's stack text not yet in its spool file
  std::unique_ptr<std::FILE, FileCloser> spool;  // a feature's stack, copied into the model by finish()
};

class ThreeMfWriter final : public ContourSink {
 public:
  ThreeMfWriter(const std::filesystem::path& path, const ContourJob& job, const FacetSoup* mesh,
                bool overwrite, double layerHeight, std::span<const FacetSoup> featureMeshes)
      : file_(path, overwrite), job_(job), layerHeight_(layerHeight), parts_(1 + job.features.size()) {
    assert(layerHeight >= 0);
    assert(featureMeshes.empty() || featureMeshes.size() == job.features.size());
    bool lowres = false;
    for (std::size_t p = 0; p < parts_.size(); ++p) {
      Part& part = parts_[p];
      part.mesh = p == 0 ? mesh : featureMeshes.empty() ? nullptr : &featureMeshes[p - 1];
      // The slices are the mesh's cuts (fullres) only when no outline correction moved them: else the
      // mesh stands for the part at a lower resolution and a consumer must use the slices.
      part.box = part.mesh == nullptr || !hasProperFacet(*part.mesh);
      part.lowres = part.box || job.outlinesCorrected;
      part.reversed = p > 0 && job.features[p - 1].role == PartRole::Remove;
      lowres = lowres || part.lowres;
      if (p == 0) continue;
      // A feature's stack is spooled to an unnamed temporary file and copied into the model entry by
      // finish(): minizip writes one entry at a time, and the model's stack streams into it meanwhile.
      part.spool.reset(std::tmpfile());
      if (!part.spool) {
        throw OutputError(path.string() + ": cannot create a temporary file for feature '" +
                          job.features[p - 1].name + "': " + std::generic_category().message(errno));
      }
    }
    // minizip writes the temporary through its own handle (it seeks back to complete each local
    // header); file_ owns the name, its removal when abandoned (signals included) and the final rename.
    zip_.reset(openZipOnTemporary(file_.tempPath()));
    if (zip_ == nullptr) {
      throw OutputError(path.string() + ": cannot create " + file_.tempPath().string() + ": " +
                        std::generic_category().message(errno));
    }
    info_.tmz_date.tm_year = 1980;  // the earliest zip (DOS) time: 1980-01-01 00:00:00
    info_.tmz_date.tm_mday = 1;
    addEntry("[Content_Types].xml", kContentTypes);
    addEntry("_rels/.rels", kRootRels);
    openEntry("3D/3dmodel.model", true);
    out_.append(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
        "<model unit=\"millimeter\" xml:lang=\"en-US\" "
        "xmlns=\"http://schemas.microsoft.com/3dmanufacturing/core/2015/02\" "
        "xmlns:s=\"http://schemas.microsoft.com/3dmanufacturing/slice/2015/07\"");
    out_.append(lowres ? " requiredextensions=\"s\">\n" : ">\n");
    out_.append("<metadata name=\"Application\">toposlice</metadata>\n<resources>\n");
  }

  void writeLayer(uint32_t index, std::span<const LayerContours> layers) override {
    assert(index == next_ && index < job_.layerCount);
    assert(layers.size() == parts_.size());
    ++next_;
    const double z = layers[0].z;
    for (std::size_t p = 0; p < parts_.size(); ++p) {
      Part& part = parts_[p];
      assert(layers[p].loopClosed.size() == layers[p].loopCount());
      part.body.clear();
      encodeSliceBody(layers[p], part.reversed, part.body);
      if (layerHeight_ > 0) {
        if (index == 0) openStack(p, z - layerHeight_ / 2);
        emitSlice(p, z + layerHeight_ / 2, part.body);
        continue;
      }
      // Uneven planes: slice k's ztop is known once plane k+1 has arrived.
      if (index > 0) {
        if (index == 1) openStack(p, pendingZ_ - (z - pendingZ_) / 2);
        emitSlice(p, (pendingZ_ + z) / 2, part.pending);
      }
      part.pending.swap(part.body);
    }
    if (layerHeight_ > 0) return;
    previousZ_ = pendingZ_;
    pendingZ_ = z;
  }

  void finish() override {
    assert(next_ == job_.layerCount);
    for (std::size_t p = 0; p < parts_.size(); ++p) {
      if (next_ == 0) {
        openStack(p, static_cast<double>(job_.bounds.min.z));
      } else if (layerHeight_ <= 0) {
        double half = (pendingZ_ - previousZ_) / 2;
        if (next_ == 1) {
          half = pendingZ_ - static_cast<double>(job_.bounds.min.z);
          if (!(half > 0)) half = kLoneSlabHalf;
          openStack(p, pendingZ_ - half);
        }
        emitSlice(p, pendingZ_ + half, parts_[p].pending);
      }
      stackText(p).append("</s:slicestack>\n");
    }
    for (std::size_t p = 1; p < parts_.size(); ++p) copySpool(p);
    for (std::size_t p = 0; p < parts_.size(); ++p) writeObject(p);
    out_.append("</resources>\n<build>\n");
    // Removals are resources only: a consumer printing the build must not print them as solids.
    for (std::size_t p = 0; p < parts_.size(); ++p) {
      if (parts_[p].reversed) continue;
      out_.append("<item objectid=\"");
      out_.appendUint(objectId(p));
      out_.append("\"/>\n");
    }
    out_.append("</build>\n</model>\n");
    flushText();
    int rc = zipCloseFileInZip(zip_.get());
    if (rc != ZIP_OK) fail("cannot write 3D/3dmodel.model", rc);
    rc = zipClose(zip_.release(), kZipComment.data());  // the comment: how --force knows it
    if (rc != ZIP_OK) fail("cannot write", rc);
    alignCentralVersions(file_.tempPath(), file_.finalPath());
    file_.commit();
  }

 private:
  [[noreturn]] void fail(const std::string& what, int code) {
    throw OutputError(file_.finalPath().string() + ": " + what + ": " + zipErrorText(code));
  }

  void openEntry(const char* name, bool zip64) {
    // Deflated, no data descriptor; zip64 reserves the Zip64 sizes in the local header, so the model
    // entry may pass 4 GiB.
    const int rc = zipOpenNewFileInZip4_64(zip_.get(), name, &info_, nullptr, 0, nullptr, 0, nullptr,
                                           Z_DEFLATED, kDeflateLevel, 0, -MAX_WBITS, DEF_MEM_LEVEL,
                                           Z_DEFAULT_STRATEGY, nullptr, 0, 0, 0, zip64 ? 1 : 0);
    if (rc != ZIP_OK) fail(std::string("cannot write ") + name, rc);
  }

  void writeToEntry(const char* data, std::size_t size) {
    while (size > 0) {
      const unsigned piece = static_cast<unsigned>(std::min<std::size_t>(size, UINT_MAX / 2));
      const int rc = zipWriteInFileInZip(zip_.get(), data, piece);
      if (rc != ZIP_OK) fail("cannot write", rc);
      data += piece;
      size -= piece;
    }
  }

  void addEntry(const char* name, std::string_view text) {
    openEntry(name, false);
    writeToEntry(text.data(), text.size());
    const int rc = zipCloseFileInZip(zip_.get());
    if (rc != ZIP_OK) fail(std::string("cannot write ") + name, rc);
  }

  void flushText() {
    writeToEntry(out_.data(), out_.size());
    out_.clear();
  }
  void flushIfLarge() {
    if (out_.size() >= kFlushBytes) flushText();
  }

  // Part p's stack text: the model's goes to the model entry (out_), a feature's to its spool file.
  Text& stackText(std::size_t p) { return p == 0 ? out_ : parts_[p].text; }

  void writeToStack(std::size_t p, const char* data, std::size_t size) {
    if (p == 0) return writeToEntry(data, size);
    if (size > 0 && std::fwrite(data, 1, size, parts_[p].spool.get()) != size) failSpool(p);
  }

  void flushStack(std::size_t p) {
    Text& text = stackText(p);
    writeToStack(p, text.data(), text.size());
    text.clear();
  }

  [[noreturn]] void failSpool(std::size_t p) {
    throw OutputError(file_.finalPath().string() + ": cannot spool the slices of feature '" +
                      job_.features[p - 1].name + "': " + std::generic_category().message(errno));
  }

  // Appends feature p's spooled stack to the model entry.
  void copySpool(std::size_t p) {
    flushStack(p);
    std::FILE* spool = parts_[p].spool.get();
    if (std::fflush(spool) != 0 || std::fseek(spool, 0, SEEK_SET) != 0) failSpool(p);
    flushText();
    std::vector<char> chunk(kFlushBytes);
    for (;;) {
      const std::size_t got = std::fread(chunk.data(), 1, chunk.size(), spool);
      writeToEntry(chunk.data(), got);
      if (got < chunk.size()) break;
    }
    if (std::ferror(spool)) failSpool(p);
    parts_[p].spool.reset();
  }

  void openStack(std::size_t p, double zbottom) {
    Text& out = stackText(p);
    out.append("<s:slicestack id=\"");
    out.appendUint(sliceStackId(p));
    out.append("\" zbottom=\"");
    out.appendDecimal(zbottom);
    out.append("\">\n");
  }

  void emitSlice(std::size_t p, double ztop, const Text& body) {
    Text& out = stackText(p);
    out.append("<s:slice ztop=\"");
    out.appendDecimal(ztop);
    if (body.empty()) {
      out.append("\"/>\n");
    } else {
      out.append("\">\n");
      if (body.size() >= kFlushBytes) {  // a large layer goes to deflate directly, not via a copy
        flushStack(p);
        writeToStack(p, body.data(), body.size());
      } else {
        out.append(body);
      }
      out.append("</s:slice>\n");
    }
    if (out.size() >= kFlushBytes) flushStack(p);
  }

  // <s:vertices> then one <s:polygon> per loop of 2 or more points; nothing for a layer without such
  // loops. Vertex i of the slice is point i of the kept loops, in loop order.
  // A reversed part's loops are written reversed (writtenIndex); the index lists do not change.
  void encodeSliceBody(const LayerContours& layer, bool reversed, Text& text) const {
    std::size_t kept = 0;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const std::size_t n = layer.loopOffsets[l + 1] - layer.loopOffsets[l];
      if (n >= 2) kept += n;
    }
    if (kept == 0) return;
    if (kept >= (std::size_t{1} << 31)) {
      throw OutputError(file_.finalPath().string() + ": a 3MF slice holds fewer than 2^31 vertices; layer " +
                        std::to_string(next_ - 1) + " has " + std::to_string(kept));
    }
    text.append("<s:vertices>\n");
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto pts = layer.loopPoints(l);
      if (pts.size() < 2) continue;
      for (std::size_t i = 0; i < pts.size(); ++i) {
        const Point2d& q = pts[writtenIndex(i, pts.size(), layer.loopClosed[l] != 0, reversed)];
        text.append("<s:vertex x=\"");
        text.appendDecimal(q.x);
        text.append("\" y=\"");
        text.appendDecimal(q.y);
        text.append("\"/>\n");
      }
    }
    text.append("</s:vertices>\n");
    uint64_t start = 0;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const std::size_t n = layer.loopOffsets[l + 1] - layer.loopOffsets[l];
      if (n < 2) continue;
      text.append("<s:polygon startv=\"");
      text.appendUint(start);
      text.append("\">\n");
      for (uint64_t v = start + 1; v < start + n; ++v) {
        text.append("<s:segment v2=\"");
        text.appendUint(v);
        text.append("\"/>\n");
      }
      // Every polygon is closed, open polylines included: the Slice Extension requires closed polygons
      // in a "model" object (lib3mf refuses open ones), so an open polyline left after gap bridging is
      // closed by a straight segment here (the slice summary counts them).
      text.append("<s:segment v2=\"");
      text.appendUint(start);
      text.append("\"/>\n");
      text.append("</s:polygon>\n");
      start += n;
    }
  }

  void appendVertex(const Point3f& p) {
    out_.append("<vertex x=\"");
    out_.appendFloat(p.x);
    out_.append("\" y=\"");
    out_.appendFloat(p.y);
    out_.append("\" z=\"");
    out_.appendFloat(p.z);
    out_.append("\"/>\n");
    flushIfLarge();
  }

  void appendTriangle(uint32_t a, uint32_t b, uint32_t c) {
    out_.append("<triangle v1=\"");
    out_.appendUint(a);
    out_.append("\" v2=\"");
    out_.appendUint(b);
    out_.append("\" v3=\"");
    out_.appendUint(c);
    out_.append("\"/>\n");
    flushIfLarge();
  }

  // A triangle as written: a removal's triangles reversed (inside out, like its loops).
  void appendPartTriangle(const Part& part, uint32_t a, uint32_t b, uint32_t c) {
    if (part.reversed) std::swap(b, c);
    appendTriangle(a, b, c);
  }

  // Object of part p: the model's named after the job, a feature's "add <name>" or "remove <name>".
  void writeObject(std::size_t p) {
    const Part& part = parts_[p];
    out_.append("<object id=\"");
    out_.appendUint(objectId(p));
    out_.append("\" type=\"model\" name=\"");
    if (p == 0) {
      out_.append(xmlName(job_.name));
    } else {
      const ContourPart& feature = job_.features[p - 1];
      out_.append(xmlName(std::string(partRoleName(feature.role)) + " " + feature.name));
    }
    out_.append("\" s:slicestackid=\"");
    out_.appendUint(sliceStackId(p));
    out_.append(part.lowres ? "\" s:meshresolution=\"lowres\">\n" : "\" s:meshresolution=\"fullres\">\n");
    out_.append("<mesh>\n<vertices>\n");
    if (part.box) {
      // Corner i of the bounding box takes max x when bit 0 is set, max y for bit 1, max z for bit 2.
      // The box of a feature's own facets when it has any, else the model's.
      const bool ownBox = p > 0 && part.mesh != nullptr && !part.mesh->corners.empty();
      const BoundingBox b = ownBox ? boundsOf(part.mesh->corners) : job_.bounds;
      for (uint32_t i = 0; i < 8; ++i) {
        appendVertex({(i & 1) ? b.max.x : b.min.x, (i & 2) ? b.max.y : b.min.y, (i & 4) ? b.max.z : b.min.z});
      }
      out_.append("</vertices>\n<triangles>\n");
      // Two counter-clockwise (outward) triangles per face: -z, +z, -y, +y, -x, +x.
      static constexpr uint32_t kBox[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6},
                                               {0, 1, 5}, {0, 5, 4}, {2, 6, 7}, {2, 7, 3},
                                               {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
      for (const auto& t : kBox) appendPartTriangle(part, t[0], t[1], t[2]);
    } else {
      const IndexedMesh welded = weldCorners(part.mesh->corners);
      for (const Point3f& v : welded.vertices) appendVertex(v);
      out_.append("</vertices>\n<triangles>\n");
      const std::vector<uint32_t>& fv = welded.facetVertices;
      for (std::size_t f = 0; f + 2 < fv.size(); f += 3) {
        if (fv[f] != fv[f + 1] && fv[f + 1] != fv[f + 2] && fv[f] != fv[f + 2])
          appendPartTriangle(part, fv[f], fv[f + 1], fv[f + 2]);
      }
    }
    out_.append("</triangles>\n</mesh>\n</object>\n");
  }

  OutputFile file_;  // declared first: destroyed last, after zip_ has closed its handle
  ContourJob job_;
  double layerHeight_;
  std::vector<Part> parts_;  // [0] the model, then job_.features
  // Closed also without finish(); file_ then removes the temporary.
  std::unique_ptr<std::remove_pointer_t<zipFile>, ZipCloser> zip_;
  zip_fileinfo info_{};
  Text out_;  // model text not yet handed to deflate
  double pendingZ_ = 0;
  double previousZ_ = 0;
  uint32_t next_ = 0;
};

}  // namespace

std::unique_ptr<ContourSink> makeThreeMfWriter(const std::filesystem::path& path, const ContourJob& job,
                                               const FacetSoup* mesh, bool overwrite, double layerHeight,
                                               std::span<const FacetSoup> featureMeshes) {
  return std::make_unique<ThreeMfWriter>(path, job, mesh, overwrite, layerHeight, featureMeshes);
}

}  // namespace toposlice
