// A user's files are sacred (docs/RELIABILITY.md, "What toposlice promises about your files"): the
// cases of the output-safety issue, each run through the real program as a user runs it.
//   1. an interrupted `template` leaves no table and says so truthfully;
//   2. a job's outputs are one unit: one failing output leaves none of them (slice and batch);
//   3. --force replaces only what toposlice writes;
//   4. no output ever replaces an input, through links too;
//   5. jobs that make nothing say so;
//   6. numbers and options that cannot apply are refused;
//   7. messages name what is wrong and where.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tests/tool_runner.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using namespace tool_test;

using OutputSafety = CliToolBase;
using EmptyResults = CliToolBase;
using OptionChecks = CliToolBase;
using Messages = CliToolBase;
using Summary = CliToolBase;

// A binary STL of an axis-aligned box [0, s]^2 x [z0, z0 + s]; `insideOut` reverses every facet.
std::string boxStl(double s, double z0, bool insideOut) {
  const float p[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                         {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  const int faces[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                            {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
  std::string stl(80, ' ');
  const uint32_t count = 12;
  stl.append(reinterpret_cast<const char*>(&count), 4);
  for (const auto& f : faces) {
    const float normal[3] = {0, 0, 0};
    stl.append(reinterpret_cast<const char*>(normal), 12);
    for (int c = 0; c < 3; ++c) {
      const int v = f[insideOut ? 2 - c : c];
      const float xyz[3] = {static_cast<float>(p[v][0] * s), static_cast<float>(p[v][1] * s),
                            static_cast<float>(z0 + p[v][2] * s)};
      stl.append(reinterpret_cast<const char*>(xyz), 12);
    }
    stl.append(2, '\0');
  }
  return stl;
}

// A uniform light-uniformity map for the SL1's display (1440 x 2560, portrait), as a PNG file's bytes.
std::string sl1LightMapPng(uint8_t value) {
  MaskImage light;
  light.width = 1440;
  light.height = 2560;
  light.pixels.assign(std::size_t{1440} * 2560, value);
  std::vector<uint8_t> png;
  encodeMaskPng(light, png);
  return std::string(png.begin(), png.end());
}

std::vector<std::string> entries(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// ---------------------------------------------------------------------------------------------------
// 1. An interrupted template run leaves no table, or finishes and keeps it, and says which.

TEST_F(OutputSafety, InterruptedTemplateLeavesNoTableOrACompleteOne) {
  const fs::path model = sharedModel("derived/aligner_upper_case0.stl.gz");
  if (!fs::exists(model)) GTEST_SKIP() << model << " not found";
  int stopped = 0;
  for (const auto delay : {10ms, 30ms, 60ms, 100ms, 150ms}) {
    fs::remove(path("t.topo"));
    const pid_t pid = start({"template", model.string(), "-o", "t.topo"});
    std::this_thread::sleep_for(delay);
    ::kill(pid, SIGTERM);
    const RunResult r = finish(pid);
    if (r.signalled(SIGTERM)) {
      ++stopped;
      EXPECT_FALSE(fs::exists(path("t.topo")))
          << "killed after " << delay.count() << " ms, yet a table is there\n"
          << r.describe();
      if (!r.err.empty()) {
        EXPECT_TRUE(contains(r.err, "no output was left behind")) << r.describe();
      }
    } else {
      // The signal came after the table was complete: the run says so and ends normally.
      ASSERT_EQ(r.code(), 0) << r.describe();
      const std::string table = readBytes(path("t.topo"));
      EXPECT_TRUE(table.starts_with(std::string("TOPOSLC", 7))) << "not a complete table";
    }
    expectNoTemporaries();
  }
  EXPECT_GT(stopped, 0) << "no run was stopped before its end: the delays are too long for this machine";
}

// An interrupted batch keeps the variants it completed (each with all of its outputs, whole) and the
// table if it was saved, leaves no temporary and no folder it made without a file in it, and a re-run
// finishes the job.
TEST_F(OutputSafety, InterruptedBatchKeepsCompletedVariantsOnlyAndNoEmptyFolder) {
  const fs::path model = sharedModel("derived/aligner_upper_case0.stl.gz");
  const fs::path stage2 = sharedModel("derived/aligner_upper_case0_stage2.stl.gz");
  if (!fs::exists(model) || !fs::exists(stage2)) GTEST_SKIP() << model << " not found";
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": " + jsonString(model.string()) +
                 ", \"table\": \"out/t/aligner.topo\"}, \"settings\": {\"layer_height\": 0.02, "
                 "\"printer\": \"sl1\"}, \"variants\": [{\"name\": \"a\", \"model\": " +
                 jsonString(model.string()) +
                 ", \"contours\": \"out/a/a.cli\", \"masks\": \"out/a/a.sl1\"}, {\"name\": \"b\", "
                 "\"model\": " +
                 jsonString(stage2.string()) +
                 ", \"contours\": \"out/b/b.cli\", \"masks\": \"out/b/b.sl1\"}]}");
  int stopped = 0;
  for (const auto delay : {10ms, 60ms, 150ms, 300ms, 600ms, 1000ms}) {
    fs::remove_all(path("out"));
    const pid_t pid = start({"batch", "job.json", "-q"});
    std::this_thread::sleep_for(delay);
    ::kill(pid, SIGTERM);
    const RunResult r = finish(pid);
    if (!r.signalled(SIGTERM)) {
      ASSERT_EQ(r.code(), 0) << r.describe();  // done before the signal
      continue;
    }
    ++stopped;
    if (!r.err.empty()) {  // empty: stopped before the program set its handlers
      EXPECT_TRUE(contains(r.err, "interrupted")) << r.describe();
    }
    // Every folder left holds a file; every file left is whole.
    for (auto it = fs::recursive_directory_iterator(dir_); it != fs::recursive_directory_iterator(); ++it) {
      const fs::path p = it->path();
      EXPECT_EQ(p.filename().string().find(".tmp-"), std::string::npos)
          << "a temporary left after " << delay.count() << " ms: " << p;
      if (it->is_directory()) {
        EXPECT_FALSE(fs::is_empty(p)) << "an empty folder left after " << delay.count() << " ms: " << p;
      } else if (p.extension() == ".topo") {
        EXPECT_TRUE(readBytes(p).starts_with(std::string("TOPOSLC", 7))) << p;
      } else if (p.extension() == ".sl1") {
        EXPECT_FALSE(zipEntryNames(readBytes(p)).empty()) << "not a whole archive: " << p;
      }
    }
    // A variant's outputs are there together or not at all.
    for (const char* v : {"a", "b"}) {
      const fs::path folder = path("out") / v;
      EXPECT_EQ(fs::exists(folder / (std::string(v) + ".cli")),
                fs::exists(folder / (std::string(v) + ".sl1")))
          << "variant " << v << " after " << delay.count() << " ms";
    }
  }
  EXPECT_GT(stopped, 0) << "no run was stopped before its end: the delays are too long for this machine";
  const RunResult again = run({"batch", "job.json", "-q"});
  ASSERT_EQ(again.code(), 0) << again.describe();
  for (const char* file : {"out/a/a.cli", "out/a/a.sl1", "out/b/b.cli", "out/b/b.sl1", "out/t/aligner.topo"})
    EXPECT_TRUE(fs::exists(path(file))) << file;
}

// ---------------------------------------------------------------------------------------------------
// 2. Several outputs are one unit.

TEST_F(OutputSafety, OneFailingOutputLeavesNoneOfTheJobsOutputs) {
  // Every file may grow to 600 kB: the CLI (~500 kB), 3MF (~350 kB) and report fit, the SL1 (~900 kB)
  // does not, so its write fails as on a full disk, after the others were complete.
  setFileSizeLimit(600 * 1024);
  const RunResult r = run({"slice", examplePart().string(), "-o", "r.cli", "-o", "r.3mf", "--report", "r.csv",
                           "--masks", "x.sl1", "--printer", "sl1", "--summary", "s.json"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "x.sl1")) << r.err;
  EXPECT_TRUE(contains(r.err, "File too large")) << r.err;
  EXPECT_TRUE(entries(dir_).empty()) << testing::PrintToString(entries(dir_));
}

TEST_F(OutputSafety, ReplacedOutputsComeBackWhenTheJobFails) {
  ASSERT_EQ(run({"slice", examplePart().string(), "-H", "0.5", "-o", "r.cli", "--report", "r.csv"}).code(),
            0);
  const std::string cli = readBytes(path("r.cli")), csv = readBytes(path("r.csv"));
  setFileSizeLimit(600 * 1024);
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.05", "-o", "r.cli", "--report", "r.csv",
                           "--masks", "x.sl1", "--printer", "sl1", "--force"});
  expectOneErrorLine(r);
  EXPECT_EQ(readBytes(path("r.cli")), cli);  // the earlier outputs, untouched
  EXPECT_EQ(readBytes(path("r.csv")), csv);
  EXPECT_EQ(entries(dir_), (std::vector<std::string>{"r.cli", "r.csv"}));
}

TEST_F(OutputSafety, FailingBatchVariantLeavesNoneOfItsOutputs) {
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": " + jsonString(examplePart().string()) +
                 "}, \"settings\": {\"layer_height\": 0.05, \"printer\": \"sl1\"}, \"variants\": [{\"name\": "
                 "\"a\", \"model\": " +
                 jsonString(examplePart().string()) +
                 ", \"contours\": \"a.cli\", \"masks\": \"a.sl1\", \"report\": \"a.csv\"}]}");
  setFileSizeLimit(600 * 1024);
  const RunResult r = run({"batch", "job.json", "-q"});
  // One error line naming the variant and what failed (the summary table is not printed with -q).
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "variant 'a'") && contains(r.err, "cannot write")) << r.describe();
  EXPECT_EQ(entries(dir_), std::vector<std::string>{"job.json"});
  // Without -q the table says "failed" on stdout, and the error line is on stderr all the same.
  const RunResult loud = run({"batch", "job.json"});
  EXPECT_EQ(loud.code(), 1) << loud.describe();
  EXPECT_TRUE(contains(loud.out, "failed")) << loud.describe();
  EXPECT_TRUE(contains(loud.err, "toposlice: error: variant 'a'")) << loud.describe();
}

