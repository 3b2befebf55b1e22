// Streaming mask-stack writers: one MaskSink per output, fed one layer at a time (docs/FORMATS.md).
//
// Contract shared by every sink:
// - Layers arrive in order, index 0, 1, 2, ... (one thread at a time; a sink is not thread-safe), each
//   a MaskImage of exactly job.grid.width x job.grid.height. Memory never grows with the layer count,
//   except for the VDB sink's default single grid, whose tree stays in memory until finish() (OpenVDB
//   writes a grid at once; its slab layout keeps one slab); the others keep per-file bookkeeping.
// - PNG-based sinks (wantsPng() == true) take the layer as pre-encoded PNG bytes (encodeMaskPng), so
//   the caller can encode in parallel; they encode `mask` themselves when `png` is empty. Other sinks
//   read `mask` and ignore `png`.
// - Nothing appears under the final path until finish() returns: output goes to a temporary beside it
//   ("<final>.tmp-<pid>-<n>") and is renamed into place at the end. A sink destroyed without finish()
//   (an exception, a cancelled run) removes its temporary. Without `overwrite`, an existing final path
//   is an OutputError, both when the sink is created and when it finishes.
// - I/O failures throw OutputError naming the path; the sink can then only be destroyed.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "core/mask_image.h"
#include "io/staged_directory.h"

namespace toposlice {

struct MaskJob {
  std::string name;           // file-name prefix of the layers ("<name>00000.png"); the SL1 jobDir
  PixelGrid grid;             // image size, pixel size, origin and mirroring of every layer
  double layerHeight = 0.05;  // mm
  uint32_t layerCount = 0;    // expected number of layers (sets the digits of the layer file names)
  bool antiAliased = false;   // values 0..255 (coverage) rather than 0/255
  std::string printerModel;   // SL1 printerModel ("SL1", "SL1S"); empty: "SL1"
  double volumeMl = 0;        // resin volume, filled before finish if known (SL1 usedMaterial)
  // Creation time written into archives (SL1 entry times and fileCreationTimestamp), seconds since
  // 1970 UTC; 0: 1980-01-01. SOURCE_DATE_EPOCH, when set, overrides it. Never the clock, so the same
  // input gives the same bytes.
  std::int64_t created = 0;
  // SL1 exposure settings (config.ini expTime, expTimeFirst, numFade); ignored by the other formats.
  double exposureTime = 8.0;          // s
  double initialExposureTime = 35.0;  // s, first layer; faded linearly to exposureTime
  uint32_t fadeLayers = 10;           // layers of that fade, at least 2 for the SL1 firmware
  // VDB only: one grid per slab of kVdbSlabLayers layers (io/masks/vdb_writer.h) instead of one grid for
  // the whole stack; ignored by the other formats.
  bool vdbSlabs = false;
};

class MaskSink {
 public:
  virtual ~MaskSink() = default;
  // PNG-based sinks take pre-encoded PNG bytes so encoding can run in parallel elsewhere; other sinks
  // take the image.
  virtual bool wantsPng() const { return false; }
  // Layer `index` (0-based, in order) cut at height z (mm). `png` is encodeMaskPng(mask) or empty.
  virtual void writeLayer(uint32_t index, double z, const MaskImage& mask, std::span<const uint8_t> png) = 0;
  // The same for a PNG sink, with the CRC-32 of `png` already computed (in the parallel stage), so the
  // in-order writer does not checksum every byte again. Default: writeLayer.
  virtual void writePngLayer(uint32_t index, double z, const MaskImage& mask, std::span<const uint8_t> png,
                             uint32_t pngCrc32) {
    (void)pngCrc32;
    writeLayer(index, z, mask, png);
  }
  // Sinks that prepare layers in the caller's parallel stage (encodesLayers() == true): the caller runs
  // encodeLayer there, on any thread and concurrently (it reads only `mask` and the sink's job, and
  // writes only `out`), and passes the bytes, in layer order, to writeEncodedLayer instead of calling
  // writeLayer. The bytes are the sink's own format, never read by anyone else.
  virtual bool encodesLayers() const { return false; }
  virtual void encodeLayer(const MaskImage& mask, std::vector<uint8_t>& out) const {
    (void)mask;
    out.clear();
  }
  virtual void writeEncodedLayer(uint32_t index, double z, std::span<const uint8_t> encoded) {
    (void)index, (void)z, (void)encoded;
  }
  // Completes the output and moves it under its final name. finalJob is the job as known at the end
  // (volumeMl filled); the layer count written is the number of writeLayer calls. Call at most once.
  virtual void finish(const MaskJob& finalJob) = 0;
};

// Picks the writer by extension (case-insensitive): .sl1/.sl1s -> SL1 archive, .exr -> directory of
// OpenEXR files, .vdb -> OpenVDB file, anything else -> directory of PNGs. Throws OutputError when the
// output exists and !overwrite or cannot be created.
std::unique_ptr<MaskSink> makeMaskSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// File name of layer `index`: "<prefix><index>.<ext>", the index zero-padded to 5 digits, or to as many
// as layerCount - 1 needs, so that names sort in layer order. `prefix` is the job name with path
// separators and control characters replaced by '_' ("layer" when empty).
std::string maskLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount, const char* ext);
std::string maskFilePrefix(const std::string& name);

}  // namespace toposlice
