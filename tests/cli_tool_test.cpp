// The `toposlice` program end to end: each test runs the real binary (fork + exec, stdout and stderr
// captured to files, exit status checked) in a fresh temporary directory, and checks what it prints and
// what it leaves on disk (README.md, docs/DESIGN.md "Errors and outputs", docs/FORMATS.md "Output files",
// docs/TEMPLATES.md, docs/MASKS.md).
//
// The binary is $TOPOSLICE_BIN (set by ctest) or, when the tests run outside ctest, the build's own
// toposlice (TOPOSLICE_BIN_PATH).
#include <fcntl.h>
#include <gtest/gtest.h>
#include <pty.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zip.h>  // libzip: reads the SL1 back

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/slicing/contours.h"
#include "io/coders/mask_png.h"
#include "io/masks/exr_writer.h"
#include "io/readers/mesh_reader.h"
#include "io/readers/stl_writer.h"
#include "tests/fixtures/archives.h"
#include "tests/fixtures/shapes.h"
#include "tests/fixtures/winding.h"
#include "tests/tinyexr_read.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using namespace tool_test;

// Suites, one per area (all named CliTool*).
using CliToolHelp = CliToolBase;
using CliToolInfo = CliToolBase;
using CliToolSliceErrors = CliToolBase;
using CliToolOverwrite = CliToolBase;
using CliToolDeterminism = CliToolBase;
using CliToolTemplate = CliToolBase;
using CliToolBatch = CliToolBase;
using CliToolMasks = CliToolBase;
using CliToolFeatures = CliToolBase;
using CliToolInterrupt = CliToolBase;
using CliToolQuiet = CliToolBase;

// ---------------------------------------------------------------------------------------------------
// 1. --help

TEST_F(CliToolHelp, ProgramAndEverySubcommandListTheirKeyOptions) {
  const std::map<std::vector<std::string>, std::vector<std::string>> expected{
      {{"--help"}, {"info", "slice", "template", "batch", "--version"}},
      {{"info", "--help"}, {"model", "--threads", "--quiet"}},
      {{"slice", "--help"},
       {"--layer-height", "-H",           "--layers", "--z0",      "--method",   "cp",
        "sr-lazy",        "--cli-binary", "--masks",  "--printer", "--template", "--on-mismatch",
        "--band-layers",  "--threads",    "--quiet",  "--force",   "--add",      "--remove",
        "--report",       "--crop",       "--output"}},
      {{"template", "--help"}, {"model", "--output", "--force", "--quiet"}},
      {{"batch", "--help"}, {"job", "--threads", "--quiet"}},
  };
  for (const auto& [args, words] : expected) {
    const RunResult r = run(args);
    const std::string what = testing::PrintToString(args);
    EXPECT_EQ(r.code(), 0) << what << ": " << r.describe();
    EXPECT_TRUE(r.err.empty()) << what << ": " << r.describe();
    for (const auto& w : words)
      EXPECT_TRUE(contains(r.out, w)) << what << " does not mention " << w << "\n" << r.out;
  }
}

// ---------------------------------------------------------------------------------------------------
// 2. info

TEST_F(CliToolInfo, ExamplePartIsClosedWithThreeShells) {
  const std::string stl = readBytes(examplePart());
  ASSERT_GE(stl.size(), 84u);
  const uint32_t facets = le32(stl, 80);  // binary STL: 80-byte header, then the facet count
  ASSERT_EQ(stl.size(), 84u + 50u * facets) << "example_part.stl is not a plain binary STL";
  EXPECT_EQ(facets, 8384u);

  const RunResult r = run({"info", examplePart().string()});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, "facets         : " + std::to_string(facets) + "\n")) << r.out;
  EXPECT_TRUE(contains(r.out, "closed         : yes")) << r.out;
  EXPECT_TRUE(contains(r.out, "shells         : 3\n")) << r.out;
  EXPECT_TRUE(contains(r.out, "boundary edges : 0\n")) << r.out;
  EXPECT_TRUE(contains(r.out, "(binary STL)")) << r.out;
  EXPECT_TRUE(r.err.empty()) << r.describe();

  // -q: errors only (the report was printed anyway); the exit status says whether the file reads.
  const RunResult quiet = run({"info", examplePart().string(), "-q"});
  EXPECT_EQ(quiet.code(), 0) << quiet.describe();
  EXPECT_TRUE(quiet.out.empty() && quiet.err.empty()) << quiet.describe();
  const RunResult missing = run({"info", "missing.stl", "-q"});
  expectOneErrorLine(missing);
}

// The committed example is what its generator makes (examples/generate_example_part.cpp).
TEST_F(CliToolInfo, ExamplePartIsFreshFromItsGenerator) {
  const fs::path generator =
      toposliceBinary().parent_path().parent_path() / "tests" / "generate_example_part";
  ASSERT_TRUE(fs::exists(generator)) << generator;
  ASSERT_EQ(std::system((generator.string() + " " + path("fresh.stl").string()).c_str()), 0);
  EXPECT_TRUE(readBytes(path("fresh.stl")) == readBytes(examplePart()))
      << "examples/example_part.stl differs from a fresh one: run "
         "build/tests/generate_example_part examples/example_part.stl";
}

// Nothing in the bundled example is unprintable: every layer from the first (on the plate) to the last
// holds part of the model (10 um layers, by the report), and every island of a layer's mask rests on
// something lit in the layer below (50 um layers, 50 um pixels, 4-connected islands).
TEST_F(CliToolInfo, ExamplePartHasNoEmptyLayerAndNoFloatingIsland) {
  const RunResult report = run({"slice", examplePart().string(), "-H", "0.01", "--report", "r.csv", "-q"});
  ASSERT_EQ(report.code(), 0) << report.describe();
  const auto lines = splitLines(readBytes(path("r.csv")));
  EXPECT_EQ(lines.size(), 620u + 1u);  // ceil(6.2 / 0.01) layers, from z 0 to the torus's top
  ASSERT_GE(lines.size(), 2u);
  EXPECT_TRUE(lines[1].starts_with("0,0.005000,")) << lines[1];
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::vector<std::string> fields;
    std::istringstream row(lines[i]);
    for (std::string f; std::getline(row, f, ',');) fields.push_back(f);
    ASSERT_EQ(fields.size(), 5u) << lines[i];
    EXPECT_GT(std::stoul(fields[3]), 0u) << "empty layer: " << lines[i];
    EXPECT_GT(std::stod(fields[2]), 0.0) << "empty layer: " << lines[i];
  }

  const RunResult masks = run({"slice", examplePart().string(), "-H", "0.05", "--masks", "m", "--pixel",
                               "0.05", "--resolution", "400x300", "-q"});
  ASSERT_EQ(masks.code(), 0) << masks.describe();
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(path("m"))) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  EXPECT_EQ(files.size(), 124u);  // ceil(6.2 / 0.05)
  MaskImage below, layer;
  for (std::size_t k = 0; k < files.size(); ++k) {
    const std::string png = readBytes(files[k]);
    ASSERT_TRUE(decodeMaskPng({reinterpret_cast<const uint8_t*>(png.data()), png.size()}, layer)) << files[k];
    if (k > 0) {
      // Flood every island; it must cover at least one pixel lit in the layer below.
      const uint32_t w = layer.width, h = layer.height;
      std::vector<uint8_t> seen(layer.pixels.size(), 0);
      std::vector<std::size_t> stack;
      uint32_t islands = 0;
      for (std::size_t start = 0; start < layer.pixels.size(); ++start) {
        if (layer.pixels[start] == 0 || seen[start]) continue;
        ++islands;
        bool rests = false;
        seen[start] = 1;
        stack.assign(1, start);
        while (!stack.empty()) {
          const std::size_t p = stack.back();
          stack.pop_back();
          rests = rests || below.pixels[p] != 0;
          const uint32_t x = static_cast<uint32_t>(p % w), y = static_cast<uint32_t>(p / w);
          for (const std::size_t q :
               {x > 0 ? p - 1 : p, x + 1 < w ? p + 1 : p, y > 0 ? p - w : p, y + 1 < h ? p + w : p})
            if (layer.pixels[q] != 0 && !seen[q]) seen[q] = 1, stack.push_back(q);
        }
        EXPECT_TRUE(rests) << files[k].filename() << ": island " << islands
                           << " floats (nothing lit below it)";
      }
      EXPECT_GT(islands, 0u) << files[k].filename() << " is dark";
    }
    std::swap(below, layer);
  }
}

TEST_F(CliToolInfo, InsideOutHorseHasNegativeVolume) {
  const RunResult r = run({"info", sharedModel("horse_cyberware.stl").string()});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, "volume         : -")) << r.out;
  EXPECT_TRUE(contains(r.out, "inside out")) << r.out;
  EXPECT_TRUE(contains(r.out, "facets         : 96966\n")) << r.out;  // SOURCES.md
  EXPECT_TRUE(contains(r.out, "closed         : yes")) << r.out;
}

TEST_F(CliToolInfo, CrackedPigReportsItsBoundaryEdges) {
  const RunResult r = run({"info", sharedModel("defect_pig_cracks.stl").string()});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, "boundary edges : 1296\n")) << r.out;  // SOURCES.md
  EXPECT_TRUE(contains(r.out, "facets         : 16848\n")) << r.out;
  EXPECT_TRUE(contains(r.out, "closed         : no")) << r.out;
  // An open surface's volume depends on the reference point: said so.
  EXPECT_TRUE(contains(r.out, "the mesh is not closed: where edges are open")) << r.out;
}