// Warnings of a variant's slice job (an inside-out mesh, layers outside the model) reach the user as
// they do from slice, even with -q.
TEST_F(OutputSafety, BatchShowsEachVariantsWarningsEvenWhenQuiet) {
  writeBytes(path("inv.stl"), boxStl(5, 0, true));
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": \"inv.stl\"}, \"settings\": {\"layer_height\": 0.5, \"z0\": -3},"
             " \"variants\": [{\"name\": \"a\", \"model\": \"inv.stl\", \"contours\": \"o.cli\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  EXPECT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.err, "toposlice: warning: variant 'a'")) << r.describe();
  EXPECT_TRUE(contains(r.err, "inside out")) << r.describe();
  EXPECT_TRUE(contains(r.err, "outside the model's height")) << r.describe();
}

// A batch makes the folders its variants write into; those that end without a file (every variant there
// failed) are taken away again, as a failed job leaves none of its outputs. Folders with results stay.
TEST_F(OutputSafety, BatchRemovesTheEmptyFoldersItMade) {
  writeBytes(path("box.stl"), boxStl(5, 0, false));
  writeBytes(path("bad.stl"), "solid nothing\nendsolid nothing\n");
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": \"box.stl\"}, \"settings\": {\"layer_height\": 1},"
             " \"variants\": [{\"name\": \"ok\", \"model\": \"box.stl\", \"contours\": \"good/a.cli\"},"
             " {\"name\": \"bad\", \"model\": \"bad.stl\", \"contours\": \"made/deep/b.cli\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  EXPECT_EQ(r.code(), 1) << r.describe();
  EXPECT_TRUE(fs::exists(path("good/a.cli")));
  EXPECT_FALSE(fs::exists(path("made"))) << "the failed variant's folders stayed";
}

// Masks with no image size anywhere in the job: refused when the job is read, naming its keys (it was
// found per variant, after the earlier variants were sliced, naming slice's --printer).
TEST_F(OutputSafety, BatchMasksWithoutAnImageAreRefusedFirst) {
  writeBytes(path("box.stl"), boxStl(5, 0, false));
  writeBytes(
      path("job.json"),
      "{\"template\": {\"model\": \"box.stl\", \"table\": \"t.topo\"}, \"settings\": {\"layer_height\": 1},"
      " \"variants\": [{\"name\": \"a\", \"model\": \"box.stl\", \"contours\": \"a.cli\"},"
      " {\"name\": \"b\", \"model\": \"box.stl\", \"masks\": \"b.sl1\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "job.json: masks need an image size: give settings.printer")) << r.err;
  EXPECT_EQ(entries(dir_), (std::vector<std::string>{"box.stl", "job.json"}));
}

// ---------------------------------------------------------------------------------------------------
// 3. --force replaces only toposlice's own outputs.

TEST_F(OutputSafety, ForceRefusesAFolderWithForeignFiles) {
  fs::create_directory(path("masks"));
  writeBytes(path("masks/notes.txt"), "my notes");
  fs::create_directory(path("masks/sub"));
  const RunResult r =
      run({"slice", examplePart().string(), "--masks", "masks", "--printer", "sl1", "--force"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "notes.txt") || contains(r.err, "'sub'")) << r.err;
  EXPECT_EQ(readBytes(path("masks/notes.txt")), "my notes");
  EXPECT_TRUE(fs::is_directory(path("masks/sub")));
  expectNoTemporaries();
}

// An output inside the job's own mask folder (made and replaced as a whole): refused up front, naming
// it. It was refused at the end, blaming the report's own temporary as a file toposlice did not write.
TEST_F(OutputSafety, AnOutputInsideTheMaskFolderIsRefused) {
  for (const char* masks : {"dd", "dd.exr"}) {
    const std::string report = std::string(masks) + "/r.csv";
    const RunResult r = run({"slice", examplePart().string(), "-H", "1", "--masks", masks, "--pixel", "0.2",
                             "--resolution", "300x300", "--report", report, "-q"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, report + ": lies inside the mask folder " + masks)) << r.err;
  }
  EXPECT_TRUE(entries(dir_).empty());
}

TEST_F(OutputSafety, ForceReplacesAFolderToposliceWrote) {
  ASSERT_EQ(
      run({"slice", examplePart().string(), "-H", "0.5", "--masks", "masks", "--printer", "sl1"}).code(), 0);
  const auto first = entries(path("masks"));
  ASSERT_EQ(first.size(), 13u);  // ceil(6.2 / 0.5)
  const RunResult r =
      run({"slice", examplePart().string(), "-H", "1", "--masks", "masks", "--printer", "sl1", "--force"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_EQ(entries(path("masks")).size(), 7u);  // ceil(6.2 / 1)
  expectNoTemporaries();
}

TEST_F(OutputSafety, ForceRefusesAFileOfAnotherFormat) {
  writeBytes(path("r.csv"), "name,phone\nAnn,123\n");
  writeBytes(path("p.cli"), "my own notes, not a CLI file\n");
  for (const auto& args : std::vector<std::vector<std::string>>{{"--report", "r.csv"}, {"-o", "p.cli"}}) {
    std::vector<std::string> all{"slice", examplePart().string(), "-H", "0.5", "--force"};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult r = run(all);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, args[1])) << r.err;
  }
  EXPECT_EQ(readBytes(path("r.csv")), "name,phone\nAnn,123\n");
  EXPECT_EQ(readBytes(path("p.cli")), "my own notes, not a CLI file\n");
}

// A JSON or CSV file is replaced only when it is a summary, plate report or per-layer report (their own
// first bytes), not any JSON object or any text starting "layer,"; a file of an extension toposlice
// never writes is never replaced, and the commands whose output has one kind refuse other names.
TEST_F(OutputSafety, ForceRefusesForeignJsonCsvAndOtherExtensions) {
  writeBytes(path("notes.json"), "{\"my\": \"settings\"}\n");
  writeBytes(path("layers.csv"), "layer,owner\n1,me\n");
  writeBytes(path("x.dat"), "precious\n");
  writeBytes(path("x.jpg"), "JPEGDATA\n");
  // Another program's archives start as ours do; they lack the comment toposlice puts in every zip.
  const std::string prusa = std::string("PK\x03\x04", 4) + "a PrusaSlicer archive";
  writeBytes(path("prusa.sl1"), prusa);
  writeBytes(path("cad.3mf"), prusa);
  const std::string part = examplePart().string();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
      {{"slice", part, "-H", "0.5", "--summary", "notes.json", "--force"}, "notes.json: exists and is not"},
      {{"slice", part, "-H", "0.5", "--report", "layers.csv", "--force"}, "layers.csv: exists and is not"},
      {{"template", part, "-o", "x.dat", "--force"}, "x.dat: the table is a .topo file"},
      {{"preview", part, "-o", "x.jpg", "--force"}, "x.jpg: the picture is a PNG"},
      {{"slice", part, "-H", "0.5", "--printer", "sl1", "--masks", "prusa.sl1", "--force"},
       "prusa.sl1: exists and is not"},
      {{"slice", part, "-H", "0.5", "-o", "cad.3mf", "--force"}, "cad.3mf: exists and is not"},
  };
  for (const auto& [args, message] : cases) {
    const RunResult r = run(args);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, message)) << r.err;
  }
  EXPECT_EQ(readBytes(path("notes.json")), "{\"my\": \"settings\"}\n");
  EXPECT_EQ(readBytes(path("layers.csv")), "layer,owner\n1,me\n");
  EXPECT_EQ(readBytes(path("x.dat")), "precious\n");
  EXPECT_EQ(readBytes(path("x.jpg")), "JPEGDATA\n");
  EXPECT_EQ(readBytes(path("prusa.sl1")), prusa);
  EXPECT_EQ(readBytes(path("cad.3mf")), prusa);
  expectNoTemporaries();

  // What toposlice wrote is replaced: a summary, a report and archives of an earlier run.
  const std::vector<std::string> outputs{"--summary", "s.json",  "--report", "r.csv", "--printer",
                                         "sl1",       "--masks", "m.sl1",    "-o",    "c.3mf"};
  std::vector<std::string> first{"slice", part, "-H", "0.5"}, second{"slice", part, "-H", "1", "--force"};
  first.insert(first.end(), outputs.begin(), outputs.end());
  second.insert(second.end(), outputs.begin(), outputs.end());
  ASSERT_EQ(run(first).code(), 0);
  const RunResult again = run(second);
  ASSERT_EQ(again.code(), 0) << again.describe();
  EXPECT_TRUE(contains(readBytes(path("r.csv")), "\n6,")) << "7 layers at 1 mm";
  expectNoTemporaries();
}

// Files of the formats toposlice writes, written by other programs, start as toposlice's do; --force
// tells them apart by toposlice's mark (a CLI and SVG comment, a PNG tEXt chunk, an EXR attribute, the
// GOO software field, the VDB "creator"), and replaces only its own, layer folders file by file.
TEST_F(OutputSafety, ForceRefusesOtherProgramsFilesOfTheFormatsToposliceWrites) {
  using namespace std::string_literals;
  const std::string png = "\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR\0\0\0\x10\0\0\0\x10\x08\x02\0\0\0"s +
                          "\0\0\0\0\0\0\0\x0dtEXtSoftware\0GIMP"s;
  const std::map<std::string, std::string> foreign{
      {"photo.png", png},
      {"other.cli", "$$HEADERSTART\n$$ASCII\n$$UNITS/1\n$$HEADEREND\n$$GEOMETRYSTART\n"},
      {"drawing.svg",
       "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"/>\n"},
      {"chitu.goo", "V3.0\x07\0\0\0DLP\0CHITUBOX\0"s + std::string(40, '\0')},
      {"cloud.vdb", " BDV\0\0\0\0\xe0\0\0\0\x0a\0\0\0\x01houdini"s},
      {"shots/img0001.png", png},
      {"renders.exr/frame0001.exr", "v/1\x01\2\0\0\0channels\0chlist\0"s},
  };
  fs::create_directory(path("shots"));
  fs::create_directory(path("renders.exr"));
  for (const auto& [name, bytes] : foreign) writeBytes(path(name), bytes);
  const std::string part = examplePart().string();
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
      {{"preview", part, "-o", "photo.png"}, "photo.png"},
      {{"slice", part, "-H", "0.5", "-o", "other.cli"}, "other.cli"},
      {{"slice", part, "-H", "0.5", "-o", "drawing.svg"}, "drawing.svg"},
      {{"slice", part, "-H", "0.5", "--masks", "chitu.goo", "--printer", "sl1"}, "chitu.goo"},
      {{"slice", part, "-H", "0.5", "--masks", "cloud.vdb", "--printer", "sl1"}, "cloud.vdb"},
      {{"slice", part, "-H", "0.5", "--masks", "shots", "--printer", "sl1"}, "img0001.png"},
      {{"slice", part, "-H", "0.5", "--masks", "renders.exr", "--printer", "sl1"}, "frame0001.exr"},
  };
  for (auto [args, named] : cases) {
    args.push_back("--force");
    const RunResult r = run(args);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, named)) << r.err;
    EXPECT_TRUE(contains(r.err, "not replaced")) << r.err;
  }
  for (const auto& [name, bytes] : foreign) EXPECT_EQ(readBytes(path(name)), bytes) << name;
  expectNoTemporaries();

  // toposlice's own files of each format are replaced.
  for (const auto& [name, bytes] : foreign) fs::remove(path(name));
  fs::remove(path("shots"));
  fs::remove(path("renders.exr"));
  for (auto [args, named] : cases) {
    ASSERT_EQ(run(args).code(), 0) << named;
    args.push_back("--force");
    if (args[0] == "slice") args[3] = "1";  // 7 layers instead of 13
    const RunResult again = run(args);
    EXPECT_EQ(again.code(), 0) << again.describe();
  }
  EXPECT_EQ(entries(path("shots")).size(), 7u);
  EXPECT_EQ(entries(path("renders.exr")).size(), 7u);
  expectNoTemporaries();
}

