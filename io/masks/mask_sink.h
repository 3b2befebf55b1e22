// Streaming mask-stack writers: one MaskSink per output, fed one layer at a time (docs/FORMATS.md).
//
// Contract shared by every sink:
// - Layers arrive in order, index 0, 1, 2, ... (one thread at a time; a sink is not thread-safe), each
//   a MaskImage of exactly job.grid.width x job.grid.height. Memory never grows with the layer count,
//   except for the VDB sink's default single grid, whose tree stays in memory until finish() (OpenVDB
//   writes a grid at once; its slab layout keeps one slab); the others keep per-file bookkeeping.
// - A layer goes in either whole (writeLayer) or in two steps (encodeLayer, then writeEncodedLayer), so
//   that the caller can encode layers in parallel and only write them in order: encodeLayer is
//   thread-safe and may run for many layers at once; writeEncodedLayer takes its results in layer order.
//   Both ways give the same bytes. Sinks that store each layer as bytes of its own (PNG directory, SL1,
//   EXR) encode those bytes there; the default hands the layer over as mask runs (core/raster/mask_runs.h).
// - Nothing appears under the final path until finish() returns: output goes to a temporary beside it
//   ("<final>.tmp-<pid>-<n>") and is renamed into place at the end. A sink destroyed without finish()
//   (an exception, a cancelled run) removes its temporary. Without `overwrite`, an existing final path
//   is an OutputError, both when the sink is created and when it finishes.
// - I/O failures throw OutputError naming the path; the sink can then only be destroyed.
#pragma once

#include <cstdint>
#include <ctime>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"
#include "core/raster/mask_image.h"
#include "io/coders/deflate_runs.h"
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
  // The job's printer and material (io/jobs/profile.h): names (SL1 config.ini printerProfile and
  // materialName; empty: "toposlice") and every setting as PrusaSlicer key = value text, written into
  // prusaslicer.ini (PrusaSlicer's keys) and as metadata "toposlice:<key>" into EXR and VDB files.
  std::string printerProfile, materialName;
  std::vector<std::pair<std::string, std::string>> settings;
  // VDB only: one grid per slab of kVdbSlabLayers layers (io/masks/vdb_writer.h) instead of one grid for
  // the whole stack; ignored by the other formats.
  bool vdbSlabs = false;
  // Platform motion and light for the formats that carry them (GOO, NanoDLP), from the printer profile
  // (io/jobs/profile.h: lift_distance, lift_speed, ...); these defaults when a sink is used on its own.
  double liftDistance = 5.0;        // mm, every layer after the bottom ones
  double liftSpeed = 65.0;          // mm/min
  double bottomLiftDistance = 5.0;  // mm, the bottom (first) layer
  double bottomLiftSpeed = 65.0;    // mm/min
  double retractSpeed = 150.0;      // mm/min, back down to the next layer
  double waitBeforeExposure = 1.0;  // s, resin settling after the retract
  uint8_t lightPwm = 255;           // UV power 0..255
  double resinDensity = 1.1;        // g/ml, for the weight of resin (GOO); the material's material_density
  // The model's facets (3 corners each) for the preview pictures (GOO, SL1 thumbnails, NanoDLP 3d.png).
  // Read only while makeMaskSink runs: sinks render what they need then and keep no reference, unless
  // deferPreviews. Empty: the previews show no model.
  std::span<const Point3f> previewModel;
  // The caller keeps previewModel alive until finish, and the sinks draw their previews later, in
  // drawPreviews() -- which the caller may run beside the layers' encoding -- or, when it was not
  // called, when they need them: SL1 as its first layer is written (its thumbnails come first in the
  // archive), GOO and NanoDLP at finish (the GOO header is rewritten then, NanoDLP's 3d.png is added
  // then). The file is the same bytes either way.
  bool deferPreviews = false;
  // Runs the preview renderer's chunks (the tools give parallelChunkRunner); the pictures are the same
  // for any runner.
  ChunkRunner previewRunner = serialChunkRunner();
};

// One layer as encodeLayer leaves it for writeEncodedLayer.
struct EncodedMaskLayer {
  std::vector<uint8_t> bytes;      // what the sink stores (a PNG, an EXR file) or, by default, mask runs
  uint32_t crc32 = 0;              // CRC-32 of `bytes` where the sink needs one (zip entries)
  uint32_t width = 0, height = 0;  // the image's size (the runs need it)
  std::string text;                // per-layer text a sink keeps beside the bytes (NanoDLP's info.json)
};

// Reusable buffers of encodeLayer, one per thread; each sink uses the parts it needs.
struct MaskEncodeScratch {
  DeflateScratch deflate;
  std::vector<uint8_t> bytes;
  std::vector<uint32_t> runs;
};

