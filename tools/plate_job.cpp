#include "tools/plate_job.h"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "core/mesh/mesh_info.h"
#include "core/number_text.h"
#include "core/print/arrange.h"
#include "core/print/corrections.h"
#include "core/slicing/contours.h"
#include "io/coders/mask_png.h"
#include "io/errors.h"
#include "io/output_file.h"
#include "offset/polygon_offset.h"
#include "parallel/parallel.h"
#include "tools/progress_bar.h"
#include "tools/slice_stages.h"

namespace toposlice {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string mm(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3f mm", v);
  return text;
}

// One part in memory: its meshes (model, add-ons, removals) in the plate's orientation.
struct LoadedPart {
  FacetSoup model;
  std::vector<FacetSoup> features;  // add-ons first, then removals
  std::vector<int32_t> built;       // its own table when built
  std::vector<std::vector<int32_t>> featureTables;
  std::span<const int32_t> adjacency;
  Footprint footprint;  // model and add-ons, unrotated
  BoundingBox bounds;   // rotated, before translation; model and add-ons
};

void rotateSoup(FacetSoup& soup, double degrees) {
  double c = 1, s = 0;
  rotationCosSin(degrees, c, s);
  if (c == 1 && s == 0) return;
  for (Point3f& p : soup.corners) {
    const double x = p.x, y = p.y;
    p.x = static_cast<float>(c * x - s * y);
    p.y = static_cast<float>(s * x + c * y);
  }
}

// Every output path of plates [first, end), with whether it is the masks (whose check depends on their
// format); the report, which is one for all plates, with the first plate.
void forEachPlateOutput(const PlateJob& job, uint32_t first, uint32_t end,
                        const std::function<void(const std::filesystem::path&, bool masks)>& visit) {
  if (first == 0 && !job.report.empty()) visit(job.report, false);
  for (uint32_t plate = first; plate < end; ++plate) {
    if (!job.masks.empty()) visit(plateOutputPath(job.masks, plate), true);
    if (!job.picture.empty()) visit(plateOutputPath(job.picture, plate), false);
    for (const auto& c : job.contours) visit(plateOutputPath(c, plate), false);
  }
}

// Two outputs of the job that name one file (two contour paths that -O puts in one folder, a given
// "o/c-plate2.cli" beside "o/c.cli" on two plates): refused, as slice refuses an output given twice.
void checkDistinctPlateOutputs(const PlateJob& job, uint32_t plates) {
  std::map<std::filesystem::path, std::filesystem::path> seen;  // resolved -> as named
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>>
      folders;  // mask folders: resolved, named
  const std::string maskExt = lowerExtension(job.masks);
  forEachPlateOutput(job, 0, plates, [&](const std::filesystem::path& path, bool masks) {
    const auto [it, added] = seen.emplace(resolvedPath(path), path);
    if (!added)
      throw InputError(path.string() + ": given as more than one output" +
                       (it->second == path ? "" : " (it is " + it->second.string() + ")"));
    if (masks && (maskExt.empty() || maskExt == ".exr")) folders.emplace_back(it->first, path);
  });
  // A folder of masks (PNG or EXR layers) is made and replaced as a whole: no other output may lie in it.
  for (const auto& [resolved, named] : seen)
    for (const auto& [folder, folderNamed] : folders) {
      if (resolved == folder) continue;
      const auto [f, o] = std::mismatch(folder.begin(), folder.end(), resolved.begin(), resolved.end());
      if (f == folder.end())
        throw InputError(named.string() + ": lies inside the mask folder " + folderNamed.string() +
                         ", which this job writes as a whole: give it a place outside");
    }
}

// Outputs of plates [first, end) that may not be written (an input of the job, also through a link or
// inside a mask folder; they exist and the job does not overwrite, or they are not toposlice's to
// replace), refused before the slicing. The later plates' names (-plate2, ...) too: a part's model or the
// light map at one of them was replaced by that plate's output, being marked as toposlice's.
void checkPlateOutputs(const PlateJob& job, uint32_t first, uint32_t end,
                       const std::vector<std::filesystem::path>& inputs) {
  forEachPlateOutput(job, first, end, [&](const std::filesystem::path& path, bool masks) {
    checkNotAnInput(path, inputs);
    if (masks)
      checkMaskOutputAllowed(path, job.overwrite);
    else
      checkOutputAllowed(path, job.overwrite);
  });
}

BoundingBox partBounds(const LoadedPart& part, std::size_t addCount) {
  return unite(boundsOf(part.model.corners), std::span<const FacetSoup>(part.features).first(addCount));
}

struct PlateGeometry {
  uint32_t width = 0, height = 0;
  double pixel = 0, buildHeight = 0;
  double widthMm() const { return width * pixel; }
  double heightMm() const { return height * pixel; }
};

// The plate's display: the resolved printer's (preset or profile, with print_settings), then settings.
PlateGeometry plateGeometry(const PlateJob& job, const PrintSettings& print) {
  PlateGeometry g;
  g.width = print.pixelsX;
  g.height = print.pixelsY;
  g.pixel = print.pixelsX > 0 && print.displayWidth > 0 ? print.displayWidth / print.pixelsX : 0.0;
  g.buildHeight = print.maxPrintHeight;
  if (job.resolution) g.width = (*job.resolution)[0], g.height = (*job.resolution)[1];
  if (job.pixel) g.pixel = *job.pixel;
  if (job.buildHeight) g.buildHeight = *job.buildHeight;
  const std::string where =
      (job.sourceFile.empty() ? "" : job.sourceFile.string() + ": ") +
      (print.printerName.empty() ? "the printer" : "printer '" + print.printerName + "'");
  if (print.printerName.empty() && !job.profile.empty() && !job.resolution)  // a profile of several printers
    throw InputError((job.sourceFile.empty() ? "" : job.sourceFile.string() + ": ") +
                     "printer: missing, and the profile " + job.profile.string() +
                     " does not hold exactly one printer to take: name one (or give settings.resolution and "
                     "settings.pixel)");
  if (g.width == 0 || g.height == 0)
    throw InputError(where + " has no display size: give settings.resolution, or display_pixels_x and _y");
  if (!(g.pixel > 0))
    throw InputError(where + " has no fixed pixel size: give settings.pixel (mm), or display_width");
  return g;
}

// The scaling correction acts along the printer's (the plate's) axes. The same factor in x and y turns
// with the part: it is applied when the part is read, before it is arranged. Different factors are
// applied once the part is turned, about the centre of its turned model (one rounding either way).
bool scalesWhenRead(const PrintSettings& print) {
  const auto s = print.scale();
  return print.scales() && s[0] == s[1];
}
bool scalesWhenTurned(const PrintSettings& print) {
  return print.scales() && !scalesWhenRead(print);
}

// The part's model and features scaled by the scaling correction about the centre of the model as it
// lies now (as for that model sliced alone).
void scalePart(LoadedPart& part, const PrintSettings& print) {
  const std::array<double, 3> centre = scaleCentre(boundsOf(part.model.corners)), factors = print.scale();
  scaleCorners(part.model.corners, factors, centre);
  for (FacetSoup& f : part.features) scaleCorners(f.corners, factors, centre);
}

// An inside-out (negative volume) model or feature of a part: flipped when the job sets
// "fix_orientation", else a warning, as slice does (an inside-out model prints nothing under the positive
// rule, an inside-out add-on cuts its model away, a removal adds to it). Returns the warnings.
std::vector<std::string> fixInsideOutMeshes(const PlateJob& job, const PlatePart& spec, LoadedPart& part) {
  std::vector<std::string> warnings;
  const auto check = [&](FacetSoup& soup, const std::filesystem::path& file, const std::string& what) {
    if (std::string w = fixInsideOut(soup, "part '" + spec.name + "': " + file.string() + ": the " + what,
                                     job.fixOrientation, "\"fix_orientation\": true in the job's settings",
                                     what == "mesh" ? "prints nothing" : "counts with the opposite sign");
        !w.empty())
      warnings.push_back(std::move(w));
  };
  check(part.model, spec.model, "mesh");
  for (std::size_t f = 0; f < part.features.size(); ++f) {
    const bool add = f < spec.add.size();
    check(part.features[f], add ? spec.add[f] : spec.remove[f - spec.add.size()],
          add ? "add-on feature" : "removal feature");
  }
  return warnings;
}

// The contours of a layer moved by (tx, ty), into `out` (its capacity reused).
void translateLayer(const LayerContours& in, double tx, double ty, LayerContours& out) {
  out = in;
  for (Point2d& p : out.points) p = {p.x + tx, p.y + ty};
}

// Picture of the plate: the masks of up to kPictureLayers evenly spaced layers, OR-ed, shrunk by an
// integer factor to at most kPictureWidth pixels wide.
constexpr uint32_t kPictureLayers = 100, kPictureWidth = 2048;

struct Picture {
  uint32_t factor = 1;
  MaskImage image;
  void reset(uint32_t width, uint32_t height) {
    factor = std::max<uint32_t>(1, (width + kPictureWidth - 1) / kPictureWidth);
    image.width = (width + factor - 1) / factor;
    image.height = (height + factor - 1) / factor;
    image.pixels.assign(static_cast<std::size_t>(image.width) * image.height, 0);
  }
  // A mask on `grid`. Portrait masks (PixelGrid::transposed) go back to the plate's axes, seen from
  // above (x right, y up), so the picture shows the plate as it is laid out whatever the display.
  void add(const MaskImage& mask, const PixelGrid& grid) {
    for (uint32_t j = 0; j < mask.height; ++j) {
      uint32_t a = 0, b = mask.width;
      if (mask.hasExtents()) a = mask.litBegin[j], b = mask.litEnd[j];
      const uint8_t* row = mask.pixels.data() + static_cast<std::size_t>(j) * mask.width;
      if (!grid.transposed) {
        uint8_t* out = image.pixels.data() + static_cast<std::size_t>(j / factor) * image.width;
        for (uint32_t i = a; i < b; ++i)
          if (row[i]) out[i / factor] = 255;
        continue;
      }
      const uint32_t x = grid.mirrorY ? mask.height - 1 - j : j;  // the plate's pixel column
      for (uint32_t i = a; i < b; ++i) {
        if (!row[i]) continue;
        const uint32_t y = grid.mirrorX ? mask.width - 1 - i : i;  // the plate's pixel row
        image.pixels[static_cast<std::size_t>(y / factor) * image.width + x / factor] = 255;
      }
    }
  }
  void merge(const Picture& other) {
    for (std::size_t k = 0; k < image.pixels.size(); ++k) image.pixels[k] |= other.image.pixels[k];
  }
};

struct PlateSlice {
  uint32_t layers = 0;
  double volumeMl = 0;
};

// The mask options of a plate written to `out`: the plate's display, the image's origin at the plate's
// corner.
MaskOptions plateMaskOptions(const PlateJob& job, const PrintSettings& print, const PlateGeometry& geometry,
                             const std::filesystem::path& out) {
  MaskOptions o;
  o.printer = print.printerName;
  o.pixel = geometry.pixel;
  o.resolution = std::pair<uint32_t, uint32_t>{geometry.width, geometry.height};
  o.origin = std::pair<double, double>{0.0, 0.0};
  o.mirrorX = job.mirrorX.value_or(false);
  o.mirrorY = job.mirrorY.value_or(false);
  o.antialias = job.antialias;
  o.output = out;  // the format decides whether a portrait printer's orientation applies
  o.fitAdvice = "every part must lie on the plate's display: check the placements and the corrections";
  return o;
}

// Slices the parts `members` of one plate together and writes its outputs into the transaction.
PlateSlice slicePlate(const PlateJob& job, uint32_t plate, const std::vector<std::size_t>& members,
                      std::vector<LoadedPart>& loaded, std::vector<PlatePartResult>& results,
                      const PrintSettings& print, const PlateGeometry& geometry,
                      const ProgressContext* progress) {
  // Planes: z0 from the job, else the lowest part bottom of this plate.
  double zmin = INFINITY, zmax = -INFINITY;
  BoundingBox extent{{INFINITY, INFINITY, INFINITY}, {-INFINITY, -INFINITY, -INFINITY}};
  for (const std::size_t p : members) {
    extent = unite(extent, results[p].bounds);
    zmin = std::min<double>(zmin, results[p].bounds.min.z);
    zmax = std::max<double>(zmax, results[p].bounds.max.z);
  }
  PlaneSpec spec;
  spec.layerHeight = job.layerHeight;
  spec.z0 = job.z0;
  std::string error;
  const std::vector<double> planes = makePlanes(spec, zmin, zmax, error);
  if (!error.empty())
    throw InputError(job.sourceFile.string() + ": plate " + std::to_string(plate + 1) + ": " + error);

  // Meshes in plate order: each part's model, add-ons, removals; their sign and owning part.
  std::vector<SliceMesh> meshes;
  std::vector<int> signs;
  std::vector<std::size_t> owner;      // index into members
  std::vector<std::size_t> partStart;  // per member: index of its model in meshes (its features follow)
  ContourJob contourJob;
  contourJob.name = job.parts[members[0]].name;
  contourJob.bounds = contourExtent(extent, print);
  contourJob.layerCount = static_cast<uint32_t>(planes.size());
  contourJob.outlinesCorrected = print.correctsOutlines();
  for (std::size_t m = 0; m < members.size(); ++m) {
    const std::size_t p = members[m];
    LoadedPart& part = loaded[p];
    const PlatePart& given = job.parts[p];
    if (m > 0) contourJob.features.push_back({given.name, PartRole::Model});
    partStart.push_back(meshes.size());
    meshes.push_back({part.model.corners, part.adjacency});
    signs.push_back(1);
    owner.push_back(m);
    for (std::size_t f = 0; f < part.features.size(); ++f) {
      const bool add = f < given.add.size();
      const std::filesystem::path& file = add ? given.add[f] : given.remove[f - given.add.size()];
      std::string stem = file.stem().string();
      if (stem.ends_with(".stl")) stem.resize(stem.size() - 4);
      contourJob.features.push_back({given.name + "/" + stem, add ? PartRole::Add : PartRole::Remove});
      meshes.push_back({part.features[f].corners, part.featureTables[f]});
      signs.push_back(add ? 1 : -1);
      owner.push_back(m);
    }
  }

  SliceJobOptions sinkOptions;
  sinkOptions.cliBinary = job.cliBinary;
  sinkOptions.overwrite = job.overwrite;
  for (const auto& c : job.contours) sinkOptions.outputs.push_back(plateOutputPath(c, plate));
  auto sinks = openContourSinks(sinkOptions, contourJob, nullptr, {}, job.layerHeight);

  const bool masks = !job.masks.empty();
  MaskJob maskJob;
  std::unique_ptr<MaskSink> maskSink;
  MaskTransfer transfer;  // gamma and the light-uniformity map of every mask
  if (masks) {
    const std::filesystem::path out = plateOutputPath(job.masks, plate);
    const MaskOptions o = plateMaskOptions(job, print, geometry, out);
    std::string name = out.stem().string();
    try {
      maskJob = makeMaskJob(o, print, extent, name, planes);
    } catch (const InputError& e) {  // said of the plate, not of "the model"
      std::string what = e.what();
      if (what.starts_with("the model (")) what.replace(0, 9, "its parts");
      throw InputError(job.sourceFile.string() + ": plate " + std::to_string(plate + 1) + ": " + what);
    }
    maskJob.layerHeight = job.layerHeight;
    struct stat info {};
    if (::stat(job.sourceFile.c_str(), &info) == 0) maskJob.created = info.st_mtim.tv_sec;
    // The previews of the printer files (GOO, SL1 thumbnails, NanoDLP) show the plate: every part's model
    // and add-ons where the plate puts them. The copy lives only while the sink renders it.
    std::vector<Point3f> plateModel;
    for (std::size_t m = 0; m < members.size(); ++m) {
      const std::size_t p = members[m];
      const PlatePartResult& placed = results[p];
      const auto addPlaced = [&](const std::vector<Point3f>& corners) {
        for (const Point3f& c : corners)
          plateModel.push_back(
              {static_cast<float>(c.x + placed.tx), static_cast<float>(c.y + placed.ty), c.z});
      };
      addPlaced(loaded[p].model.corners);
      for (std::size_t f = 0; f < job.parts[p].add.size(); ++f) addPlaced(loaded[p].features[f].corners);
    }
    maskJob.previewModel = plateModel;
    maskJob.previewRunner = parallelChunkRunner();
    maskSink = makeMaskSink(out, maskJob, job.overwrite);
    maskJob.previewModel = {};
    transfer = maskTransfer(print, maskJob);
  }
  SliceSettings settings;
  if (!job.method.empty()) parseSliceMethod(job.method, settings.method);
  const BandPlan plan = planBands(planes.size(), settings);
  const std::size_t partCount = members.size();
  const uint32_t pictureEvery =
      std::max<uint32_t>(1, static_cast<uint32_t>((planes.size() + kPictureLayers - 1) / kPictureLayers));
  struct LayerResult {
    // Every mesh's contours on the plate; with corrections each part's model holds its corrected region
    // and its features are empty.
    std::vector<LayerContours> moved;
    std::vector<double> partArea;  // per part: its solid region's area (model and features, positive rule)
    EncodedMaskLayer encoded;
    double area = 0;
  };
  struct SlotState : MaskSlotScratch {
    std::vector<LayerResult> layers;
    Picture picture;
    LayerContours corrected;  // a part's corrected region where the part was sliced, before it is moved
    LayerContours raw;        // a part's raw offset loops where it was sliced (a growing correction)
    LayerContours solid;      // a part's solid region, for its area, where it has features
    std::vector<LayerContours> maskLoops;  // per part: its raw offset loops moved, when its masks use them
    std::vector<uint8_t> rawMasks;         // per part: 1 when its masks rasterize maskLoops
  };
  std::vector<SlotState> slots(plan.slots);
  for (SlotState& s : slots) {
    s.layers.resize(plan.bandLayers);
    for (LayerResult& r : s.layers) r.moved.resize(meshes.size()), r.partArea.resize(partCount);
    s.maskLoops.resize(partCount);
    s.rawMasks.assign(partCount, 0);
    if (!job.picture.empty()) s.picture.reset(geometry.width, geometry.height);
  }
  std::vector<double> partVolume(partCount, 0.0);
  double volumeMm3 = 0;

  LayerStages stages;
  stages.process = [&](uint32_t k, std::span<const LayerContours> layer, std::size_t slot,
                       uint32_t position) {
    SlotState& s = slots[slot];
    LayerResult& r = s.layers[position];
    std::fill(r.partArea.begin(), r.partArea.end(), 0.0);
    // Absolute correction and elephant foot, part by part on its solid region (model, add-ons,
    // removals): every output sees the corrected parts, as a part sliced alone would be corrected. A nil
    // correction (no correction set, or above the elephant foot without an absolute one): the sliced
    // layer, moved.
    const LayerCorrection correction = layerCorrection(print, k, planes.size());
    if (correction.any()) {
      // Each part corrected where it was sliced, then moved: the same loops as the part corrected alone.
      for (std::size_t m = 0; m < partCount; ++m) {
        const std::size_t first = partStart[m], end = m + 1 < partCount ? partStart[m + 1] : layer.size();
        s.sets.clear();
        for (std::size_t i = first; i < end; ++i) s.sets.push_back({&layer[i], signs[i]});
        // An absolute correction alone: the part's masks rasterize its raw offset loops, as the part
        // sliced alone does, and its polygons are those loops united (correctLayer's result).
        s.rawMasks[m] = masks && rawCorrectedLoops(s.sets, correction, layer[first].z, s.raw);
        if (s.rawMasks[m])
          unitePositive(s.raw, layer[first].z, s.corrected);
        else
          correctLayer(s.sets, correction, layer[first].z, s.corrected);
        const PlatePartResult& part = results[members[m]];
        translateLayer(s.corrected, part.tx, part.ty, r.moved[first]);
        if (s.rawMasks[m]) translateLayer(s.raw, part.tx, part.ty, s.maskLoops[m]);
        for (std::size_t i = first + 1; i < end; ++i) r.moved[i].clear(layer[i].z);
      }
    } else {
      for (std::size_t i = 0; i < layer.size(); ++i) {
        const PlatePartResult& part = results[members[owner[i]]];
        translateLayer(layer[i], part.tx, part.ty, r.moved[i]);
      }
    }
    s.sets.clear();
    for (std::size_t i = 0; i < layer.size(); ++i) s.sets.push_back({&r.moved[i], signs[i]});
    // A part's area: its model's signed area, or with features in the layer (or outer loops of its own
    // that may overlap) the area of the solid region they make under the positive rule, as the masks
    // light it (an add-on over the model counts once, a removal reaching out of it takes nothing there,
    // intersecting shells count their common part once), as slice's report takes it.
    for (std::size_t m = 0; m < partCount; ++m) {
      const std::size_t first = partStart[m], end = m + 1 < partCount ? partStart[m + 1] : layer.size();
      bool features = false;
      for (std::size_t i = first + 1; i < end; ++i) features = features || r.moved[i].loopCount() > 0;
      if (!features && !outerLoopsMayOverlap(r.moved[first])) {
        r.partArea[m] = signs[first] * layerSignedArea(r.moved[first]);
        continue;
      }
      correctLayer(std::span<const ContourSet>(s.sets).subspan(first, end - first), LayerCorrection{},
                   layer[first].z, s.solid);
      r.partArea[m] = 0;
      for (std::size_t l = 0; l < s.solid.loopCount(); ++l)
        r.partArea[m] += signedArea(s.solid.loopPoints(l));
    }
    r.area = 0;
    if (!masks) {
      for (const double a : r.partArea) r.area += a;
      return;
    }
    if (correction.any()) {
      s.sets.clear();
      for (std::size_t i = 0; i < layer.size(); ++i) {
        const std::size_t m = owner[i];
        if (!s.rawMasks[m])
          s.sets.push_back({&r.moved[i], signs[i]});
        else if (i == partStart[m])
          s.sets.push_back({&s.maskLoops[m], 1});
      }
    }
    r.area = rasterizeLayerSets(s.sets, maskJob, s.mask, s.raster, &transfer);
    if (!job.picture.empty() && (k % pictureEvery == 0 || k + 1 == planes.size()))
      s.picture.add(s.mask, maskJob.grid);
    maskSink->encodeLayer(k, planes[k], s.mask, r.encoded, s.encodeScratch);
  };
  stages.consume = [&](uint32_t k, std::span<const LayerContours>, std::size_t slot, uint32_t position) {
    const LayerResult& r = slots[slot].layers[position];
    for (auto& sink : sinks) sink->writeLayer(k, r.moved);
    if (maskSink) maskSink->writeEncodedLayer(k, planes[k], r.encoded);
    for (std::size_t m = 0; m < partCount; ++m) {
      PlatePartResult& part = results[members[m]];
      partVolume[m] += r.partArea[m] * job.layerHeight;
      bool any = false;
      for (std::size_t i = 0; i < r.moved.size(); ++i)
        any = any || (owner[i] == m && r.moved[i].loopCount() > 0);
      if (any) {
        if (part.firstLayer < 0) part.firstLayer = k;
        part.lastLayer = k;
      }
    }
    volumeMm3 += r.area * job.layerHeight;
  };
  ProgressContext context = progress ? *progress : ProgressContext{};
  context.cancel = &interruptRequested();
  const SliceStats stats = sliceMeshes(meshes, planes, settings, stages, &context);
  if (stats.cancelled) throw InputError("interrupted");
  for (std::size_t m = 0; m < partCount; ++m) {
    PlatePartResult& part = results[members[m]];
    part.volumeMl = partVolume[m] / 1000.0;
    if (part.firstLayer < 0)
      throw InputError(job.parts[members[m]].model.string() + ": part '" + part.name +
                       "': no layer of the plate cuts it: nothing to print");
  }
  if (masks && !(volumeMm3 > 0))
    throw InputError(job.sourceFile.string() + ": plate " + std::to_string(plate + 1) +
                     ": every mask layer is dark: nothing would print");
  for (auto& sink : sinks) sink->finish();
  if (maskSink) {
    maskJob.volumeMl = volumeMm3 / 1000.0;
    maskSink->finish(maskJob);
  }
  if (!job.picture.empty()) {
    Picture& picture = slots[0].picture;
    for (std::size_t s = 1; s < slots.size(); ++s) picture.merge(slots[s].picture);
    std::vector<uint8_t> png;
    encodeMaskPng(picture.image, png);
    OutputFile file(plateOutputPath(job.picture, plate), job.overwrite);
    file.write(png.data(), png.size());
    file.commit();
  }
  return {static_cast<uint32_t>(planes.size()), volumeMm3 / 1000.0};
}

// One error for all of a plate job's problems: "JOB.json: <heading>:", then each problem on its own line.
[[noreturn]] void throwProblems(const PlateJob& job, const std::string& heading,
                                const std::vector<std::string>& problems) {
  std::string text = job.sourceFile.string() + ": " + heading + ":";
  for (const std::string& p : problems) text += "\n  " + p;
  throw InputError(text);
}

// Given placements: overlaps (with the spacing), parts outside the printable area, parts taller than
// the printer. Every problem is listed, each naming its part(s). `grow`: how far a positive
// absolute_correction widens every part's solid region (each part's on its own), so that parts keep the
// spacing and the plate's edges as they print.
void checkPlacements(const PlateJob& job, const std::vector<LoadedPart>& loaded,
                     const std::vector<PlatePartResult>& results, const PlateGeometry& g, double spacing,
                     double grow) {
  std::vector<std::string> problems;
  std::vector<std::size_t> fixed;
  std::vector<CellShape> grown;  // each grown by half the spacing
  // The layers of a plate start at the job's z0, else at the lowest bottom of its parts: a part is as tall
  // as the stack from there to its top.
  std::map<uint32_t, double> plateBottom;
  for (const PlatePartResult& r : results) {
    const auto [at, added] = plateBottom.emplace(r.plate, job.z0.value_or(r.bounds.min.z));
    if (!added && !job.z0) at->second = std::min<double>(at->second, r.bounds.min.z);
  }
  const std::string grownBy =
      grow > 0 ? " with its absolute_correction of " + mm(grow) + " (each part grows by it)" : "";
  for (std::size_t p = 0; p < results.size(); ++p) {
    const PlatePartResult& r = results[p];
    const double bottom = std::min<double>(plateBottom.at(r.plate), r.bounds.min.z);
    const double height = r.bounds.max.z - bottom;
    if (g.buildHeight > 0 && height > g.buildHeight)
      problems.push_back(
          "part '" + r.name + "' " +
          (bottom < r.bounds.min.z
               ? "reaches " + mm(height) + " above the bottom of its plate's layers (z " + mm(bottom) +
                     "), " + mm(height - g.buildHeight) + " beyond"
               : "is " + mm(height) + " tall, " + mm(height - g.buildHeight) + " taller than") +
          " the printer's build height of " + mm(g.buildHeight));
    if (r.arranged) continue;
    const double out =
        std::max({0.0, grow - double{r.bounds.min.x}, grow - double{r.bounds.min.y},
                  double{r.bounds.max.x} + grow - g.widthMm(), double{r.bounds.max.y} + grow - g.heightMm()});
    if (out > 0)
      problems.push_back("part '" + r.name + "' (x " + mm(r.bounds.min.x) + " .. " + mm(r.bounds.max.x) +
                         ", y " + mm(r.bounds.min.y) + " .. " + mm(r.bounds.max.y) + ")" + grownBy +
                         " sticks out of the printable area (" + mm(g.widthMm()) + " x " + mm(g.heightMm()) +
                         ") by " + mm(out));
    fixed.push_back(p);
    grown.push_back(placeFootprint(loaded[p].footprint, r.placement.rotation, r.tx, r.ty, 0.5 * spacing));
  }
  // The cell covers are conservative (by up to a few cells): a pair whose covers meet is measured on
  // its facets, turned and scaled as they print (so against the job's own spacing).
  const auto projected = [&](std::size_t p) {
    std::vector<std::span<const Point3f>> lists = {loaded[p].model.corners};
    for (std::size_t f = 0; f < job.parts[p].add.size(); ++f) lists.push_back(loaded[p].features[f].corners);
    return lists;
  };
  for (std::size_t a = 0; a < fixed.size(); ++a)
    for (std::size_t b = a + 1; b < fixed.size(); ++b) {
      if (!shapesOverlap(grown[a], grown[b])) continue;
      const PlatePartResult &ra = results[fixed[a]], &rb = results[fixed[b]];
      // Parts that overlap (distance 0) are refused whatever the spacing, 0 too; a gap up to a micrometre
      // short of the spacing is taken as the spacing (placements given in rounded decimals).
      constexpr double kToleranceMm = 0.001;
      const double needed = job.spacing + 2 * grow;  // each part grows by its correction
      const double distance = projectionDistance(projected(fixed[a]), ra.tx, ra.ty, projected(fixed[b]),
                                                 rb.tx, rb.ty, std::max(needed, kToleranceMm));
      if (distance > 0 && distance >= needed - kToleranceMm) continue;
      problems.push_back("parts '" + ra.name + "' and '" + rb.name + "' " +
                         (distance > 0 ? "are " + mm(distance) + " apart, closer than the spacing of " +
                                             mm(job.spacing) +
                                             (grow > 0 ? " plus twice the absolute_correction of " +
                                                             mm(grow) + " (each part grows by it)"
                                                       : "")
                                       : std::string("overlap or touch")));
    }
  if (!problems.empty()) throwProblems(job, "the plate cannot be printed as given", problems);
}

// Room the footprints (of parts not yet scaled) leave for a scaling correction applied after turning
// (scalesWhenTurned): its larger x/y factor minus 1 times the farthest any vertex can be from the centre
// of a turned model's bounding box (at most half the diagonal of a square as wide as the part's
// diameter; the model's box lies inside the part's), for two neighbours.
double residualSpacing(const PlateJob& job, const std::vector<LoadedPart>& loaded,
                       const PrintSettings& print) {
  if (!scalesWhenTurned(print)) return 0;
  const double grow = std::max(print.scale()[0], print.scale()[1]) - 1;
  if (!(grow > 0)) return 0;
  double diameter = 0;  // bounded by the diagonal of the unturned box
  for (std::size_t p = 0; p < loaded.size(); ++p) {
    const BoundingBox box = partBounds(loaded[p], job.parts[p].add.size());
    diameter = std::max(diameter, std::hypot(double{box.max.x} - box.min.x, double{box.max.y} - box.min.y));
  }
  return 2 * grow * diameter * std::sqrt(0.5);
}

}  // namespace