// Out of memory said "toposlice: error: std::bad_alloc", naming nothing: now the input, what ran out and
// what makes a job smaller, in one line, and nothing is left behind.
TEST_F(OutputSafety, OutOfMemoryNamesTheInputAndLeavesNothing) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "the sanitizers' shadow memory needs more address space than the limit";
#endif
  setMemoryLimit(rlim_t{1536} << 20);
  const RunResult r = run({"slice", examplePart().string(), "-H", "2", "--masks", "m.sl1", "--pixel", "0.001",
                           "--resolution", "100000x100000", "-o", "m.cli", "-q"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, examplePart().string() + ": out of memory")) << r.err;
  EXPECT_FALSE(fs::exists(path("m.sl1")) || fs::exists(path("m.cli")));
  expectNoTemporaries();
  // A batch variant and a plate part said "std::bad_alloc".
  writeBytes(path("job.json"), "{\"template\": {\"model\": " + jsonString(examplePart().string()) +
                                   "}, \"settings\": {\"layer_height\": 2, \"pixel\": 0.001, \"resolution\": "
                                   "[100000, 100000]}, \"variants\": [{\"name\": \"v\", \"model\": " +
                                   jsonString(examplePart().string()) + ", \"masks\": \"v.sl1\"}]}");
  const RunResult batch = run({"batch", "job.json", "-q"});
  EXPECT_EQ(batch.code(), 1) << batch.describe();
  EXPECT_TRUE(contains(batch.err, "variant 'v'") && contains(batch.err, "out of memory")) << batch.err;
  EXPECT_FALSE(contains(batch.err, "bad_alloc")) << batch.err;
  EXPECT_FALSE(fs::exists(path("v.sl1")));
}

// A file-size limit (ulimit -f) does not kill the job with its temporaries in place: the write fails, the
// job says so in one line and leaves nothing.
TEST_F(OutputSafety, FileSizeLimitFailsTheJobCleanly) {
  setFileSizeLimit(4096, /*ignoreSignal=*/false);
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.05", "-o", "a.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "a.cli: cannot write")) << r.err;
  EXPECT_FALSE(fs::exists(path("a.cli")));
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 4. An output is never an input.

TEST_F(OutputSafety, OutputThatIsAnInputIsRefusedEvenWithForce) {
  const std::string model = readBytes(examplePart());
  writeBytes(path("copy.stl"), model);
  fs::create_symlink("copy.stl", path("link.csv"));
  fs::create_hard_link(path("copy.stl"), path("hard.cli"));
  const std::vector<std::vector<std::string>> cases{
      {"slice", "copy.stl", "--masks", "copy.stl", "--force"},
      {"slice", "copy.stl", "--report", "copy.stl", "--force"},
      {"slice", "copy.stl", "--report", "link.csv", "--force"},
      {"slice", "copy.stl", "-o", "hard.cli", "--force"},
      {"slice", examplePart().string(), "--add", "copy.stl", "-o", "hard.cli", "--force"},
      {"template", "copy.stl", "-o", "copy.stl", "--force"},
      {"template", "copy.stl", "-o", "link.csv", "--force"},
  };
  for (const auto& args : cases) {
    const RunResult r = run(args);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "input")) << r.err;
    EXPECT_EQ(readBytes(path("copy.stl")), model) << testing::PrintToString(args);
  }
  EXPECT_TRUE(fs::is_symlink(path("link.csv")));
  expectNoTemporaries();
}

// The profile and the light map are inputs too; a folder output (a PNG stack) replaces the whole folder,
// so an input inside it is refused as well; and one file spelt twice through a linked folder is one
// output given twice, for slice and for batch jobs.
TEST_F(OutputSafety, ProfilesLightMapsInFoldersAndLinkedSpellingsAreCaught) {
  writeBytes(path("prof.json"),
             "{\"printers\": {\"lab\": {\"inherits\": \"sl1\"}}, \"materials\": {\"resin\": "
             "{\"exposure_time\": 6.5}}}");
  const std::string profile = readBytes(path("prof.json"));
  const std::string part = examplePart().string();
  RunResult r = run({"slice", part, "-H", "0.5", "--profile", "prof.json", "--printer", "lab", "--material",
                     "resin", "--masks", "a.sl1", "--summary", "prof.json", "--force"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "input")) << r.err;
  EXPECT_EQ(readBytes(path("prof.json")), profile);

  // The light map, inside the folder that a PNG stack would replace (its name even looks like a layer's).
  fs::create_directory(path("lm"));
  writeBytes(path("lm/uniformity1.png"), sl1LightMapPng(200));
  r = run({"slice", part, "-H", "0.5", "--printer", "sl1", "--antialias", "--light-map", "lm/uniformity1.png",
           "--masks", "lm", "--force"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "holds the job's input")) << r.err;
  EXPECT_TRUE(fs::exists(path("lm/uniformity1.png")));

  fs::create_directory_symlink(".", path("same"));
  r = run({"slice", part, "-H", "0.5", "-o", "f.cli", "-o", "same/f.cli", "--force"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "given as more than one output")) << r.err;
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": " + nlohmann::json(part).dump() +
                 "}, \"settings\": {\"layer_height\": 0.5, \"overwrite\": true}, \"variants\": ["
                 "{\"name\": \"a\", \"model\": " +
                 nlohmann::json(part).dump() +
                 ", \"contours\": \"o.cli\"},"
                 "{\"name\": \"b\", \"model\": " +
                 nlohmann::json(part).dump() + ", \"contours\": \"same/o.cli\"}]}");
  r = run({"batch", "job.json", "-q"});
  EXPECT_NE(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.err, "already written by")) << r.describe();
  EXPECT_FALSE(fs::exists(path("o.cli")));
  expectNoTemporaries();
}

TEST_F(OutputSafety, BatchOutputThatIsAnInputIsRefused) {
  const std::string model = readBytes(examplePart());
  writeBytes(path("v.stl"), model);
  fs::create_symlink("v.stl", path("v.cli"));
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": \"v.stl\"}, \"settings\": {\"overwrite\": true, \"layer_height\": "
             "0.5}, \"variants\": "
             "[{\"name\": \"a\", \"model\": \"v.stl\", \"contours\": \"v.cli\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  EXPECT_EQ(r.code(), 1) << r.describe();
  EXPECT_TRUE(contains(r.err, "input")) << r.describe();
  EXPECT_EQ(readBytes(path("v.stl")), model);
}

// ---------------------------------------------------------------------------------------------------
// 5. Jobs that make nothing.

TEST_F(EmptyResults, NoLayersOrNoPlaneInTheModelIsAnError) {
  for (const auto& args : std::vector<std::vector<std::string>>{
           {"-H", "1e-19"}, {"--z0", "1000"}, {"--z", "100,200"}, {"--z", "-5,-4"}}) {
    std::vector<std::string> all{"slice", examplePart().string(), "-o", "a.cli"};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult r = run(all);
    expectOneErrorLine(r);
    EXPECT_FALSE(fs::exists(path("a.cli"))) << testing::PrintToString(args);
    // The model's height as the file holds it (a float), not that float's double (6.199999809265137).
    if (args[0] == "--z") {
      EXPECT_TRUE(contains(r.err, "the model spans z 0 .. 6.2 mm")) << r.err;
    }
  }
  expectNoTemporaries();
}

