// Plate jobs (tools/plate_job.h, core/print/arrange.h): parts sliced together equal the parts sliced alone,
// arrangement invariants and its baseline, errors before slicing, template reuse, and the program.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/mesh/mesh_info.h"
#include "core/mesh/weld.h"
#include "core/print/arrange.h"
#include "io/coders/mask_png.h"
#include "io/errors.h"
#include "io/jobs/plate_job_file.h"
#include "io/jobs/profile.h"
#include "io/jobs/template_file.h"
#include "io/masks/mask_sink.h"
#include "io/readers/mesh_reader.h"
#include "io/readers/stl_writer.h"
#include "parallel/parallel.h"
#include "tests/fixtures/runners.h"
#include "tests/fixtures/shapes.h"
#include "tests/tool_runner.h"
#include "tools/plate_job.h"
#include "tools/slice_job.h"

namespace toposlice {
namespace {

using tool_test::CliToolBase;
using tool_test::readBytes;
using tool_test::sharedModel;
using tool_test::toposliceBinary;
using tool_test::zipEntry;
namespace fs = std::filesystem;

const fs::path kCase0 = sharedModel("derived/aligner_upper_case0.stl.gz");
const fs::path kStage2 = sharedModel("derived/aligner_upper_case0_stage2.stl.gz");

const FacetSoup& aligner(int which) {
  static const FacetSoup a = readMesh(kCase0, {}), b = readMesh(kStage2, {});
  return which == 0 ? a : b;
}

std::string q(const fs::path& p) {
  return "\"" + p.string() + "\"";
}

class PlateTest : public CliToolBase {
 public:
  // The template table of the aligners, written once per test into the work folder.
  fs::path alignerTable() {
    const fs::path path = dir_ / "aligner.topo";
    if (!fs::exists(path))
      writeTemplateFile(path, buildTemplateTable(weldCorners(aligner(0).corners)), false);
    return path;
  }
  PlateJob job(const std::string& text) { return parsePlateJob(text, dir_, "job.json"); }
  void expectPartsAsSlicedAlone(const std::string& print, const ProfileChoice& choice);
};

MaskImage readPng(const fs::path& path) {
  const std::string bytes = readBytes(path);
  MaskImage mask;
  EXPECT_TRUE(decodeMaskPng({reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()}, mask)) << path;
  return mask;
}

// The polylines of an ASCII CLI file: per layer, per polyline its id, dir and coordinates.
struct CliPolyline {
  int id = 0, dir = 0;
  std::vector<double> xy;
};
std::vector<std::vector<CliPolyline>> readAsciiCliLayers(const fs::path& path) {
  std::vector<std::vector<CliPolyline>> layers;
  std::istringstream in(readBytes(path));
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("$$LAYER/", 0) == 0) layers.emplace_back();
    if (line.rfind("$$POLYLINE/", 0) != 0) continue;
    std::istringstream fields(line.substr(11));
    std::string field;
    std::vector<double> numbers;
    while (std::getline(fields, field, ',')) numbers.push_back(std::stod(field));
    CliPolyline polyline{static_cast<int>(numbers.at(0)), static_cast<int>(numbers.at(1)), {}};
    polyline.xy.assign(numbers.begin() + 3, numbers.end());
    EXPECT_EQ(polyline.xy.size(), 2 * static_cast<std::size_t>(numbers.at(2))) << line;
    layers.back().push_back(std::move(polyline));
  }
  return layers;
}

// Every layer of the plate is the union of the parts sliced alone, pixel for pixel, and no pixel is lit
// by two parts; its contours are the parts' contours sliced alone, moved by the parts' translations, part
// after part. Part b is turned by 90 degrees on the plate and compared with its mesh turned the same way
// and sliced alone; placements are whole pixels apart. `print` adds members to the job's top level (a
// profile, print_settings); the parts alone are sliced with `choice`, the same settings.
void PlateTest::expectPartsAsSlicedAlone(const std::string& print, const ProfileChoice& choice) {
  const double pixel = 0.05;
  FacetSoup turned = aligner(1);
  for (Point3f& p : turned.corners) p = {-p.y, p.x, p.z};  // 90 degrees, exact
  writeBinaryStl(dir_ / "b_turned.stl", turned, "turned", {});
  const BoundingBox ba = boundsOf(aligner(0).corners), bb = boundsOf(turned.corners);
  // x, y: centres of the bounding boxes moved by whole pixels.
  const auto snap = [&](double centre, double target) {
    return centre + std::round((target - centre) / pixel) * pixel;
  };
  const double ax = snap(0.5 * (ba.min.x + ba.max.x), 36), ay = snap(0.5 * (ba.min.y + ba.max.y), 38);
  const double bx = snap(0.5 * (bb.min.x + bb.max.x), 100), by = snap(0.5 * (bb.min.y + bb.max.y), 40);
  char text[2048];
  std::snprintf(text, sizeof text, R"({%s "settings": {"layer_height": 0.25, "z0": -3.6, "pixel": 0.05,
      "resolution": [2600, 1600]},
    "parts": [{"name": "a", "model": %s, "template": %s, "placement": {"x": %.17g, "y": %.17g}},
              {"name": "b", "model": %s, "template": %s, "placement": {"x": %.17g, "y": %.17g, "rotation": 90}}],
    "outputs": {"masks": "plate", "contours": ["plate.cli"], "report": "report.json"}})",
                print.c_str(), q(kCase0).c_str(), q(alignerTable()).c_str(), ax, ay, q(kStage2).c_str(),
                q(alignerTable()).c_str(), bx, by);
  const PlateResult plate = runPlateJob(job(text), nullptr);
  ASSERT_EQ(plate.plates, 1u);
  EXPECT_EQ(plate.templateChecked, 2u);
  EXPECT_EQ(plate.built, 0u) << "with a table, no weld or adjacency is built";
  const std::string report = readBytes(dir_ / "report.json");
  EXPECT_NE(report.find("\"parts_with_weld_and_adjacency_built\": 0"), std::string::npos) << report;

  const fs::path models[2] = {kCase0, dir_ / "b_turned.stl"};
  for (int p = 0; p < 2; ++p) {
    SliceJobOptions o;
    o.planes.layerHeight = 0.25;
    o.planes.z0 = -3.6;
    o.masks.output = dir_ / ("alone" + std::to_string(p));
    o.masks.pixel = pixel;
    o.masks.resolution = std::pair<uint32_t, uint32_t>{2600, 1600};
    o.masks.origin = std::pair<double, double>{-plate.parts[p].tx, -plate.parts[p].ty};
    o.outputs = {dir_ / ("alone" + std::to_string(p) + ".cli")};
    o.print = resolvePrintSettings(choice);
    runSliceJob(models[p], o, nullptr);
  }
  // Contours: part p + 1 of each plate layer is part p's layer alone, translated (6 decimals each way).
  const auto plateCli = readAsciiCliLayers(dir_ / "plate.cli");
  ASSERT_EQ(plateCli.size(), plate.layers[0]);
  std::size_t points = 0;
  for (int p = 0; p < 2; ++p) {
    const auto alone = readAsciiCliLayers(dir_ / ("alone" + std::to_string(p) + ".cli"));
    ASSERT_EQ(alone.size(), plateCli.size());
    const double t[2] = {plate.parts[p].tx, plate.parts[p].ty};
    for (std::size_t k = 0; k < alone.size(); ++k) {
      std::vector<CliPolyline> part;
      for (const CliPolyline& l : plateCli[k])
        if (l.id == p + 1) part.push_back(l);
      ASSERT_EQ(part.size(), alone[k].size()) << "part " << p << " layer " << k;
      for (std::size_t l = 0; l < part.size(); ++l) {
        ASSERT_EQ(part[l].dir, alone[k][l].dir);
        ASSERT_EQ(part[l].xy.size(), alone[k][l].xy.size());
        for (std::size_t i = 0; i < part[l].xy.size(); ++i)
          ASSERT_NEAR(part[l].xy[i], alone[k][l].xy[i] + t[i % 2], 1.5e-6) << "part " << p << " layer " << k;
        points += part[l].xy.size() / 2;
      }
    }
  }
  EXPECT_GT(points, 10000u);
  uint64_t lit = 0, grey = 0;
  const auto layerFiles = [](const fs::path& folder) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(folder))
      if (e.path().extension() == ".png") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    return files;
  };
  const std::vector<fs::path> plateFiles = layerFiles(dir_ / "plate"), aFiles = layerFiles(dir_ / "alone0"),
                              bFiles = layerFiles(dir_ / "alone1");
  ASSERT_EQ(plateFiles.size(), plate.layers[0]);
  ASSERT_EQ(aFiles.size(), plate.layers[0]);
  ASSERT_EQ(bFiles.size(), plate.layers[0]);
  for (uint32_t k = 0; k < plate.layers[0]; ++k) {
    const MaskImage whole = readPng(plateFiles[k]), a = readPng(aFiles[k]), b = readPng(bFiles[k]);
    ASSERT_EQ(whole.pixels.size(), a.pixels.size());
    std::size_t differ = 0, shared = 0;
    for (std::size_t i = 0; i < whole.pixels.size(); ++i) {
      differ += whole.pixels[i] != std::max(a.pixels[i], b.pixels[i]) ? 1 : 0;
      shared += a.pixels[i] && b.pixels[i] ? 1 : 0;
      lit += whole.pixels[i] ? 1 : 0;
    }
    EXPECT_EQ(differ, 0u) << "layer " << k;
    for (const uint8_t v : whole.pixels) grey += v != 0 && v != 255 ? 1 : 0;
    EXPECT_EQ(shared, 0u) << "layer " << k;
  }
  EXPECT_GT(lit, 100000u);
  const PrintSettings settings = resolvePrintSettings(choice);
  EXPECT_EQ(grey > 0, settings.gammaCorrection.value_or(0) > 0) << "anti-aliased masks have grey edges";
}