struct PreparedPlateJob::Impl {
  PlateJob job;
  PrintSettings print;  // printer, material, corrections (profile.h)
  PlateGeometry geometry;
  std::map<std::filesystem::path, TemplateTable> tables;  // by file; the parts' adjacency spans point here
  std::vector<LoadedPart> loaded;                         // in the plate orientation
  PlateResult result;
  std::vector<std::filesystem::path> outputs;  // plate 1's: masks, report, picture, contours (empty: none)
  std::vector<std::filesystem::path> inputs;   // the job file, profile, light map, parts' files
};

// The job's printer, material and corrections, before its settings.resolution, settings.pixel and
// settings.build_height are recorded (the plate's geometry is taken from these, with the printer's own
// pitch).
PrintSettings givenPlateSettings(const PlateJob& job) {
  PrintSettings print = resolvePrintSettings(
      {job.profile, job.printer, job.material, job.printSettings, "plate job print_settings",
       job.sourceFile.string() + ": printer", job.sourceFile.string() + ": material"});
  checkDisplayOverrides(print, "plate job print_settings", job.resolution.has_value(), job.pixel.has_value(),
                        job.mirrorX, job.mirrorY,
                        {"settings.resolution", "settings.pixel", "settings.mirror", "settings.mirror"});
  applyJobMirror(print, job.mirrorX, job.mirrorY, "plate job settings.mirror");
  // The elephant foot's other keys shape its compensation: without one they do nothing (slice refuses them).
  checkElephantFootKeys(print, job.printSettings, job.sourceFile, "print_settings.");
  // A material named for contours only does nothing unless a material_correction changes them (or its
  // density the report's resin mass).
  if (!job.material.empty() && job.masks.empty())
    if (const std::string why = unusedMaterialReason(print, !job.report.empty(), "the contours",
                                                     job.report.empty() ? "" : "the report");
        !why.empty())
      throw InputError(job.sourceFile.string() + ": material: does nothing in this job: " + why +
                       "; its exposures need outputs.masks");
  return settingsForMaskFormat(print, job.masks);
}

