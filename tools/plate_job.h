// `toposlice plate JOB.json`: many different parts on one build plate (or several, when `auto`
// placements spill over), each checked against its template or built, arranged, and sliced together on
// the plate's shared planes (docs/FORMATS.md, "Plate jobs").
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "io/jobs/plate_job_file.h"

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
};

// Runs the job. Everything that can be refused is refused before any slicing: unknown printer,
// overlapping given placements (naming both parts), parts outside the printable area or taller than
// the build height (naming the part and by how much), a variant whose connectivity differs from its
// template (unless settings.allow_rebuild), a part too large for an empty plate. All outputs of all
// plates form one OutputTransaction. Throws InputError or OutputError.
PlateResult runPlateJob(const PlateJob& job, const ProgressContext* progress);

// The command: reads the job, runs it with job.threads, prints the per-part table; returns 0. A
// non-empty `outputDir` puts every output there under its file name (instead of where the job says).
int runPlateCommand(const std::filesystem::path& jobPath, bool quiet, const std::filesystem::path& outputDir);

}  // namespace toposlice