TEST_F(PlateTest, PartMasksEqualThePartsSlicedAlone) {
  expectPartsAsSlicedAlone("", {});
}

// With a profile file, a material and overrides (scaling, z scaling, absolute correction, elephant foot,
// gamma, a light map), every part on the plate is what it is when sliced alone with the same settings:
// scaled about its own centre, corrected, then moved.
TEST_F(PlateTest, CorrectionsApplyToEachPartAsWhenSlicedAlone) {
  MaskImage light;
  light.width = 2600;
  light.height = 1600;
  light.pixels.resize(std::size_t{2600} * 1600);
  for (std::size_t i = 0; i < light.pixels.size(); ++i)
    light.pixels[i] = static_cast<uint8_t>(200 + (i % 2600) * 55 / 2599);  // brighter to the right
  std::vector<uint8_t> png;
  encodeMaskPng(light, png);
  tool_test::writeBytes(dir_ / "light.png", std::string(png.begin(), png.end()));
  tool_test::writeBytes(dir_ / "lab.json", R"({"printers": {"lab": {"relative_correction_x": 1.02,
      "relative_correction_y": 1.02, "gamma_correction": 0.8}},
    "materials": {"resin": {"exposure_time": 3.5, "material_correction_z": 1.01}}})");
  ProfileChoice choice;
  choice.file = dir_ / "lab.json";
  choice.printer = "lab";
  choice.material = "resin";
  choice.overrides = {{"absolute_correction", "0.05"},
                      {"elefant_foot_compensation", "0.2"},
                      {"light_map", (dir_ / "light.png").string()}};
  expectPartsAsSlicedAlone(R"("profile": "lab.json", "printer": "lab", "material": "resin",
      "print_settings": {"absolute_correction": 0.05, "elefant_foot_compensation": 0.2,
      "light_map": "light.png"},)",
                           choice);
}

// A growing absolute correction on binary masks: the plate and the parts alone rasterize each part's
// raw offset loops (no union), moved or not; the masks still match pixel for pixel.
TEST_F(PlateTest, GrowingCorrectionOnBinaryMasksAsWhenSlicedAlone) {
  ProfileChoice choice;
  choice.overrides = {{"absolute_correction", "0.05"}};
  expectPartsAsSlicedAlone(R"("print_settings": {"absolute_correction": 0.05},)", choice);
}

ArrangeSettings plate8k() {
  ArrangeSettings s;
  s.plateWidth = 7680 * 0.043;
  s.plateHeight = 4320 * 0.043;
  s.margin = 5;
  s.spacing = 2;
  s.rotationStep = 90;
  return s;
}

// The footprint of a part and its add-on, their facets split over the threads, is the one of both corner
// lists joined on one thread, for every runner and cell size; an empty list changes nothing.
TEST(ArrangeTest, SplitFootprintsOfSeveralListsEqualTheJoinedOneOnOneThread) {
  const FacetSoup& model = aligner(0);
  const FacetSoup monogram = readMesh(sharedModel("derived/monogram_A1_on_aligner.stl"), {});
  std::vector<Point3f> joined = model.corners;
  joined.insert(joined.end(), monogram.corners.begin(), monogram.corners.end());
  // The pool, and pieces taken last first on a width of 5 (not on the lists' boundaries).
  const ChunkRunner parallel = parallelChunkRunner(), backwards = fixtures::shuffledRunner(true, 5);
  const std::span<const Point3f> lists[3] = {model.corners, {}, monogram.corners};
  for (const double cell : {0.5, 0.13}) {
    const Footprint serial = projectFootprint(joined, cell);
    ASSERT_GT(serial.centres.size(), 1000u);
    for (const ChunkRunner* runner : {&serialChunkRunner(), &parallel, &backwards}) {
      const Footprint split = projectFootprint(lists, cell, *runner);
      EXPECT_EQ(split.cell, cell);
      EXPECT_TRUE(split.centres == serial.centres)
          << "cell " << cell << ", width " << runner->width << ": " << split.centres.size() << " against "
          << serial.centres.size();
    }
  }
}

// The distance between two parts' projections, against boxes and a turned square whose distances are
// known: apart along an axis, across a diagonal, a corner towards an edge, touching, overlapping, and
// farther than the limit.
TEST(ArrangeTest, ProjectionDistanceOfBoxes) {
  const FacetSoup a = fixtures::box(0, 0, 0, 10, 5, 3), b = fixtures::box(0, 0, 0, 8, 5, 2);
  const auto distance = [](const FacetSoup& p, double px, double py, const FacetSoup& q, double qx, double qy,
                           double limit) {
    const std::span<const Point3f> lp[1] = {p.corners}, lq[1] = {q.corners};
    return projectionDistance(lp, px, py, lq, qx, qy, limit);
  };
  EXPECT_NEAR(distance(a, 0, 0, b, 12, 0, 5), 2.0, 1e-12);
  EXPECT_NEAR(distance(b, 12, 0, a, 0, 0, 5), 2.0, 1e-12);
  EXPECT_NEAR(distance(a, 0, 0, b, 13, 9, 10), 5.0, 1e-12);  // corner (10, 5) to corner (13, 9)
  EXPECT_EQ(distance(a, 0, 0, b, 10, 0, 5), 0.0);            // sharing an edge
  EXPECT_EQ(distance(a, 0, 0, b, 4, 1, 5), 0.0);             // overlapping
  EXPECT_EQ(distance(a, 0, 0, b, 30, 0, 5), 5.0);            // beyond the limit: the limit
  // A square of side 2 turned by 45 degrees: its left corner sqrt(2) left of its centre.
  FacetSoup diamond = fixtures::box(-1, -1, 0, 1, 1, 1);
  for (Point3f& p : diamond.corners) {
    const double x = p.x, y = p.y, r = std::sqrt(0.5);
    p.x = static_cast<float>(r * (x - y));
    p.y = static_cast<float>(r * (x + y));
  }
  EXPECT_NEAR(distance(a, 0, 0, diamond, 10 + 1.5 + std::sqrt(2.0), 2.5, 5), 1.5, 1e-6);
  // A small square inside a larger one (no edges meet): overlapping all the same.
  EXPECT_EQ(distance(fixtures::box(0, 0, 0, 20, 20, 1), 0, 0, diamond, 10, 10, 5), 0.0);
}