// settings.resolution, settings.pixel and settings.build_height as the printer's display_pixels_x/y,
// display_width/height and max_print_height, naming them: --explain and the report say what the plate is.
void recordPlateSettings(PrintSettings& print, const PlateJob& job) {
  MaskOptions o;
  o.pixel = job.pixel;
  if (job.resolution)
    o.resolution = std::pair<uint32_t, uint32_t>{(*job.resolution)[0], (*job.resolution)[1]};
  recordDisplayOptions(print, o, "settings.resolution", "settings.pixel");
  if (job.buildHeight)
    assignSetting(print, "max_print_height", formatNumber(*job.buildHeight), "settings.build_height");
}

PrintSettings plateJobSettings(const PlateJob& job) {
  PrintSettings print = givenPlateSettings(job);
  recordPlateSettings(print, job);
  return print;
}

// The masks' own checks with the job's resolved settings and display, as slicePlate makes them.
static void checkPlateMasks(const PlateJob& job, const PrintSettings& print, const PlateGeometry& geometry) {
  if (job.masks.empty()) return;
  MaskOptions o = plateMaskOptions(job, print, geometry, plateOutputPath(job.masks, 0));
  o.crop = true;  // no parts: the image's own checks only
  maskTransfer(print, makeMaskJob(o, print, BoundingBox{}, "plate", {}));
}