// Metre-sized models keep their digits (six decimals gave 0.000279 m^3 for a head) and no "-0" bound.
TEST_F(CliToolInfo, SmallVolumesKeepTheirDigits) {
  writeBinaryStl(path("tiny.stl"), fixtures::box(-0.0f, 0, 0, 0.01f, 0.02f, 0.03f), "tiny", false);
  const RunResult r = run({"info", "tiny.stl"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  // 0.01 x 0.02 x 0.03 in floats: 6e-06 to seven digits.
  EXPECT_TRUE(contains(r.out, "volume         : 5.9999996e-06 mm^3\n") ||
              contains(r.out, "volume         : 6.0000002e-06 mm^3\n"))
      << r.out;
  EXPECT_FALSE(contains(r.out, "[-0,")) << r.out;
}

// ---------------------------------------------------------------------------------------------------
// 3. slice errors

TEST_F(CliToolSliceErrors, MissingModelIsOneErrorLineNamingThePath) {
  const RunResult r = run({"slice", "no_such_model.stl", "-o", "out.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "no_such_model.stl")) << r.err;
  EXPECT_FALSE(fs::exists(path("out.cli")));
  expectNoTemporaries();
}

TEST_F(CliToolSliceErrors, TruncatedStlIsReportedAndWritesNothing) {
  writeBytes(path("cut.stl"), readBytes(examplePart()).substr(0, 500));
  const RunResult r = run(
      {"slice", "cut.stl", "-o", "out.cli", "--masks", "out.sl1", "--printer", "sl1", "--report", "r.csv"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "cut.stl")) << r.err;
  EXPECT_TRUE(contains(r.err, "truncated")) << r.err;
  EXPECT_FALSE(fs::exists(path("out.cli")));
  EXPECT_FALSE(fs::exists(path("out.sl1")));
  EXPECT_FALSE(fs::exists(path("r.csv")));
  expectNoTemporaries();
}

TEST_F(CliToolSliceErrors, UnknownOptionIsRejectedBeforeAnythingIsWritten) {
  const RunResult r = run({"slice", examplePart().string(), "-o", "out.cli", "--no-such-option"});
  EXPECT_TRUE(r.exited()) << r.describe();
  EXPECT_NE(r.code(), 0) << r.describe();
  EXPECT_NE(r.code(), 1) << "a usage error must be told apart from a failed run\n" << r.describe();
  EXPECT_TRUE(contains(r.err, "--no-such-option")) << r.describe();
  EXPECT_FALSE(fs::exists(path("out.cli")));
  expectNoTemporaries();
}

// README/DESIGN: command-line usage errors exit with status 2. The program returns CLI11's own exit
// codes instead (109 for an unknown option, 106 for a missing argument, 105 for a bad choice, 104 for a
// value that does not convert).
TEST_F(CliToolSliceErrors, UsageErrorsExitWithStatus2) {
  const std::vector<std::vector<std::string>> usageErrors{
      {"slice", examplePart().string(), "--no-such-option"},  // CLI11 ExtrasError: 109
      {"slice"},                                              // RequiredError: 106
      {},                                                     // no subcommand: 106
      {"slice", examplePart().string(), "--method", "xx"},    // ValidationError: 105
      {"slice", examplePart().string(), "-H", "abc"},         // ConversionError: 104
  };
  for (const auto& args : usageErrors) {
    const RunResult r = run(args);
    EXPECT_EQ(r.code(), 2) << testing::PrintToString(args) << ": " << r.describe();
  }
}

// README: "A failing command prints one line `toposlice: error: ...`". Usage errors print CLI11's two
// lines ("The following argument was not expected: --no-such-option" / "Run with --help for more
// information.") without the prefix.
TEST_F(CliToolSliceErrors, UsageErrorIsOneToposliceErrorLine) {
  const RunResult r = run({"slice", examplePart().string(), "--no-such-option"});
  EXPECT_TRUE(r.err.starts_with("toposlice: error: ")) << r.describe();
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.describe();
}

TEST_F(CliToolSliceErrors, ZeroLayerHeightIsRefused) {
  const RunResult r = run({"slice", examplePart().string(), "--layer-height", "0", "-o", "out.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "layer height")) << r.err;
  EXPECT_FALSE(fs::exists(path("out.cli")));
  expectNoTemporaries();
}

TEST_F(CliToolSliceErrors, UnknownOutputExtensionIsRefused) {
  const RunResult r = run({"slice", examplePart().string(), "-o", "out.xyz"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "out.xyz")) << r.err;
  EXPECT_TRUE(contains(r.err, ".cli")) << r.err;  // says what is known
  EXPECT_FALSE(fs::exists(path("out.xyz")));
  expectNoTemporaries();
}

// -o and --contours name the same outputs, in any mix: the last option's values replaced the others
// (-o a.cli --contours b.svg wrote only b.svg, exit 0).
TEST_F(CliToolSliceErrors, OutputAndContoursOptionsAddUp) {
  const RunResult r = run({"slice", examplePart().string(), "--layers", "3", "-o", "a.cli", "--contours",
                           "b.svg", "-o", "c.3mf", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  for (const char* name : {"a.cli", "b.svg", "c.3mf"}) EXPECT_TRUE(fs::exists(path(name))) << name;
  // Together they are one list: the same path through both is one output named twice.
  const RunResult twice =
      run({"slice", examplePart().string(), "--layers", "3", "-o", "d.cli", "--contours", "d.cli", "-q"});
  EXPECT_NE(twice.code(), 0) << twice.describe();
  EXPECT_FALSE(fs::exists(path("d.cli")));
}

// ---------------------------------------------------------------------------------------------------
// 4. existing outputs

TEST_F(CliToolOverwrite, ExistingOutputIsKeptWithoutForceAndReplacedWithIt) {
  const std::string old = fixtures::fileToposliceWrote(".cli", "an older CLI file, kept without --force\n");
  writeBytes(path("out.cli"), old);

  const RunResult refused = run({"slice", examplePart().string(), "-H", "0.5", "-o", "out.cli"});
  expectOneErrorLine(refused);
  EXPECT_TRUE(contains(refused.err, "out.cli")) << refused.err;
  EXPECT_TRUE(contains(refused.err, "already exists")) << refused.err;
  EXPECT_EQ(readBytes(path("out.cli")), old);
  expectNoTemporaries();

  const RunResult forced = run({"slice", examplePart().string(), "-H", "0.5", "-o", "out.cli", "--force"});
  ASSERT_EQ(forced.code(), 0) << forced.describe();
  const std::string cli = readBytes(path("out.cli"));
  EXPECT_TRUE(cli.starts_with("$$HEADERSTART\n// written by toposlice //\n$$ASCII\n")) << cli.substr(0, 100);
  EXPECT_TRUE(contains(cli, "$$LAYERS/13\n"));  // ceil(6.2 / 0.5)
  EXPECT_TRUE(cli.ends_with("$$GEOMETRYEND\n"));
  expectNoTemporaries();
}

TEST_F(CliToolOverwrite, OneExistingOutputLeavesTheOthersUnwritten) {
  writeBytes(path("r.csv"), "keep\n");
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.5", "-o", "out.cli", "--masks",
                           "out.sl1", "--printer", "sl1", "--report", "r.csv"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "r.csv")) << r.err;
  EXPECT_TRUE(contains(r.err, "already exists")) << r.err;
  EXPECT_EQ(readBytes(path("r.csv")), "keep\n");
  EXPECT_FALSE(fs::exists(path("out.cli")));
  EXPECT_FALSE(fs::exists(path("out.sl1")));
  expectNoTemporaries();
}

// Every output is checked before the model is read, the summary included (it was opened only after the
// slicing, so a job ran to its end before refusing an existing summary). A model that is not a mesh
// would fail the read: the existing output is what the run reports, so nothing was read first.
TEST_F(CliToolOverwrite, ExistingSummaryIsRefusedBeforeTheModelIsRead) {
  writeBytes(path("s.json"), "{\n  \"toposlice\": \"an earlier run\"}\n");
  writeBytes(path("notamesh.stl"), "this is not a mesh\n");
  const RunResult early =
      run({"slice", path("notamesh.stl").string(), "-H", "0.5", "-o", "out.cli", "--summary", "s.json"});
  expectOneErrorLine(early);
  EXPECT_TRUE(contains(early.err, "s.json: already exists")) << early.err;

  const RunResult r = run({"slice", examplePart().string(), "-H", "0.5", "-o", "out.cli", "--masks", "m.sl1",
                           "--printer", "sl1", "--summary", "s.json"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "s.json: already exists")) << r.err;
  EXPECT_EQ(readBytes(path("s.json")), "{\n  \"toposlice\": \"an earlier run\"}\n");
  EXPECT_FALSE(fs::exists(path("out.cli")));
  EXPECT_FALSE(fs::exists(path("m.sl1")));
  expectNoTemporaries();

  const RunResult forced =
      run({"slice", examplePart().string(), "-H", "0.5", "-o", "out.cli", "--summary", "s.json", "--force"});
  ASSERT_EQ(forced.code(), 0) << forced.describe();
  EXPECT_TRUE(contains(readBytes(path("s.json")), "\"outputs\"")) << readBytes(path("s.json"));
  EXPECT_TRUE(fs::exists(path("out.cli")));
  expectNoTemporaries();
}

// The template and preview commands, and --force on a file toposlice did not write, are checked before
// the model is read as well: a model that is not a mesh would fail the read, so the refused output is
// what each run reports.
TEST_F(CliToolOverwrite, RefusedOutputsOfEveryCommandAreNamedBeforeTheModelIsRead) {
  writeBytes(path("notamesh.stl"), "this is not a mesh\n");
  writeBytes(path("t.topo"), "kept\n");
  writeBytes(path("p.png"), "kept\n");
  writeBytes(path("foreign.json"), "not a summary toposlice wrote\n");
  const std::string model = path("notamesh.stl").string();
  const std::vector<std::pair<std::vector<std::string>, std::string>> runs{
      {{"template", model, "-o", "t.topo"}, "t.topo: already exists"},
      {{"preview", model, "-o", "p.png"}, "p.png: already exists"},
      {{"slice", model, "-H", "0.5", "-o", "out.cli", "--summary", "foreign.json", "--force"},
       "foreign.json: exists and is not a json file toposlice wrote"},
  };
  for (const auto& [args, message] : runs) {
    const RunResult r = run(args);
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, message)) << args[0] << ": " << r.err;
  }
  EXPECT_EQ(readBytes(path("t.topo")), "kept\n");
  EXPECT_EQ(readBytes(path("p.png")), "kept\n");
  EXPECT_EQ(readBytes(path("foreign.json")), "not a summary toposlice wrote\n");
  EXPECT_FALSE(fs::exists(path("out.cli")));
  expectNoTemporaries();
}

// tools/slice_job.h: "on any error or cancellation no output is left under its final name". The same
// path given twice makes the run fail ("b.cli: already exists", although it did not exist before) after
// the first writer has already committed b.cli, which stays behind.
TEST_F(CliToolOverwrite, FailedRunWithTheSameOutputTwiceLeavesNoOutput) {
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.5", "-o", "b.cli", "-o", "b.cli"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "b.cli")) << r.err;
  EXPECT_FALSE(fs::exists(path("b.cli"))) << "a failed run left its output under the final name";
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 5. determinism

TEST_F(CliToolDeterminism, ExamplePartIsByteIdenticalForEveryThreadCountAndBandSize) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> variants{
      {"t1", {"--threads", "1"}},     {"t2", {"--threads", "2"}},     {"t8", {"--threads", "8"}},
      {"b1", {"--band-layers", "1"}}, {"b7", {"--band-layers", "7"}},
  };
  std::string refCli, refSl1;
  std::map<std::string, std::string> refPng;
  for (const auto& [tag, extra] : variants) {
    std::vector<std::string> args{
        "slice",   examplePart().string(), "-H",        "0.05", "-o", tag + ".cli", "--cli-binary",
        "--masks", tag + ".sl1",           "--printer", "sl1",  "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult a = run(args);
    ASSERT_EQ(a.code(), 0) << tag << ": " << a.describe();
    std::vector<std::string> pngArgs{
        "slice", examplePart().string(), "-H", "0.05", "--masks", tag + "_png", "--printer", "sl1", "-q"};
    pngArgs.insert(pngArgs.end(), extra.begin(), extra.end());
    const RunResult b = run(pngArgs);
    ASSERT_EQ(b.code(), 0) << tag << ": " << b.describe();

    const std::string cli = readBytes(path(tag + ".cli")), sl1 = readBytes(path(tag + ".sl1"));
    const auto png = directoryContents(path(tag + "_png"));
    if (refCli.empty()) {
      refCli = cli;
      refSl1 = sl1;
      refPng = png;
      EXPECT_TRUE(cli.starts_with("$$HEADERSTART\n// written by toposlice //\n$$BINARY\n"));
      EXPECT_TRUE(contains(cli, "$$LAYERS/124\n"));  // ceil(6.2 / 0.05)
      EXPECT_EQ(png.size(), 124u);
      continue;
    }
    EXPECT_TRUE(cli == refCli) << tag << ": binary CLI differs from " << variants[0].first;
    EXPECT_TRUE(sl1 == refSl1) << tag << ": SL1 differs from " << variants[0].first;
    EXPECT_EQ(png.size(), refPng.size()) << tag;
    EXPECT_TRUE(png == refPng) << tag << ": PNG directory differs from " << variants[0].first;
  }
  expectNoTemporaries();
}

// Anti-aliased masks keep lit extents and reuse each pipeline slot's image from layer to layer (only
// the previous layer's lit spans are cleared): the archive must not depend on which layers share a slot.
TEST_F(CliToolDeterminism, AntiAliasedSl1IsByteIdenticalForEveryThreadCountAndBandSize) {
  std::string reference;
  for (const std::vector<std::string>& extra : {std::vector<std::string>{"--threads", "1"},
                                                {"--threads", "2"},
                                                {"--band-layers", "1"},
                                                {"--band-layers", "7"},
                                                {"--band-layers", "16"}}) {
    const std::string tag = "aa" + extra[0].substr(2, 1) + extra[1];
    std::vector<std::string> args{
        "slice", examplePart().string(), "-H", "0.05", "--masks", tag + ".sl1", "--printer",
        "sl1",   "--antialias",          "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult a = run(args);
    ASSERT_EQ(a.code(), 0) << tag << ": " << a.describe();
    const std::string sl1 = readBytes(path(tag + ".sl1"));
    if (reference.empty()) {
      reference = sl1;
      continue;
    }
    EXPECT_TRUE(sl1 == reference) << tag << ": anti-aliased SL1 differs from --threads 1";
  }
  expectNoTemporaries();
}

// The aligner's 545k facets take far longer to draw as the printer files' previews than its first
// layers take to slice: on more than one thread they are drawn beside the bands, the first SL1 layers
// set aside until the thumbnails are in the archive, the GOO and NanoDLP previews stored at finish
// (slice_job.cpp, "Deferred previews"). Each file is still the one-thread file, byte for byte.
TEST_F(CliToolDeterminism, PrinterFilesWithPreviewsDrawnBesideTheLayersAreTheOneThreadFiles) {
  const std::string aligner = sharedModel("derived/aligner_upper_case0.stl.gz").string();
  for (const std::string ext : {".sl1", ".goo", ".nanodlp"}) {
    std::string reference;
    for (const char* threads : {"1", "2", "4"}) {
      const std::string out = std::string("held") + threads + ext;
      const RunResult r = run(
          {"slice", aligner, "-H", "0.05", "--printer", "sl1", "--masks", out, "--threads", threads, "-q"});
      ASSERT_EQ(r.code(), 0) << threads << ": " << r.describe();
      const std::string bytes = readBytes(path(out));
      if (ext == ".sl1") {
        ASSERT_TRUE(contains(bytes.substr(0, 4096), "thumbnail/thumbnail400x400.png")) << threads;
      }
      if (reference.empty())
        reference = bytes;
      else
        EXPECT_TRUE(bytes == reference) << ext << ", --threads " << threads << ": differs from --threads 1";
    }
  }
  expectNoTemporaries();
}

// A .vdb carries a UUID in its header; ours is derived from the content, so the file is the same bytes for
// every thread count and band size, and another content gets another UUID.
TEST_F(CliToolDeterminism, VdbIsByteIdenticalForEveryThreadCountAndBandSize) {
  std::map<std::string, std::string> reference;
  for (const std::vector<std::string>& extra : {std::vector<std::string>{"--threads", "1"},
                                                {"--threads", "2"},
                                                {"--threads", "8"},
                                                {"--band-layers", "7"}}) {
    for (const std::string kind : {"single", "slabs"}) {
      const std::string tag = "v" + kind + extra[0].substr(2, 1) + extra[1];
      std::vector<std::string> args{
          "slice", examplePart().string(), "-H", "0.05", "--masks", tag + ".vdb", "--printer", "sl1", "-q"};
      if (kind == "slabs") args.insert(args.end(), {"--vdb-layout", "slabs", "--antialias"});
      args.insert(args.end(), extra.begin(), extra.end());
      const RunResult a = run(args);
      ASSERT_EQ(a.code(), 0) << tag << ": " << a.describe();
      const std::string vdb = readBytes(path(tag + ".vdb"));
      ASSERT_GT(vdb.size(), 57u) << tag;
      if (!reference.contains(kind)) {
        reference[kind] = vdb;
        continue;
      }
      EXPECT_TRUE(vdb == reference[kind]) << tag << ": VDB differs from --threads 1";
    }
  }
  // Binary single grid and anti-aliased slabs: different contents, different UUIDs (bytes 21 to 56).
  EXPECT_NE(reference["single"].substr(21, 36), reference["slabs"].substr(21, 36));
  expectNoTemporaries();
}

// The layer PNGs of an SL1 archive, by entry name.
std::map<std::string, std::vector<uint8_t>> sl1Layers(const fs::path& file) {
  std::map<std::string, std::vector<uint8_t>> layers;
  int err = 0;
  zip_t* zip = zip_open(file.c_str(), ZIP_RDONLY, &err);
  if (zip == nullptr) return layers;
  for (zip_int64_t i = 0; i < zip_get_num_entries(zip, 0); ++i) {
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_stat_index(zip, static_cast<zip_uint64_t>(i), 0, &st) != 0) continue;
    const std::string name = st.name;
    if (!name.ends_with(".png") || name.starts_with("thumbnail/")) continue;
    std::vector<uint8_t> data(st.size);
    if (zip_file_t* f = zip_fopen_index(zip, static_cast<zip_uint64_t>(i), 0)) {
      zip_fread(f, data.data(), st.size);
      zip_fclose(f);
    }
    layers[name] = std::move(data);
  }
  zip_close(zip);
  return layers;
}

// The prusaslicer.ini of an SL1 archive as key -> value.
std::map<std::string, std::string> sl1PrusaSlicerIni(const fs::path& file) {
  std::map<std::string, std::string> ini;
  int err = 0;
  zip_t* zip = zip_open(file.c_str(), ZIP_RDONLY, &err);
  if (zip == nullptr) return ini;
  zip_stat_t st;
  zip_stat_init(&st);
  if (zip_stat(zip, "prusaslicer.ini", 0, &st) == 0) {
    std::string text(st.size, '\0');
    zip_file_t* f = zip_fopen(zip, "prusaslicer.ini", 0);
    if (f != nullptr && zip_fread(f, text.data(), st.size) == static_cast<zip_int64_t>(st.size)) {
      std::istringstream in(text);
      for (std::string line; std::getline(in, line);)
        if (const std::size_t eq = line.find(" = "); eq != std::string::npos)
          ini[line.substr(0, eq)] = line.substr(eq + 3);
    }
    if (f != nullptr) zip_fclose(f);
  }
  zip_close(zip);
  return ini;
}

// The Prusa SL1 and SL1S show only images as tall as the display's long side (their firmware refuses
// others). The presets write PrusaSlicer's portrait images: with display_mirror_x = mx and
// display_mirror_y = my, the transpose of the landscape image mirrored by (!my, mx). Checked for every
// mirror setting on an L-shaped part (no symmetry to hide a wrong flip); PrusaSlicer itself agrees
// (bench/prusa_compare.sh, docs/BENCHMARKS.md).
TEST_F(CliToolMasks, Sl1PresetsWritePortraitImagesAsPrusaSlicer) {
  FacetSoup l = fixtures::box(0, 0, 0, 20, 4, 2);
  fixtures::append(l, fixtures::box(0, 0, 0, 4, 12, 2));
  writeBinaryStl(path("l.stl"), l, "L", false);
  const auto pngOf = [](const std::vector<uint8_t>& bytes) {
    MaskImage m;
    EXPECT_TRUE(decodeMaskPng(bytes, m));
    return m;
  };
  // Pixel (column c, row r from the top) of a decoded PNG.
  const auto at = [](const MaskImage& m, uint32_t c, uint32_t r) {
    return m.pixels[static_cast<std::size_t>(m.height - 1 - r) * m.width + c];
  };
  for (const char* printer : {"sl1", "sl1s"}) {
    const RunResult preset = run({"slice", path("l.stl").string(), "-H", "1", "--printer", printer, "--masks",
                                  path("p.sl1").string(), "-f", "-q"});
    ASSERT_EQ(preset.code(), 0) << preset.describe();
    auto ini = sl1PrusaSlicerIni(path("p.sl1"));
    EXPECT_EQ(ini["display_orientation"], "portrait") << printer;
    EXPECT_EQ(ini["display_mirror_x"], "1") << printer;
    EXPECT_EQ(ini["display_mirror_y"], "0") << printer;
    EXPECT_EQ(ini["display_pixels_x"], "2560") << printer;
    const auto layers = sl1Layers(path("p.sl1"));
    ASSERT_EQ(layers.size(), 2u) << printer;
    const MaskImage first = pngOf(layers.begin()->second);
    EXPECT_EQ(first.width, std::string(printer) == "sl1" ? 1440u : 1620u) << printer;
    EXPECT_EQ(first.height, 2560u) << printer;
  }
  for (const int mx : {0, 1}) {
    for (const int my : {0, 1}) {
      const RunResult portrait =
          run({"slice", path("l.stl").string(), "-H", "1", "--printer", "sl1", "--set",
               "display_mirror_x=" + std::to_string(mx), "--set", "display_mirror_y=" + std::to_string(my),
               "--masks", path("p.sl1").string(), "-f", "-q"});
      std::vector<std::string> landscapeArgs{"slice",     path("l.stl").string(),
                                             "-H",        "1",
                                             "--printer", "sl1",
                                             "--set",     "display_orientation=landscape",
                                             "--set",     "display_mirror_x=0",
                                             "--masks",   path("l.sl1").string(),
                                             "-f",        "-q"};
      if (!my) landscapeArgs.push_back("--mirror-x");
      if (mx) landscapeArgs.push_back("--mirror-y");
      const RunResult landscape = run(landscapeArgs);
      ASSERT_EQ(portrait.code(), 0) << portrait.describe();
      ASSERT_EQ(landscape.code(), 0) << landscape.describe();
      auto ini = sl1PrusaSlicerIni(path("p.sl1"));
      EXPECT_EQ(ini["display_mirror_x"], std::to_string(mx));
      EXPECT_EQ(ini["display_mirror_y"], std::to_string(my));
      const auto p = sl1Layers(path("p.sl1")), q = sl1Layers(path("l.sl1"));
      ASSERT_EQ(p.size(), q.size());
      for (auto i = p.begin(), j = q.begin(); i != p.end(); ++i, ++j) {
        const MaskImage a = pngOf(i->second), b = pngOf(j->second);
        ASSERT_EQ(a.width, b.height);
        ASSERT_EQ(a.height, b.width);
        uint64_t lit = 0, differ = 0;
        for (uint32_t r = 0; r < a.height; ++r)
          for (uint32_t c = 0; c < a.width; ++c) {
            lit += at(a, c, r) != 0;
            differ += at(a, c, r) != at(b, r, c);
          }
        EXPECT_GT(lit, 1000u) << i->first;
        EXPECT_EQ(differ, 0u) << "mirror " << mx << my << ", " << i->first;
      }
    }
  }
  // Volumes and landscape printer files take the preset's grid but not its display orientation; a
  // portrait asked for by name is refused for them.
  const RunResult exr = run({"slice", path("l.stl").string(), "-H", "1", "--printer", "sl1", "--masks",
                             path("v.exr").string(), "-f", "-q"});
  EXPECT_EQ(exr.code(), 0) << exr.describe();
  const RunResult asked = run({"slice", path("l.stl").string(), "-H", "1", "--printer", "sl1", "--set",
                               "display_orientation=portrait", "--masks", path("w.exr").string(), "-q"});
  expectOneErrorLine(asked);
  EXPECT_NE(asked.err.find("SL1 archives and PNG folders only"), std::string::npos) << asked.err;
  // There the preset's own mirroring goes with its portrait display, but a mirroring the user set
  // applies, as --mirror-y does (it was dropped without a word, while --explain and the summary said
  // display_mirror_y = 1); --explain says what the masks have.
  const auto goo = [&](const std::string& out, std::vector<std::string> extra) {
    std::vector<std::string> args{
        "slice", path("l.stl").string(), "-H", "1", "--printer", "sl1", "--masks", out, "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.code(), 0) << r.describe();
    return r.out;
  };
  goo("plain.goo", {});
  goo("set.goo", {"--set", "display_mirror_y=1"});
  goo("option.goo", {"--mirror-y"});
  EXPECT_NE(readBytes(path("plain.goo")), readBytes(path("set.goo")));
  EXPECT_EQ(readBytes(path("set.goo")), readBytes(path("option.goo")));
  const std::string explained = goo("e.goo", {"--display-mirror-y", "1", "--explain"});
  EXPECT_TRUE(
      contains(explained, "display_orientation        = landscape    (printer sl1, as .goo masks have it)"))
      << explained;
  EXPECT_TRUE(
      contains(explained, "display_mirror_x           = 0            (printer sl1, as .goo masks have it)"))
      << explained;
  EXPECT_TRUE(contains(explained, "display_mirror_y           = 1            (command line)")) << explained;
}

// EXR stacks: the same bytes for every thread count and band size, and every layer, read by tinyexr,
// the pixels of the SL1 layer of the same run (binary and anti-aliased).
TEST_F(CliToolDeterminism, ExrStackIsByteIdenticalAndMatchesTheSl1) {
  for (const bool antiAliased : {false, true}) {
    std::map<std::string, std::string> reference;
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--threads", "1"}, {"--threads", "2"}, {"--band-layers", "7"}}) {
      const std::string tag = (antiAliased ? "aa" : "bin") + extra[0].substr(2, 1) + extra[1];
      // The SL1 in the EXR's landscape frame (the sl1 preset's display is portrait).
      std::vector<std::string> args{"slice",     examplePart().string(),
                                    "-H",        "0.1",
                                    "--printer", "sl1",
                                    "--set",     "display_orientation=landscape",
                                    "--set",     "display_mirror_x=0",
                                    "-q"};
      if (antiAliased) args.push_back("--antialias");
      args.insert(args.end(), extra.begin(), extra.end());
      std::vector<std::string> exrArgs = args, sl1Args = args;
      exrArgs.insert(exrArgs.end(), {"--masks", tag + ".exr"});
      sl1Args.insert(sl1Args.end(), {"--masks", tag + ".sl1"});
      const RunResult a = run(exrArgs);
      ASSERT_EQ(a.code(), 0) << tag << ": " << a.describe();
      const auto files = directoryContents(path(tag + ".exr"));
      if (reference.empty()) {
        reference = files;
        const RunResult b = run(sl1Args);
        ASSERT_EQ(b.code(), 0) << tag << ": " << b.describe();
        const auto pngs = sl1Layers(path(tag + ".sl1"));
        ASSERT_EQ(pngs.size(), 62u) << tag;  // ceil(6.2 / 0.1)
        ASSERT_EQ(files.size(), pngs.size()) << tag;
        uint32_t k = 0;
        for (const auto& [name, png] : pngs) {
          MaskImage expected;
          ASSERT_TRUE(decodeMaskPng(png, expected)) << name;
          const TinyExrLayer layer =
              readExrWithTinyExr(path(tag + ".exr") / exrLayerFileName("example_part", k, 62));
          ASSERT_EQ(layer.error, "") << tag << " layer " << k;
          EXPECT_EQ(layer.layer, static_cast<int>(k));
          EXPECT_TRUE(layer.exact) << tag << " layer " << k;
          EXPECT_TRUE(layer.mask.pixels == expected.pixels)
              << tag << " layer " << k << " differs from " << name;
          ++k;
        }
        continue;
      }
      EXPECT_TRUE(files == reference) << tag << ": EXR stack differs from --threads 1";
    }
  }
  expectNoTemporaries();
}

TEST_F(CliToolDeterminism, FemurGivesTheSameCliForEveryMethod) {
  const std::string femur = sharedModel("knee_femur_ssm_S001.stl").string();
  std::map<std::string, std::string> cli;
  for (const std::string method : {"cp", "sr-lazy", "sr"}) {
    const RunResult r =
        run({"slice", femur, "-H", "0.5", "--method", method, "-o", method + ".cli", "--cli-binary", "-q"});
    ASSERT_EQ(r.code(), 0) << method << ": " << r.describe();
    cli[method] = readBytes(path(method + ".cli"));
  }
  EXPECT_GT(cli["sr"].size(), 1000u);
  EXPECT_TRUE(cli["cp"] == cli["sr"]) << "cp and sr differ";
  EXPECT_TRUE(cli["sr-lazy"] == cli["sr"]) << "sr-lazy and sr differ";
}

// ---------------------------------------------------------------------------------------------------
// 6. template reuse (intra-model)

TEST_F(CliToolTemplate, VariantSlicedWithTheTableMatchesSlicingFromScratch) {
  const RunResult t = run({"template", sharedModel("knee_femur_ssm_S001.stl").string(), "-o", "t.topo"});
  ASSERT_EQ(t.code(), 0) << t.describe();
  EXPECT_EQ(fs::file_size(path("t.topo")), 40u + 12u * 14622u);  // TEMPLATES.md: 40 + 12 t bytes

  const std::string s002 = sharedModel("knee_femur_ssm_S002.stl").string();
  const RunResult withTable = run({"slice", s002, "-H", "0.5", "--template", "t.topo", "-o", "a.cli"});
  ASSERT_EQ(withTable.code(), 0) << withTable.describe();
  EXPECT_TRUE(contains(withTable.out, "loaded from template")) << withTable.out;
  const RunResult scratch = run({"slice", s002, "-H", "0.5", "-o", "b.cli"});
  ASSERT_EQ(scratch.code(), 0) << scratch.describe();
  EXPECT_TRUE(contains(scratch.out, "built")) << scratch.out;
  EXPECT_TRUE(readBytes(path("a.cli")) == readBytes(path("b.cli")));
  EXPECT_GT(fs::file_size(path("a.cli")), 1000u);
}

// A variant inside out against its template (here the femur mirrored in x: the same facets, every one
// turned around), flipped by --fix-orientation, is every template facet reversed: sliced with the table
// (edges 1 and 2 of each facet trade places), as from scratch. It failed the connectivity check.
TEST_F(CliToolTemplate, FlippedInsideOutVariantUsesTheTable) {
  ASSERT_EQ(run({"template", sharedModel("knee_femur_ssm_S001.stl").string(), "-o", "t.topo", "-q"}).code(),
            0);
  FacetSoup mirrored = readMesh(sharedModel("knee_femur_ssm_S002.stl"), {});
  for (Point3f& p : mirrored.corners) p.x = -p.x;
  writeBinaryStl(path("mirrored.stl"), mirrored, "mirrored", false);
  const RunResult withTable =
      run({"slice", "mirrored.stl", "-H", "0.5", "--template", "t.topo", "--fix-orientation", "-o", "a.cli"});
  ASSERT_EQ(withTable.code(), 0) << withTable.describe();
  EXPECT_TRUE(contains(withTable.out, "loaded from template, every facet reversed")) << withTable.out;
  const RunResult scratch = run({"slice", "mirrored.stl", "-H", "0.5", "--fix-orientation", "-o", "b.cli"});
  ASSERT_EQ(scratch.code(), 0) << scratch.describe();
  EXPECT_TRUE(readBytes(path("a.cli")) == readBytes(path("b.cli")));
  EXPECT_GT(fs::file_size(path("a.cli")), 1000u);
  // Not flipped, it matches the table as it is (and warns that it is inside out).
  const RunResult asIs = run({"slice", "mirrored.stl", "-H", "0.5", "--template", "t.topo", "-o", "c.cli"});
  ASSERT_EQ(asIs.code(), 0) << asIs.describe();
  EXPECT_TRUE(contains(asIs.out, "loaded from template (connectivity verified)")) << asIs.out;
}

TEST_F(CliToolTemplate, MismatchingVariantsAndBadTablesAreRefused) {
  const RunResult t = run({"template", sharedModel("knee_femur_ssm_S001.stl").string(), "-o", "t.topo"});
  ASSERT_EQ(t.code(), 0) << t.describe();
  const std::string s002 = sharedModel("knee_femur_ssm_S002.stl").string();

  // Another shape model: a different facet count.
  {
    const RunResult r = run({"slice", sharedModel("knee_tibia_ssm_S001.stl").string(), "-H", "0.5",
                             "--template", "t.topo", "-o", "tibia.cli"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "knee_tibia_ssm_S001.stl")) << r.err;
    EXPECT_TRUE(contains(r.err, "does not share the template's connectivity")) << r.err;
    EXPECT_TRUE(contains(r.err, "11756")) << r.err;
    EXPECT_TRUE(contains(r.err, "14622")) << r.err;
    EXPECT_FALSE(fs::exists(path("tibia.cli")));
  }

  // S002 with two facet records swapped: same count, other connectivity.
  {
    std::string stl = readBytes(s002);
    ASSERT_EQ(stl.size(), 84u + 50u * le32(stl, 80));
    const std::size_t a = 84 + 50 * 10, b = 84 + 50 * 5000;
    const std::string recordA = stl.substr(a, 50);
    stl.replace(a, 50, stl.substr(b, 50));
    stl.replace(b, 50, recordA);
    writeBytes(path("swapped.stl"), stl);

    const RunResult r = run({"slice", "swapped.stl", "-H", "0.5", "--template", "t.topo", "-o", "sw.cli"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "swapped.stl")) << r.err;
    EXPECT_TRUE(contains(r.err, "does not share the template's connectivity")) << r.err;
    bool namesFacet = false;
    for (std::size_t p = r.err.find("facet "); p != std::string::npos; p = r.err.find("facet ", p + 1))
      namesFacet =
          namesFacet || (p + 6 < r.err.size() && std::isdigit(static_cast<unsigned char>(r.err[p + 6])));
    EXPECT_TRUE(namesFacet) << "no facet index in: " << r.err;
    EXPECT_FALSE(fs::exists(path("sw.cli")));

    const RunResult rebuilt = run({"slice", "swapped.stl", "-H", "0.5", "--template", "t.topo",
                                   "--on-mismatch", "rebuild", "-o", "sw.cli"});
    ASSERT_EQ(rebuilt.code(), 0) << rebuilt.describe();
    EXPECT_TRUE(contains(rebuilt.out, "rebuilt")) << rebuilt.out;
    EXPECT_TRUE(readBytes(path("sw.cli")).starts_with("$$HEADERSTART\n"));
    // The rebuild is a warning, so that -q does not hide that the variant did not match.
    const RunResult quiet = run({"slice", "swapped.stl", "-H", "0.5", "--template", "t.topo", "--on-mismatch",
                                 "rebuild", "-o", "sw.cli", "--force", "-q"});
    ASSERT_EQ(quiet.code(), 0) << quiet.describe();
    EXPECT_TRUE(quiet.out.empty()) << quiet.out;
    EXPECT_TRUE(contains(quiet.err, "toposlice: warning: swapped.stl: does not match the template"))
        << quiet.err;
  }

  const std::string table = readBytes(path("t.topo"));
  // One flipped bit in the middle of the table.
  {
    std::string corrupt = table;
    corrupt[corrupt.size() / 2] = static_cast<char>(corrupt[corrupt.size() / 2] ^ 0x40);
    writeBytes(path("corrupt.topo"), corrupt);
    const RunResult r = run({"slice", s002, "-H", "0.5", "--template", "corrupt.topo", "-o", "c.cli"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "corrupt.topo")) << r.err;
    EXPECT_TRUE(contains(r.err, "corrupt")) << r.err;
    EXPECT_FALSE(fs::exists(path("c.cli")));
  }
  // Cut short.
  {
    writeBytes(path("short.topo"), table.substr(0, table.size() / 3));
    const RunResult r = run({"slice", s002, "-H", "0.5", "--template", "short.topo", "-o", "s.cli"});
    expectOneErrorLine(r);
    EXPECT_TRUE(contains(r.err, "short.topo")) << r.err;
    EXPECT_TRUE(contains(r.err, "truncated")) << r.err;
    EXPECT_FALSE(fs::exists(path("s.cli")));
  }
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 7. batch

// The status word of a variant's line in a batch summary ("<name> : <status> ..."), empty if absent.
std::string batchStatus(const std::string& out, const std::string& name, std::string* line = nullptr) {
  for (const auto& l : splitLines(out)) {
    std::istringstream in(l);
    std::string first, colon, status;
    in >> first >> colon >> status;
    if (first == name && colon == ":") {
      if (line) *line = l;
      return status;
    }
  }
  return {};
}

struct FileStamp {
  ino_t inode = 0;
  timespec mtime{};
  bool operator==(const FileStamp& o) const {
    return inode == o.inode && mtime.tv_sec == o.mtime.tv_sec && mtime.tv_nsec == o.mtime.tv_nsec;
  }
};

FileStamp stampOf(const fs::path& p) {
  struct stat s {};
  EXPECT_EQ(::stat(p.c_str(), &s), 0) << p;
  return {s.st_ino, s.st_mtim};
}

TEST_F(CliToolBatch, SlicesEveryMatchingVariantReportsTheMismatchAndSkipsCompleteOnesOnRerun) {
  const std::string json =
      "{\n"
      "  \"version\": 1,\n"
      "  \"description\": \"femur variants and one tibia that does not fit the template\",\n"
      "  \"template\": {\"model\": " +
      jsonString(sharedModel("knee_femur_ssm_S001.stl").string()) +
      ", \"table\": \"tables/femur.topo\"},\n"
      "  \"settings\": {\"layer_height\": 0.5, \"method\": \"sr\"},\n"
      "  \"variants\": [\n"
      "    {\"name\": \"s002\", \"model\": " +
      jsonString(sharedModel("knee_femur_ssm_S002.stl").string()) +
      ", \"contours\": \"out/s002.cli\"},\n"
      "    {\"name\": \"s003\", \"model\": " +
      jsonString(sharedModel("knee_femur_ssm_S003.stl").string()) +
      ", \"contours\": \"out/s003.cli\"},\n"
      "    {\"name\": \"mean\", \"model\": " +
      jsonString(sharedModel("knee_femur_ssm_mean.stl").string()) +
      ", \"contours\": \"out/mean.cli\"},\n"
      "    {\"name\": \"tibia\", \"model\": " +
      jsonString(sharedModel("knee_tibia_ssm_S001.stl").string()) +
      ", \"contours\": \"out/tibia.cli\"}\n"
      "  ]\n"
      "}\n";
  writeBytes(path("job.json"), json);
  const std::vector<std::pair<std::string, std::string>> femurs{{"s002", "knee_femur_ssm_S002.stl"},
                                                                {"s003", "knee_femur_ssm_S003.stl"},
                                                                {"mean", "knee_femur_ssm_mean.stl"}};

  const RunResult first = run({"batch", "job.json"});
  EXPECT_EQ(first.code(), 1) << first.describe();
  for (const auto& [name, model] : femurs) EXPECT_EQ(batchStatus(first.out, name), "ok") << first.out;
  std::string tibiaLine;
  EXPECT_EQ(batchStatus(first.out, "tibia", &tibiaLine), "failed") << first.out;
  EXPECT_TRUE(contains(tibiaLine, "does not share the template's connectivity")) << tibiaLine;
  EXPECT_TRUE(contains(first.out, "3 sliced")) << first.out;
  EXPECT_TRUE(contains(first.out, "1 failed")) << first.out;
  EXPECT_FALSE(fs::exists(path("out/tibia.cli")));
  EXPECT_TRUE(fs::exists(path("tables/femur.topo")));

  // Every output equals a single `slice --template` run with the same settings.
  const RunResult t =
      run({"template", sharedModel("knee_femur_ssm_S001.stl").string(), "-o", "t.topo", "-q"});
  ASSERT_EQ(t.code(), 0) << t.describe();
  EXPECT_TRUE(readBytes(path("t.topo")) == readBytes(path("tables/femur.topo")));
  std::map<std::string, FileStamp> stamps;
  std::map<std::string, std::string> bytes;
  for (const auto& [name, model] : femurs) {
    const fs::path out = path("out/" + name + ".cli");
    ASSERT_TRUE(fs::exists(out)) << out;
    const RunResult single = run({"slice", sharedModel(model).string(), "-H", "0.5", "--template", "t.topo",
                                  "-o", name + "_single.cli", "-q"});
    ASSERT_EQ(single.code(), 0) << single.describe();
    bytes[name] = readBytes(out);
    EXPECT_TRUE(bytes[name] == readBytes(path(name + "_single.cli"))) << name << ": batch and slice differ";
    stamps[name] = stampOf(out);
  }

  std::this_thread::sleep_for(20ms);  // a rewrite would get a later mtime
  const RunResult again = run({"batch", "job.json"});
  EXPECT_EQ(again.code(), 1) << again.describe();
  for (const auto& [name, model] : femurs) {
    EXPECT_EQ(batchStatus(again.out, name), "complete") << again.out;
    EXPECT_TRUE(stampOf(path("out/" + name + ".cli")) == stamps[name]) << name << " was rewritten";
    EXPECT_TRUE(readBytes(path("out/" + name + ".cli")) == bytes[name]) << name;
  }
  EXPECT_EQ(batchStatus(again.out, "tibia"), "failed") << again.out;
  EXPECT_TRUE(contains(again.out, "3 already complete")) << again.out;
  EXPECT_TRUE(contains(again.out, "1 failed")) << again.out;
  expectNoTemporaries();
  EXPECT_TRUE(temporariesIn(path("out")).empty());

  // An output that is not toposlice's (another program's file at its path, or one cut short) is no
  // finished variant: it fails naming the file, which stays (it was skipped as "complete").
  const std::string victim = femurs.begin()->first;
  writeBytes(path("out/" + victim + ".cli"), "my own notes");
  const RunResult foreign = run({"batch", "job.json"});
  std::string line;
  EXPECT_EQ(batchStatus(foreign.out, victim, &line), "failed") << foreign.out;
  EXPECT_TRUE(contains(foreign.err, "not a cli file toposlice wrote")) << foreign.err;
  EXPECT_EQ(readBytes(path("out/" + victim + ".cli")), "my own notes");
  // An empty output, or one of ours cut short, is not finished either: sliced again, whole.
  for (const std::string& broken : {std::string(), bytes[victim].substr(0, bytes[victim].size() / 2)}) {
    writeBytes(path("out/" + victim + ".cli"), broken);
    const RunResult redo = run({"batch", "job.json"});
    EXPECT_EQ(batchStatus(redo.out, victim), "ok") << redo.out;
    EXPECT_TRUE(readBytes(path("out/" + victim + ".cli")) == bytes[victim]) << broken.size();
  }
}

// A table left from another template (the job's template.model changed, the table file stayed): the
// job is refused naming both, before any variant (each was blamed for its connectivity).
TEST_F(CliToolBatch, ATableOfAnotherTemplateIsRefused) {
  ASSERT_EQ(run({"template", sharedModel("knee_femur_ssm_S001.stl").string(), "-o", "t.topo", "-q"}).code(),
            0);
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": " + jsonString(sharedModel("knee_tibia_ssm_S001.stl").string()) +
                 ", \"table\": \"t.topo\"}, \"settings\": {\"layer_height\": 1}, \"variants\": "
                 "[{\"name\": \"t2\", \"model\": " +
                 jsonString(sharedModel("knee_tibia_ssm_S002.stl").string()) +
                 ", \"contours\": \"t2.cli\"}]}");
  const RunResult r = run({"batch", "job.json", "-q"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "template.table") && contains(r.err, "is not the table of template.model"))
      << r.err;
  EXPECT_TRUE(contains(r.err, "the model has 11756 facets, the table has 14622")) << r.err;
  EXPECT_FALSE(fs::exists(path("t2.cli")));
}

// The table of an inside-out template built without "fix_orientation" is its table with every facet
// reversed for a job with it: accepted (it was refused as another model's), the variant sliced.
TEST_F(CliToolBatch, ATableBuiltWithTheOtherOrientationIsTheModels) {
  FacetSoup mirrored = readMesh(sharedModel("knee_femur_ssm_S001.stl"), {});
  for (Point3f& p : mirrored.corners) p.x = -p.x;
  writeBinaryStl(path("t.stl"), mirrored, "mirrored", false);
  ASSERT_EQ(run({"template", "t.stl", "-o", "t.topo", "-q"}).code(), 0);
  writeBytes(path("job.json"),
             "{\"template\": {\"model\": \"t.stl\", \"table\": \"t.topo\"}, \"settings\": "
             "{\"layer_height\": 1, \"fix_orientation\": true}, \"variants\": [{\"name\": \"v\", "
             "\"model\": \"t.stl\", \"contours\": \"v.cli\"}]}");
  const RunResult r = run({"batch", "job.json"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_EQ(batchStatus(r.out, "v"), "ok") << r.out;
  EXPECT_TRUE(contains(r.out, "every facet reversed")) << r.out;
}

// ---------------------------------------------------------------------------------------------------
// 8. masks and report

TEST_F(CliToolMasks, Sl1ArchiveAndReportOfTheExamplePart) {
  const RunResult r = run({"slice", examplePart().string(), "--masks", "out.sl1", "--printer", "sl1", "-H",
                           "0.05", "--report", "r.csv"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, "resin")) << r.out;

  constexpr std::size_t kLayers = 124;  // ceil(6.2 mm / 0.05 mm)
  const auto names = zipEntryNames(readBytes(path("out.sl1")));
  EXPECT_EQ(names.size(), kLayers + 4);
  EXPECT_EQ(std::count(names.begin(), names.end(), "config.ini"), 1);
  EXPECT_EQ(std::count(names.begin(), names.end(), "prusaslicer.ini"), 1);
  // PrusaSlicer's two thumbnails, then the layers.
  EXPECT_EQ(std::count(names.begin(), names.end(), "thumbnail/thumbnail400x400.png"), 1);
  EXPECT_EQ(std::count(names.begin(), names.end(), "thumbnail/thumbnail800x480.png"), 1);
  EXPECT_EQ(
      std::count_if(names.begin(), names.end(),
                    [](const std::string& n) { return n.ends_with(".png") && !n.starts_with("thumbnail/"); }),
      static_cast<std::ptrdiff_t>(kLayers));

  const auto lines = splitLines(readBytes(path("r.csv")));
  ASSERT_EQ(lines.size(), kLayers + 1);
  EXPECT_TRUE(lines.front().starts_with("layer,")) << lines.front();
  EXPECT_TRUE(lines[1].starts_with("0,")) << lines[1];
  EXPECT_TRUE(lines[kLayers].starts_with(std::to_string(kLayers - 1) + ",")) << lines[kLayers];
  // Every line is a CSV row (no comment trailer); the resin volume is the sum of area x thickness.
  double ml = 0;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto fields = lines[i].find(',', lines[i].find(',') + 1);
    ml += std::stod(lines[i].substr(fields + 1)) * 0.05 / 1000.0;
  }
  // Square frame 12 x 12 with a 6 x 6 hole, 4 mm tall; sphere r = 1.5; torus R = 4, r = 1.2, less its
  // lowest 0.2 mm, which the masks count once, inside the frame: the circular segment of the tube 1 mm
  // below its centre, turned about the axis (Pappus: its area x 2 pi R, its centroid being at R). The few
  // percent of that segment over the hole, not inside the frame, are left out.
  const double pi = std::numbers::pi;
  const double segmentMm2 = 1.2 * 1.2 * std::acos(1.0 / 1.2) - 1.0 * std::sqrt(1.2 * 1.2 - 1.0 * 1.0);
  const double analyticMm3 = (12.0 * 12.0 - 6.0 * 6.0) * 4.0 + 2.0 * pi * pi * 4.0 * 1.2 * 1.2 -
                             segmentMm2 * 2.0 * pi * 4.0 + 4.0 / 3.0 * pi * 1.5 * 1.5 * 1.5;
  EXPECT_NEAR(ml, analyticMm3 / 1000.0, 0.02 * analyticMm3 / 1000.0) << ml;
  expectNoTemporaries();

  // The printer's build height reaches prusaslicer.ini (it said 150 whatever the printer's was); none
  // (0) gives PrusaSlicer's 150.
  EXPECT_EQ(sl1PrusaSlicerIni(path("out.sl1"))["max_print_height"], "150");  // the sl1 preset's
  for (const auto& [given, written] :
       {std::pair{"200", "200"}, std::pair{"40", "40"}, std::pair{"0", "150"}}) {
    const RunResult h = run({"slice", examplePart().string(), "--masks", "h.sl1", "--printer", "sl1", "-H",
                             "0.5", "--max-print-height", given, "--force", "-q"});
    ASSERT_EQ(h.code(), 0) << h.describe();
    EXPECT_EQ(sl1PrusaSlicerIni(path("h.sl1"))["max_print_height"], written) << given;
  }
  // Numbers in fixed notation, never the exponent form of the shortest text ("1e-05").
  ASSERT_EQ(run({"slice", examplePart().string(), "--masks", "h.sl1", "--printer", "sl1", "-H", "0.5",
                 "--exposure-time", "0.00001", "--absolute-correction", "0.0000001", "--force", "-q"})
                .code(),
            0);
  auto ini = sl1PrusaSlicerIni(path("h.sl1"));
  EXPECT_EQ(ini["exposure_time"], "0.00001");
  EXPECT_EQ(ini["absolute_correction"], "0.0000001");
}

TEST_F(CliToolMasks, ModelThatDoesNotFitNeedsCrop) {
  const RunResult r = run({"slice", examplePart().string(), "--layers", "4", "--masks", "m.sl1", "--printer",
                           "sl1", "--pixel", "0.001"});
  expectOneErrorLine(r);
  EXPECT_TRUE(contains(r.err, "does not fit")) << r.err;
  EXPECT_TRUE(contains(r.err, "--crop")) << r.err;
  EXPECT_FALSE(fs::exists(path("m.sl1")));
  expectNoTemporaries();

  const RunResult cropped = run({"slice", examplePart().string(), "--layers", "4", "--masks", "m.sl1",
                                 "--printer", "sl1", "--pixel", "0.001", "--crop"});
  ASSERT_EQ(cropped.code(), 0) << cropped.describe();
  EXPECT_EQ(zipEntryNames(readBytes(path("m.sl1"))).size(), 4u + 2u + 2u);  // layers, ini files, thumbnails
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 9. features (inter-model reuse)

// Without masks the report's area is the solid region's under the positive rule, as the masks light it:
// an add-on over the model counts once, a removal reaching out of the model takes nothing there. (The
// signed areas' sum said 100 + 100 - 30 = 170 here.)
TEST_F(CliToolFeatures, ContourOnlyAreaIsTheSolidRegions) {
  writeBinaryStl(path("model.stl"), fixtures::box(0, 0, 0, 10, 10, 2), "model", false);
  writeBinaryStl(path("add.stl"), fixtures::box(5, 0, 0, 15, 10, 2), "add", false);
  writeBinaryStl(path("remove.stl"), fixtures::box(-2, 0, 0, 1, 10, 2), "remove", false);
  const RunResult r = run({"slice", "model.stl", "--add", "add.stl", "--remove", "remove.stl", "-H", "1",
                           "-o", "a.cli", "--report", "a.csv", "--summary", "a.json", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const std::string csv = readBytes(path("a.csv"));
  EXPECT_TRUE(contains(csv, "0,0.500000,140.000000,")) << csv;
  EXPECT_TRUE(contains(csv, "1,1.500000,140.000000,")) << csv;
  // The masks' area, for comparison: the same region (0.1 mm pixels, binary).
  const RunResult m =
      run({"slice", "model.stl", "--add", "add.stl", "--remove", "remove.stl", "-H", "1", "--masks", "m",
           "--pixel", "0.1", "--resolution", "300x200", "--report", "m.csv", "-q"});
  ASSERT_EQ(m.code(), 0) << m.describe();
  EXPECT_TRUE(contains(readBytes(path("m.csv")), "0,0.500000,140.000000,")) << readBytes(path("m.csv"));
}

// The same for a model whose own shells intersect (neighbouring teeth of a dental arch, a part joined by
// placing one box into another): their common part counts once, as the masks light it, where the signed
// areas' sum said 100 + 100 + 50 = 250 here. A disjoint island beside them counts as it is.
TEST_F(CliToolFeatures, ContourOnlyAreaCountsIntersectingShellsOnce) {
  FacetSoup model = fixtures::box(0, 0, 0, 10, 10, 2);
  for (const FacetSoup& shell : {fixtures::box(5, 5, 0, 15, 15, 2), fixtures::box(20, 0, 0, 25, 10, 2)})
    model.corners.insert(model.corners.end(), shell.corners.begin(), shell.corners.end());
  writeBinaryStl(path("model.stl"), model, "model", false);
  const RunResult r = run({"slice", "model.stl", "-H", "1", "-o", "a.cli", "--report", "a.csv", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const std::string csv = readBytes(path("a.csv"));
  EXPECT_TRUE(contains(csv, "0,0.500000,225.000000,")) << csv;
  EXPECT_TRUE(contains(csv, "1,1.500000,225.000000,")) << csv;
  const RunResult m = run({"slice", "model.stl", "-H", "1", "--masks", "m", "--pixel", "0.1", "--resolution",
                           "300x200", "--report", "m.csv", "-q"});
  ASSERT_EQ(m.code(), 0) << m.describe();
  EXPECT_TRUE(contains(readBytes(path("m.csv")), "0,0.500000,225.000000,")) << readBytes(path("m.csv"));
}

TEST_F(CliToolFeatures, AddOnsLightMorePixelsAndEngravingsFewer) {
  const std::string aligner = sharedModel("derived/aligner_upper_case0.stl.gz").string();
  const std::string monogram = sharedModel("derived/monogram_A1_on_aligner.stl").string();
  const std::string engraving = sharedModel("derived/engraving_Q7_on_aligner.stl").string();
  const std::vector<std::string> common{"--layers", "40", "--printer", "sl1", "-q"};
  auto slice = [&](const std::string& model, const std::string& out, std::vector<std::string> extra) {
    std::vector<std::string> args{"slice", model, "--masks", out};
    args.insert(args.end(), common.begin(), common.end());
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args);
  };

  const RunResult plain = slice(aligner, "plain", {});
  ASSERT_EQ(plain.code(), 0) << plain.describe();
  const RunResult added = slice(aligner, "added", {"--add", monogram});
  ASSERT_EQ(added.code(), 0) << added.describe();
  const RunResult removed = slice(aligner, "removed", {"--remove", engraving});
  ASSERT_EQ(removed.code(), 0) << removed.describe();

  std::size_t images = 0;
  const uint64_t litPlain = litPixelsInDirectory(path("plain"), &images);
  EXPECT_EQ(images, 40u);
  const uint64_t litAdded = litPixelsInDirectory(path("added"), &images);
  EXPECT_EQ(images, 40u);
  const uint64_t litRemoved = litPixelsInDirectory(path("removed"), &images);
  EXPECT_EQ(images, 40u);
  EXPECT_GT(litPlain, 0u);
  EXPECT_GT(litAdded, litPlain);
  EXPECT_LT(litRemoved, litPlain);

  // The template's table is not touched by features: the next stage slices with it and an add-on.
  const RunResult t = run({"template", aligner, "-o", "aligner.topo", "-q"});
  ASSERT_EQ(t.code(), 0) << t.describe();
  const RunResult stage2 =
      run({"slice", sharedModel("derived/aligner_upper_case0_stage2.stl.gz").string(), "--template",
           "aligner.topo", "--add", monogram, "--masks", "stage2", "--layers", "40", "--printer", "sl1"});
  ASSERT_EQ(stage2.code(), 0) << stage2.describe();
  EXPECT_TRUE(contains(stage2.out, "loaded from template")) << stage2.out;
  EXPECT_GT(litPixelsInDirectory(path("stage2"), &images), 0u);
  EXPECT_EQ(images, 40u);
  expectNoTemporaries();
}

// An ASCII CLI file's labels and layers: every polyline with its id, dir and points (a closed polyline's
// repeated last point dropped).
struct ParsedCli {
  std::vector<std::string> labels;  // "$$LABEL/" lines without the command
  struct Polyline {
    int id = 0, dir = 0;
    std::vector<Point2d> points;
  };
  std::vector<std::vector<Polyline>> layers;
};

ParsedCli parseAsciiCli(const std::string& text) {
  ParsedCli cli;
  for (const std::string& line : splitLines(text)) {
    if (line.starts_with("$$LABEL/")) cli.labels.push_back(line.substr(8));
    if (line.starts_with("$$LAYER/")) cli.layers.emplace_back();
    if (!line.starts_with("$$POLYLINE/") || cli.layers.empty()) continue;
    std::vector<double> v;
    std::istringstream in(line.substr(11));
    for (std::string item; std::getline(in, item, ',');) v.push_back(std::stod(item));
    ParsedCli::Polyline poly;
    poly.id = static_cast<int>(v.at(0));
    poly.dir = static_cast<int>(v.at(1));
    const std::size_t n = static_cast<std::size_t>(v.at(2));
    EXPECT_EQ(v.size(), 3 + 2 * n) << line;
    for (std::size_t i = 0; i < n; ++i) poly.points.push_back({v.at(3 + 2 * i), v.at(4 + 2 * i)});
    if (poly.dir != 2) poly.points.pop_back();
    cli.layers.back().push_back(std::move(poly));
  }
  return cli;
}

// Area of a convex polygon's part with x <= xmax (one Sutherland-Hodgman step).
double areaLeftOf(const std::vector<Point2d>& poly, double xmax) {
  std::vector<Point2d> kept;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const Point2d& a = poly[i];
    const Point2d& b = poly[(i + 1) % poly.size()];
    if (a.x <= xmax) kept.push_back(a);
    if ((a.x <= xmax) != (b.x <= xmax))
      kept.push_back({xmax, a.y + (xmax - a.x) / (b.x - a.x) * (b.y - a.y)});
  }
  return signedArea(kept);
}

// Model: a 20 x 10 x 5 box. Add-on: a 6 x 6 block z 4..7 at y 6..12, half in the model (winding 2) and
// half beside it. Removal: a 32-sided cylinder r = 2 at (19, 5), z 2..6, reaching 1 mm beyond the
// model's side (winding -1 there, which the positive rule leaves empty). Planes every 0.5 mm from 0.25
// to 6.75: the default planes cover the add-on above the model too.
TEST_F(CliToolFeatures, ContourOutputsCarryLabelledPartsThatCombineToTheMaskArea) {
  writeBinaryStl(path("model.stl"), fixtures::box(0, 0, 0, 20, 10, 5), "model", false);
  writeBinaryStl(path("knob.stl"), fixtures::box(2, 6, 4, 8, 12, 7), "add-on", false);
  writeBinaryStl(path("bore.stl"), fixtures::cylinder(19, 5, 2, 32, 2, 6), "removal", false);
  const RunResult r = run({"slice",
                           path("model.stl").string(),
                           "--add",
                           path("knob.stl").string(),
                           "--remove",
                           path("bore.stl").string(),
                           "-H",
                           "0.5",
                           "-o",
                           path("f.cli").string(),
                           "-o",
                           path("f.svg").string(),
                           "--svg-layers",
                           "0-last",
                           "--masks",
                           path("masks").string(),
                           "--resolution",
                           "480x300",
                           "--pixel",
                           "0.05",
                           "--report",
                           path("r.csv").string(),
                           "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();

  const std::string text = readBytes(path("f.cli"));
  const ParsedCli cli = parseAsciiCli(text);
  EXPECT_EQ(cli.labels, (std::vector<std::string>{"1,model", "2,add knob", "3,remove bore"}));
  const auto rows = splitLines(readBytes(path("r.csv")));
  constexpr std::size_t kLayers = 14;
  ASSERT_EQ(cli.layers.size(), kLayers);
  ASSERT_EQ(rows.size(), kLayers + 1);  // the header and one row per layer
  std::vector<Point2d> section;         // the cylinder's cross-section, counter-clockwise
  for (int i = 0; i < 32; ++i) {
    const double a = 2 * std::numbers::pi * i / 32;
    section.push_back({static_cast<float>(19 + 2 * std::cos(a)), static_cast<float>(5 + 2 * std::sin(a))});
  }
  const double bore = signedArea(section), cut = areaLeftOf(section, 20);
  for (std::size_t k = 0; k < kLayers; ++k) {
    const double z = 0.25 + 0.5 * static_cast<double>(k);
    const double expected = z < 2 ? 200 : z < 4 ? 200 - cut : z < 5 ? 200 - cut + 12 : 36;
    std::vector<std::vector<Point2d>> loops;
    double removalArea = 0;
    int removalLoops = 0;
    for (const auto& poly : cli.layers[k]) {
      EXPECT_TRUE(poly.id >= 1 && poly.id <= 3) << poly.id;
      EXPECT_NE(poly.dir, 2) << "layer " << k;
      loops.push_back(poly.points);
      if (poly.id != 3) continue;
      ++removalLoops;
      removalArea += signedArea(poly.points);
      EXPECT_EQ(poly.dir, 0) << "a removal's outer loop, reversed, is clockwise: layer " << k;
    }
    // The removal is written reversed: negative area where it is cut.
    EXPECT_EQ(removalLoops, z > 2 && z < 6 ? 1 : 0) << "layer " << k;
    if (removalLoops > 0) {
      EXPECT_NEAR(removalArea, -bore, 1e-4) << "layer " << k;
    }
    // The documented rule applied to the parsed CLI: the analytic area and the masks' (the report's).
    const double rule = fixtures::positiveWindingArea(loops, 0.001);
    EXPECT_NEAR(rule, expected, 1e-3 * expected) << "layer " << k;
    const std::string& row = rows[k + 1];
    const std::size_t c1 = row.find(','), c2 = row.find(',', c1 + 1);
    const double reported = std::stod(row.substr(c2 + 1));
    EXPECT_NEAR(rule, reported, 0.01 * expected) << row;
  }

  // Without features the model's output is what it always was: the same bytes as the feature file
  // (on its planes) without the features' labels and polylines, and with the model's extent (the feature
  // file's holds the add-on, which reaches 2 mm beyond the model in y and z, and the removal).
  const RunResult alone = run({"slice", path("model.stl").string(), "-H", "0.5", "--layers", "14", "-o",
                               path("m.cli").string(), "-q"});
  ASSERT_EQ(alone.code(), 0) << alone.describe();
  std::string filtered;
  for (const std::string& line : splitLines(text)) {
    if (line.starts_with("$$LABEL/2,") || line.starts_with("$$LABEL/3,") ||
        line.starts_with("$$POLYLINE/2,") || line.starts_with("$$POLYLINE/3,"))
      continue;
    if (line.starts_with("$$DIMENSION/")) {
      EXPECT_EQ(line, "$$DIMENSION/0.000000,0.000000,0.000000,21.000000,12.000000,7.000000");  // bore: x 21
      filtered += "$$DIMENSION/0.000000,0.000000,0.000000,20.000000,10.000000,5.000000\n";
      continue;
    }
    filtered += line + "\n";
  }
  EXPECT_EQ(readBytes(path("m.cli")), filtered);

  // SVG: every panel has a group per part; the removal's group draws its outline.
  const std::string svg = readBytes(path("f.svg"));
  std::size_t groups = 0, removals = 0;
  for (std::size_t at = svg.find("class=\"part "); at != std::string::npos;
       at = svg.find("class=\"part ", at + 1))
    ++groups;
  for (std::size_t at = svg.find("<polygon class=\"remove\""); at != std::string::npos;
       at = svg.find("<polygon class=\"remove\"", at + 1))
    ++removals;
  EXPECT_EQ(groups, 3 * kLayers);
  EXPECT_EQ(removals, 8u);  // planes 2.25 .. 5.75
  EXPECT_TRUE(contains(svg, "<title>remove bore</title>"));
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 10. interrupt

// Starts a long slice, waits until an output temporary appears (at most 15 s) and holds bytes (at most
// 1.5 s more), sends `signal`, and checks the run ended early and left nothing behind.
void interruptAndCheck(CliToolBase& t, const std::vector<std::string>& args, int signal,
                       const fs::path& output, RunResult& result, bool twice = false) {
  const auto begin = std::chrono::steady_clock::now();
  const pid_t pid = t.start(args);
  ASSERT_GT(pid, 0);
  bool sawTemporary = false;
  int status = 0;
  bool exitedEarly = false;
  while (std::chrono::steady_clock::now() - begin < 15s) {
    if (!temporariesIn(output.parent_path()).empty()) {
      sawTemporary = true;
      break;
    }
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      exitedEarly = true;
      break;
    }
    std::this_thread::sleep_for(10ms);
  }
  if (exitedEarly) {
    FAIL() << "toposlice ended before it was interrupted, status " << status;
  }
  EXPECT_TRUE(sawTemporary) << "no output temporary appeared within 15 s";
  // Let it write for a moment: until the temporary holds bytes, at most 1.5 s.
  const auto appeared = std::chrono::steady_clock::now();
  while (sawTemporary && std::chrono::steady_clock::now() - appeared < 1500ms) {
    bool written = false;
    for (const auto& name : temporariesIn(output.parent_path())) {
      std::error_code ec;
      written = written || fs::file_size(output.parent_path() / name, ec) > 0;
    }
    if (written) break;
    std::this_thread::sleep_for(10ms);
  }
  std::this_thread::sleep_for(100ms);
  ASSERT_EQ(::kill(pid, signal), 0) << std::strerror(errno);
  if (twice) {  // a user pressing Ctrl-C again: the process stops at once, from the signal handler
    std::this_thread::sleep_for(2ms);
    ::kill(pid, signal);
  }
  result = t.finish(pid, 30s);
  EXPECT_TRUE(result.signalled(signal) || (result.exited() && result.code() != 0)) << result.describe();
  EXPECT_LT(std::chrono::steady_clock::now() - begin, 20s) << "the run did not stop at the signal";
  EXPECT_FALSE(fs::exists(output)) << output;
  const auto left = temporariesIn(output.parent_path());
  EXPECT_TRUE(left.empty()) << "temporaries left: " << testing::PrintToString(left);
}

TEST_F(CliToolInterrupt, SigtermDuringSl1OutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001",
                     "--masks", "big.sl1", "--printer", "sl1", "-q"},
                    SIGTERM, path("big.sl1"), r);
}

// A hang-up (the terminal closed, an ssh session dropped) stops the job as SIGTERM does: it left the
// staged archive and said nothing.
TEST_F(CliToolInterrupt, SighupDuringSl1OutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001",
                     "--masks", "big.sl1", "--printer", "sl1", "-q"},
                    SIGHUP, path("big.sl1"), r);
  EXPECT_TRUE(contains(r.err, "interrupted")) << r.err;
}

TEST_F(CliToolInterrupt, SigtermDuringPngFolderOutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001",
                     "--masks", "bigpng", "--printer", "sl1", "-q"},
                    SIGTERM, path("bigpng"), r);
}

// A second signal ends the run at once from the handler, which removes the staged folder of a PNG stack
// (its files, then the folder) as it removes temporary files, and says so.
TEST_F(CliToolInterrupt, SecondSigintDuringPngFolderOutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001",
                     "--masks", "bigpng", "--printer", "sl1", "-q"},
                    SIGINT, path("bigpng"), r, /*twice=*/true);
  EXPECT_TRUE(contains(r.err, "interrupted")) << r.describe();
}

// The second signal while the first one's unwinding removes a large staged folder (thousands of EXR
// layers): the folder stays known to the handler until it is gone. It was unregistered before its
// files were removed, and a second Ctrl-C then left the folder, half full, saying the temporaries were
// removed.
TEST_F(CliToolInterrupt, SecondSignalWhileAStagedFolderIsRemovedLeavesNothing) {
  const pid_t pid = start({"slice", sharedModel("knee_femur_ssm_mean.ply").string(), "-H", "0.005", "--pixel",
                           "0.1", "--resolution", "1000x800", "--threads", "1", "--masks", "big.exr", "-q"});
  ASSERT_GT(pid, 0);
  // Until the staged folder holds 1,500 layers (or 20 s went by).
  const auto begin = std::chrono::steady_clock::now();
  std::size_t files = 0;
  while (files < 1500 && std::chrono::steady_clock::now() - begin < 20s) {
    files = 0;
    for (const auto& name : temporariesIn(dir_)) {
      std::error_code ec;
      for (auto it = fs::directory_iterator(dir_ / name, ec); !ec && it != fs::directory_iterator();
           it.increment(ec))
        ++files;
    }
    std::this_thread::sleep_for(20ms);
  }
  ASSERT_EQ(::kill(pid, SIGTERM), 0) << std::strerror(errno);
  std::this_thread::sleep_for(3ms);
  ::kill(pid, SIGTERM);
  const RunResult r = finish(pid, 30s);
  EXPECT_TRUE(r.signalled(SIGTERM) || (r.exited() && r.code() != 0)) << r.describe();
  EXPECT_FALSE(fs::exists(path("big.exr")));
  const auto left = temporariesIn(dir_);
  EXPECT_TRUE(left.empty()) << "left: " << testing::PrintToString(left) << " (" << files
                            << " layers when signalled)";
}

// A read can block (a pipe that no one writes) or take long (a 3MF whose components place a mesh 10^10
// times, inside lib3mf): the first signal was only a request the job would look at after the read, so a
// single Ctrl-C did nothing. While a single-model command reads, the first signal stops it at once.
TEST_F(CliToolInterrupt, FirstSignalWhileReadingStopsAtOnce) {
  ASSERT_EQ(::mkfifo(path("pipe.stl").c_str(), 0600), 0) << std::strerror(errno);
  for (const int signal : {SIGINT, SIGTERM}) {
    const auto begin = std::chrono::steady_clock::now();
    const pid_t pid =
        start({"slice", "pipe.stl", "-H", "0.5", "-o", "p.cli", "--masks", "p.sl1", "--printer", "sl1"});
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(300ms);  // blocked opening the pipe
    ASSERT_EQ(::kill(pid, signal), 0) << std::strerror(errno);
    const RunResult r = finish(pid, 10s);
    EXPECT_TRUE(r.signalled(signal)) << r.describe();
    EXPECT_LT(std::chrono::steady_clock::now() - begin, 8s);
    EXPECT_TRUE(contains(r.err, "interrupted while reading: stopped at once")) << r.describe();
    EXPECT_FALSE(fs::exists(path("p.cli")) || fs::exists(path("p.sl1")));
    expectNoTemporaries();
  }
}

TEST_F(CliToolInterrupt, SigintDuringBinaryCliOutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001", "-o",
                     "big.cli", "--cli-binary", "-q"},
                    SIGINT, path("big.cli"), r);
}

// ---------------------------------------------------------------------------------------------------
// 11. --quiet and the progress bar

TEST_F(CliToolQuiet, QuietPrintsNothingOnSuccess) {
  const RunResult r = run({"slice", examplePart().string(), "-H", "0.5", "-o", "q.cli", "--quiet"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(r.out.empty()) << r.out;
  EXPECT_TRUE(r.err.empty()) << r.err;
  EXPECT_TRUE(fs::exists(path("q.cli")));

  const RunResult t = run({"template", examplePart().string(), "-o", "q.topo", "-q"});
  ASSERT_EQ(t.code(), 0) << t.describe();
  EXPECT_TRUE(t.out.empty()) << t.out;
  EXPECT_TRUE(t.err.empty()) << t.err;
}

// Everything the program writes when its output is a terminal (a pseudo-terminal), run in `dir`.
std::string outputOnTerminal(const fs::path& dir, const std::vector<std::string>& args) {
  int master = -1;
  const pid_t pid = ::forkpty(&master, nullptr, nullptr, nullptr);
  if (pid == 0) {
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    std::vector<std::string> all{toposliceBinary().string()};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  std::string out;
  if (pid < 0) return out;
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(master, buffer, sizeof buffer);
    if (n > 0)
      out.append(buffer, static_cast<std::size_t>(n));
    else if (n < 0 && errno == EINTR)
      continue;
    else
      break;  // EIO once the program has ended
  }
  ::close(master);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return out;
}

// On a terminal the long commands draw a progress bar (slice, and plate naming the plate), and --quiet
// keeps them silent.
TEST_F(CliToolQuiet, ProgressBarsOnATerminalAndNotWithQuiet) {
  const std::string demo = (fs::path(TOPOSLICE_SOURCE_DIR) / "examples" / "plate_demo.json").string();
  const std::string slice =
      outputOnTerminal(dir_, {"slice", examplePart().string(), "-H", "0.01", "-o", "t.cli"});
  EXPECT_TRUE(contains(slice, "100%")) << slice;
  const std::string plate = outputOnTerminal(dir_, {"plate", demo, "-O", "p"});
  EXPECT_TRUE(contains(plate, "plate 1/1 layers")) << plate;
  EXPECT_TRUE(contains(plate, "100%")) << plate;
  EXPECT_TRUE(contains(plate, "1 plate, 3 parts")) << plate;
  const std::string quiet = outputOnTerminal(dir_, {"plate", demo, "-O", "q", "-q"});
  EXPECT_TRUE(quiet.empty()) << quiet;
}

TEST_F(CliToolQuiet, NoProgressBarWhenStderrIsNotATerminal) {
  const RunResult r = run(
      {"slice", examplePart().string(), "-H", "0.05", "-o", "p.cli", "--masks", "p.sl1", "--printer", "sl1"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(r.err.empty()) << r.err;
  EXPECT_TRUE(contains(r.out, "wrote      : p.cli")) << r.out;
  EXPECT_TRUE(contains(r.out, "wrote      : p.sl1")) << r.out;
}

}  // namespace
}  // namespace toposlice