// No two footprints, each grown by half the spacing, overlap, all lie inside the margin, the result repeats,
// and it needs no more plates and packs no less densely than shelf packing of bounding boxes.
TEST(ArrangeTest, AlignersNestBetterThanShelves) {
  const Footprint fp[2] = {projectFootprint(aligner(0).corners, 0.5),
                           projectFootprint(aligner(1).corners, 0.5)};
  const ArrangeSettings s = plate8k();
  for (const std::size_t n : {12u, 24u, 48u}) {
    std::vector<ArrangeItem> items(n);
    for (std::size_t k = 0; k < n; ++k) items[k].footprint = &fp[k % 2];
    const Arrangement a = arrangeFootprints(items, s);
    const Arrangement again = arrangeFootprints(items, s);
    const Arrangement shelf = shelfPackBoxes(items, s);
    std::vector<CellShape> raw, grown;
    for (std::size_t k = 0; k < n; ++k) {
      const ArrangedPart& p = a.parts[k];
      EXPECT_EQ(p.tx, again.parts[k].tx);
      EXPECT_EQ(p.ty, again.parts[k].ty);
      EXPECT_EQ(p.rotation, again.parts[k].rotation);
      // The arranger moves shapes by whole cells: the same here.
      const int32_t di = static_cast<int32_t>(std::lround(p.tx / 0.5)),
                    dj = static_cast<int32_t>(std::lround(p.ty / 0.5));
      raw.push_back(shiftShape(placeFootprint(*items[k].footprint, p.rotation, 0, 0, 0), di, dj));
      grown.push_back(
          shiftShape(placeFootprint(*items[k].footprint, p.rotation, 0, 0, 0.5 * s.spacing), di, dj));
      const CellShape& r = raw.back();
      EXPECT_GE(r.minI * 0.5, s.margin - 1e-9);
      EXPECT_GE(r.j0 * 0.5, s.margin - 1e-9);
      EXPECT_LE(r.maxI * 0.5, s.plateWidth - s.margin + 1e-9);
      EXPECT_LE((r.j0 + static_cast<int32_t>(r.rows())) * 0.5, s.plateHeight - s.margin + 1e-9);
    }
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        if (i != j && a.parts[i].plate == a.parts[j].plate) {
          EXPECT_FALSE(shapesOverlap(grown[i], grown[j])) << i << " " << j;
        }
    EXPECT_LE(a.plates, shelf.plates) << n;
    EXPECT_GE(a.density(0), shelf.density(0)) << n;
    std::printf("%zu parts: %u plates (shelf %u), first plate density %.3f (shelf %.3f)\n", n, a.plates,
                shelf.plates, a.density(0), shelf.density(0));
  }
}

// A scaling correction that differs in x and y acts along the plate's axes: part b, turned by 90 degrees
// on the plate, is scaled like its mesh turned first and sliced alone.
TEST_F(PlateTest, ScalingAlongThePlateAxesWhateverThePartsRotation) {
  ProfileChoice choice;
  choice.overrides = {{"relative_correction_x", "1.01"}, {"material_correction_y", "0.995"}};
  expectPartsAsSlicedAlone(
      R"("print_settings": {"relative_correction_x": 1.01, "material_correction_y": 0.995},)", choice);
}

// Through the program: the display comes from the profile file's only printer, the exposure from its
// only material, print_settings override both; the SL1 and the report carry what was chosen.
TEST_F(PlateTest, ProfileSettingsReachThePrinterFileAndTheReport) {
  tool_test::writeBytes(dir_ / "lab.json", R"({"printers": {"lab": {"display_pixels_x": 3000,
      "display_pixels_y": 2000, "display_width": 150, "display_height": 100, "max_print_height": 40}},
    "materials": {"resin": {"exposure_time": 2.5, "initial_exposure_time": 25, "faded_layers": 3}}})");
  tool_test::writeBytes(dir_ / "job.json",
                        "{\"profile\": \"lab.json\", \"print_settings\": "
                        "{\"faded_layers\": 4, \"absolute_correction\": -0.02},"
                        "\"settings\": {\"layer_height\": 0.5},"
                        "\"parts\": [{\"name\": \"a\", \"model\": " +
                            q(kCase0) +
                            ", \"placement\": \"auto\"}],"
                            "\"outputs\": {\"masks\": \"p.sl1\", \"report\": \"r.json\"}}");
  // --explain shows the settings the job will use and writes nothing.
  const tool_test::RunResult explained = run({"plate", (dir_ / "job.json").string(), "--explain"});
  ASSERT_EQ(explained.code(), 0) << explained.describe();
  for (const char* line : {"printer    : lab\n", "material   : resin\n",
                           "exposure   : 2.5 s, first layer 25 s, faded over 4 layers\n",
                           "  absolute_correction        = -0.02        (plate job print_settings)\n"})
    EXPECT_NE(explained.out.find(line), std::string::npos) << line << explained.out;
  EXPECT_FALSE(fs::exists(dir_ / "p.sl1"));
  const tool_test::RunResult moved =
      run({"plate", (dir_ / "job.json").string(), "--explain", "-O", (dir_ / "o").string()});
  EXPECT_NE(moved.out.find("masks      : " + (dir_ / "o" / "p.sl1").string() + ", binary"), std::string::npos)
      << moved.out;
  EXPECT_FALSE(fs::exists(dir_ / "o"));
  const tool_test::RunResult r = run({"plate", (dir_ / "job.json").string(), "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const std::string config = zipEntry(dir_ / "p.sl1", "config.ini");
  for (const char* line : {"expTime = 2.5\n", "expTimeFirst = 25\n", "numFade = 4\n"})
    EXPECT_NE(config.find(line), std::string::npos) << line << config;
  const std::string prusa = zipEntry(dir_ / "p.sl1", "prusaslicer.ini");
  for (const char* line : {"display_pixels_x = 3000\n", "absolute_correction = -0.02\n"})
    EXPECT_NE(prusa.find(line), std::string::npos) << line << prusa;
  const auto report = nlohmann::json::parse(readBytes(dir_ / "r.json"));
  EXPECT_EQ(report["printer"], "lab");
  EXPECT_EQ(report["material"], "resin");
  EXPECT_EQ(report["image"]["width"], 3000);
  EXPECT_EQ(report["image"]["pixel_mm"], 0.05);
  EXPECT_EQ(report["print_settings"]["values"]["exposure_time"], "2.5");
  EXPECT_EQ(report["print_settings"]["set_by"]["faded_layers"], "plate job print_settings");

  // The profile's max_print_height is the plate's build height; a key print_settings does not know, a light
  // map on binary masks and one of the wrong size are refused, named, before anything is written.
  const auto refused = [&](const std::string& print, const std::string& expected, bool oneLine = true) {
    tool_test::writeBytes(dir_ / "bad.json", "{\"profile\": \"lab.json\", " + print +
                                                 "\"settings\": {\"layer_height\": 0.5},"
                                                 "\"parts\": [{\"name\": \"a\", \"model\": " +
                                                 q(kCase0) +
                                                 ", \"placement\": \"auto\"}],"
                                                 "\"outputs\": {\"masks\": \"q.sl1\"}}");
    const tool_test::RunResult bad = run({"plate", (dir_ / "bad.json").string()});
    EXPECT_EQ(bad.code(), 1) << bad.describe();
    if (oneLine) expectOneErrorLine(bad);
    EXPECT_NE(bad.err.find(expected), std::string::npos) << bad.err;
    EXPECT_FALSE(fs::exists(dir_ / "q.sl1"));
  };
  refused("\"print_settings\": {\"max_print_height\": 8},", "taller than the printer's build height of 8.000",
          false);  // the placement problems are listed, one per line
  refused("\"print_settings\": {\"exposure\": 8},", "bad.json: print_settings.exposure: unknown");
  MaskImage small;
  small.width = small.height = 10;
  small.pixels.assign(100, 255);
  std::vector<uint8_t> png;
  encodeMaskPng(small, png);
  tool_test::writeBytes(dir_ / "light.png", std::string(png.begin(), png.end()));
  refused("\"print_settings\": {\"light_map\": \"light.png\"},", "light_map");
  refused("\"print_settings\": {\"light_map\": \"light.png\", \"gamma_correction\": 1},",
          "light.png: the light map is 10x10 pixels, the masks 3000x2000");
}

TEST_F(PlateTest, ProblemsWithGivenPlacementsNameTheParts) {
  const std::string parts = "\"parts\": [{\"name\": \"left\", \"model\": " + q(kCase0) +
                            ", \"placement\": {\"x\": 60, \"y\": 60}},"
                            "{\"name\": \"right\", \"model\": " +
                            q(kStage2) +
                            ", \"placement\": {\"x\": 90, \"y\": 60}},"
                            "{\"name\": \"edge\", \"model\": " +
                            q(kStage2) + ", \"placement\": {\"x\": 10, \"y\": 150}}],";
  try {
    runPlateJob(job("{\"printer\": \"generic-8k\", \"settings\": {\"build_height\": 8}," + parts +
                    "\"outputs\": {\"report\": \"r.json\"}}"),
                nullptr);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("parts 'left' and 'right' overlap"), std::string::npos) << what;
    EXPECT_NE(what.find("part 'edge' (x"), std::string::npos) << what;
    EXPECT_NE(what.find("sticks out of the printable area"), std::string::npos) << what;
    // The plate's layers start at the lower of the two aligners' bottoms (stage 2's): measured from there.
    EXPECT_NE(what.find("part 'left' reaches 10.941 mm above the bottom of its plate's layers (z -3.597 mm), "
                        "2.941 mm beyond the printer's build height of 8.000 mm"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("part 'right' is 10.946 mm tall, 2.946 mm taller"), std::string::npos) << what;
  }
  EXPECT_FALSE(fs::exists(dir_ / "r.json"));
}

// Given placements are measured on the parts' facets: 2.4 mm apart with a spacing of 2 is fine (the
// cell covers, conservative by a few cells, refused it), 1.6 mm apart is refused with the distance.
TEST_F(PlateTest, GivenPlacementsAreMeasuredOnTheParts) {
  writeBinaryStl(dir_ / "a.stl", fixtures::box(0, 0, 0, 10, 5, 3), "box", false);
  const auto text = [&](double gap) {
    return "{\"settings\": {\"layer_height\": 1, \"pixel\": 0.05, \"resolution\": [2000, 1000]}, "
           "\"arrange\": {\"spacing\": 2}, \"parts\": [{\"name\": \"a\", \"model\": \"a.stl\", "
           "\"placement\": {\"x\": 20, \"y\": 20}}, {\"name\": \"b\", \"model\": \"a.stl\", "
           "\"placement\": {\"x\": " +
           std::to_string(30 + gap) + ", \"y\": 20}}], \"outputs\": {\"contours\": [\"p.cli\"]}}";
  };
  EXPECT_NO_THROW(runPlateJob(job(text(2.4)), nullptr));
  fs::remove(dir_ / "p.cli");
  // Overlapping parts with a spacing of 0 (the exact measure was asked for a distance up to 0 and
  // accepted them), and two parts in one place.
  for (const double gap : {-0.5, -10.0}) {
    std::string zero = text(gap);
    zero.replace(zero.find("\"spacing\": 2"), 12, "\"spacing\": 0");
    try {
      runPlateJob(job(zero), nullptr);
      ADD_FAILURE() << "accepted, gap " << gap;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("parts 'a' and 'b' overlap or touch"), std::string::npos)
          << e.what();
    }
  }
  // A gap a few nanometres short of the spacing (placements in rounded decimals) is the spacing.
  EXPECT_NO_THROW(runPlateJob(job(text(2.0 - 2.4e-5)), nullptr));
  fs::remove(dir_ / "p.cli");
  try {
    runPlateJob(job(text(1.6)), nullptr);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "parts 'a' and 'b' are 1.600 mm apart, closer than the spacing of 2.000 mm"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "p.cli"));
}