void checkPlateMaskSettings(const PlateJob& job) {
  PrintSettings print = givenPlateSettings(job);
  const PlateGeometry geometry = plateGeometry(job, print);
  recordPlateSettings(print, job);
  checkPlateMasks(job, print, geometry);
}

PreparedPlateJob::PreparedPlateJob(PlateJob given) : impl_(std::make_unique<Impl>()) {
  impl_->job = std::move(given);
  const PlateJob& job = impl_->job;
  impl_->print = givenPlateSettings(job);
  impl_->geometry = plateGeometry(job, impl_->print);
  recordPlateSettings(impl_->print, job);
  const PrintSettings& print = impl_->print;
  const PlateGeometry& geometry = impl_->geometry;
  // A spacing wider than the plate keeps every part from every other on any plate; the arrangement's
  // grids grow with it (10^5 mm ran out of memory): a mistake, said as one.
  if (const double diagonal = std::hypot(geometry.widthMm(), geometry.heightMm()); job.spacing > diagonal)
    throw InputError(job.sourceFile.string() + ": arrange.spacing: " + formatNumber(job.spacing) +
                     " mm is more than the plate's diagonal (" + formatNumber(diagonal) +
                     " mm): no two parts could share a plate");
  checkMaskSettings(print, job.antialias, !job.masks.empty(), "settings.antialias");
  checkPlateMasks(job, print, geometry);  // the light map against the display, before any part is read
  PlateResult& result = impl_->result;
  const std::size_t count = job.parts.size();
  std::vector<std::filesystem::path> inputs{job.sourceFile, job.profile, print.lightMap};
  for (const PlatePart& p : job.parts) {
    inputs.push_back(p.model);
    if (!p.templateFile.empty()) inputs.push_back(p.templateFile);
    inputs.insert(inputs.end(), p.add.begin(), p.add.end());
    inputs.insert(inputs.end(), p.remove.begin(), p.remove.end());
  }
  std::vector<std::filesystem::path>& outputs = impl_->outputs;
  outputs = {job.masks, job.report, job.picture};
  outputs.insert(outputs.end(), job.contours.begin(), job.contours.end());
  std::erase_if(inputs, [](const std::filesystem::path& p) { return p.empty(); });
  impl_->inputs = inputs;
  checkDistinctPlateOutputs(job, 1);
  checkPlateOutputs(job, 0, 1, inputs);  // before anything is read; the other plates' once they are known

  // Read every part (and each distinct template table once), in parallel across parts.
  auto start = std::chrono::steady_clock::now();
  std::map<std::filesystem::path, TemplateTable>& tables = impl_->tables;
  for (const PlatePart& p : job.parts) {
    if (p.templateFile.empty() || tables.count(p.templateFile)) continue;
    try {
      tables[p.templateFile] = readTemplateFile(p.templateFile);
    } catch (const InputError& e) {  // named by the first part that uses it, as a part's model is
      throw InputError("part '" + p.name + "': template: " + e.what());
    }
  }
  MeshReadOptions read;
  read.unitMm = job.unitMm;
  read.scale = job.scale;
  read.runner = parallelChunkRunner();
  std::vector<LoadedPart>& loaded = impl_->loaded;
  loaded.resize(count);
  std::vector<std::string> errors(count);
  std::vector<std::vector<std::string>> partWarnings(count);
  result.parts.resize(count);
  const double cell = job.cell;
  parallelForChunks(count, 1, [&](std::size_t b, std::size_t e) {
    for (std::size_t p = b; p < e; ++p) {
      try {
        const PlatePart& spec = job.parts[p];
        LoadedPart& part = loaded[p];
        checkFeatureFiles(spec.model, spec.add, spec.remove);
        part.model = readMesh(spec.model, read);
        for (const auto* list : {&spec.add, &spec.remove})
          for (const auto& path : *list) part.features.push_back(readMesh(path, read));
        partWarnings[p] = fixInsideOutMeshes(job, spec, part);
        if (scalesWhenRead(print)) scalePart(part, print);
        // The footprint covers the model and its add-ons (a removal never widens it).
        std::vector<std::span<const Point3f>> covered = {part.model.corners};
        for (std::size_t f = 0; f < spec.add.size(); ++f) covered.emplace_back(part.features[f].corners);
        part.footprint = projectFootprint(covered, cell, read.runner);
        // Topology: the template's table after the linear check, or built (weld + adjacency).
        SliceJobOptions options;
        if (!job.method.empty()) parseSliceMethod(job.method, options.slice.method);
        options.rebuildOnMismatch = job.allowRebuild;
        SliceJobResult topo;
        const TemplateTable* table = spec.templateFile.empty() ? nullptr : &tables.at(spec.templateFile);
        part.adjacency = modelTopology(spec.model, part.model, table, options, topo, part.built);
        for (const std::string& w : topo.warnings)  // a mismatching part rebuilt ("allow_rebuild")
          partWarnings[p].push_back("part '" + spec.name + "': " + w);
        part.featureTables.resize(part.features.size());
        if (options.slice.method == SliceMethod::SelfReuse)
          for (std::size_t f = 0; f < part.features.size(); ++f)
            buildTable(part.features[f], part.featureTables[f]);
        PlatePartResult& r = result.parts[p];
        r.name = spec.name;
        r.topology = topo.topology;
        r.facets = part.model.facetCount();
        r.edgesCounted = topo.edgesCounted;
        r.edges = topo.edges;
      } catch (const std::bad_alloc&) {  // named as the model it was reading, not "std::bad_alloc"
        errors[p] = job.parts[p].model.string() + ": out of memory reading or preparing the part";
      } catch (const std::exception& failure) {
        errors[p] = failure.what();
      }
    }
  });
  // Every part that cannot be loaded is named, in job order (one line alone, else a list).
  std::vector<std::string> failed;
  for (std::size_t p = 0; p < count; ++p)
    if (!errors[p].empty()) failed.push_back("part '" + job.parts[p].name + "': " + errors[p]);
  if (failed.size() == 1) throw InputError(failed[0]);
  if (!failed.empty()) throwProblems(job, std::to_string(failed.size()) + " parts cannot be used", failed);
  for (auto& w : partWarnings) result.warnings.insert(result.warnings.end(), w.begin(), w.end());
  for (const PlatePartResult& r : result.parts) {
    const bool fromTable = r.topology.starts_with("loaded from template");
    result.templateChecked += fromTable ? 1 : 0;
    result.built +=
        r.topology.starts_with("built") || r.topology.find("rebuilt") != std::string::npos ? 1 : 0;
  }
  result.readSeconds = secondsSince(start);

  // Arrangement: given placements stay, `auto` parts are nested around them.
  start = std::chrono::steady_clock::now();
  std::vector<ArrangeItem> items(count);
  for (std::size_t p = 0; p < count; ++p) {
    items[p].footprint = &loaded[p].footprint;
    const auto& placement = job.parts[p].placement;
    if (!placement) continue;
    // tx, ty put the centre of the rotated bounding box at (x, y).
    FacetSoup rotated = loaded[p].model;
    rotateSoup(rotated, placement->rotation);
    LoadedPart probe;
    probe.model = std::move(rotated);
    for (std::size_t f = 0; f < job.parts[p].add.size(); ++f) {
      probe.features.push_back(loaded[p].features[f]);
      rotateSoup(probe.features.back(), placement->rotation);
    }
    const BoundingBox box = partBounds(probe, job.parts[p].add.size());
    items[p].fixedRotation = placement->rotation;
    items[p].fixedTx = placement->x - 0.5 * (double{box.min.x} + box.max.x);
    items[p].fixedTy = placement->y - 0.5 * (double{box.min.y} + box.max.y);
  }
  ArrangeSettings arrange;
  arrange.plateWidth = geometry.widthMm();
  arrange.plateHeight = geometry.heightMm();
  // A positive absolute_correction widens every part by that much as it prints, a scaling correction
  // with different x and y factors scales it once turned (residualSpacing: for two neighbours, each
  // point moving up to sqrt(2) times as far as along one axis): the parts are nested with room for both,
  // from each other and from the plate's edges (there, along one axis only).
  const double grow = std::max(0.0, print.absoluteCorrection), residual = residualSpacing(job, loaded, print);
  arrange.margin = job.margin + grow + residual / (2 * std::sqrt(2.0));
  arrange.spacing = job.spacing + residual + 2 * grow;
  arrange.rotationStep = job.rotationStep;
  arrange.cancel = &interruptRequested();
  Arrangement arranged;
  try {
    arranged = arrangeFootprints(items, arrange);
    if (arranged.cancelled) throw InputError("interrupted");
  } catch (const std::invalid_argument& e) {
    const std::size_t p = std::stoul(e.what());
    throw InputError(job.sourceFile.string() + ": part '" + job.parts[p].name + "' (footprint " +
                     formatNumber(loaded[p].footprint.area()) + " mm^2) does not fit an empty " +
                     mm(arrange.plateWidth) + " x " + mm(arrange.plateHeight) + " plate with a margin of " +
                     mm(job.margin));
  }
  result.arrangeSeconds = secondsSince(start);
  result.plates = arranged.plates;
  checkDistinctPlateOutputs(job, result.plates);
  checkPlateOutputs(job, 1, result.plates, impl_->inputs);
  for (uint32_t p = 0; p < arranged.plates; ++p) result.density.push_back(arranged.density(p));
  result.layers.assign(result.plates, 0);
  result.volumeMl.assign(result.plates, 0.0);

  // Orientation: meshes turned in place (after the template check, which does not depend on it).
  for (std::size_t p = 0; p < count; ++p) {
    PlatePartResult& r = result.parts[p];
    const ArrangedPart& a = arranged.parts[p];
    rotateSoup(loaded[p].model, a.rotation);
    for (FacetSoup& f : loaded[p].features) rotateSoup(f, a.rotation);
    if (scalesWhenTurned(print)) scalePart(loaded[p], print);  // along the plate's axes, once turned
    BoundingBox box = partBounds(loaded[p], job.parts[p].add.size());
    r.plate = a.plate;
    r.arranged = !job.parts[p].placement;
    r.tx = a.tx;
    r.ty = a.ty;
    box.min = {static_cast<float>(box.min.x + a.tx), static_cast<float>(box.min.y + a.ty), box.min.z};
    box.max = {static_cast<float>(box.max.x + a.tx), static_cast<float>(box.max.y + a.ty), box.max.z};
    r.bounds = box;
    r.placement = job.parts[p].placement.value_or(PlatePlacement{
        0.5 * (double{box.min.x} + box.max.x), 0.5 * (double{box.min.y} + box.max.y), a.rotation});
    // The footprint was projected before a scaling applied once turned: its area scales with x and y.
    r.footprintMm2 =
        loaded[p].footprint.area() * (scalesWhenTurned(print) ? print.scale()[0] * print.scale()[1] : 1.0);
  }
  checkPlacements(job, loaded, result.parts, geometry, arrange.spacing, grow);
}