// One layer is a job: --layers 1 has the model's height as its layer height (layer 0 is cut at
// z0 + h / 2), its masks are lit (they were refused as "dark": the volume, area x a thickness of 0, was
// the test) and the summary says so. One explicit plane has no thickness, which printer files need:
// refused with masks, naming --z; its contours are fine.
TEST_F(EmptyResults, OneLayerJobs) {
  RunResult r = run({"slice", examplePart().string(), "--layers", "1", "--printer", "sl1", "--masks",
                     "one.sl1", "--summary", "one.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const nlohmann::json summary = nlohmann::json::parse(readBytes(path("one.json")));
  EXPECT_NEAR(summary["layers"]["layer_height_mm"].get<double>(), 6.2, 1e-6) << summary.dump();
  EXPECT_GT(summary["volume_ml"].get<double>(), 0.5) << summary.dump();

  r = run({"slice", examplePart().string(), "--z", "1", "--printer", "sl1", "--masks", "z.sl1"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "--z 1: one explicit plane")) << r.err;
  EXPECT_FALSE(fs::exists(path("z.sl1")));
  r = run({"slice", examplePart().string(), "--z", "1", "-o", "z.cli", "-q"});
  EXPECT_EQ(r.code(), 0) << r.describe();
  expectNoTemporaries();
}

// An inside-out feature counts with the opposite sign (an add-on cut the model away, silently): a
// warning names it even with -q, and --fix-orientation flips it, as it flips the model.
TEST_F(EmptyResults, InsideOutFeatureIsAWarningAndFlippedOnRequest) {
  writeBytes(path("model.stl"), boxStl(10, 0, false));
  writeBytes(path("inv.stl"), boxStl(4, 2, true));  // inside the model: as an add-on it changes nothing
  const auto volume = [&](const std::string& tag, const std::string& extra) {
    std::vector<std::string> args{"slice",     "model.stl",   "-H",         "1",     "--printer",
                                  "sl1",       "--masks",     tag + ".sl1", "--add", "inv.stl",
                                  "--summary", tag + ".json", "-q"};
    if (!extra.empty()) args.push_back(extra);
    const RunResult r = run(args);
    EXPECT_EQ(r.code(), 0) << r.describe();
    EXPECT_TRUE(contains(r.err, extra.empty()
                                    ? "toposlice: warning: inv.stl: the add-on feature is inside out"
                                    : "toposlice: warning: inv.stl: the add-on feature was inside out"))
        << r.err;
    return nlohmann::json::parse(readBytes(path(tag + ".json")))["volume_ml"].get<double>();
  };
  const double cut = volume("a", ""), whole = volume("b", "--fix-orientation");
  EXPECT_NEAR(whole, 1.0, 0.02);        // the 10 mm cube, the add-on inside it (lit pixels)
  EXPECT_NEAR(cut, 1.0 - 0.064, 0.02);  // the inside-out 4 mm cube cut away
  EXPECT_GT(whole - cut, 0.05);
}

// An add-on reaching above or below the model (a base, a tall label) is part of the print: the default
// planes cover it (it was cut off at the model's height, silently), and the build height counts it.
TEST_F(EmptyResults, AddOnsBeyondTheModelsHeightAreSlicedWhole) {
  writeBytes(path("model.stl"), boxStl(10, 0, false));  // z 0 .. 10
  writeBytes(path("tall.stl"), boxStl(4, 8, false));    // z 8 .. 12
  writeBytes(path("low.stl"), boxStl(4, -3, false));    // z -3 .. 1
  const auto layers = [&](const std::string& addOn, const std::string& tag) {
    const RunResult r = run({"slice", "model.stl", "-H", "1", "--add", addOn, "-o", tag + ".cli", "--printer",
                             "sl1", "--masks", tag + ".sl1", "--summary", tag + ".json", "-q"});
    EXPECT_EQ(r.code(), 0) << r.describe();
    EXPECT_EQ(r.err, "");  // nothing to warn about: the default planes
    return nlohmann::json::parse(readBytes(path(tag + ".json")));
  };
  const nlohmann::json tall = layers("tall.stl", "t"), low = layers("low.stl", "l");
  EXPECT_EQ(tall["layers"]["count"], 12);
  EXPECT_EQ(low["layers"]["count"], 13);
  EXPECT_EQ(low["layers"]["first_z_mm"], -2.5);
  EXPECT_TRUE(contains(readBytes(path("l.cli")), "$$LAYER/-2.500000"));
  EXPECT_NEAR(tall["volume_ml"].get<double>(), 1.0 + 0.064 * 2 / 4, 0.01);  // 2 of the add-on's 4 mm above
  EXPECT_NEAR(low["volume_ml"].get<double>(), 1.0 + 0.064 * 3 / 4, 0.01);
  EXPECT_NEAR(low["layers"]["layer_height_mm"].get<double>(), 1.0, 1e-12);
  const RunResult high = run({"slice", "model.stl", "-H", "1", "--add", "tall.stl", "--printer", "sl1",
                              "--max-print-height", "11", "--masks", "h.sl1"});
  expectOneErrorLine(high);
  EXPECT_TRUE(contains(high.err,
                       "model.stl: the model with its add-ons is 12 mm tall, more than the printer's "
                       "max_print_height 11 mm"))
      << high.err;
}

TEST_F(EmptyResults, InsideOutMeshWithMasksIsAnErrorAndAWarningWithContours) {
  writeBytes(path("inv.stl"), boxStl(5, 0, true));
  const RunResult masks =
      run({"slice", "inv.stl", "-H", "0.5", "--masks", "m.sl1", "--printer", "sl1", "-q"});
  expectOneErrorLine(masks);
  EXPECT_TRUE(contains(masks.err, "dark")) << masks.err;
  EXPECT_TRUE(contains(masks.err, "--fix-orientation")) << masks.err;
  EXPECT_FALSE(fs::exists(path("m.sl1")));

  const RunResult contours = run({"slice", "inv.stl", "-H", "0.5", "-o", "c.cli", "-q"});
  ASSERT_EQ(contours.code(), 0) << contours.describe();
  EXPECT_TRUE(contours.out.empty()) << contours.out;
  EXPECT_TRUE(contains(contours.err, "warning")) << contours.err;  // not hidden by -q
  EXPECT_TRUE(contains(contours.err, "inside out")) << contours.err;

  const RunResult fixed = run(
      {"slice", "inv.stl", "-H", "0.5", "--masks", "m.sl1", "--printer", "sl1", "-q", "--fix-orientation"});
  EXPECT_EQ(fixed.code(), 0) << fixed.describe();
  EXPECT_TRUE(fixed.err.empty()) << fixed.err;
}

// Plate and batch jobs have no --fix-orientation: an inside-out part printed nothing on a plate, without a
// word. Each inside-out model or feature is a warning naming the part (even with -q), and the jobs'
// "fix_orientation" setting flips it (in a batch the template model too, whose table the variants meet).
TEST_F(EmptyResults, InsideOutPartsOfPlateAndBatchJobsAreWarningsAndFlippedOnRequest) {
  writeBytes(path("box.stl"), boxStl(5, 0, false));
  writeBytes(path("inv.stl"), boxStl(5, 0, true));
  const auto plate = [&](const std::string& settings) {
    writeBytes(path("plate.json"),
               R"({"version": 1, "printer": "sl1", "settings": {"layer_height": 0.5, "overwrite": true)" +
                   settings +
                   R"(}, "parts": [{"name": "right", "model": "box.stl", "placement": "auto"},
                   {"name": "wrong", "model": "inv.stl", "placement": "auto"}],
                   "outputs": {"masks": "p.sl1", "report": "p.json"}})");
    const RunResult r = run({"plate", "plate.json", "-q"});
    EXPECT_EQ(r.code(), 0) << r.describe();
    const auto report = nlohmann::json::parse(readBytes(path("p.json")));
    return std::make_pair(r.err, report["parts"][1]["volume_ml"].get<double>());
  };
  const auto [warned, inverted] = plate("");
  EXPECT_TRUE(contains(warned, "toposlice: warning: part 'wrong': ")) << warned;
  EXPECT_TRUE(contains(warned, "inv.stl: the mesh is inside out")) << warned;
  EXPECT_TRUE(contains(warned, "\"fix_orientation\": true")) << warned;
  EXPECT_FALSE(contains(warned, "part 'right'")) << warned;
  EXPECT_LT(inverted, 0);
  const auto [flipped, volume] = plate(R"(, "fix_orientation": true)");
  EXPECT_TRUE(contains(flipped, "part 'wrong': ")) << flipped;
  EXPECT_TRUE(contains(flipped, "was inside out (negative volume): flipped")) << flipped;
  EXPECT_NEAR(volume, 0.125, 0.005);  // the 5 mm cube

  // A batch: the template and the variant both inside out.
  const auto batch = [&](const std::string& settings) {
    writeBytes(path("batch.json"), R"({"version": 1, "template": {"model": "inv.stl"},
                   "settings": {"layer_height": 0.5, "overwrite": true, "printer": "sl1")" +
                                       settings + R"(},
                   "variants": [{"name": "v", "model": "inv.stl", "masks": "v.sl1", "report": "v.csv"}]})");
    return run({"batch", "batch.json", "-q"});
  };
  const RunResult refused = batch("");
  EXPECT_NE(refused.code(), 0);
  EXPECT_TRUE(contains(refused.err, "inside out")) << refused.err;
  EXPECT_TRUE(contains(refused.err, "\"fix_orientation\": true")) << refused.err;
  EXPECT_FALSE(fs::exists(path("v.sl1")));
  const RunResult fixed = batch(R"(, "fix_orientation": true)");
  EXPECT_EQ(fixed.code(), 0) << fixed.describe();
  EXPECT_TRUE(fs::exists(path("v.sl1")));
  expectNoTemporaries();
}

TEST_F(EmptyResults, PlanesBelowTheModelAreAWarningEvenWhenQuiet) {
  writeBytes(path("box.stl"), boxStl(2, 3, false));  // z 3 .. 5
  const RunResult r = run({"slice", "box.stl", "-H", "0.5", "--z0", "0", "-o", "b.cli", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.err, "warning: ")) << r.err;
  EXPECT_TRUE(contains(r.err, "6 of 10 layers")) << r.err;
  EXPECT_TRUE(fs::exists(path("b.cli")));
}

// A vertex on a plane counts as above it (DESIGN.md): a plane at the model's top cuts its top face's
// outline, one at its bottom cuts nothing. The warning and the refusal count planes as the slicer cuts.
TEST_F(EmptyResults, APlaneAtTheTopCutsTheModelAndOneAtTheBottomDoesNot) {
  writeBytes(path("box.stl"), boxStl(2, 3, false));  // z 3 .. 5
  const RunResult top = run({"slice", "box.stl", "--z", "5", "-o", "t.cli", "-q"});
  ASSERT_EQ(top.code(), 0) << top.describe();
  EXPECT_EQ(top.err, "");
  EXPECT_TRUE(contains(readBytes(path("t.cli")), "$$POLYLINE/")) << readBytes(path("t.cli"));
  const RunResult both = run({"slice", "box.stl", "--z", "3,4,5", "-o", "b.cli", "-q"});
  ASSERT_EQ(both.code(), 0) << both.describe();
  EXPECT_TRUE(contains(both.err, "1 of 3 layers lie outside")) << both.err;
  const RunResult bottom = run({"slice", "box.stl", "--z", "3", "-o", "u.cli", "-q"});
  expectOneErrorLine(bottom);
  EXPECT_TRUE(contains(bottom.err, "no plane cuts the model")) << bottom.err;
}

// Messages print a mesh's coordinates readably: the exponent form where the fixed one is long.
TEST_F(EmptyResults, TinyCoordinatesReadInMessages) {
  writeBytes(path("box.stl"), boxStl(2, -5.077714e-17, false));
  const RunResult r = run({"slice", "box.stl", "--z", "7,8", "-o", "b.cli", "-q"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "the model spans z -5.077714e-17 .. 2 mm")) << r.err;
}