class MaskSink {
 public:
  virtual ~MaskSink() = default;
  // Layer `index` (0-based, in order) cut at height z (mm).
  virtual void writeLayer(uint32_t index, double z, const MaskImage& mask) = 0;
  // Encodes layer `index` into `out` (replaced; its capacity reused). Thread-safe: reads only what the
  // sink was created with; any thread, any layers at once, each call with scratch of its own. Throws
  // OutputError for a mask not of the job's size. Default: the layer's runs (encodeMaskRuns).
  virtual void encodeLayer(uint32_t index, double z, const MaskImage& mask, EncodedMaskLayer& out,
                           MaskEncodeScratch& scratch) const;
  // Writes what encodeLayer made of layer `index`, in order, as writeLayer would have. Default: decodes
  // the runs and calls writeLayer.
  virtual void writeEncodedLayer(uint32_t index, double z, const EncodedMaskLayer& layer);
  // Draws the preview pictures a sink deferred (MaskJob::deferPreviews). Thread-safe with encodeLayer,
  // and with writeLayer/writeEncodedLayer where previewsBeforeLayers() is false; call at most once,
  // before finish, and where previewsBeforeLayers() before the first layer is written. Default: nothing.
  virtual void drawPreviews() {}
  // Whether deferred previews must be drawn before the first layer is written (SL1: the thumbnails are
  // the archive's first entries); the caller then holds its layers or waits. Default: no.
  virtual bool previewsBeforeLayers() const { return false; }
  // Completes the output and moves it under its final name. finalJob is the job as known at the end
  // (volumeMl filled); the layer count written is the number of layers written. Call at most once.
  virtual void finish(const MaskJob& finalJob) = 0;

 private:
  MaskImage decoded_;  // the default writeEncodedLayer's image
};

// Base of the sinks that encode each layer into the bytes they store: writeLayer is encodeLayer then
// writeEncodedLayer on the calling thread, so both ways give the same bytes by construction.
class EncodingMaskSink : public MaskSink {
 public:
  void writeLayer(uint32_t index, double z, const MaskImage& mask) final;
  void encodeLayer(uint32_t index, double z, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const override = 0;
  void writeEncodedLayer(uint32_t index, double z, const EncodedMaskLayer& layer) override = 0;

 private:
  EncodedMaskLayer layer_;
  MaskEncodeScratch scratch_;
};

// Base of the sinks that store each layer as a file of its own in a folder (PNG and EXR stacks): the
// folder is staged (io/staged_directory.h) and committed by finish(). Each layer's file is encoded and
// written in encodeLayer, in the caller's parallel stage (files of one folder are independent, so their
// creation and writing need no order); writeEncodedLayer only checks that every layer came, in order.
// Derived sinks provide encodeLayerBytes and the file name.
class LayerFolderSink : public EncodingMaskSink {
 public:
  // layerExt: the extension of the layer files (".png", ".exr"), for StagedDirectory's overwrite check.
  LayerFolderSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite,
                  std::string layerExt);
  void encodeLayer(uint32_t index, double z, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const final;
  void writeEncodedLayer(uint32_t index, double z, const EncodedMaskLayer& layer) final;
  void finish(const MaskJob& finalJob) override;

 protected:
  // The bytes of layer `index`'s file; thread-safe.
  virtual void encodeLayerBytes(uint32_t index, double z, const MaskImage& mask, std::vector<uint8_t>& out,
                                MaskEncodeScratch& scratch) const = 0;
  virtual std::string layerFileName(uint32_t index) const = 0;
  const std::filesystem::path& finalPath() const { return dir_.finalPath(); }
  const MaskJob& job() const { return job_; }

 private:
  StagedDirectory dir_;
  MaskJob job_;
  uint32_t next_ = 0;
};

// Picks the writer by extension (case-insensitive): .sl1/.sl1s -> SL1 archive, .goo -> Elegoo GOO file,
// .nanodlp -> NanoDLP plate archive, .exr -> directory of OpenEXR files, .vdb -> OpenVDB file, anything
// else -> directory of PNGs. Throws OutputError when the
// output exists and !overwrite or cannot be created.
std::unique_ptr<MaskSink> makeMaskSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// The check makeMaskSink's sink makes when it opens `path` (checkOutputAllowed, output_file.h: a file, or
// for a PNG or EXR stack a folder of its layers), for a command to make before its long work.
void checkMaskOutputAllowed(const std::filesystem::path& path, bool overwrite);

// File name of layer `index`: "<prefix><index>.<ext>", the index zero-padded to 5 digits, or to as many
// as layerCount - 1 needs, so that names sort in layer order. `prefix` is the job name with path
// separators and control characters replaced by '_' ("layer" when empty).
std::string maskLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount, const char* ext);
std::string maskFilePrefix(const std::string& name);
// The zero-padded index alone, as in maskLayerFileName.
std::string maskLayerNumber(uint32_t index, uint32_t layerCount);

// Creation time written into printer files: SOURCE_DATE_EPOCH when set (a number >= 0), else
// job.created (0 when not positive). Never the clock.
std::time_t maskCreationTime(const MaskJob& job);

// Throws OutputError naming `output` and layer `index` when `mask` is not width x height of `grid`.
void checkMaskLayerSize(const MaskImage& mask, const PixelGrid& grid, const std::filesystem::path& output,
                        uint32_t index);

}  // namespace toposlice