PreparedPlateJob::~PreparedPlateJob() = default;

const PlateJob& PreparedPlateJob::job() const {
  return impl_->job;
}

PlateResult& PreparedPlateJob::result() {
  return impl_->result;
}

void PreparedPlateJob::slicePlate(uint32_t plate, const ProgressContext* progress) {
  PlateResult& result = impl_->result;
  std::vector<std::size_t> members;
  for (std::size_t p = 0; p < result.parts.size(); ++p)
    if (result.parts[p].plate == plate) members.push_back(p);
  const PlateSlice s = toposlice::slicePlate(impl_->job, plate, members, impl_->loaded, result.parts,
                                             impl_->print, impl_->geometry, progress);
  result.layers[plate] = s.layers;
  result.volumeMl[plate] = s.volumeMl;
}

void PreparedPlateJob::writeReport() const {
  const PlateJob& job = impl_->job;
  const PlateGeometry& geometry = impl_->geometry;
  const PlateResult& result = impl_->result;
  const std::vector<std::filesystem::path>& outputs = impl_->outputs;
  if (!job.report.empty()) {
    nlohmann::ordered_json j;
    j["toposlice"] = TOPOSLICE_VERSION_TEXT;
    j["job"] = job.sourceFile.string();
    j["printer"] = impl_->print.printerName;
    j["material"] = impl_->print.materialName;
    j["print_settings"] =
        printSettingsJson(impl_->print,
                          "each part's own: the centre of its bounding box in x and y, "
                          "lowest z; x and y along the plate's axes",
                          job.masks.empty() ? nullptr : "settings.antialias", job.antialias);
    j["image"] = {{"width", geometry.width}, {"height", geometry.height}, {"pixel_mm", geometry.pixel}};
    j["layer_height_mm"] = job.layerHeight;
    j["template_reuse"] = {{"parts_checked_against_template", result.templateChecked},
                           {"parts_with_weld_and_adjacency_built", result.built}};
    nlohmann::ordered_json plates = nlohmann::ordered_json::array();
    for (uint32_t p = 0; p < result.plates; ++p) {
      nlohmann::ordered_json outs = nlohmann::ordered_json::array();
      for (const auto& o : outputs)
        if (!o.empty() && o != job.report) outs.push_back(plateOutputPath(o, p).string());
      plates.push_back({{"plate", p + 1},
                        {"layers", result.layers[p]},
                        {"density", result.density[p]},
                        {"volume_ml", result.volumeMl[p]},
                        {"outputs", outs}});
    }
    j["plates"] = plates;
    nlohmann::ordered_json parts = nlohmann::ordered_json::array();
    for (const PlatePartResult& r : result.parts) {
      parts.push_back(
          {{"name", r.name},
           {"plate", r.plate + 1},
           {"placement", {{"x", r.placement.x}, {"y", r.placement.y}, {"rotation", r.placement.rotation}}},
           {"arranged", r.arranged},
           {"translation_mm", {r.tx, r.ty}},
           {"topology", r.topology},
           {"facets", r.facets},
           // As in the slice summary: counted where the adjacency was built, null after a table.
           {"defects",
            {{"boundary_edges", r.edgesCounted ? nlohmann::ordered_json(r.edges.boundary) : nullptr},
             {"non_manifold_edges", r.edgesCounted ? nlohmann::ordered_json(r.edges.nonManifold) : nullptr},
             {"inconsistent_edges",
              r.edgesCounted ? nlohmann::ordered_json(r.edges.inconsistent) : nullptr}}},
           {"volume_ml", r.volumeMl},
           {"first_layer", r.firstLayer},
           {"last_layer", r.lastLayer},
           {"footprint",
            {{"area_mm2", r.footprintMm2},
             {"min_mm", {r.bounds.min.x, r.bounds.min.y}},
             {"max_mm", {r.bounds.max.x, r.bounds.max.y}}}}});
    }
    j["parts"] = parts;
    j["seconds"] = {{"read_and_topology", result.readSeconds},
                    {"arrange", result.arrangeSeconds},
                    {"slice_and_write", result.sliceSeconds}};
    const std::string text = j.dump(2) + "\n";
    OutputFile file(job.report, job.overwrite);
    file.write(text.data(), text.size());
    file.commit();
  }
}