TEST_F(EmptyResults, NoOutputSaysNothingWasWritten) {
  const RunResult r = run({"slice", examplePart().string(), "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.err, "nothing was written")) << r.err;
}

// ---------------------------------------------------------------------------------------------------
// 6. Numbers and options.

TEST_F(OptionChecks, BadNumbersAreRefusedNamingTheOption) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
      {{"--close-gaps", "-1"}, "--close-gaps"},
      {{"--close-gaps", "nan"}, "--close-gaps"},
      {{"--method", "cp", "--join-tolerance", "nan"}, "--join-tolerance"},
      {{"--z", "1,,2"}, "--z"},
      {{"--z", "1,2,"}, "--z"},
      {{"--z", "1,2,1e400"}, "1e400"},
      {{"--layer-height", "inf"}, "layer height"},
      {{"--masks", "m.sl1", "--printer", "sl1", "--pixel", "-0.1"}, "--pixel"},
      // 2^32 + 1 wrapped to 1 (a 1 x 10 image) before.
      {{"--masks", "m.sl1", "--printer", "sl1", "--resolution", "4294967297x10"}, "--resolution"},
      {{"--masks", "m.sl1", "--printer", "sl1", "--resolution", "-5x10"}, "--resolution"},
      // An empty value is a mistake, not the option left out (these ran with the defaults before).
      {{"--z", ""}, "--z"},
      {{"--masks", ""}, "--masks"},
      {{"--summary", ""}, "--summary"},
      // Written as --masks= with nothing after the '=', CLI11 took the next argument for the value (the
      // masks went into a folder named -q).
      {{"--masks=", "-q"}, "--masks: an empty value"},
      {{"--summary=", "--force"}, "--summary: an empty value"},
      // sr-lazy slices its layers in order on one thread: no bands, no band starts.
      {{"--method", "sr-lazy", "--band-layers", "4"}, "--band-layers does nothing"},
      {{"--method", "sr-lazy", "--candidates", "embree"}, "--candidates does nothing"},
  };
  for (const auto& [args, named] : cases) {
    std::vector<std::string> all{"slice", examplePart().string(), "-o", "a.cli"};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult r = run(all);
    EXPECT_NE(r.code(), 0) << r.describe();
    EXPECT_TRUE(contains(r.err, named)) << testing::PrintToString(args) << "\n" << r.err;
    EXPECT_FALSE(fs::exists(path("a.cli")));
  }
  // Planes out of order name --z, not the model, and before the model is read (a missing one here).
  for (const char* z : {"3,1,2", "1,1"}) {
    const RunResult r = run({"slice", "missing.stl", "-o", "a.cli", "--z", z});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "toposlice: error: --z: the planes must be strictly increasing")) << r.err;
  }
  EXPECT_FALSE(fs::exists(path("-q")));
  // --threads has the job files' bound ("threads": 0 to 4096).
  const RunResult threads = run({"slice", examplePart().string(), "-o", "a.cli", "--threads", "5000", "-q"});
  EXPECT_EQ(threads.code(), 2) << threads.describe();
  EXPECT_TRUE(contains(threads.err, "--threads: must be between 0 (all cores) and 4096, got 5000"))
      << threads.err;
  EXPECT_FALSE(fs::exists(path("a.cli")));
  // The preview is fitted to the model, a template's table is its connectivity: --units and --scale
  // would change nothing in either.
  for (const char* opt : {"--units", "--scale"}) {
    const RunResult r =
        run({"preview", examplePart().string(), "-o", "p.png", opt, opt[2] == 'u' ? "in" : "2", "-q"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, std::string(opt) + " does nothing in preview")) << r.err;
    EXPECT_FALSE(fs::exists(path("p.png")));
    const RunResult t =
        run({"template", examplePart().string(), "-o", "t.topo", opt, opt[2] == 'u' ? "in" : "2", "-q"});
    expectOneErrorLine(t);
    EXPECT_TRUE(contains(t.err, std::string(opt) + " does nothing in template")) << t.err;
    EXPECT_FALSE(fs::exists(path("t.topo")));
  }
  const RunResult wrapped =
      run({"preview", examplePart().string(), "-o", "p.png", "--size", "4294967297x10", "-q"});
  EXPECT_NE(wrapped.code(), 0) << wrapped.describe();
  EXPECT_TRUE(contains(wrapped.err, "--size")) << wrapped.err;
  EXPECT_FALSE(fs::exists(path("p.png")));
}

// Printer files carry one layer height: uneven planes came out as a part of another height (0.5, 1, 3,
// 6 printed as 0.5, 1, 1.5, 2), silently. Refused there; the image stacks keep each plane.
// --method cp builds and reads no adjacency: a --template was read and never checked against the model,
// so a variant of other connectivity went through silently.
TEST_F(OptionChecks, TemplateWithTheClosestPointMethodIsAnError) {
  ASSERT_EQ(run({"template", examplePart().string(), "-o", "t.topo", "-q"}).code(), 0);
  const RunResult r =
      run({"slice", examplePart().string(), "--template", "t.topo", "--method", "cp", "-o", "c.cli", "-q"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "--template")) << r.err;
  EXPECT_TRUE(contains(r.err, "--method cp")) << r.err;
  EXPECT_FALSE(fs::exists(path("c.cli")));
  EXPECT_EQ(run({"slice", examplePart().string(), "--template", "t.topo", "--method", "sr-lazy", "-o",
                 "c.cli", "-q"})
                .code(),
            0);
}

// One file given twice among a model's features, or both added and removed, or the model as its own
// feature, is a mistake: refused naming the file, in slice, batch and plate alike (through links too).
TEST_F(OptionChecks, AFeatureFileGivenTwiceOrAsTheModelIsRefused) {
  writeBytes(path("box.stl"), boxStl(5, 0, false));
  writeBytes(path("tab.stl"), boxStl(2, 4, false));
  fs::create_symlink(path("tab.stl"), path("link.stl"));
  const std::string model = path("box.stl").string();
  const struct {
    std::vector<std::string> features;
    const char* said;
  } cases[] = {
      {{"--add", "tab.stl", "--add", "tab.stl"}, "tab.stl: given twice as an add-on feature"},
      {{"--remove", "tab.stl", "--remove", "link.stl"}, "link.stl: given twice as a removal feature"},
      {{"--add", "tab.stl", "--remove", "link.stl"}, "given both as an add-on feature and as a removal"},
      {{"--add", "box.stl"}, "box.stl: the model itself given as an add-on feature"},
  };
  for (const auto& c : cases) {
    std::vector<std::string> args{"slice", model, "-H", "0.5", "-o", "c.cli", "-q"};
    args.insert(args.end(), c.features.begin(), c.features.end());
    const RunResult r = run(args);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, c.said)) << r.err;
    EXPECT_FALSE(fs::exists(path("c.cli")));
  }
  EXPECT_EQ(run({"slice", model, "-H", "0.5", "-o", "c.cli", "-q", "--add", "tab.stl"}).code(), 0);

  writeBytes(path("batch.json"), R"({"version": 1, "template": {"model": "box.stl"},
      "settings": {"layer_height": 0.5},
      "variants": [{"name": "good", "model": "box.stl", "contours": "good.cli", "add": ["tab.stl"]},
                   {"name": "v", "model": "box.stl", "contours": "v.cli", "add": ["tab.stl"],
                    "remove": ["link.stl"]}]})");
  // Refused before any variant (the good one before it was written first), and by --explain.
  for (const char* flag : {"-q", "--explain"}) {
    const RunResult batch = run({"batch", "batch.json", flag});
    expectOneErrorLine(batch);
    EXPECT_TRUE(contains(batch.err, "batch.json: variant 'v': ") &&
                contains(batch.err, "given both as an add-on"))
        << batch.err;
    EXPECT_FALSE(fs::exists(path("good.cli")));
    EXPECT_FALSE(fs::exists(path("v.cli")));
  }

  writeBytes(path("plate.json"), R"({"version": 1, "printer": "sl1", "settings": {"layer_height": 0.5},
      "parts": [{"name": "p", "model": "box.stl", "add": ["tab.stl", "link.stl"], "placement": "auto"}],
      "outputs": {"contours": ["p.cli"]}})");
  const RunResult plate = run({"plate", "plate.json", "-q"});
  expectOneErrorLine(plate);
  EXPECT_TRUE(contains(plate.err, "part 'p'") && contains(plate.err, "given twice as an add-on"))
      << plate.err;
  EXPECT_FALSE(fs::exists(path("p.cli")));
}

// An image side beyond 100000 pixels is one bound wherever the size is given: --resolution, a batch's or a
// plate's settings.resolution, a profile's display_pixels_x/y (a batch took 5000000 x 300 and sliced it).
TEST_F(OptionChecks, ImageSizesHaveOneBoundEverywhere) {
  const std::string part = examplePart().string();
  const RunResult cli = run({"slice", part, "-H", "1", "--masks", "m.sl1", "--printer", "generic-4k",
                             "--pixel", "0.05", "--resolution", "100001x300", "-q"});
  expectOneErrorLine(cli);
  EXPECT_TRUE(contains(cli.err, "--resolution '100001x300': expected WxH in pixels, each 1 to 100000"))
      << cli.err;
  writeBytes(path("batch.json"), R"({"version": 1, "template": {"model": ")" + part + R"("},
      "settings": {"layer_height": 1, "printer": "generic-4k", "pixel": 0.05, "resolution": [100001, 300]},
      "variants": [{"name": "v", "model": ")" +
                                     part + R"(", "masks": "v.sl1"}]})");
  const RunResult batch = run({"batch", "batch.json", "-q"});
  expectOneErrorLine(batch);
  EXPECT_TRUE(contains(batch.err, "settings.resolution[0]: must be between 1 and 100000, got 100001"))
      << batch.err;
  writeBytes(path("plate.json"), R"({"version": 1, "printer": "generic-4k",
      "settings": {"layer_height": 1, "pixel": 0.05, "resolution": [300, 100001]},
      "parts": [{"name": "p", "model": ")" +
                                     part + R"(", "placement": "auto"}], "outputs": {"masks": "p.sl1"}})");
  const RunResult plate = run({"plate", "plate.json", "-q"});
  expectOneErrorLine(plate);
  EXPECT_TRUE(contains(plate.err, "settings.resolution[1]: must be between 1 and 100000, got 100001"))
      << plate.err;
  writeBytes(path("wide.json"), R"({"printers": {"wide": {"inherits": "sl1", "display_pixels_x": 100001}}})");
  const RunResult profile = run(
      {"slice", part, "-H", "1", "--masks", "m.sl1", "--profile", "wide.json", "--printer", "wide", "-q"});
  expectOneErrorLine(profile);
  EXPECT_TRUE(contains(profile.err, "display_pixels_x")) << profile.err;
  EXPECT_EQ(entries(dir_), (std::vector<std::string>{"batch.json", "plate.json", "wide.json"}));
}