// A positive absolute_correction grows every part as it prints: given placements keep the spacing
// plus twice the correction between parts and the correction from the plate's edges, and auto parts
// are nested with that room (parts fused, or were cut at the plate's edge, without a word).
TEST_F(PlateTest, APositiveCorrectionKeepsTheSpacingAndTheEdges) {
  writeBinaryStl(dir_ / "a.stl", fixtures::box(0, 0, 0, 10, 5, 3), "box", false);
  const auto given = [&](double x, double gap, double correction) {
    return "{\"print_settings\": {\"absolute_correction\": " + std::to_string(correction) +
           "}, \"settings\": {\"layer_height\": 1, \"pixel\": 0.05, \"resolution\": [2000, 1000]}, "
           "\"arrange\": {\"spacing\": 2}, \"parts\": [{\"name\": \"a\", \"model\": \"a.stl\", "
           "\"placement\": {\"x\": " +
           std::to_string(x) +
           ", \"y\": 20}}, {\"name\": \"b\", \"model\": \"a.stl\", \"placement\": {\"x\": " +
           std::to_string(x + 10 + gap) + ", \"y\": 20}}], \"outputs\": {\"contours\": [\"p.cli\"]}}";
  };
  const auto refusal = [&](const std::string& text) {
    try {
      runPlateJob(job(text), nullptr);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    fs::remove(dir_ / "p.cli");
    return std::string("accepted");
  };
  EXPECT_EQ(refusal(given(20, 2.1, 0)), "accepted");
  EXPECT_NE(refusal(given(20, 2.1, 0.1))
                .find("parts 'a' and 'b' are 2.100 mm apart, closer than the spacing of "
                      "2.000 mm plus twice the absolute_correction of 0.100 mm"),
            std::string::npos);
  EXPECT_EQ(refusal(given(20, 2.25, 0.1)), "accepted");
  EXPECT_EQ(refusal(given(5.05, 3, 0)), "accepted");  // 0.05 mm from the edge
  EXPECT_NE(
      refusal(given(5.05, 3, 0.1))
          .find("part 'a' (x 0.050 mm .. 10.050 mm, y 17.500 mm .. 22.500 mm) with its absolute_correction "
                "of 0.100 mm (each part grows by it) sticks out of the printable area (100.000 mm x "
                "50.000 mm) by 0.050 mm"),
      std::string::npos);
  // Auto: a 96 mm bar on a 100 mm plate with no margin, grown by 1 mm; and two bars 1 + 2 x 0.5 mm apart.
  writeBinaryStl(dir_ / "bar.stl", fixtures::box(0, 0, 0, 96, 20, 2), "bar", false);
  const PlateResult one = runPlateJob(
      job(R"({"print_settings": {"absolute_correction": 1}, "settings": {"layer_height": 1, "pixel": 0.05,
          "resolution": [2000, 1000]}, "arrange": {"spacing": 1, "margin": 0},
          "parts": [{"name": "bar", "model": "bar.stl", "placement": "auto"}], "outputs": {"contours": ["q.cli"]}})"),
      nullptr);
  ASSERT_EQ(one.plates, 1u);
  const BoundingBox b = one.parts[0].bounds;
  EXPECT_GE(b.min.x, 1 - 1e-4);
  EXPECT_GE(b.min.y, 1 - 1e-4);
  EXPECT_LE(b.max.x, 99 + 1e-4);
  EXPECT_LE(b.max.y, 49 + 1e-4);
  writeBinaryStl(dir_ / "slab.stl", fixtures::box(0, 0, 0, 40, 20, 2), "slab", false);
  const PlateResult two = runPlateJob(
      job(R"({"print_settings": {"absolute_correction": 0.5}, "settings": {"layer_height": 1, "pixel": 0.05,
          "resolution": [2000, 1000]}, "arrange": {"spacing": 1, "margin": 0},
          "parts": [{"name": "s", "model": "slab.stl", "placement": "auto"},
                    {"name": "t", "model": "slab.stl", "placement": "auto"}], "outputs": {"contours": ["r.cli"]}})"),
      nullptr);
  ASSERT_EQ(two.plates, 1u);
  const BoundingBox s = two.parts[0].bounds, t = two.parts[1].bounds;
  const double apart = std::max({t.min.x - s.max.x, s.min.x - t.max.x, t.min.y - s.max.y, s.min.y - t.max.y});
  EXPECT_GE(apart, 2 - 1e-4);
}