void warnAboutLaterPlates(const PlateJob& job, PlateResult& result) {
  std::vector<std::string> stale;
  for (uint32_t plate = result.plates; plate < result.plates + 1000; ++plate) {
    bool any = false;
    forEachPlateOutput(job, plate, plate + 1, [&](const std::filesystem::path& path, bool) {
      if (outputPathExists(path)) {
        any = true;
        stale.push_back(path.string());
      }
    });
    if (!any) break;
  }
  if (stale.empty()) return;
  const std::size_t more = stale.size() - 1;
  result.warnings.push_back(stale.front() +
                            (more > 0
                                 ? " and " + std::to_string(more) +
                                       (more == 1 ? " more file" : " more files") + " of later plates exist"
                                 : " exists") +
                            " from an earlier run; this job made " + std::to_string(result.plates) +
                            (result.plates == 1 ? " plate" : " plates") + " and left them as they were");
}

void makePlateOutputFolders(const PlateJob& job, uint32_t plates) {
  forEachPlateOutput(job, 0, plates, [](const std::filesystem::path& path, bool) {
    const std::filesystem::path folder = path.parent_path();
    if (folder.empty()) return;
    std::error_code ec;
    std::filesystem::create_directories(folder, ec);
    if (ec && !std::filesystem::is_directory(folder))
      throw OutputError(folder.string() + ": cannot create the output folder: " + ec.message());
  });
}