// A pixel size of many decimals with --resolution: its display_width and _height, recorded in whole
// nanometres, differed in the last digit per pixel and the job was refused as having pixels that are not
// square.
TEST_F(OptionChecks, AGivenPixelOfManyDecimalsIsSquare) {
  const RunResult r =
      run({"slice", examplePart().string(), "-H", "1", "--masks", "m.sl1", "--printer", "generic-4k",
           "--pixel", "0.0123456789", "--resolution", "1000x900", "--crop", "--summary", "s.json", "-q"});
  EXPECT_EQ(r.code(), 0) << r.describe();
  const auto summary = nlohmann::json::parse(readBytes(path("s.json")));
  EXPECT_EQ(summary["print_settings"]["values"]["display_width"], "12.345679") << summary.dump(2);
}

// A batch variant too large for the image was told to use --crop and --origin, which a batch job has
// not: its own setting is named.
TEST_F(OptionChecks, ABatchVariantThatDoesNotFitIsToldWhatTheJobCanDo) {
  writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + examplePart().string() +
                                   R"("}, "settings": {"layer_height": 1, "printer": "sl1", "units": "cm"},
      "variants": [{"name": "big", "model": ")" +
                                   examplePart().string() + R"(", "masks": "big.sl1"}]})");
  const RunResult r = run({"batch", "job.json", "-q"});
  EXPECT_NE(r.code(), 0);
  EXPECT_TRUE(contains(r.err, "does not fit")) << r.err;
  EXPECT_TRUE(contains(r.err, "set settings.origin")) << r.err;
  EXPECT_FALSE(contains(r.err, "--crop")) << r.err;
}

// Two values the user gave for one display setting: the option replaced the setting without a word
// (--display-pixels-x 400 --resolution 300x300 made 300-pixel images). Refused naming both, in slice and
// in a batch job.
TEST_F(OptionChecks, DisplayOptionsAndTheSettingsTheyReplaceAreNotBothGiven) {
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases{
      {{"--display-pixels-x", "400", "--resolution", "300x300"}, "--resolution and display_pixels_x"},
      {{"--set", "display_pixels_y=400", "--resolution", "300x300"}, "--resolution and display_pixels_y"},
      {{"--display-width", "20", "--pixel", "0.05"}, "--pixel and display_width"},
  };
  for (const auto& [args, named] : cases) {
    std::vector<std::string> all{"slice",     examplePart().string(), "-H",      "1",
                                 "--printer", "generic-8k",           "--masks", "m.sl1"};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult r = run(all);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, named)) << testing::PrintToString(args) << "\n" << r.err;
    EXPECT_FALSE(fs::exists(path("m.sl1")));
  }
  // --mirror-x mirrors on top of display_mirror_x, whatever set it (documented): no contradiction.
  const RunResult onTop = run({"slice", examplePart().string(), "-H", "1", "--printer", "generic-8k",
                               "--display-mirror-x", "0", "--mirror-x", "--masks", "m.sl1", "-q"});
  EXPECT_EQ(onTop.code(), 0) << onTop.describe();
  writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + examplePart().string() +
                                   R"("}, "settings": {"layer_height": 1, "printer": "generic-8k",
      "resolution": [300, 300], "print_settings": {"display_pixels_x": 400}},
      "variants": [{"name": "v", "model": ")" +
                                   examplePart().string() + R"(", "masks": "v.sl1"}]})");
  const RunResult batch = run({"batch", "job.json", "-q"});
  EXPECT_NE(batch.code(), 0) << batch.describe();
  EXPECT_TRUE(contains(batch.err, "settings.resolution and display_pixels_x (batch job print_settings)"))
      << batch.err;
  EXPECT_FALSE(fs::exists(path("v.sl1")));
  // A job's settings.mirror replaces display_mirror_x/y (documented): both given, each another, refused.
  writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + examplePart().string() +
                                   R"("}, "settings": {"layer_height": 1, "printer": "generic-8k",
      "mirror": "none", "print_settings": {"display_mirror_x": 1}},
      "variants": [{"name": "v", "model": ")" +
                                   examplePart().string() + R"(", "masks": "v.sl1"}]})");
  const RunResult mirrored = run({"batch", "job.json", "-q"});
  EXPECT_NE(mirrored.code(), 0) << mirrored.describe();
  EXPECT_TRUE(
      contains(mirrored.err, "settings.mirror and display_mirror_x 1 (batch job print_settings) contradict"))
      << mirrored.err;
}

// Batch variants write every printer file slice writes (they took .sl1, .exr and .vdb only), with the
// job's printer settings: the same bytes as slice gives, but for the archives' dates.
TEST_F(OptionChecks, BatchVariantsWriteEveryPrinterFile) {
  writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + examplePart().string() +
                                   R"("}, "settings": {"layer_height": 1, "printer": "sl1",
      "print_settings": {"lift_speed": 70}}, "variants": [
      {"name": "g", "model": ")" + examplePart().string() +
                                   R"(", "masks": "g.goo"},
      {"name": "n", "model": ")" + examplePart().string() +
                                   R"(", "masks": "n.nanodlp"},
      {"name": "s", "model": ")" + examplePart().string() +
                                   R"(", "masks": "s.sl1s"}]})");
  const RunResult r = run({"batch", "job.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(readBytes(path("g.goo")).starts_with(std::string("V3.0\x07\0\0\0DLP\0toposlice", 21)));
  EXPECT_TRUE(readBytes(path("n.nanodlp")).starts_with("PK\x03\x04"));
  EXPECT_TRUE(readBytes(path("s.sl1s")).starts_with("PK\x03\x04"));
  ASSERT_EQ(run({"slice", examplePart().string(), "-H", "1", "--printer", "sl1", "--lift-speed", "70",
                 "--masks", "alone.goo", "-q"})
                .code(),
            0);
  EXPECT_EQ(readBytes(path("g.goo")).size(), readBytes(path("alone.goo")).size());
}

TEST_F(OptionChecks, UnevenPlanesAreRefusedForPrinterFiles) {
  for (const char* masks : {"u.sl1", "u.goo", "u.nanodlp"}) {
    const RunResult r = run(
        {"slice", examplePart().string(), "--z", "0.5,1,3,6", "--printer", "sl1", "--masks", masks, "-q"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "--z: the planes are not evenly spaced")) << r.err;
    EXPECT_FALSE(fs::exists(path(masks)));
  }
  EXPECT_EQ(run({"slice", examplePart().string(), "--z", "0.5,1,1.5,2", "--printer", "sl1", "--masks",
                 "e.goo", "-q"})
                .code(),
            0);
  EXPECT_EQ(
      run({"slice", examplePart().string(), "--z", "0.5,1,3,6", "--printer", "sl1", "--masks", "e.exr", "-q"})
          .code(),
      0);
}

TEST_F(OptionChecks, OptionsThatDoNothingAreErrors) {
  const std::vector<std::vector<std::string>> cases{
      {"-o", "a.cli", "--svg-layers", "1"},
      {"-o", "a.svg", "--cli-binary"},
      {"-o", "a.cli", "--antialias"},
      {"-o", "a.cli", "--mirror-x"},
      {"-o", "a.cli", "--crop"},
      {"-o", "a.cli", "--printer", "sl1"},
      {"-o", "a.cli", "--on-mismatch", "rebuild"},
      {"-o", "a.cli", "--join-tolerance", "0.001"},
      {"-o", "a.cli", "--vdb-layout", "slabs"},
      {"--masks", "m.sl1", "--vdb-layout", "slabs", "--printer", "sl1"},
      // Settings only a printer file carries, with a mask format that does not carry them.
      {"--masks", "pngs", "--exposure-time", "5", "--printer", "sl1"},
      {"--masks", "m.sl1", "--lift-speed", "10", "--printer", "sl1"},
      {"--masks", "m.nanodlp", "--printer-model", "XYZ", "--printer", "sl1"},
      {"--masks", "m.nanodlp", "--light-pwm", "100", "--printer", "sl1"},
      // The density only makes the resin mass of the summary and of the files that record it.
      {"-o", "a.cli", "--material-density", "1.5"},
      {"--masks", "pngs", "--material-density", "1.5", "--printer", "sl1"},
      // Named as given: the option's own name, or --set KEY.
      {"-o", "a.cli", "--elefant-foot-layers", "3"},
      {"--masks", "m.sl1", "--set", "light_pwm=3", "--printer", "sl1"},
  };
  for (const auto& args : cases) {
    std::vector<std::string> all{"slice", examplePart().string()};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult r = run(all);
    expectOneErrorLine(r);
    const std::string named = args[2] == "--set" ? "--set " + args[3].substr(0, args[3].find('=')) : args[2];
    EXPECT_TRUE(contains(r.err, named + " does nothing")) << r.err;
  }
  EXPECT_TRUE(entries(dir_).empty());
  // A material for contours only: its exposures need masks (a material_correction would change them).
  const RunResult material = run({"slice", examplePart().string(), "-o", "a.cli", "--material", "default"});
  expectOneErrorLine(material);
  EXPECT_TRUE(contains(material.err, "--material default does nothing in this job")) << material.err;
  EXPECT_FALSE(fs::exists(path("a.cli")));
  writeBytes(path("p.json"), R"({"materials": {"shrinks": {"material_correction_x": 1.01}}})");
  EXPECT_EQ(run({"slice", examplePart().string(), "-H", "1", "-o", "a.cli", "--profile", "p.json",
                 "--material", "shrinks", "-q"})
                .code(),
            0);
  // An SL1 archive records it (prusaslicer.ini, as PrusaSlicer's own): accepted there (it was refused).
  const RunResult sl1 = run({"slice", examplePart().string(), "--masks", "d.sl1", "--material-density", "1.5",
                             "--printer", "sl1", "-H", "1", "-q"});
  EXPECT_EQ(sl1.code(), 0) << sl1.describe();
  // A batch or plate job's print_settings that slice refuses, refused there too (they went through).
  const std::string part = examplePart().string();
  const std::vector<std::pair<std::string, std::string>> jobs{
      {R"("elefant_foot_layers": 3)",
       "settings.print_settings.elefant_foot_layers: does nothing in this job: "
       "it needs elefant_foot_compensation > 0"},
      {R"("material_density": 1.2)", "settings.print_settings.material_density: does nothing in this job"},
  };
  for (const auto& [setting, message] : jobs) {
    writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + part +
                                     R"("}, "settings": {"layer_height": 1, "print_settings": {)" + setting +
                                     R"(}}, "variants": [{"name": "v", "model": ")" + part +
                                     R"(", "contours": "v.cli"}]})");
    const RunResult r = run({"batch", "job.json", "-q"});
    EXPECT_NE(r.code(), 0) << r.describe();
    EXPECT_TRUE(contains(r.err, message)) << r.err;
    EXPECT_FALSE(fs::exists(path("v.cli")));
  }
}

