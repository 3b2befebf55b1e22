// `toposlice plate JOB.json`: many different parts on one build plate (or several, when `auto`
// placements spill over), each checked against its template or built, arranged, and sliced together on
// the plate's shared planes (docs/FORMATS.md, "Plate jobs").
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "io/jobs/plate_job_file.h"
#include "io/jobs/profile.h"

namespace toposlice {

struct PlatePartResult {
  std::string name;
  uint32_t plate = 0;        // 0-based
  PlatePlacement placement;  // as given, or as arranged (centre of the rotated bounding box)
  double tx = 0, ty = 0;     // translation applied to the rotated model, mm
  bool arranged = false;     // placed by `auto`
  std::string topology;      // how its adjacency was obtained
  uint64_t facets = 0;
  double volumeMl = 0;                      // contour area x layer height, features included
  int64_t firstLayer = -1, lastLayer = -1;  // plate layers holding its contours; -1: none
  double footprintMm2 = 0;                  // area of its footprint cells
  BoundingBox bounds;                       // on the plate, mm (after rotation and translation)
  bool edgesCounted = false;                // the model's edges were counted (its adjacency built here)
  EdgeStats edges;                          // then: boundary, non-manifold, inconsistent edges
};

struct PlateResult {
  uint32_t plates = 0;
  std::vector<PlatePartResult> parts;       // in job order
  std::vector<double> density;              // per plate: footprint area / area inside the margin
  std::vector<uint32_t> layers;             // per plate
  std::vector<double> volumeMl;             // per plate (lit mask area, or contour area without masks)
  uint32_t templateChecked = 0, built = 0;  // parts whose adjacency came from a table / was built
  double readSeconds = 0, topologySeconds = 0, arrangeSeconds = 0, sliceSeconds = 0;
  std::vector<std::filesystem::path> written;
  std::vector<std::string> warnings;  // one line each, in job order (inside-out meshes)
};

// The job's printer, material and corrections: its profile file (when given), printer and material, then
// print_settings. Throws InputError for an unknown name, a bad file, key or value.
PrintSettings plateJobSettings(const PlateJob& job);

// For --explain (a run makes them before any part is read): the plate's masks' own checks as a run makes
// them, without the parts (a size and a pixel pitch, an orientation the format carries, the light map against
// the display). Throws InputError.
void checkPlateMaskSettings(const PlateJob& job);

// Runs the job. Everything that can be refused is refused before any slicing: unknown printer,
// overlapping given placements (naming both parts), parts outside the printable area or taller than
// the build height (naming the part and by how much), a variant whose connectivity differs from its
// template (unless settings.allow_rebuild), a part too large for an empty plate. All outputs of all
// plates form one OutputTransaction. Throws InputError or OutputError.
// `progress` reports each plate's layers; `onPlate(plate, plates)`, when given, is called before each
// plate is sliced (the command's progress bar names the plate with it).
PlateResult runPlateJob(const PlateJob& job, const ProgressContext* progress,
                        const std::function<void(uint32_t, uint32_t)>& onPlate = {});

// Creates the folders that the outputs of plates [0, plates) go into where they are missing, as a
// batch does (runPlateJob and toposlice-mpi, after preparing). Throws OutputError naming a folder that
// cannot be made.
void makePlateOutputFolders(const PlateJob& job, uint32_t plates);

// A plate job read, checked and arranged, ready to be sliced plate by plate: runPlateJob slices every
// plate in one process, toposlice-mpi (tools/mpi_batch.cpp) hands the plates to its ranks, each of
// which prepares the same job. Preparing reads every part and template table, obtains each part's
// topology, arranges, and refuses what runPlateJob refuses before slicing; it writes nothing. The
// arrangement is serial and integer-based: every process that prepares the job gets the same plates
// and placements, bit for bit.
class PreparedPlateJob {
 public:
  explicit PreparedPlateJob(PlateJob job);  // throws InputError
  ~PreparedPlateJob();
  PreparedPlateJob(const PreparedPlateJob&) = delete;
  PreparedPlateJob& operator=(const PreparedPlateJob&) = delete;

  const PlateJob& job() const;
  // The parts as placed, template reuse and the preparation's seconds; per plate `density`. `layers`
  // and `volumeMl` (per plate) and each part's volumeMl, firstLayer and lastLayer are filled by
  // slicePlate, or by the caller for plates sliced in another process; sliceSeconds by the caller.
  PlateResult& result();

  // Slices plate `plate` (0-based) and writes its outputs (`-plate<n>` names after the first) into the
  // calling thread's current OutputTransaction, in a fixed order: contours, masks, picture. Throws
  // InputError (a part no layer cuts, every mask dark, interrupted) or OutputError.
  void slicePlate(uint32_t plate, const ProgressContext* progress);

  // Writes the report (outputs.report), when the job names one, from result() after every plate's
  // numbers are in; joins the current OutputTransaction.
  void writeReport() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The summary `toposlice plate` prints: plates, one line per part, the outputs written, the seconds.
void printPlateSummary(std::FILE* out, const PlateResult& result);

// After a job: files of plates beyond result.plates at the job's output names, left by an earlier run
// that made more plates, are a warning in result.warnings (not this job's output, never deleted, but a
// script collecting "p*.sl1" would print them).
void warnAboutLaterPlates(const PlateJob& job, PlateResult& result);

// The job as the command runs it: read, and with a non-empty `outputDir` every output moved there under
// its file name.
PlateJob readPlateCommandJob(const std::filesystem::path& jobPath, const std::filesystem::path& outputDir);

// The command: reads the job, runs it with job.threads, prints the per-part table; returns 0. A
// non-empty `outputDir` puts every output there under its file name (instead of where the job says).
int runPlateCommand(const std::filesystem::path& jobPath, bool quiet, const std::filesystem::path& outputDir);

}  // namespace toposlice