// The plate's layers start at the lowest bottom of its parts (or settings.z0): a part that starts higher
// is measured from there against the build height (a part floating 145 mm up made a 153 mm stack on a
// 150 mm printer without a word).
TEST_F(PlateTest, TheBuildHeightIsMeasuredFromThePlatesBottom) {
  writeBinaryStl(dir_ / "low.stl", fixtures::box(0, 0, 0, 10, 10, 8), "low", false);
  writeBinaryStl(dir_ / "high.stl", fixtures::box(0, 0, 145, 10, 10, 153), "high", false);
  try {
    runPlateJob(job(R"({"printer": "sl1", "settings": {"layer_height": 0.5},
        "parts": [{"name": "low", "model": "low.stl", "placement": "auto"},
                  {"name": "high", "model": "high.stl", "placement": "auto"}], "outputs": {"contours": ["p.cli"]}})"),
                nullptr);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(
        std::string(e.what()).find("part 'high' reaches 153.000 mm above the bottom of its plate's layers "
                                   "(z 0.000 mm), 3.000 mm beyond the printer's build height of 150.000 mm"),
        std::string::npos)
        << e.what();
    EXPECT_EQ(std::string(e.what()).find("part 'low'"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "p.cli"));
}

// A scaling that differs in x and y is applied once the part is turned, after its footprint was
// projected: the report's footprint area is the scaled one (it was the unscaled area).
TEST_F(PlateTest, TheReportedFootprintIsTheScaledPartsArea) {
  writeBinaryStl(dir_ / "a.stl", fixtures::box(0, 0, 0, 10, 5, 3), "box", false);
  const auto footprint = [&](const std::string& settings) {
    tool_test::writeBytes(dir_ / "job.json", R"({"version": 1, "printer": "sl1", )" + settings +
                                                 R"("settings": {"layer_height": 1, "overwrite": true},
        "parts": [{"name": "a", "model": "a.stl", "placement": "auto"}],
        "outputs": {"contours": ["p.cli"], "report": "r.json"}})");
    const auto r = run({"plate", "job.json", "-q"});
    EXPECT_EQ(r.code(), 0) << r.describe();
    const nlohmann::json report = nlohmann::json::parse(readBytes(dir_ / "r.json"));
    return report.at("parts").at(0).at("footprint").at("area_mm2").get<double>();
  };
  const double plain = footprint("");
  EXPECT_TRUE(plain >= 50.0 && plain < 60.0) << plain;  // 10 x 5 mm, covered by the footprint's cells
  EXPECT_NEAR(footprint(R"("print_settings": {"relative_correction_x": 1.1, "relative_correction_y": 0.9},)"),
              plain * 1.1 * 0.9, 1e-6 * plain);
  EXPECT_NEAR(footprint(R"("print_settings": {"relative_correction_x": 1.1, "relative_correction_y": 1.1},)"),
              plain * 1.21, 0.02 * plain);  // scaled when read: projected anew
}

// settings.resolution, settings.pixel and settings.build_height are the plate's display and height:
// --explain and the report's print_settings give them, naming the setting (they gave the preset's).
TEST_F(PlateTest, TheJobsDisplaySettingsAreTheReportedOnes) {
  writeBinaryStl(dir_ / "a.stl", fixtures::box(0, 0, 0, 10, 5, 3), "box", false);
  const std::string text = R"({"version": 1, "printer": "sl1", "settings": {"layer_height": 1, "pixel": 0.05,
      "resolution": [2000, 1200], "build_height": 20},
      "parts": [{"name": "a", "model": "a.stl", "placement": "auto"}], "outputs": {"masks": "p.sl1", "report": "r.json"}})";
  tool_test::writeBytes(dir_ / "job.json", text);
  const auto explained = run({"plate", "job.json", "--explain"});
  ASSERT_EQ(explained.code(), 0) << explained.describe();
  for (const char* line : {"display_pixels_x           = 2000         (settings.resolution)",
                           "display_width              = 100          (settings.pixel)",
                           "max_print_height           = 20           (settings.build_height)"})
    EXPECT_NE(explained.out.find(line), std::string::npos) << line << "\n" << explained.out;
  ASSERT_EQ(run({"plate", "job.json", "-q"}).code(), 0);
  const nlohmann::json report = nlohmann::json::parse(readBytes(dir_ / "r.json"));
  const auto& settings = report.at("print_settings");
  EXPECT_EQ(settings.at("values").at("display_pixels_y"), "1200");
  EXPECT_EQ(settings.at("values").at("display_height"), "60");
  EXPECT_EQ(settings.at("values").at("max_print_height"), "20");
  EXPECT_EQ(settings.at("set_by").at("display_height"), "settings.pixel");
  // A batch job's settings.resolution and settings.pixel, in its --explain.
  tool_test::writeBytes(dir_ / "batch.json", R"({"version": 1, "template": {"model": "a.stl"},
      "settings": {"layer_height": 1, "printer": "sl1", "resolution": [2000, 1200]},
      "variants": [{"name": "v", "model": "a.stl", "masks": "v.sl1"}]})");
  const auto batch = run({"batch", "batch.json", "--explain"});
  ASSERT_EQ(batch.code(), 0) << batch.describe();
  EXPECT_NE(batch.out.find("display_pixels_y           = 1200         (settings.resolution)"),
            std::string::npos)
      << batch.out;
  EXPECT_NE(batch.out.find("display_width              = 94.5         (settings.resolution)"),
            std::string::npos)
      << batch.out;
}

// A part whose mesh is not closed is said in the report (its defects, as in the slice summary) and the
// summary, as slice says it (the plate was silent); a closed one has none.
TEST_F(PlateTest, APartThatIsNotClosedIsSaid) {
  FacetSoup open = fixtures::box(0, 0, 0, 10, 10, 2);
  open.corners.resize(open.corners.size() - 3);  // one facet less: three boundary edges
  writeBinaryStl(dir_ / "open.stl", open, "open", false);
  writeBinaryStl(dir_ / "closed.stl", fixtures::box(0, 0, 0, 10, 10, 2), "closed", false);
  const PlateResult r = runPlateJob(job(R"({"printer": "sl1", "settings": {"layer_height": 0.5},
          "parts": [{"name": "o", "model": "open.stl", "placement": "auto"},
                    {"name": "c", "model": "closed.stl", "placement": "auto"}],
          "outputs": {"contours": ["p.cli"], "report": "r.json"}})"),
                                    nullptr);
  const nlohmann::json report = nlohmann::json::parse(readBytes(dir_ / "r.json"));
  EXPECT_EQ(report["parts"][0]["defects"]["boundary_edges"], 3) << report["parts"][0].dump();
  EXPECT_EQ(report["parts"][1]["defects"]["boundary_edges"], 0) << report["parts"][1].dump();
  char* text = nullptr;
  std::size_t size = 0;
  std::FILE* out = ::open_memstream(&text, &size);
  printPlateSummary(out, r);
  std::fclose(out);
  const std::string summary(text, size);
  std::free(text);
  EXPECT_NE(summary.find("part 'o': mesh not closed or not consistently oriented: 3 boundary, 0 "
                         "non-manifold, 0 inconsistent edges"),
            std::string::npos)
      << summary;
  EXPECT_EQ(summary.find("part 'c': mesh not closed"), std::string::npos) << summary;
}