PlateResult runPlateJob(const PlateJob& job, const ProgressContext* progress,
                        const std::function<void(uint32_t, uint32_t)>& onPlate) {
  PreparedPlateJob prepared(job);
  PlateResult& result = prepared.result();
  makePlateOutputFolders(job, result.plates);
  // Slicing, plate by plate; every output of every plate and the report join one transaction.
  const auto start = std::chrono::steady_clock::now();
  OutputTransaction transaction;
  for (uint32_t plate = 0; plate < result.plates; ++plate) {
    if (onPlate) onPlate(plate, result.plates);
    prepared.slicePlate(plate, progress);
  }
  result.sliceSeconds = secondsSince(start);
  prepared.writeReport();
  transaction.commit(&interruptRequested());
  result.written = transaction.committed();
  warnAboutLaterPlates(job, result);
  return std::move(result);
}

PlateJob readPlateCommandJob(const std::filesystem::path& jobPath, const std::filesystem::path& outputDir) {
  PlateJob job = readPlateJob(jobPath);
  if (!outputDir.empty()) {
    for (auto* path : {&job.masks, &job.report, &job.picture})
      if (!path->empty()) *path = outputDir / path->filename();
    for (auto& path : job.contours) path = outputDir / path.filename();
  }
  return job;
}

int runPlateCommand(const std::filesystem::path& jobPath, bool quiet,
                    const std::filesystem::path& outputDir) {
  const PlateJob job = readPlateCommandJob(jobPath, outputDir);
  // The folder the user named for the outputs (-O, as `plate job.json -O out` in the README) and those
  // of the job's outputs are made when missing (the latter by runPlateJob). A failed job takes the
  // folders it made away again (they hold nothing then).
  MadeFolders made;
  made.note(outputDir);
  forEachPlateOutput(job, 0, 1,
                     [&](const std::filesystem::path& path, bool) { made.note(path.parent_path()); });
  if (!outputDir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(outputDir, ec);
    if (ec) throw OutputError(outputDir.string() + ": cannot create the output folder: " + ec.message());
  }
  ThreadLimit threads(job.threads);
  PlateResult r;
  try {
    // A progress bar on a terminal (not with --quiet), naming the plate; its line ends before the summary.
    ProgressBar bar("plate", quiet);
    ProgressContext progress;
    progress.report = [&bar](uint64_t done, uint64_t total) { bar.update(done, total); };
    r = runPlateJob(job, &progress, [&bar](uint32_t plate, uint32_t plates) {
      bar.setLabel("plate " + std::to_string(plate + 1) + "/" + std::to_string(plates) + " layers");
    });
  } catch (...) {
    made.removeEmpty();
    throw;
  }
  for (const auto& w : r.warnings) std::fprintf(stderr, "toposlice: warning: %s\n", w.c_str());  // even -q
  if (!quiet) printPlateSummary(stdout, r);
  return 0;
}