// --explain refuses what the run would refuse (it approved a light map without anti-aliasing, which the
// run then refused), and the option checks of the run apply to it.
TEST_F(OptionChecks, ExplainRefusesWhatTheRunRefuses) {
  writeBytes(path("light.png"), sl1LightMapPng(220));
  writeBytes(path("lab.json"), R"({"printers": {"lab": {"inherits": "sl1", "light_map": "light.png"}}})");
  const std::vector<std::vector<std::string>> cases{
      {"--profile", "lab.json", "--printer", "lab", "--masks", "part.sl1", "--explain"},
      {"-o", "a.cli", "--printer", "sl1", "--explain"},
      // The image's own checks, which the run made after reading the model and --explain not at all.
      {"--printer", "sl1", "--masks", "o.goo", "--display-orientation", "portrait", "--explain"},
      {"--masks", "o.sl1", "--explain"},
      {"--printer", "sl1", "--display-width", "100", "--masks", "o.sl1", "--explain"},
      {"--printer", "generic-4k", "--masks", "o.sl1", "--explain"},
  };
  for (const auto& args : cases) {
    std::vector<std::string> all{"slice", examplePart().string(), "-H", "0.5"};
    all.insert(all.end(), args.begin(), args.end());
    const RunResult explained = run(all);
    expectOneErrorLine(explained);
    all.pop_back();
    const RunResult ran = run(all);
    expectOneErrorLine(ran);
    EXPECT_EQ(explained.err, ran.err);
  }
  EXPECT_FALSE(fs::exists(path("part.sl1")));
}

// The SL1's portrait light map with masks that are landscape whatever the display (.goo, .exr, ...): said
// as a turned display, not only as "not the display's size" (the same map serves the .sl1).
// A batch job's mask settings that contradict each other are refused once, up front, naming the job's
// settings: every variant failed with slice's option names (--antialias) before.
TEST_F(OptionChecks, ABatchJobsContradictingMaskSettingsAreRefusedUpFront) {
  const std::string part = examplePart().string();
  const std::vector<std::pair<std::string, std::string>> cases{
      {R"("antialias": true, "print_settings": {"gamma_correction": 0})",
       "settings.antialias and gamma_correction 0 (binary masks) contradict each other"},
      {R"("print_settings": {"display_orientation": "portrait"})",
       "variant 'v': display_orientation portrait (batch job print_settings) applies to SL1 archives and PNG "
       "folders only; .exr stacks are written landscape"},
  };
  for (const auto& [settings, message] : cases) {
    writeBytes(path("job.json"), R"({"version": 1, "template": {"model": ")" + part +
                                     R"("}, "settings": {"layer_height": 1, "printer": "sl1", )" + settings +
                                     R"(}, "variants": [{"name": "v", "model": ")" + part +
                                     R"(", "masks": "v.exr"}]})");
    const RunResult r = run({"batch", "job.json", "-q"});
    EXPECT_NE(r.code(), 0) << r.describe();
    EXPECT_TRUE(contains(r.err, "job.json: " + message)) << r.err;
    EXPECT_FALSE(contains(r.err, "--antialias")) << r.err;
    EXPECT_FALSE(fs::exists(path("v.exr")));
  }
}

TEST_F(OptionChecks, APortraitLightMapForLandscapeMasksIsSaidToBeTurned) {
  writeBytes(path("light.png"), sl1LightMapPng(220));
  const RunResult goo = run({"slice", examplePart().string(), "-H", "0.5", "--printer", "sl1", "--antialias",
                             "--light-map", "light.png", "--masks", "m.goo"});
  expectOneErrorLine(goo);
  EXPECT_TRUE(contains(goo.err,
                       "light.png: the light map is 1440x2560 pixels, the masks 2560x1440 (landscape: "
                       ".goo, .nanodlp, .exr and .vdb masks are, whatever the display)"))
      << goo.err;
  EXPECT_FALSE(fs::exists(path("m.goo")));
  EXPECT_EQ(run({"slice", examplePart().string(), "-H", "0.5", "--printer", "sl1", "--antialias",
                 "--light-map", "light.png", "--masks", "m.sl1", "-q"})
                .code(),
            0);
}

// Batch and plate --explain read the light map as their runs do (they approved a map the run refused).
TEST_F(OptionChecks, BatchAndPlateExplainReadTheLightMap) {
  writeBytes(path("light.png"), sl1LightMapPng(220));
  const std::string part = jsonString(examplePart().string());
  const std::string settings = R"("print_settings": {"light_map": "light.png"})";
  writeBytes(path("batch.json"),
             R"({"version": 1, "template": {"model": )" + part +
                 R"(}, "settings": {"layer_height": 1, "printer": "sl1", "antialias": true, )" + settings +
                 R"(}, "variants": [{"name": "v", "model": )" + part +
                 R"(, "masks": "v.sl1"}, {"name": "w", "model": )" + part + R"(, "masks": "w.goo"}]})");
  writeBytes(
      path("plate.json"),
      R"({"printer": "sl1", )" + settings +
          R"(, "settings": {"layer_height": 1, "antialias": true}, "parts": [{"name": "a", "model": )" +
          part + R"(, "placement": "auto"}], "outputs": {"masks": "p.goo"}})");
  for (const char* command : {"batch", "plate"}) {
    const std::string job = path(std::string(command) + ".json").string();
    const RunResult explained = run({command, job, "--explain"});
    expectOneErrorLine(explained);
    EXPECT_TRUE(contains(explained.err, "light.png: the light map is 1440x2560 pixels, the masks 2560x1440"))
        << explained.err;
    if (command == std::string("batch")) {
      EXPECT_TRUE(contains(explained.err, "batch.json: variant 'w': "));
    }
    const RunResult ran = run({command, job, "-q"});
    expectOneErrorLine(ran);
    EXPECT_EQ(explained.err, ran.err) << command;
  }
  EXPECT_FALSE(fs::exists(path("v.sl1")));
  EXPECT_FALSE(fs::exists(path("p.goo")));
}

// A material named for contours only does nothing unless one of its settings changes them (slice
// refused it; batch and plate ignored it).
TEST_F(OptionChecks, AMaterialThatChangesNothingIsRefusedInBatchAndPlate) {
  writeBytes(path("prof.json"), R"({"materials": {"m": {"exposure_time": 5},
      "shrinks": {"exposure_time": 5, "material_correction_x": 1.01}}})");
  const std::string part = jsonString(examplePart().string());
  const auto batchJob = [&](const std::string& material) {
    writeBytes(path("batch.json"),
               R"({"version": 1, "template": {"model": )" + part +
                   R"(}, "settings": {"layer_height": 2, "profile": "prof.json", "material": ")" + material +
                   R"("}, "variants": [{"name": "v", "model": )" + part + R"(, "contours": "v.svg"}]})");
  };
  const auto plateJob = [&](const std::string& material) {
    writeBytes(path("plate.json"),
               R"({"printer": "sl1", "profile": "prof.json", "material": ")" + material +
                   R"(", "settings": {"layer_height": 2}, "parts": [{"name": "a", "model": )" + part +
                   R"(, "placement": "auto"}], "outputs": {"contours": ["p.cli"]}})");
  };
  for (const char* material : {"m", "default"}) {
    batchJob(material);
    const RunResult batch = run({"batch", "batch.json", "-q"});
    expectOneErrorLine(batch);
    EXPECT_TRUE(contains(batch.err, "batch.json: settings.material: does nothing in this job: ") &&
                contains(batch.err, "; its exposures need a variant with masks"))
        << batch.err;
    EXPECT_FALSE(fs::exists(path("v.svg")));
    plateJob(material);
    const RunResult plate = run({"plate", "plate.json", "-q"});
    expectOneErrorLine(plate);
    EXPECT_TRUE(contains(plate.err, "plate.json: material: does nothing in this job: ") &&
                contains(plate.err, "; its exposures need outputs.masks"))
        << plate.err;
    EXPECT_FALSE(fs::exists(path("p.cli")));
  }
  batchJob("shrinks");  // its material_correction_x changes the contours
  EXPECT_EQ(run({"batch", "batch.json", "-q"}).code(), 0);
  plateJob("shrinks");
  EXPECT_EQ(run({"plate", "plate.json", "-q"}).code(), 0);
}

TEST_F(OptionChecks, UnknownMaskExtensionListsTheKnownOnes) {
  const RunResult r = run({"slice", examplePart().string(), "--masks", "layers.zip", "--printer", "sl1"});
  expectOneErrorLine(r);
  for (const char* ext : {"layers.zip", ".sl1", ".exr", ".vdb", "PNG"})
    EXPECT_TRUE(contains(r.err, ext)) << r.err;
  EXPECT_FALSE(fs::exists(path("layers.zip")));
}

// ---------------------------------------------------------------------------------------------------
// 7. Messages.

TEST_F(Messages, MistypedCommandIsNamedWithASuggestion) {
  const RunResult r = run({"slise", examplePart().string()});
  EXPECT_EQ(r.code(), 2) << r.describe();
  EXPECT_TRUE(contains(r.err, "'slise'")) << r.err;
  EXPECT_TRUE(contains(r.err, "did you mean 'slice'")) << r.err;
}

TEST_F(Messages, UsageErrorsPointToTheSubcommandsHelp) {
  const RunResult r = run({"slice", examplePart().string(), "--no-such-option"});
  EXPECT_EQ(r.code(), 2) << r.describe();
  EXPECT_TRUE(contains(r.err, "toposlice slice --help")) << r.err;
}

