// Streaming destination for per-layer contours (CLI, SVG, ...).
//
// A slicing run creates one sink per output, calls writeLayer once per layer in increasing index order
// (0, 1, ..., layerCount-1), then finish(). A sink writes through an OutputFile, so nothing appears under
// the final name before finish() returns; a sink destroyed without finish() (error, cancellation) leaves
// nothing on disk. I/O failures are thrown as OutputError from any of the calls.
//
// Parts: a layer is the model's contours followed by those of each feature (job.features, add-ons first,
// then removals), each sliced on its own at the same plane. The solid of a layer is where the winding
// numbers of all parts' closed loops, a removal's counted with the opposite sign (winding -1 inside it),
// add up to more than zero: the positive rule of the masks. Every format writes a removal's loops
// reversed, so that a reader applies that rule to all written loops as they stand.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"
#include "io/text_buffer.h"

namespace toposlice {

enum class PartRole : uint8_t { Model, Add, Remove };

// "model", "add" or "remove": the role's word in file labels.
inline const char* partRoleName(PartRole role) {
  return role == PartRole::Add ? "add" : role == PartRole::Remove ? "remove" : "model";
}

// One feature sliced with the model (`toposlice slice --add/--remove`).
struct ContourPart {
  std::string name;  // the feature file's stem, sanitized by each format
  PartRole role = PartRole::Add;
  // +1 for the model and add-ons, -1 for a removal.
  int winding() const { return role == PartRole::Remove ? -1 : 1; }
};

// What a sink knows before the first layer: used for file headers.
struct ContourJob {
  std::string name;    // model or part name, written into headers (sanitized by each format)
  BoundingBox bounds;  // model bounds in mm
  uint32_t layerCount = 0;
  // Part 1, 2, ... of every layer (part 0 is the model): add-ons first, then removals. Empty without
  // features, and then every format writes exactly what it wrote before features existed.
  std::vector<ContourPart> features;
  // An outline correction (absolute_correction, elephant foot) moved the contours off the meshes' cuts:
  // a mesh written beside them (3MF) is then not what the slices were cut from.
  bool outlinesCorrected = false;
};

class ContourSink {
 public:
  virtual ~ContourSink() = default;
  // Writes layer `index`; called for every layer, in layer order. `parts` holds 1 + job.features.size()
  // layers, all at the same z: [0] the model, then the features in job.features order.
  virtual void writeLayer(uint32_t index, std::span<const LayerContours> parts) = 0;
  // A job without features: the model's layer alone.
  void writeLayer(uint32_t index, const LayerContours& model) { writeLayer(index, {&model, 1}); }
  // Formats whose layers are independent byte ranges (CLI) split writeLayer in two, so the in-order stage
  // only copies bytes: encodeLayer makes a layer's bytes in the parallel stage (const, any thread, any
  // order), and writeEncodedLayer writes them, called like writeLayer (every layer, in layer order).
  // writeLayer(k, parts) is the same as both in turn.
  virtual bool encodesLayers() const { return false; }
  virtual void encodeLayer(std::span<const LayerContours> parts, TextBuffer& bytes) const {
    (void)parts;
    (void)bytes;
  }
  virtual void writeEncodedLayer(uint32_t index, const TextBuffer& bytes) {
    (void)index;
    (void)bytes;
  }
  // Completes and commits the file; without finish() nothing is left on disk.
  virtual void finish() = 0;
};

}  // namespace toposlice