// A part's volume is its solid region's: an add-on over the model counts once, a removal reaching out
// of it takes nothing there (the signed areas gave 100 + 100 - 30 = 170 mm^2 a layer), with or without
// masks; the plate's volume without masks is the parts'.
TEST_F(PlateTest, PartVolumesAreTheirSolidRegions) {
  writeBinaryStl(dir_ / "model.stl", fixtures::box(0, 0, 0, 10, 10, 2), "model", false);
  writeBinaryStl(dir_ / "add.stl", fixtures::box(5, 0, 0, 15, 10, 2), "add", false);
  writeBinaryStl(dir_ / "remove.stl", fixtures::box(-2, 0, 0, 1, 10, 2), "remove", false);
  for (const char* outputs : {R"({"contours": ["p.cli"]})", R"({"masks": "p.sl1"})"}) {
    const PlateResult r = runPlateJob(
        job(std::string(
                "{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 0.5}, \"parts\": [{\"name\": "
                "\"a\", \"model\": \"model.stl\", \"add\": [\"add.stl\"], \"remove\": [\"remove.stl\"], "
                "\"placement\": {\"x\": 40, \"y\": 30}}], \"outputs\": ") +
            outputs + "}"),
        nullptr);
    ASSERT_EQ(r.parts.size(), 1u);
    EXPECT_NEAR(r.parts[0].volumeMl, 0.28, 1e-9) << outputs;  // 140 mm^2 x 2 mm
    EXPECT_NEAR(r.volumeMl[0], 0.28, outputs[2] == 'm' ? 0.003 : 1e-9) << outputs;
  }
}

TEST_F(PlateTest, OtherConnectivityIsRefusedByNameUnlessRebuildIsAllowed) {
  const std::string text =
      "{\"printer\": \"generic-8k\", \"settings\": {\"layer_height\": 0.5%s},"
      "\"parts\": [{\"name\": \"odd one\", \"model\": " +
      q(tool_test::examplePart()) + ", \"template\": " + q(alignerTable()) +
      ", \"placement\": \"auto\"}], \"outputs\": {\"report\": \"r.json\"}}";
  char refused[4096], allowed[4096];
  std::snprintf(refused, sizeof refused, text.c_str(), "");
  std::snprintf(allowed, sizeof allowed, text.c_str(), ", \"allow_rebuild\": true");
  try {
    runPlateJob(job(refused), nullptr);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("part 'odd one'"), std::string::npos) << e.what();
  }
  const PlateResult r = runPlateJob(job(allowed), nullptr);
  EXPECT_EQ(r.built, 1u);
  EXPECT_NE(r.parts[0].topology.find("rebuilt"), std::string::npos);
  // Said as a warning too (stderr, never hidden by -q), naming the part.
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_EQ(r.warnings[0].rfind("part 'odd one': ", 0), 0u) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("does not match the template"), std::string::npos) << r.warnings[0];
}

TEST_F(PlateTest, EveryPartThatCannotBeUsedIsNamedInOneError) {
  // Two parts of other connectivity and a missing model among good ones: one error lists all three,
  // in job order, and nothing is written.
  const auto part = [](const std::string& name, const std::string& model, const std::string& table) {
    return "{\"name\": \"" + name + "\", \"model\": " + q(model) +
           (table.empty() ? "" : ", \"template\": " + q(table)) + ", \"placement\": \"auto\"}";
  };
  const std::string parts = "\"parts\": [" + part("good", kCase0, alignerTable()) + "," +
                            part("odd one", tool_test::examplePart(), alignerTable()) + "," +
                            part("missing", (dir_ / "nowhere.stl").string(), "") + "," +
                            part("odd two", tool_test::examplePart(), alignerTable()) + "],";
  try {
    runPlateJob(job("{\"printer\": \"generic-8k\", \"settings\": {\"layer_height\": 0.5}," + parts +
                    "\"outputs\": {\"report\": \"r.json\"}}"),
                nullptr);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("3 parts cannot be used"), std::string::npos) << what;
    const std::size_t one = what.find("part 'odd one'"), missing = what.find("part 'missing'"),
                      two = what.find("part 'odd two'");
    ASSERT_NE(one, std::string::npos) << what;
    ASSERT_NE(missing, std::string::npos) << what;
    ASSERT_NE(two, std::string::npos) << what;
    EXPECT_LT(one, missing);
    EXPECT_LT(missing, two);
    EXPECT_EQ(what.find("part 'good'"), std::string::npos) << what;
  }
  EXPECT_FALSE(fs::exists(dir_ / "r.json"));
}

// Outputs that may not be written are refused before the work: the report and the first plate's files
// before any part is read (a missing model would fail the read, so the refused report is what is
// reported), a later plate's files once the arrangement has made that plate.
// Two outputs that name one file once -O has put them in one folder are refused as one output given
// twice (they said "already exists" of a file that did not exist); and a failed job run with -O takes
// the folders -O made away again.
TEST_F(PlateTest, CollidingOutputsAndAFailedJobsOutputFolder) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  tool_test::writeBytes(dir_ / "coll.json",
                        "{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 1}, \"parts\": [" + part +
                            "], \"outputs\": {\"contours\": [\"x/c.cli\", \"y/c.cli\"]}}");
  tool_test::RunResult r = run({"plate", (dir_ / "coll.json").string(), "-O", (dir_ / "oc").string()});
  EXPECT_EQ(r.code(), 1) << r.describe();
  EXPECT_NE(r.err.find("c.cli: given as more than one output"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "oc")) << "the folder -O made stays behind";

  // Parts too large for the display: the job fails after -O made its folders.
  tool_test::writeBytes(dir_ / "big.json",
                        "{\"settings\": {\"layer_height\": 1, \"pixel\": 0.05, \"resolution\": [100, 100]},"
                        " \"parts\": [" +
                            part + "], \"outputs\": {\"masks\": \"m.sl1\"}}");
  r = run({"plate", (dir_ / "big.json").string(), "-O", (dir_ / "o5" / "deep").string()});
  EXPECT_EQ(r.code(), 1) << r.describe();
  EXPECT_FALSE(fs::exists(dir_ / "o5")) << "the folders -O made stay behind";
}

// "mirror" is the display's mirroring: "none" turns the SL1's own x mirror off (it was ORed with the
// printer's, so none and x gave the same masks), and the settings say what was used.
TEST_F(PlateTest, MirrorSettingReplacesThePrintersMirror) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  std::map<std::string, std::string> first;
  for (const char* mirror : {"none", "x", "y", "xy"}) {
    const fs::path out = dir_ / (std::string("m-") + mirror);
    runPlateJob(job("{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 2, \"mirror\": \"" +
                    std::string(mirror) + "\"}, \"parts\": [" + part +
                    "], \"outputs\": {\"masks\": " + q(out) + "}}"),
                nullptr);
    std::vector<fs::path> layers;
    for (const auto& e : fs::directory_iterator(out)) layers.push_back(e.path());
    std::sort(layers.begin(), layers.end());
    ASSERT_FALSE(layers.empty());
    first[mirror] = tool_test::readBytes(layers[layers.size() / 2]);
  }
  EXPECT_NE(first["none"], first["x"]);
  EXPECT_NE(first["y"], first["xy"]);
  EXPECT_NE(first["none"], first["y"]);
  PlateJob given = job("{\"printer\": \"sl1\", \"settings\": {\"mirror\": \"none\"}, \"parts\": [" + part +
                       "], \"outputs\": {\"masks\": \"p.sl1\"}}");
  given.sourceFile = dir_ / "job.json";
  const PrintSettings print = plateJobSettings(given);
  EXPECT_FALSE(print.mirrorX);
  EXPECT_EQ(print.origin.at("display_mirror_x"), "plate job settings.mirror");
}

