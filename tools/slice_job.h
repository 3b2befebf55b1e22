// One model through the whole slicing path: read, topology (built, loaded from a template, or none),
// planes, slicing, and every requested output streamed layer by layer. Shared by `toposlice slice` and
// `toposlice batch`.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/slicing/planes.h"
#include "io/jobs/profile.h"
#include "io/jobs/template_file.h"
#include "io/readers/mesh_reader.h"
#include "parallel/band_slicer.h"

namespace toposlice {

// Mask output settings (issue "Mask stacks for the projector").
struct MaskOptions {
  std::filesystem::path output;  // .sl1, .exr, .vdb, or a directory of PNGs; empty: no masks
  std::string printer;           // preset name (core/print/printer.h); empty: none
  std::optional<double> pixel;   // mm
  std::optional<std::pair<uint32_t, uint32_t>> resolution;  // width, height
  std::optional<std::pair<double, double>> origin;          // lower-left corner of pixel (0, 0), mm
  bool mirrorX = false, mirrorY = false;
  bool antialias = false;
  bool crop = false;      // allow a model larger than the image
  bool vdbSlabs = false;  // .vdb only: one grid per slab of layers instead of one grid (--vdb-layout slabs)
  // What a model that does not fit the image may do, in the words of the command (a batch job has no
  // --crop, and its origin is a setting).
  std::string fitAdvice =
      "use --crop to cut it off, --origin to move the image, a smaller model or larger pixels";
};

struct SliceJobOptions {
  MeshReadOptions read;  // units and scale of the model and feature files
  PlaneSpec planes;
  SliceSettings slice;
  std::vector<std::filesystem::path> outputs;  // contour files by extension: .cli, .svg
  bool cliBinary = false;
  std::string svgLayers = "mid";
  bool overwrite = false;
  const TemplateTable* templateTable = nullptr;  // intra-model reuse: skip welding and adjacency
  std::filesystem::path templateFile;            // or the table's file, read while the model is read
  bool rebuildOnMismatch = false;                // a variant that does not match: rebuild instead of failing
  bool fixOrientation = false;                   // flip every facet of an inside-out (negative volume) mesh
  // How the user asks for fixOrientation, for the warnings that advise it: the option on slice's
  // command line, the setting in a batch job.
  std::string fixOrientationOption = "--fix-orientation";
  MaskOptions masks;
  // Printer and material settings (io/jobs/profile.h), resolved: exposure for the printer files, the
  // corrections applied to the geometry, gamma and light map applied to the masks.
  PrintSettings print;
  std::vector<std::filesystem::path> add, remove;  // add-on and removal features (inter-model reuse)
  std::filesystem::path report;                    // per-layer CSV report; empty: none
  std::filesystem::path summary;                   // machine-readable summary (JSON); empty: none
  // Further inputs of the job that no output may replace (the batch job file, the template's model and
  // table); the model, features and templateFile are always checked.
  std::vector<std::filesystem::path> otherInputs;
};

struct SliceJobResult {
  MeshSource source;  // the model file's format
  uint64_t facets = 0;
  BoundingBox bounds;
  // What is printed: the model's box and its add-ons' (a base or a label reaching beyond the model is
  // part of the print). The default planes cover its z range, the build height is measured on it, and
  // the masks' image is placed on it.
  BoundingBox printed;
  std::string topology;           // how the adjacency was obtained, for the summary
  EdgeStats edges;                // when built here
  bool edgesCounted = false;      // the adjacency was built here, so `edges` counts the model's defects
  uint64_t degenerateFacets = 0;  // skipped
  double volume = 0;              // signed, before any fix (after the scaling correction)
  bool inverted = false, flipped = false;
  double readSeconds = 0, topologySeconds = 0, sliceSeconds = 0;
  SliceStats stats;
  double volumeMl = 0;  // resin: mask area (or contour area without masks) x layer thickness
  std::vector<std::filesystem::path> written;
  // Things a user must hear even with --quiet (an inside-out mesh, layers outside the model), one line
  // each, without the "warning: " prefix.
  std::vector<std::string> warnings;
};

// Checks what can be checked before reading any file: numbers (finite, in range) and the output
// extensions. Throws InputError naming the option.
void validateSliceOptions(const SliceJobOptions& options);

// The mask output extensions toposlice writes, for messages: ".sl1, .sl1s, .goo, .nanodlp, .exr, .vdb, or a
// folder of PNGs (a name without an extension)".
std::string maskOutputKinds();

// Throws InputError when `output` is, or resolves to (through links, or as a hard link), one of
// `inputs`: a job never writes over its own input, even with --force.
void checkNotAnInput(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs);

// Throws InputError when one file is given twice among a model's features (`add`, then `remove`), or
// as a feature of itself (`model`), through links too: a feature added twice or both added and removed
// is a mistake in the command or the job, not a shape.
void checkFeatureFiles(const std::filesystem::path& model, const std::vector<std::filesystem::path>& add,
                       const std::vector<std::filesystem::path>& remove);

// Runs one slicing job. Its outputs form one OutputTransaction (io/output_file.h): they appear together
// when everything succeeded, or not at all. Refused before anything is read: an output that is an input,
// two outputs with the same path, bad numbers. Refused after slicing, before anything appears: no layer,
// no plane that cuts the model, every layer empty, every mask layer dark. Throws InputError (bad model,
// variant mismatch, bad settings, empty result) or OutputError.
SliceJobResult runSliceJob(const std::filesystem::path& model, const SliceJobOptions& options,
                           const ProgressContext* progress);

// Set from a signal handler (lock-free, so async-signal-safe) to ask running slice jobs to stop at the
// next band; the job then throws, and unwinding removes every temporary output.
std::atomic<bool>& interruptRequested();

// Reads of input files in progress (a model, a feature, a template table): while some run and the
// command allows it (stopAtOnceWhileReading), a first stop signal ends the process at once, as a second
// one does, since a read may block (a pipe) or take long (a 3MF whose components place a mesh 10^10
// times) and nothing is committed meanwhile. Commands that commit while they read (batch, plate) leave it
// off. Both are lock-free atomics, read by the signal handler.
std::atomic<int>& readsInProgress();
std::atomic<bool>& stopAtOnceWhileReading();
class ReadScope {
 public:
  ReadScope() { readsInProgress().fetch_add(1); }
  ~ReadScope() { readsInProgress().fetch_sub(1); }
  ReadScope(const ReadScope&) = delete;
  ReadScope& operator=(const ReadScope&) = delete;
};

// Peak resident memory of this process so far, in MiB.
double peakResidentMiB();

}  // namespace toposlice
