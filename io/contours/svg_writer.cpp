#include "io/contours/svg_writer.h"

#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <string_view>

#include "io/contours/xml_text.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

constexpr const char* kSolidFill = "#a6cee3";
constexpr const char* kSolidStroke = "#1f3b73";
constexpr const char* kHoleStroke = "#d62728";
constexpr const char* kOpenStroke = "#ff7f0e";
constexpr const char* kFrameStroke = "#bbbbbb";
constexpr const char* kAddStroke = "#2ca02c";
constexpr const char* kRemoveStroke = "#9467bd";

// Point i of a loop of n points as drawn: a removal's loops reversed, a closed loop keeping its first
// point (p0, p(n-1), ..., p1), an open polyline from its last point to its first.
std::size_t drawnIndex(std::size_t i, std::size_t n, bool closed, bool reversed) {
  if (!reversed) return i;
  if (closed) return i == 0 ? 0 : n - i;
  return n - 1 - i;
}

// Fixed notation with `decimals` decimals, trailing zeros trimmed, no "-0".
void appendNumber(std::string& out, double v, int decimals) {
  char buf[400];
  char* end = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::fixed, decimals).ptr;
  char* dot = std::find(buf, end, '.');
  if (dot != end) {
    while (end[-1] == '0') --end;
    if (end[-1] == '.') --end;
  }
  std::string_view s(buf, static_cast<std::size_t>(end - buf));
  if (s == "-0") s = "0";
  out += s;
}