void printPlateSummary(std::FILE* out, const PlateResult& r) {
  std::fprintf(out, "%u plate%s, %zu parts (%u checked against a template, %u built)\n", r.plates,
               r.plates == 1 ? "" : "s", r.parts.size(), r.templateChecked, r.built);
  for (uint32_t p = 0; p < r.plates; ++p)
    std::fprintf(out, "plate %u: %u layers, packing density %.1f %%, %.3f ml\n", p + 1, r.layers[p],
                 100 * r.density[p], r.volumeMl[p]);
  std::fprintf(out, "%-20s %5s %9s %9s %7s %9s %7s %7s %10s\n", "part", "plate", "x mm", "y mm", "rot",
               "volume ml", "first", "last", "footprint");
  for (const PlatePartResult& p : r.parts)
    std::fprintf(out, "%-20s %5u %9.3f %9.3f %7.2f %9.4f %7lld %7lld %7.1f mm2\n", p.name.c_str(),
                 p.plate + 1, p.placement.x, p.placement.y, p.placement.rotation, p.volumeMl,
                 static_cast<long long>(p.firstLayer), static_cast<long long>(p.lastLayer), p.footprintMm2);
  // A part whose mesh is not closed is sliced as slice slices it (its open outlines bridged): said, as
  // slice's summary says it.
  for (const PlatePartResult& p : r.parts)
    if (p.edgesCounted && (p.edges.boundary > 0 || p.edges.nonManifold > 0 || p.edges.inconsistent > 0))
      std::fprintf(out,
                   "part '%s': mesh not closed or not consistently oriented: %llu boundary, %llu "
                   "non-manifold, %llu inconsistent edges\n",
                   p.name.c_str(), static_cast<unsigned long long>(p.edges.boundary),
                   static_cast<unsigned long long>(p.edges.nonManifold),
                   static_cast<unsigned long long>(p.edges.inconsistent));
  for (const auto& w : r.written) std::fprintf(out, "wrote %s\n", w.c_str());
  std::fprintf(out, "read+topology %.2f s, arrange %.3f s, slice+write %.2f s\n", r.readSeconds,
               r.arrangeSeconds, r.sliceSeconds);
}

}  // namespace toposlice
