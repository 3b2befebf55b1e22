#include "io/contours/cli_writer.h"

#include <bit>
#include <cassert>
#include <charconv>
#include <climits>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "io/output_file.h"
#include "io/text_buffer.h"

// Source: Common Layer Interface (CLI) specification, version 2.00, binary section, cross-checked against
// independent CLI readers: commands are uint16, "start layer long" = 127 (real z), "start polyline long"
// = 130 (int32 id, dir, n, then n pairs of reals); integers and IEEE-754 float32 reals are little-endian;
// binary data starts right after "$$HEADEREND". dir: 0 clockwise (internal), 1 counter-clockwise
// (external), 2 open line, seen looking down the z axis.

namespace toposlice {
namespace {

constexpr uint16_t kCmdLayerLong = 127;
constexpr uint16_t kCmdPolylineLong = 130;
constexpr int32_t kModelId = 1;   // feature i (0-based in job.features) is id i + 2
constexpr int32_t kDirHole = 0;   // clockwise seen from +z
constexpr int32_t kDirOuter = 1;  // counter-clockwise seen from +z
constexpr int32_t kDirOpen = 2;
constexpr int kDecimals = 6;
// Longest fixed-notation double with kDecimals decimals: sign, 309 digits, point, decimals.
constexpr std::size_t kMaxFixedChars = 1 + 309 + 1 + kDecimals;

// Fixed notation, kDecimals decimals; a value that rounds to zero is written without a minus sign.
void appendFixed(TextBuffer& buf, double v) {
  char* p = buf.reserveMore(kMaxFixedChars);
  char* end = std::to_chars(p, p + kMaxFixedChars, v, std::chars_format::fixed, kDecimals).ptr;
  if (*p == '-' && v > -1e-6) {
    bool zero = true;
    for (const char* c = p + 1; c < end; ++c) zero = zero && (*c == '0' || *c == '.');
    if (zero) {
      std::memmove(p, p + 1, static_cast<std::size_t>(end - p - 1));
      --end;
    }
  }
  buf.setEnd(end);
}

template <typename T>
char* storeLE(char* p, T value) {
  static_assert(sizeof(T) == 2 || sizeof(T) == 4);
  if constexpr (std::endian::native == std::endian::little) {
    std::memcpy(p, &value, sizeof(T));
  } else {
    using U = std::conditional_t<sizeof(T) == 2, uint16_t, uint32_t>;
    const U bits = std::bit_cast<U>(value);
    for (std::size_t i = 0; i < sizeof(T); ++i) p[i] = static_cast<char>((bits >> (8 * i)) & 0xFFu);
  }
  return p + sizeof(T);
}

// dir of loop l as written: a reversed loop's area has the opposite sign.
int32_t loopDir(const LayerContours& layer, std::size_t l, bool reversed) {
  if (!layer.loopClosed[l]) return kDirOpen;
  const double area = signedArea(layer.loopPoints(l));
  return (reversed ? -area : area) > 0 ? kDirOuter : kDirHole;
}

// Point i of a loop of n points in written order. Reversed, a closed loop keeps its first point and
// runs p0, p(n-1), ..., p1; an open polyline runs from its last point back to its first.
std::size_t writtenIndex(std::size_t i, std::size_t n, bool closed, bool reversed) {
  if (!reversed) return i;
  if (closed) return i == 0 ? 0 : n - i;
  return n - 1 - i;
}

// Header text: printable ASCII only; '/' and '$' (CLI comment and command markers) become '_'.
std::string sanitizeLabel(const std::string& name) {
  std::string out;
  for (const char c : name) {
    const bool printable = c >= 0x20 && c < 0x7f && c != '/' && c != '$';
    out.push_back(printable ? c : '_');
  }
  return out.empty() ? std::string("part") : out;
}

void appendHeader(TextBuffer& buf, const ContourJob& job, bool binary) {
  buf.append("$$HEADERSTART\n");
  buf.append(kCliMarkLine);  // how --force knows the file (checkReplaceable)
  buf.append(binary ? "$$BINARY\n" : "$$ASCII\n");
  buf.append("$$UNITS/00000001.000000\n");
  buf.append("$$VERSION/200\n");
  buf.append("$$LABEL/");
  buf.appendInt(kModelId);
  buf.append(',');
  buf.append(sanitizeLabel(job.name));
  for (std::size_t i = 0; i < job.features.size(); ++i) {
    const ContourPart& part = job.features[i];
    buf.append("\n$$LABEL/");
    buf.appendInt(kModelId + 1 + static_cast<int64_t>(i));
    buf.append(',');
    buf.append(partRoleName(part.role));
    buf.append(' ');
    buf.append(sanitizeLabel(part.name));
  }
  buf.append("\n$$DIMENSION/");
  const float dims[6] = {job.bounds.min.x, job.bounds.min.y, job.bounds.min.z,
                         job.bounds.max.x, job.bounds.max.y, job.bounds.max.z};
  for (int i = 0; i < 6; ++i) {
    if (i > 0) buf.append(',');
    appendFixed(buf, static_cast<double>(dims[i]));
  }
  buf.append("\n$$LAYERS/");
  buf.appendInt(job.layerCount);
  buf.append("\n$$HEADEREND");
  // Binary commands follow the header's last byte directly; ASCII continues with lines.
  if (!binary) buf.append("\n$$GEOMETRYSTART\n");
}

class CliWriter final : public ContourSink {
 public:
  CliWriter(const std::filesystem::path& path, const ContourJob& job, bool binary, bool overwrite)
      : file_(path, overwrite), binary_(binary), layerCount_(job.layerCount) {
    reversed_.push_back(false);
    for (const ContourPart& part : job.features) reversed_.push_back(part.role == PartRole::Remove);
    appendHeader(buf_, job, binary_);
    file_.write(buf_.data(), buf_.size());
  }