class SvgWriter final : public ContourSink {
 public:
  SvgWriter(const std::filesystem::path& path, const ContourJob& job, std::vector<uint32_t> layers,
            bool overwrite)
      : file_(path, overwrite), layers_(std::move(layers)), layerCount_(job.layerCount) {
    parts_.push_back({job.name, PartRole::Model});
    parts_.insert(parts_.end(), job.features.begin(), job.features.end());
    for (const ContourPart& part : job.features) hasRemoval_ = hasRemoval_ || part.role == PartRole::Remove;
    std::sort(layers_.begin(), layers_.end());
    layers_.erase(std::unique(layers_.begin(), layers_.end()), layers_.end());
    layers_.erase(std::lower_bound(layers_.begin(), layers_.end(), layerCount_), layers_.end());

    const BoundingBox& b = job.bounds;
    minX_ = static_cast<double>(b.min.x);
    maxY_ = static_cast<double>(b.max.y);
    // A flat or empty box still gets a visible 1 mm panel.
    width_ = std::max(static_cast<double>(b.max.x) - minX_, 1.0);
    height_ = std::max(maxY_ - static_cast<double>(b.min.y), 1.0);
    const double size = std::max(width_, height_);
    margin_ = 0.05 * size;
    fontSize_ = 0.045 * size;
    captionHeight_ = 1.6 * fontSize_;
    stroke_ = size / 400;
    cellWidth_ = width_ + 2 * margin_;
    cellHeight_ = height_ + 2 * margin_ + captionHeight_;
    const std::size_t count = layers_.size();
    columns_ =
        std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(std::sqrt(static_cast<double>(count)))));
    const std::size_t rows = (count + columns_ - 1) / columns_;
    const double totalWidth = static_cast<double>(columns_) * cellWidth_;
    const double totalHeight = rows > 0 ? static_cast<double>(rows) * cellHeight_ : 2 * margin_;

    std::string s = "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
    s += kSvgMarkLine;  // how --force knows the file (checkReplaceable)
    s += "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"";
    appendNumber(s, totalWidth, 4);
    s += "mm\" height=\"";
    appendNumber(s, totalHeight, 4);
    s += "mm\" viewBox=\"0 0 ";
    appendNumber(s, totalWidth, 4);
    s += ' ';
    appendNumber(s, totalHeight, 4);
    s += "\">\n<title>";
    appendXmlEscaped(
        s, job.name, [](unsigned char c) { return c >= 0x20; }, ' ');  // UTF-8 kept
    s += "</title>\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    file_.write(s.data(), s.size());
  }

  void writeLayer(uint32_t index, std::span<const LayerContours> layers) override {
    assert(index == nextLayer_ && index < layerCount_);
    assert(layers.size() == parts_.size());
    ++nextLayer_;
    if (nextPanel_ == layers_.size() || layers_[nextPanel_] != index) return;
    const std::size_t panel = nextPanel_++;
    text_.clear();
    appendPanel(panel, index, layers);
    file_.write(text_.data(), text_.size());
  }

  void finish() override {
    assert(nextLayer_ == layerCount_);
    file_.write("</svg>\n", 7);
    file_.commit();
  }

 private:
  void appendPoint(double ox, double oy, const Point2d& p) {
    appendNumber(text_, ox + (p.x - minX_), 4);
    text_ += ',';
    appendNumber(text_, oy + (maxY_ - p.y), 4);
  }

  void appendPointList(double ox, double oy, std::span<const Point2d> pts, bool closed = true,
                       bool reversed = false) {
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (i > 0) text_ += ' ';
      appendPoint(ox, oy, pts[drawnIndex(i, pts.size(), closed, reversed)]);
    }
  }

  bool reversed(std::size_t part) const { return parts_[part].role == PartRole::Remove; }

  // Path data of every closed loop of the parts, a removal's reversed; removals left out when
  // !withRemovals. `first` says whether nothing has been written to this path yet.
  void appendLoopsPathData(double ox, double oy, std::span<const LayerContours> layers, bool withRemovals) {
    bool first = true;
    for (std::size_t p = 0; p < layers.size(); ++p) {
      if (!withRemovals && reversed(p)) continue;
      const LayerContours& layer = layers[p];
      for (std::size_t l = 0; l < layer.loopCount(); ++l) {
        const auto pts = layer.loopPoints(l);
        if (!layer.loopClosed[l] || pts.empty()) continue;
        if (!first) text_ += ' ';
        first = false;
        text_ += 'M';
        appendPoint(ox, oy, pts[0]);
        if (pts.size() > 1) {
          text_ += " L";
          for (std::size_t i = 1; i < pts.size(); ++i) {
            if (i > 1) text_ += ' ';
            appendPoint(ox, oy, pts[drawnIndex(i, pts.size(), true, reversed(p))]);
          }
        }
        text_ += " Z";
      }
    }
  }

  void appendPanel(std::size_t panel, uint32_t index, std::span<const LayerContours> layers) {
    const LayerContours& layer = layers[0];
    const double cellX = static_cast<double>(panel % columns_) * cellWidth_;
    const double cellY = static_cast<double>(panel / columns_) * cellHeight_;
    const double ox = cellX + margin_, oy = cellY + margin_ + captionHeight_;  // top-left of the drawing

    text_ += "<g id=\"layer-";
    appendNumber(text_, index, 0);
    text_ += "\">\n<text class=\"caption\" x=\"";
    appendNumber(text_, cellX + margin_, 4);
    text_ += "\" y=\"";
    appendNumber(text_, cellY + margin_ + fontSize_, 4);
    text_ += "\" font-family=\"sans-serif\" font-size=\"";
    appendNumber(text_, fontSize_, 4);
    text_ += "\">layer ";
    appendNumber(text_, index, 0);
    text_ += ", z = ";
    appendNumber(text_, layer.z, 6);
    text_ += "</text>\n<rect class=\"frame\" x=\"";
    appendNumber(text_, ox, 4);
    text_ += "\" y=\"";
    appendNumber(text_, oy, 4);
    text_ += "\" width=\"";
    appendNumber(text_, width_, 4);
    text_ += "\" height=\"";
    appendNumber(text_, height_, 4);
    text_ += "\" fill=\"none\" stroke=\"";
    text_ += kFrameStroke;
    text_ += "\" stroke-width=\"";
    appendNumber(text_, stroke_ * 0.5, 4);
    text_ += "\"/>\n";

    // With a removal, nonzero alone would also fill where a removal reaches beyond the solid (winding
    // -1); clipping to the model and add-ons (nonzero) leaves exactly the positive-winding region as
    // long as removals do not overlap each other inside the solid.
    if (hasRemoval_) {
      text_ += "<clipPath id=\"clip-layer-";
      appendNumber(text_, index, 0);
      text_ += "\"><path clip-rule=\"nonzero\" d=\"";
      appendLoopsPathData(ox, oy, layers, false);
      text_ += "\"/></clipPath>\n";
    }
    // All closed loops of all parts in one path, so that nonzero winding leaves the holes (and what
    // removals take away, their loops being reversed) empty.
    text_ += "<path class=\"solid\"";
    if (hasRemoval_) {
      text_ += " clip-path=\"url(#clip-layer-";
      appendNumber(text_, index, 0);
      text_ += ")\"";
    }
    text_ += " fill=\"";
    text_ += kSolidFill;
    text_ += "\" fill-rule=\"nonzero\" stroke=\"";
    text_ += kSolidStroke;
    text_ += "\" stroke-width=\"";
    appendNumber(text_, stroke_, 4);
    text_ += "\" stroke-linejoin=\"round\" d=\"";
    appendLoopsPathData(ox, oy, layers, true);
    text_ += "\"/>\n";

    if (parts_.size() > 1) appendPartGroupOpen(index, 0);
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto pts = layer.loopPoints(l);
      if (pts.empty()) continue;
      if (layer.loopClosed[l]) {
        if (signedArea(pts) > 0) continue;
        text_ += "<polygon class=\"hole\" fill=\"none\" stroke=\"";
        text_ += kHoleStroke;
        text_ += "\" stroke-width=\"";
        appendNumber(text_, stroke_, 4);
        text_ += "\" stroke-dasharray=\"";
        appendNumber(text_, stroke_ * 4, 4);
        text_ += ',';
        appendNumber(text_, stroke_ * 3, 4);
        text_ += "\" points=\"";
      } else {
        appendOpenPolylineStart();
      }
      appendPointList(ox, oy, pts);
      text_ += "\"/>\n";
    }
    if (parts_.size() > 1) text_ += "</g>\n";
    for (std::size_t p = 1; p < layers.size(); ++p) appendFeatureGroup(ox, oy, index, p, layers[p]);
    text_ += "</g>\n";
  }

  // The start of an open polyline's element, up to its points (model and features draw them alike).
  void appendOpenPolylineStart() {
    text_ += "<polyline class=\"open\" fill=\"none\" stroke=\"";
    text_ += kOpenStroke;
    text_ += "\" stroke-width=\"";
    appendNumber(text_, stroke_ * 1.5, 4);
    text_ += "\" stroke-linecap=\"round\" points=\"";
  }

  // <g id="layer-<k>-part-<p+1>" class="part <role>"><title><role> <name></title> (ids as in the CLI).
  void appendPartGroupOpen(uint32_t index, std::size_t p) {
    const char* role = partRoleName(parts_[p].role);
    text_ += "<g id=\"layer-";
    appendNumber(text_, index, 0);
    text_ += "-part-";
    appendNumber(text_, static_cast<double>(p + 1), 0);
    text_ += "\" class=\"part ";
    text_ += role;
    text_ += "\"><title>";
    text_ += role;
    text_ += ' ';
    appendXmlEscaped(
        text_, parts_[p].name, [](unsigned char c) { return c >= 0x20; }, ' ');
    text_ += "</title>\n";
  }

  // A feature's outlines: every closed loop as an unfilled polygon (add-on green, removal purple and
  // dashed, drawn in the reversed order it has in the solid path), open polylines as for the model.
  void appendFeatureGroup(double ox, double oy, uint32_t index, std::size_t p, const LayerContours& layer) {
    appendPartGroupOpen(index, p);
    const bool removal = reversed(p);
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto pts = layer.loopPoints(l);
      if (pts.empty()) continue;
      const bool closed = layer.loopClosed[l] != 0;
      if (closed) {
        text_ += removal ? "<polygon class=\"remove\" fill=\"none\" stroke=\""
                         : "<polygon class=\"add\" fill=\"none\" stroke=\"";
        text_ += removal ? kRemoveStroke : kAddStroke;
        text_ += "\" stroke-width=\"";
        appendNumber(text_, stroke_, 4);
        if (removal) {
          text_ += "\" stroke-dasharray=\"";
          appendNumber(text_, stroke_ * 2, 4);
          text_ += ',';
          appendNumber(text_, stroke_ * 2, 4);
        }
        text_ += "\" points=\"";
      } else {
        appendOpenPolylineStart();
      }
      appendPointList(ox, oy, pts, closed, removal);
      text_ += "\"/>\n";
    }
    text_ += "</g>\n";
  }

  OutputFile file_;
  std::vector<uint32_t> layers_;    // sorted, unique, < layerCount_
  std::vector<ContourPart> parts_;  // [0] the model (its name and role Model), then job.features
  bool hasRemoval_ = false;
  uint32_t layerCount_;
  uint32_t nextLayer_ = 0;
  std::size_t nextPanel_ = 0;
  double minX_ = 0, maxY_ = 0, width_ = 1, height_ = 1;
  double margin_ = 0, fontSize_ = 0, captionHeight_ = 0, stroke_ = 0, cellWidth_ = 0, cellHeight_ = 0;
  std::size_t columns_ = 1;
  std::string text_;
};

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// One layer designator: a decimal index, `last` or `mid`. Returns false with `error` set.
bool parseLayer(std::string_view item, uint32_t layerCount, uint32_t& layer, std::string& error) {
  item = trim(item);
  if (item == "last") {
    layer = layerCount - 1;
    return true;
  }
  if (item == "mid") {
    layer = layerCount / 2;
    return true;
  }
  uint64_t value = 0;
  const auto [ptr, ec] = std::from_chars(item.data(), item.data() + item.size(), value);
  if (item.empty() || ec == std::errc::invalid_argument || ptr != item.data() + item.size()) {
    error = "\"" + std::string(item) + "\" is not a layer number, \"last\" or \"mid\"";
    return false;
  }
  if (ec == std::errc::result_out_of_range || value >= layerCount) {
    error =
        "layer " + std::string(item) + " is out of range (layers 0-" + std::to_string(layerCount - 1) + ")";
    return false;
  }
  layer = static_cast<uint32_t>(value);
  return true;
}

}  // namespace