TEST_F(Messages, MissingOutputFolderIsNamedNotTheTemporary) {
  const RunResult r = run({"slice", examplePart().string(), "-o", "nowhere/a.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "nowhere/a.cli: ")) << r.err;
  EXPECT_TRUE(contains(r.err, "'nowhere' does not exist")) << r.err;
  EXPECT_FALSE(contains(r.err, ".tmp-")) << r.err;
}

// A folder of masks given with a trailing slash is that folder (its temporary went inside it, in a
// folder that did not exist); a profile that inherits an unknown name names the file and the key; a
// JSON job's existing output says how to replace it there (it has no --force).
TEST_F(Messages, FolderSlashInheritsAndJsonOverwriteHints) {
  RunResult r =
      run({"slice", examplePart().string(), "-H", "1", "--printer", "sl1", "--masks", "pngs/", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_EQ(entries(path("pngs")).size(), 7u);
  expectNoTemporaries();

  writeBytes(path("p.json"), R"({"printers": {"lab": {"inherits": "nope"}}})");
  r = run({"slice", examplePart().string(), "-H", "1", "--profile", "p.json", "--printer", "lab", "--masks",
           "m.sl1"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "p.json: printers.lab.inherits: unknown printer 'nope'")) << r.err;

  writeBytes(path("r.json"), "{\n  \"toposlice\": \"an earlier run\"}\n");
  writeBytes(path("job.json"),
             "{\"printer\": \"sl1\", \"settings\": {\"layer_height\": 1}, \"parts\": [{\"name\": "
             "\"a\", \"model\": " +
                 nlohmann::json(examplePart().string()).dump() +
                 ", \"placement\": \"auto\"}], \"outputs\": {\"report\": \"r.json\"}}");
  r = run({"plate", "job.json"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "r.json: already exists (set \"overwrite\": true")) << r.err;
}

TEST_F(Messages, ModelTooLargeSaysWhichEdges) {
  const RunResult r =
      run({"slice", examplePart().string(), "--masks", "m", "--resolution", "100x100", "--pixel", "0.1"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "+x")) << r.err;
  EXPECT_TRUE(contains(r.err, "-y")) << r.err;
}

TEST_F(Messages, HelpListsEveryContourFormatAndThePixelNeed) {
  const RunResult r = run({"slice", "--help"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, ".3mf")) << r.out;
  EXPECT_TRUE(contains(r.out, "--summary")) << r.out;
  const RunResult pixel = run({"slice", examplePart().string(), "--masks", "m", "--printer", "generic-4k"});
  expectOneErrorLine(pixel);
  EXPECT_TRUE(contains(pixel.err, "--pixel")) << pixel.err;
}

// ---------------------------------------------------------------------------------------------------
// Mesh formats through the program: recognised by content, with units.

using MeshInput = CliToolBase;

TEST_F(MeshInput, PlyAndObjSliceLikeTheirStlSiblings) {
  for (const char* stem : {"knee_femur_ssm_S001", "knee_tibia_ssm_S001"}) {
    const fs::path ply = sharedModel(std::string(stem) + ".ply"),
                   stl = sharedModel(std::string(stem) + ".stl");
    if (!fs::exists(ply) || !fs::exists(stl)) GTEST_SKIP() << ply << " not found";
    // Misnamed on purpose: the format comes from the content.
    fs::copy_file(ply, path("scan.stl"));
    ASSERT_EQ(run({"slice", "scan.stl", "-H", "1", "--report", "a.csv", "-q"}).code(), 0);
    ASSERT_EQ(run({"slice", stl.string(), "-H", "1", "--report", "b.csv", "-q"}).code(), 0);
    EXPECT_EQ(readBytes(path("a.csv")), readBytes(path("b.csv"))) << stem;
    fs::remove(path("scan.stl"));
    fs::remove(path("a.csv"));
    fs::remove(path("b.csv"));
  }
}

TEST_F(MeshInput, MetreSizedObjWithUnits) {
  const fs::path obj = sharedModel("human_body_smpl_female.obj");
  if (!fs::exists(obj)) GTEST_SKIP() << obj << " not found";
  const RunResult r = run({"slice", obj.string(), "--units", "m", "-H", "5", "--summary", "s.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const auto j = nlohmann::json::parse(readBytes(path("s.json")));
  EXPECT_EQ(j["format"], "OBJ");
  EXPECT_EQ(j["units_mm"].get<double>(), 1000.0);
  // A human body: tens of litres, 1.5 to 2 m tall.
  EXPECT_GT(j["volume_ml"].get<double>(), 30000.0);
  EXPECT_LT(j["volume_ml"].get<double>(), 150000.0);
  double height = 0;  // SMPL bodies stand along y
  for (int axis = 0; axis < 3; ++axis)
    height = std::max(height,
                      j["bounds_mm"]["max"][axis].get<double>() - j["bounds_mm"]["min"][axis].get<double>());
  EXPECT_GT(height, 1400.0);
  EXPECT_LT(height, 2100.0);
}

TEST_F(MeshInput, BatchJobsTakeUnitsAndScale) {
  const fs::path obj = sharedModel("human_body_smpl_male.obj");
  if (!fs::exists(obj)) GTEST_SKIP() << obj << " not found";
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": " + jsonString(obj.string()) +
                 "}, \"settings\": {\"layer_height\": 20, \"units\": \"m\", \"scale\": 0.5},"
                 " \"variants\": [{\"name\": \"m\", \"model\": " +
                 jsonString(obj.string()) + ", \"contours\": \"m.cli\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  // The same bytes as the slice command with the same units and scale, and not the millimetre reading.
  ASSERT_EQ(
      run({"slice", obj.string(), "-H", "20", "--units", "m", "--scale", "0.5", "-o", "s.cli", "-q"}).code(),
      0);
  EXPECT_EQ(readBytes(path("m.cli")), readBytes(path("s.cli")));
  const std::string cli = readBytes(path("m.cli"));
  const auto at = cli.find("$$LAYERS/");
  ASSERT_NE(at, std::string::npos);
  EXPECT_GE(std::stoi(cli.substr(at + 9)), 5);  // the body is 0.2-0.3 m deep along z: 145 mm at scale 0.5
}

TEST_F(MeshInput, TextFileIsNotAMeshAndBadUnitsAreNamed) {
  writeBytes(path("notes.stl"), "Dear colleague,\nthe aligner files follow tomorrow.\n");
  const RunResult r = run({"slice", "notes.stl", "-o", "a.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "notes.stl: not a mesh file")) << r.err;
  EXPECT_FALSE(contains(r.err, "truncated")) << r.err;
  const RunResult units = run({"slice", examplePart().string(), "--units", "furlong", "-o", "a.cli"});
  expectOneErrorLine(units);
  EXPECT_TRUE(contains(units.err, "--units")) << units.err;
  EXPECT_FALSE(fs::exists(path("a.cli")));
}

// ---------------------------------------------------------------------------------------------------
// The machine-readable summary, and numbers that read back exactly.

TEST_F(Summary, JsonSummaryHasTheCountsVolumeAndOutputs) {
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.01", "--masks", "m.sl1", "--printer",
                           "sl1", "--report", "r.csv", "--summary", "s.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const auto j = nlohmann::json::parse(readBytes(path("s.json")));
  EXPECT_EQ(j["layers"]["count"], 620);  // ceil(6.2 / 0.01)
  EXPECT_EQ(j["layers"]["layer_height_mm"].get<double>(), 0.01);
  EXPECT_GT(j["volume_ml"].get<double>(), 0.5);
  EXPECT_LT(j["volume_ml"].get<double>(), 0.6);
  EXPECT_EQ(j["facets"], 8384);
  EXPECT_EQ(j["outputs"].size(), 3u);
  EXPECT_TRUE(j["warnings"].empty());
  // The CSV is plain rows (no trailer), and the SL1 carries the layer height as given.
  for (const auto& line : splitLines(readBytes(path("r.csv")))) EXPECT_FALSE(line.starts_with("#")) << line;
  EXPECT_EQ(j["defects"]["boundary_edges"], 0);  // the adjacency was built: counted

  // With a template's table the model's edges are not counted: null, not a clean 0.
  ASSERT_EQ(run({"template", examplePart().string(), "-o", "t.topo", "-q"}).code(), 0);
  ASSERT_EQ(run({"slice", examplePart().string(), "--template", "t.topo", "-H", "1", "-o", "t.cli",
                 "--summary", "t.json", "-q"})
                .code(),
            0);
  const auto t = nlohmann::json::parse(readBytes(path("t.json")));
  EXPECT_TRUE(contains(t["topology"].get<std::string>(), "template")) << t["topology"];
  for (const char* k : {"boundary_edges", "non_manifold_edges", "inconsistent_edges"})
    EXPECT_TRUE(t["defects"][k].is_null()) << k << " " << t["defects"];
}

// The gamma the masks have is in the summary's settings when it was left to --antialias, as every
// printer file records it (the summary left it out): 1 with --antialias, 0 for binary masks; a gamma
// the user gives is given as it is; contours alone have none.
TEST_F(Summary, TheMasksGammaIsInTheSettings) {
  const auto gamma = [&](std::vector<std::string> extra) {
    std::vector<std::string> args{"slice",  examplePart().string(), "-H", "1", "--summary", "s.json", "-q",
                                  "--force"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.code(), 0) << r.describe();
    const auto settings = nlohmann::json::parse(readBytes(path("s.json")))["print_settings"];
    return settings["values"].value("gamma_correction", std::string("none")) + " " +
           settings["set_by"].value("gamma_correction", std::string("none"));
  };
  EXPECT_EQ(gamma({"--printer", "sl1", "--masks", "a.sl1", "--antialias"}), "1 --antialias");
  EXPECT_EQ(gamma({"--printer", "sl1", "--masks", "b.sl1"}), "0 default");
  EXPECT_EQ(gamma({"--printer", "sl1", "--masks", "c.sl1", "--gamma-correction", "0.5"}), "0.5 command line");
  EXPECT_EQ(gamma({"-o", "d.cli"}), "none none");
}

TEST_F(Summary, Sl1NumbersReadBackAsGiven) {
  ASSERT_EQ(run({"slice", examplePart().string(), "-H", "0.01", "--masks", "m.sl1", "--printer", "sl1", "-q"})
                .code(),
            0);
  const std::string config = zipEntry(path("m.sl1"), "config.ini");
  const std::string prusa = zipEntry(path("m.sl1"), "prusaslicer.ini");
  EXPECT_TRUE(contains(config, "layerHeight = 0.01\n")) << config;
  EXPECT_TRUE(contains(prusa, "layer_height = 0.01\n")) << prusa;
  EXPECT_TRUE(contains(prusa, "display_width = 120.96\n")) << prusa;
  EXPECT_FALSE(contains(config + prusa, "00000000"))
      << config << prusa;  // no 0.009999999999999998-style values
}

}  // namespace
}  // namespace toposlice