  bool encodesLayers() const override { return true; }

  void encodeLayer(std::span<const LayerContours> parts, TextBuffer& buf) const override {
    assert(parts.size() == reversed_.size());
    buf.clear();
    const double z = parts[0].z;
    if (binary_) {
      char* p = buf.reserveMore(2 + 4);
      p = storeLE(p, kCmdLayerLong);
      buf.setEnd(storeLE(p, static_cast<float>(z)));
    } else {
      buf.append("$$LAYER/");
      appendFixed(buf, z);
      buf.append('\n');
    }
    for (std::size_t i = 0; i < parts.size(); ++i) {
      const LayerContours& layer = parts[i];
      assert(layer.loopClosed.size() == layer.loopCount());
      const int32_t id = kModelId + static_cast<int32_t>(i);
      if (binary_) {
        encodeBinary(buf, layer, id, reversed_[i]);
      } else {
        encodeAscii(buf, layer, id, reversed_[i]);
      }
    }
  }

  void writeEncodedLayer(uint32_t index, const TextBuffer& bytes) override {
    assert(index == nextLayer_ && index < layerCount_);
    (void)index;
    ++nextLayer_;
    file_.write(bytes.data(), bytes.size());
  }

  void writeLayer(uint32_t index, std::span<const LayerContours> parts) override {
    encodeLayer(parts, buf_);
    writeEncodedLayer(index, buf_);
  }

  void finish() override {
    assert(nextLayer_ == layerCount_);
    if (!binary_) file_.write("$$GEOMETRYEND\n", 14);
    file_.commit();
  }

 private:
  // One line per loop of one part.
  static void encodeAscii(TextBuffer& buf, const LayerContours& layer, int32_t id, bool reversed) {
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto pts = layer.loopPoints(l);
      if (pts.empty()) continue;
      const bool closed = layer.loopClosed[l] != 0;
      buf.append("$$POLYLINE/");
      buf.appendInt(id);
      buf.append(',');
      buf.appendInt(loopDir(layer, l, reversed));
      buf.append(',');
      buf.appendInt(static_cast<int64_t>(pts.size() + (closed ? 1 : 0)));
      for (std::size_t i = 0; i < pts.size(); ++i) {
        const Point2d& q = pts[writtenIndex(i, pts.size(), closed, reversed)];
        buf.append(',');
        appendFixed(buf, q.x);
        buf.append(',');
        appendFixed(buf, q.y);
      }
      if (closed) {
        buf.append(',');
        appendFixed(buf, pts[0].x);
        buf.append(',');
        appendFixed(buf, pts[0].y);
      }
      buf.append('\n');
    }
  }

  // The polylines of one part: sized first, then filled in one pass.
  static void encodeBinary(TextBuffer& buf, const LayerContours& layer, int32_t id, bool reversed) {
    constexpr std::size_t kPolylineBytes = 2 + 3 * 4, kPointBytes = 2 * 4;
    std::size_t bytes = 0;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const std::size_t n = layer.loopOffsets[l + 1] - layer.loopOffsets[l];
      if (n > 0) bytes += kPolylineBytes + kPointBytes * (n + (layer.loopClosed[l] ? 1 : 0));
    }
    char* p = buf.reserveMore(bytes);
    char* const end = p + bytes;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto pts = layer.loopPoints(l);
      if (pts.empty()) continue;
      const bool closed = layer.loopClosed[l] != 0;
      assert(pts.size() < static_cast<std::size_t>(INT32_MAX));
      p = storeLE(p, kCmdPolylineLong);
      p = storeLE(p, id);
      p = storeLE(p, loopDir(layer, l, reversed));
      p = storeLE(p, static_cast<int32_t>(pts.size() + (closed ? 1 : 0)));
      for (std::size_t i = 0; i < pts.size(); ++i) {
        const Point2d& q = pts[writtenIndex(i, pts.size(), closed, reversed)];
        p = storeLE(p, static_cast<float>(q.x));
        p = storeLE(p, static_cast<float>(q.y));
      }
      if (closed) {
        p = storeLE(p, static_cast<float>(pts[0].x));
        p = storeLE(p, static_cast<float>(pts[0].y));
      }
    }
    assert(p == end);
    buf.setEnd(end);
  }

  OutputFile file_;
  bool binary_;
  uint32_t layerCount_;
  uint32_t nextLayer_ = 0;
  std::vector<bool> reversed_;  // per part: a removal's loops are written reversed
  TextBuffer buf_;              // writeLayer's layer bytes
};

}  // namespace

std::unique_ptr<ContourSink> makeCliWriter(const std::filesystem::path& path, const ContourJob& job,
                                           bool binary, bool overwrite) {
  return std::make_unique<CliWriter>(path, job, binary, overwrite);
}

}  // namespace toposlice