// A spacing wider than the plate: every part apart from every other; the arrangement's grids grew with it
// until the job ran out of memory. Refused naming the key, the number as typed.
TEST_F(PlateTest, SpacingWiderThanThePlateIsRefused) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  try {
    runPlateJob(job("{\"printer\": \"sl1\", \"arrange\": {\"spacing\": 100000}, \"parts\": [" + part +
                    "], \"outputs\": {\"masks\": \"p.sl1\"}}"),
                nullptr);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("arrange.spacing: 100000 mm is more than the plate's diagonal"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "p.sl1"));
  // A rotation step so fine that arranging one part ran for minutes in gigabytes.
  try {
    job("{\"printer\": \"sl1\", \"arrange\": {\"rotation_step\": 1e-5}, \"parts\": [" + part +
        "], \"outputs\": {\"masks\": \"p.sl1\"}}");
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(
        std::string(e.what()).find("arrange.rotation_step: must be 0 (no rotation) or at least 1 degree"),
        std::string::npos)
        << e.what();
  }
}

// A job run again with fewer plates left the earlier run's later plates beside its own, silently: a
// script collecting p*.sl1 would print a plate of the old job. They stay (never deleted), with a warning.
TEST_F(PlateTest, LaterPlatesOfAnEarlierRunAreAWarning) {
  const std::string part =
      "{\"name\": \"%s\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  const auto text = [&](int parts) {
    std::string list;
    for (int i = 0; i < parts; ++i) {
      char one[4096];
      std::snprintf(one, sizeof one, part.c_str(), std::string(1, static_cast<char>('a' + i)).c_str());
      list += (i > 0 ? ", " : "") + std::string(one);
    }
    return "{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 1, \"overwrite\": true, \"pixel\": 0.1, "
           "\"resolution\": [300, 250]}, \"parts\": [" +
           list + "], \"outputs\": {\"masks\": \"p.sl1\"}}";
  };
  const PlateResult three = runPlateJob(job(text(3)), nullptr);
  ASSERT_EQ(three.plates, 3u);
  EXPECT_TRUE(three.warnings.empty());
  const PlateResult one = runPlateJob(job(text(1)), nullptr);
  ASSERT_EQ(one.plates, 1u);
  ASSERT_EQ(one.warnings.size(), 1u);
  EXPECT_NE(one.warnings[0].find("p-plate2.sl1 and 1 more file of later plates exist from an earlier run"),
            std::string::npos)
      << one.warnings[0];
  EXPECT_TRUE(fs::exists(dir_ / "p-plate3.sl1"));
}

// Messages that named neither the part nor the missing key: an unreadable template (shared by parts,
// named by the first that uses it), and no printer with a profile of several.
TEST_F(PlateTest, TemplateAndPrinterProblemsNameThePartAndTheKey) {
  tool_test::writeBytes(dir_ / "bad.topo", "solid x\n");
  const std::string part = "{\"name\": \"b\", \"model\": " + q(tool_test::examplePart()) +
                           ", \"template\": \"bad.topo\", \"placement\": \"auto\"}";
  const auto message = [&](const std::string& text) {
    try {
      runPlateJob(job(text), nullptr);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message("{\"printer\": \"sl1\", \"parts\": [" + part + "], \"outputs\": {\"masks\": \"p.sl1\"}}")
                .rfind("part 'b': template: ", 0),
            0u);
  tool_test::writeBytes(dir_ / "two.json",
                        R"({"printers": {"a": {"inherits": "sl1"}, "b": {"inherits": "sl1s"}}})");
  const std::string plain =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  const std::string noPrinter =
      message("{\"profile\": \"two.json\", \"parts\": [" + plain + "], \"outputs\": {\"masks\": \"p.sl1\"}}");
  EXPECT_NE(noPrinter.find("printer: missing, and the profile"), std::string::npos) << noPrinter;

  // A given rotation beyond a turn (1e300 turned the part by a floating-point remainder and printed 300
  // digits in the summary).
  for (const char* rotation : {"1e300", "720", "-361"}) {
    const std::string placed = "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) +
                               ", \"placement\": {\"x\": 30, \"y\": 20, \"rotation\": " + rotation + "}}";
    const std::string what =
        message("{\"printer\": \"sl1\", \"parts\": [" + placed + "], \"outputs\": {\"masks\": \"p.sl1\"}}");
    EXPECT_NE(what.find("parts[0].placement.rotation: must be a number of degrees from -360 to 360"),
              std::string::npos)
        << what;
  }
  // A position no plate has (1e308 printed "inf mm" in the outside-the-plate message).
  const std::string far = "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) +
                          ", \"placement\": {\"x\": 1e308, \"y\": 20}}";
  const std::string farWhat =
      message("{\"printer\": \"sl1\", \"parts\": [" + far + "], \"outputs\": {\"masks\": \"p.sl1\"}}");
  EXPECT_NE(farWhat.find("parts[0].placement.x: must be a position on the plate in mm"), std::string::npos)
      << farWhat;
}

// A plate job has no --force: its refusal of another program's file names what it has.
TEST_F(PlateTest, ForeignFileRefusalNamesTheOverwriteSetting) {
  tool_test::writeBytes(dir_ / "p.png", "not a picture toposlice wrote");
  tool_test::writeBytes(dir_ / "job.json",
                        "{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 1, "
                        "\"overwrite\": true}, \"parts\": [{\"name\": \"a\", \"model\": " +
                            q(tool_test::examplePart()) +
                            ", \"placement\": \"auto\"}], \"outputs\": {\"masks\": "
                            "\"p.sl1\", \"picture\": \"p.png\"}}");
  const tool_test::RunResult r = run({"plate", (dir_ / "job.json").string(), "-q"});
  EXPECT_NE(r.code(), 0);
  EXPECT_NE(r.err.find("not replaced, even with \"overwrite\": true"), std::string::npos) << r.err;
  EXPECT_EQ(tool_test::readBytes(dir_ / "p.png"), "not a picture toposlice wrote");
}

// Settings that cannot apply to the plate job are errors naming the key, not silently ignored.
TEST_F(PlateTest, SettingsThatCannotApplyAreRefused) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  const std::vector<std::pair<std::string, std::string>> cases{
      {R"("settings": {"layer_height": 0.5, "antialias": true}, "outputs": {"contours": ["a.cli"]})",
       "settings.antialias"},
      {R"("settings": {"layer_height": 0.5, "cli_binary": true}, "outputs": {"contours": ["a.svg"]})",
       "settings.cli_binary"},
      {R"("settings": {"layer_height": 0.5, "allow_rebuild": true}, "outputs": {"masks": "m.sl1"})",
       "settings.allow_rebuild"},
      {R"("print_settings": {"exposure_time": 5}, "settings": {"layer_height": 0.5}, "outputs": {"masks": "pngs"})",
       "print_settings.exposure_time"},
  };
  for (const auto& [rest, key] : cases) {
    try {
      runPlateJob(job("{\"printer\": \"sl1\", \"parts\": [" + part + "], " + rest + "}"), nullptr);
      ADD_FAILURE() << "accepted: " << rest;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(key + ": does nothing in this job"), std::string::npos)
          << e.what();
    }
  }
  // A part's template with the closest-point method, which uses no adjacency table.
  const std::string withTemplate = "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) +
                                   ", \"template\": " + q(dir_ / "t.topo") + ", \"placement\": \"auto\"}";
  try {
    runPlateJob(job("{\"printer\": \"sl1\", \"parts\": [" + withTemplate +
                    "], \"settings\": {\"method\": \"cp\"}, \"outputs\": {\"masks\": \"m.sl1\"}}"),
                nullptr);
    ADD_FAILURE() << "a template with method cp was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("settings.method: cp uses no adjacency table"), std::string::npos)
        << e.what();
  }
}

