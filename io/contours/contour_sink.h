// Streaming destination for per-layer contours (CLI, SVG, ...).
//
// A slicing run creates one sink per output, calls writeLayer once per layer in increasing index order
// (0, 1, ..., layerCount-1), then finish(). A sink writes through an OutputFile, so nothing appears under
// the final name before finish() returns; a sink destroyed without finish() (error, cancellation) leaves
// nothing on disk. I/O failures are thrown as OutputError from any of the calls.
#pragma once

#include <cstdint>
#include <string>

#include "core/contours.h"
#include "core/mesh.h"

namespace toposlice {

// What a sink knows before the first layer: used for file headers.
struct ContourJob {
  std::string name;    // model or part name, written into headers (sanitized by each format)
  BoundingBox bounds;  // model bounds in mm
  uint32_t layerCount = 0;
};

class ContourSink {
 public:
  virtual ~ContourSink() = default;
  // Writes layer `index`; called for every layer, in layer order.
  virtual void writeLayer(uint32_t index, const LayerContours& layer) = 0;
  // Completes and commits the file; without finish() nothing is left on disk.
  virtual void finish() = 0;
};

}  // namespace toposlice