std::unique_ptr<ContourSink> makeSvgWriter(const std::filesystem::path& path, const ContourJob& job,
                                           std::vector<uint32_t> layers, bool overwrite) {
  return std::make_unique<SvgWriter>(path, job, std::move(layers), overwrite);
}

bool parseLayerList(const std::string& text, uint32_t layerCount, std::vector<uint32_t>& out,
                    std::string& error) {
  out.clear();
  if (layerCount == 0) {
    error = "the model has no layers";
    return false;
  }
  if (trim(text).empty()) {
    error = "no layers given";
    return false;
  }
  std::string_view rest(text);
  for (std::size_t position = 1;; ++position) {
    const std::size_t comma = rest.find(',');
    const std::string_view item = trim(rest.substr(0, comma));
    if (item.empty()) {
      error = "item " + std::to_string(position) + " is empty";
      out.clear();
      return false;
    }
    const std::size_t dash = item.find('-');
    uint32_t first = 0, last = 0;
    std::string why;
    if (dash == std::string_view::npos) {
      if (!parseLayer(item, layerCount, first, why)) {
        error = why;
        out.clear();
        return false;
      }
      last = first;
    } else {
      const std::string_view from = trim(item.substr(0, dash)), to = trim(item.substr(dash + 1));
      if (from.empty() || to.empty() || to.find('-') != std::string_view::npos) {
        error = "\"" + std::string(item) + "\" is not a range \"a-b\"";
        out.clear();
        return false;
      }
      if (!parseLayer(from, layerCount, first, why) || !parseLayer(to, layerCount, last, why)) {
        error = why;
        out.clear();
        return false;
      }
      if (first > last) {
        error = "range \"" + std::string(item) + "\" runs backwards";
        out.clear();
        return false;
      }
    }
    for (uint64_t k = first; k <= last; ++k) out.push_back(static_cast<uint32_t>(k));
    if (comma == std::string_view::npos) break;
    rest.remove_prefix(comma + 1);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return true;
}

}  // namespace toposlice