// outputs.masks as slice --masks takes it: a mask format, or a name without an extension for a folder
// of PNGs. "m.png" made a folder of that name without a word.
TEST_F(PlateTest, MasksOfAnUnknownFormatAreRefused) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  for (const char* name : {"m.png", "m.jpg", "m.zip"}) {
    try {
      runPlateJob(job("{\"printer\": \"sl1\", \"parts\": [" + part +
                      "], \"settings\": {\"layer_height\": 1}, \"outputs\": {\"masks\": \"" + name + "\"}}"),
                  nullptr);
      ADD_FAILURE() << "accepted: " << name;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("outputs.masks: unknown mask format"), std::string::npos)
          << e.what();
    }
    EXPECT_FALSE(fs::exists(dir_ / name)) << name;
  }
}

// No output inside the plate's mask folder (made and replaced as a whole).
TEST_F(PlateTest, AnOutputInsideTheMaskFolderIsRefused) {
  const std::string part =
      "{\"name\": \"a\", \"model\": " + q(tool_test::examplePart()) + ", \"placement\": \"auto\"}";
  try {
    runPlateJob(job("{\"printer\": \"sl1\", \"parts\": [" + part +
                    "], \"settings\": {\"layer_height\": 1}, \"outputs\": {\"masks\": \"m\", \"report\": "
                    "\"m/r.json\"}}"),
                nullptr);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("outputs.report: "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("m/r.json lies inside"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "m"));
}

TEST_F(PlateTest, ExistingOutputsAreRefusedBeforeTheSlicing) {
  tool_test::writeBytes(dir_ / "r.json", "{\"kept\": 1}\n");
  const std::string missing =
      "{\"name\": \"m\", \"model\": " + q((dir_ / "nowhere.stl").string()) + ", \"placement\": \"auto\"}";
  try {
    runPlateJob(job("{\"printer\": \"generic-8k\", \"settings\": {\"layer_height\": 0.5}, \"parts\": [" +
                    missing + "], \"outputs\": {\"report\": \"r.json\"}}"),
                nullptr);
    FAIL() << "accepted";
  } catch (const OutputError& e) {
    EXPECT_NE(std::string(e.what()).find("r.json: already exists"), std::string::npos) << e.what();
  }
  EXPECT_EQ(readBytes(dir_ / "r.json"), "{\"kept\": 1}\n");

  // Two 16.5 x 12 mm parts on a 30 x 20 mm display with a 1 mm margin: two plates, the second's archive
  // exists.
  tool_test::writeBytes(dir_ / "m-plate2.sl1", "not an archive\n");
  const std::string part = q(tool_test::examplePart());
  try {
    runPlateJob(job("{\"settings\": {\"layer_height\": 0.5, \"pixel\": 0.05, \"resolution\": [600, 400]}, "
                    "\"arrange\": {\"margin\": 1, \"spacing\": 1},"
                    "\"parts\": [{\"name\": \"a\", \"model\": " +
                    part + ", \"placement\": \"auto\"}, {\"name\": \"b\", \"model\": " + part +
                    ", \"placement\": \"auto\"}], \"outputs\": {\"masks\": \"m.sl1\"}}"),
                nullptr);
    FAIL() << "accepted";
  } catch (const OutputError& e) {
    EXPECT_NE(std::string(e.what()).find("m-plate2.sl1: already exists"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir_ / "m.sl1"));
  EXPECT_EQ(readBytes(dir_ / "m-plate2.sl1"), "not an archive\n");
}

// A later plate's output name (-plate2, ...) that is one of the job's inputs: refused like plate 1's.
// A part's model there (a toposlice 3MF, so marked as toposlice's own) was replaced by plate 2's contours
// with overwrite on, and a light map inside plate 2's mask folder deleted.
TEST_F(PlateTest, ALaterPlatesOutputNeverReplacesAnInput) {
  ASSERT_EQ(run({"slice", tool_test::examplePart(), "-H", "0.5", "-o", "c-plate2.3mf", "-q"}).code(), 0);
  const std::string model = readBytes(dir_ / "c-plate2.3mf");
  const std::string part = q((dir_ / "c-plate2.3mf").string());
  try {
    runPlateJob(job("{\"settings\": {\"layer_height\": 0.5, \"pixel\": 0.05, \"resolution\": [600, 400], "
                    "\"overwrite\": true}, \"arrange\": {\"margin\": 1, \"spacing\": 1},"
                    "\"parts\": [{\"name\": \"a\", \"model\": " +
                    part + ", \"placement\": \"auto\"}, {\"name\": \"b\", \"model\": " + part +
                    ", \"placement\": \"auto\"}], \"outputs\": {\"contours\": [\"c.3mf\"]}}"),
                nullptr);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("c-plate2.3mf: is the job's input"), std::string::npos) << e.what();
  }
  EXPECT_EQ(readBytes(dir_ / "c-plate2.3mf"), model);
  EXPECT_FALSE(fs::exists(dir_ / "c.3mf"));
}

}  // namespace
}  // namespace toposlice

namespace toposlice {
namespace {

// The bundled plate example is what the generator makes, and the demo job runs through the program:
// every part checked against the template, none built, one plate, the picture and report written.
TEST_F(PlateTest, BundledExampleIsFreshAndTheDemoJobRuns) {
  const fs::path examples = fs::path(TOPOSLICE_SOURCE_DIR) / "examples";
  const fs::path generator =
      toposliceBinary().parent_path().parent_path() / "tests" / "generate_plate_example";
  ASSERT_TRUE(fs::exists(generator)) << generator;
  fs::create_directory(dir_ / "fresh");
  ASSERT_EQ(std::system((generator.string() + " " + (dir_ / "fresh").string()).c_str()), 0);
  for (const auto& e : fs::directory_iterator(dir_ / "fresh"))
    EXPECT_EQ(readBytes(e.path()), readBytes(examples / "plate" / e.path().filename()))
        << e.path().filename() << " differs from a fresh one: run generate_plate_example examples/plate";
  // As the README runs it: -O names a folder that does not exist yet.
  const fs::path out = dir_ / "out";
  const tool_test::RunResult r = run({"plate", (examples / "plate_demo.json").string(), "-O", out.string()});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_NE(r.out.find("1 plate, 3 parts (3 checked against a template, 0 built)"), std::string::npos)
      << r.out;
  for (const char* f :
       {"plate_demo.sl1", "plate_demo.cli", "plate_demo.svg", "plate_demo.png", "plate_demo_report.json"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  const std::string report = readBytes(out / "plate_demo_report.json");
  EXPECT_NE(report.find("\"name\": \"named\""), std::string::npos);
  // Every part starts on the first layer: nothing in the example floats.
  EXPECT_EQ(report.find("\"first_layer\": 1"), std::string::npos) << report;
  const std::string cli = readBytes(out / "plate_demo.cli");
  EXPECT_NE(cli.find("$$LABEL/4,add named_arch_named_label"), std::string::npos);
  // The printer file's previews show the plate, as PrusaSlicer names them.
  const auto entries = tool_test::zipEntryNames(readBytes(out / "plate_demo.sl1"));
  for (const char* thumbnail : {"thumbnail/thumbnail400x400.png", "thumbnail/thumbnail800x480.png"})
    EXPECT_NE(std::find(entries.begin(), entries.end(), thumbnail), entries.end()) << thumbnail;
  // Without -O, the job's own paths (out/... beside the job file) have their folders made when missing,
  // as a batch does (toposlice-mpi plate has no -O: the bundled demo failed there on a fresh checkout).
  fs::create_directory(dir_ / "copy");
  fs::copy(examples / "plate", dir_ / "copy" / "plate", fs::copy_options::recursive);
  fs::copy_file(examples / "plate_demo.json", dir_ / "copy" / "plate_demo.json");
  const tool_test::RunResult own = run({"plate", (dir_ / "copy" / "plate_demo.json").string(), "-q"});
  ASSERT_EQ(own.code(), 0) << own.describe();
  EXPECT_TRUE(fs::exists(dir_ / "copy" / "out" / "plate_demo.sl1"));
}

}  // namespace
}  // namespace toposlice
