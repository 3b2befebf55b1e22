// CLI writer (ASCII text checked byte for byte, binary parsed back) and OutputFile (temporary name,
// atomic commit, overwrite policy, cleanup on destruction, on write failure and on a signal).
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "core/slicing/contours.h"
#include "io/contours/cli_writer.h"
#include "io/errors.h"
#include "io/output_file.h"
#include "tests/fixtures/scratch_dir.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

using fixtures::readFile;
using fixtures::ScratchDir;

void writeText(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

// Layer 0: CCW square 0..10 with a CW square hole 3..7 and an open polyline; layer 1: a CCW triangle.
std::vector<LayerContours> sampleLayers() {
  std::vector<LayerContours> layers(2);
  LayerContours& a = layers[0];
  a.clear(0.025);
  a.addPoint({0, 0}, 0);
  a.addPoint({10, 0}, 1);
  a.addPoint({10, 10}, 2);
  a.addPoint({0, 10}, 3);
  a.endLoop(true);
  a.addPoint({3, 3}, 4);
  a.addPoint({3, 7}, 5);
  a.addPoint({7, 7}, 6);
  a.addPoint({7, 3}, 7);
  a.endLoop(true);
  a.addPoint({1.25, -0.5}, 8);
  a.addPoint({-1e-9, 0.125}, 9);  // rounds to zero: written without a minus sign
  a.endLoop(false);
  LayerContours& b = layers[1];
  b.clear(0.075);
  b.addPoint({0, 0}, 0);
  b.addPoint({1, 0}, 1);
  b.addPoint({0, 1}, 2);
  b.endLoop(true);
  return layers;
}

ContourJob sampleJob() {
  ContourJob job;
  job.name = "demo";
  job.bounds.min = {0, 0, 0};
  job.bounds.max = {10, 10, 0.1f};
  job.layerCount = 2;
  return job;
}

void writeSample(const fs::path& path, bool binary, bool overwrite = false) {
  const auto layers = sampleLayers();
  auto sink = makeCliWriter(path, sampleJob(), binary, overwrite);
  for (uint32_t k = 0; k < layers.size(); ++k) sink->writeLayer(k, layers[k]);
  sink->finish();
}

TEST(CliWriter, AsciiExact) {
  ScratchDir dir;
  writeSample(dir / "a.cli", false);
  const std::string expected =
      "$$HEADERSTART\n"
      "// written by toposlice //\n"
      "$$ASCII\n"
      "$$UNITS/00000001.000000\n"
      "$$VERSION/200\n"
      "$$LABEL/1,demo\n"
      "$$DIMENSION/0.000000,0.000000,0.000000,10.000000,10.000000,0.100000\n"
      "$$LAYERS/2\n"
      "$$HEADEREND\n"
      "$$GEOMETRYSTART\n"
      "$$LAYER/0.025000\n"
      "$$POLYLINE/1,1,5,0.000000,0.000000,10.000000,0.000000,10.000000,10.000000,0.000000,10.000000,"
      "0.000000,0.000000\n"
      "$$POLYLINE/1,0,5,3.000000,3.000000,3.000000,7.000000,7.000000,7.000000,7.000000,3.000000,"
      "3.000000,3.000000\n"
      "$$POLYLINE/1,2,2,1.250000,-0.500000,0.000000,0.125000\n"
      "$$LAYER/0.075000\n"
      "$$POLYLINE/1,1,4,0.000000,0.000000,1.000000,0.000000,0.000000,1.000000,0.000000,0.000000\n"
      "$$GEOMETRYEND\n";
  EXPECT_EQ(readFile(dir / "a.cli"), expected);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"a.cli"});
}

TEST(CliWriter, LabelIsSanitized) {
  ScratchDir dir;
  ContourJob job = sampleJob();
  job.name = "a/b$c\nd";
  job.layerCount = 0;
  auto sink = makeCliWriter(dir / "l.cli", job, false, false);
  sink->finish();
  EXPECT_NE(readFile(dir / "l.cli").find("$$LABEL/1,a_b_c_d\n"), std::string::npos);
}

// Minimal binary CLI reader: header lines up to "$$HEADEREND", then commands 127 and 130 only.
struct CliPolyline {
  int32_t id = 0, dir = 0;
  std::vector<float> xy;
};
struct CliLayer {
  float z = 0;
  std::vector<CliPolyline> polylines;
};
struct CliFile {
  std::string header;
  std::vector<CliLayer> layers;
};

template <typename T>
T readLE(const std::string& bytes, std::size_t& pos) {
  if (pos + sizeof(T) > bytes.size()) throw std::runtime_error("truncated binary CLI");
  using U = std::conditional_t<sizeof(T) == 2, uint16_t, uint32_t>;
  U bits = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    bits = static_cast<U>(bits | (static_cast<U>(static_cast<unsigned char>(bytes[pos + i])) << (8 * i)));
  }
  pos += sizeof(T);
  return std::bit_cast<T>(bits);
}

CliFile parseBinaryCli(const std::string& bytes) {
  CliFile file;
  const std::string end = "$$HEADEREND";
  const std::size_t headerEnd = bytes.find(end);
  if (headerEnd == std::string::npos) throw std::runtime_error("no $$HEADEREND");
  file.header = bytes.substr(0, headerEnd + end.size());
  std::size_t pos = headerEnd + end.size();
  while (pos < bytes.size()) {
    const uint16_t cmd = readLE<uint16_t>(bytes, pos);
    if (cmd == 127) {
      file.layers.push_back({readLE<float>(bytes, pos), {}});
    } else if (cmd == 130) {
      if (file.layers.empty()) throw std::runtime_error("polyline before the first layer");
      CliPolyline poly;
      poly.id = readLE<int32_t>(bytes, pos);
      poly.dir = readLE<int32_t>(bytes, pos);
      const int32_t n = readLE<int32_t>(bytes, pos);
      for (int32_t i = 0; i < 2 * n; ++i) poly.xy.push_back(readLE<float>(bytes, pos));
      file.layers.back().polylines.push_back(std::move(poly));
    } else {
      throw std::runtime_error("unknown command " + std::to_string(cmd));
    }
  }
  return file;
}

TEST(CliWriter, BinaryRoundTrip) {
  ScratchDir dir;
  writeSample(dir / "b.cli", true);
  const std::string bytes = readFile(dir / "b.cli");
  const CliFile file = parseBinaryCli(bytes);
  EXPECT_EQ(file.header,
            "$$HEADERSTART\n// written by toposlice "
            "//\n$$BINARY\n$$UNITS/00000001.000000\n$$VERSION/200\n$$LABEL/1,demo\n"
            "$$DIMENSION/0.000000,0.000000,0.000000,10.000000,10.000000,0.100000\n$$LAYERS/2\n$$HEADEREND");

  const auto layers = sampleLayers();
  ASSERT_EQ(file.layers.size(), layers.size());
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const LayerContours& in = layers[k];
    const CliLayer& out = file.layers[k];
    EXPECT_EQ(out.z, static_cast<float>(in.z));
    ASSERT_EQ(out.polylines.size(), in.loopCount());
    for (std::size_t l = 0; l < in.loopCount(); ++l) {
      const auto pts = in.loopPoints(l);
      const CliPolyline& poly = out.polylines[l];
      const bool closed = in.loopClosed[l] != 0;
      EXPECT_EQ(poly.id, 1);
      EXPECT_EQ(poly.dir, !closed ? 2 : (signedArea(pts) > 0 ? 1 : 0));
      ASSERT_EQ(poly.xy.size(), 2 * (pts.size() + (closed ? 1 : 0)));
      for (std::size_t i = 0; i < poly.xy.size() / 2; ++i) {
        const Point2d& p = pts[i % pts.size()];  // a closed loop repeats its first point
        EXPECT_EQ(poly.xy[2 * i], static_cast<float>(p.x));
        EXPECT_EQ(poly.xy[2 * i + 1], static_cast<float>(p.y));
      }
    }
  }
  // Dirs of the sample: outer, hole, open; then outer.
  EXPECT_EQ(file.layers[0].polylines[0].dir, 1);
  EXPECT_EQ(file.layers[0].polylines[1].dir, 0);
  EXPECT_EQ(file.layers[0].polylines[2].dir, 2);
  // Exact size: header + per layer 6 bytes + per polyline 14 bytes + 8 per point.
  EXPECT_EQ(bytes.size(), file.header.size() + 2 * 6 + 4 * 14 + 8 * (5 + 5 + 2 + 4));
}

// ---- features ---------------------------------------------------------------------------------------

// One layer of three parts at z = 0.5: the model a CCW square 0..10, an add-on CCW square 10..12 x 0..2
// beside it, a removal a CCW triangle (3,3) (5,3) (3,5) inside the model, with an open piece.
std::vector<LayerContours> featureParts() {
  std::vector<LayerContours> parts(3);
  for (LayerContours& part : parts) part.clear(0.5);
  for (const Point2d p : {Point2d{0, 0}, Point2d{10, 0}, Point2d{10, 10}, Point2d{0, 10}})
    parts[0].addPoint(p, 0);
  parts[0].endLoop(true);
  for (const Point2d p : {Point2d{10, 0}, Point2d{12, 0}, Point2d{12, 2}, Point2d{10, 2}})
    parts[1].addPoint(p, 0);
  parts[1].endLoop(true);
  for (const Point2d p : {Point2d{3, 3}, Point2d{5, 3}, Point2d{3, 5}}) parts[2].addPoint(p, 0);
  parts[2].endLoop(true);
  parts[2].addPoint({1, 1}, 0);
  parts[2].addPoint({2, 1}, 0);
  parts[2].addPoint({2, 2}, 0);
  parts[2].endLoop(false);
  return parts;
}

ContourJob featureJob() {
  ContourJob job = sampleJob();
  job.layerCount = 1;
  job.features = {{"knob", PartRole::Add}, {"en/grave", PartRole::Remove}};
  return job;
}

TEST(CliWriter, FeaturesAreLabelledPartsAndRemovalsAreReversed) {
  ScratchDir dir;
  auto sink = makeCliWriter(dir / "f.cli", featureJob(), false, false);
  sink->writeLayer(0, featureParts());
  sink->finish();
  const std::string expected =
      "$$HEADERSTART\n"
      "// written by toposlice //\n"
      "$$ASCII\n"
      "$$UNITS/00000001.000000\n"
      "$$VERSION/200\n"
      "$$LABEL/1,demo\n"
      "$$LABEL/2,add knob\n"
      "$$LABEL/3,remove en_grave\n"
      "$$DIMENSION/0.000000,0.000000,0.000000,10.000000,10.000000,0.100000\n"
      "$$LAYERS/1\n"
      "$$HEADEREND\n"
      "$$GEOMETRYSTART\n"
      "$$LAYER/0.500000\n"
      "$$POLYLINE/1,1,5,0.000000,0.000000,10.000000,0.000000,10.000000,10.000000,0.000000,10.000000,"
      "0.000000,0.000000\n"
      "$$POLYLINE/2,1,5,10.000000,0.000000,12.000000,0.000000,12.000000,2.000000,10.000000,2.000000,"
      "10.000000,0.000000\n"
      // Reversed from its first point: clockwise as written, so dir 0; the open piece runs backwards.
      "$$POLYLINE/3,0,4,3.000000,3.000000,3.000000,5.000000,5.000000,3.000000,3.000000,3.000000\n"
      "$$POLYLINE/3,2,3,2.000000,2.000000,2.000000,1.000000,1.000000,1.000000\n"
      "$$GEOMETRYEND\n";
  EXPECT_EQ(readFile(dir / "f.cli"), expected);
}

TEST(CliWriter, BinaryFeaturesCarryTheirIdsAndTheWindingRuleGivesTheSolid) {
  ScratchDir dir;
  auto sink = makeCliWriter(dir / "f.cli", featureJob(), true, false);
  const auto parts = featureParts();
  sink->writeLayer(0, parts);
  sink->finish();
  const CliFile file = parseBinaryCli(readFile(dir / "f.cli"));
  EXPECT_NE(file.header.find("$$LABEL/1,demo\n$$LABEL/2,add knob\n$$LABEL/3,remove en_grave\n"),
            std::string::npos)
      << file.header;
  ASSERT_EQ(file.layers.size(), 1u);
  const auto& polys = file.layers[0].polylines;
  ASSERT_EQ(polys.size(), 4u);
  EXPECT_EQ((std::vector<int32_t>{polys[0].id, polys[1].id, polys[2].id, polys[3].id}),
            (std::vector<int32_t>{1, 2, 3, 3}));
  EXPECT_EQ((std::vector<int32_t>{polys[0].dir, polys[1].dir, polys[2].dir, polys[3].dir}),
            (std::vector<int32_t>{1, 1, 0, 2}));
  // The documented rule on areas: with windings 0 or 1 the solid's area is the sum of the signed areas
  // of all closed polylines as written: 100 + 4 - 2.
  double area = 0;
  for (const CliPolyline& poly : polys) {
    if (poly.dir == 2) continue;
    std::vector<Point2d> pts;
    for (std::size_t i = 0; i + 2 < poly.xy.size(); i += 2) pts.push_back({poly.xy[i], poly.xy[i + 1]});
    area += signedArea(pts);
  }
  EXPECT_DOUBLE_EQ(area, 100.0 + 4.0 - 2.0);
}

TEST(CliWriter, ModelOnlySpanWritesTheSameBytesAsTheSingleLayerCall) {
  ScratchDir dir;
  const auto layers = sampleLayers();
  for (const bool binary : {false, true}) {
    auto sink = makeCliWriter(dir / "span.cli", sampleJob(), binary, true);
    for (uint32_t k = 0; k < layers.size(); ++k)
      sink->writeLayer(k, std::span<const LayerContours>(&layers[k], 1));
    sink->finish();
    writeSample(dir / "one.cli", binary, true);
    EXPECT_EQ(readFile(dir / "span.cli"), readFile(dir / "one.cli")) << "binary=" << binary;
  }
}

// What a batch re-run takes as finished (outputLooksWhole): a whole CLI, ASCII or binary, not one cut
// short (ASCII: before $$GEOMETRYEND; binary: in a command, or with fewer layers than $$LAYERS says).
TEST(CliWriter, WholeAndCutShortFiles) {
  ScratchDir dir;
  for (const bool binary : {false, true}) {
    writeSample(dir / "a.cli", binary, true);
    EXPECT_TRUE(outputLooksWhole(dir / "a.cli")) << "binary=" << binary;
    const std::string bytes = readFile(dir / "a.cli");
    for (const std::size_t cut : {std::size_t{1}, std::size_t{9}, bytes.size() / 2}) {
      std::ofstream(dir / "a.cli", std::ios::binary) << bytes.substr(0, bytes.size() - cut);
      EXPECT_FALSE(outputLooksWhole(dir / "a.cli")) << "binary=" << binary << ", cut " << cut;
    }
  }
}

TEST(CliWriter, Deterministic) {
  ScratchDir dir;
  for (const bool binary : {false, true}) {
    writeSample(dir / "one.cli", binary, true);
    writeSample(dir / "two.cli", binary, true);
    EXPECT_EQ(readFile(dir / "one.cli"), readFile(dir / "two.cli")) << "binary=" << binary;
  }
}

TEST(CliWriter, NothingUnderFinalNameBeforeFinish) {
  ScratchDir dir;
  const auto layers = sampleLayers();
  for (const bool binary : {false, true}) {
    const fs::path path = dir / "x.cli";
    {
      auto sink = makeCliWriter(path, sampleJob(), binary, false);
      sink->writeLayer(0, layers[0]);
      sink->writeLayer(1, layers[1]);
      EXPECT_FALSE(fs::exists(path));
      const auto names = dir.entries();
      ASSERT_EQ(names.size(), 1u);
      EXPECT_EQ(names[0].rfind("x.cli.tmp-" + std::to_string(::getpid()) + "-", 0), 0u) << names[0];
      // Destroyed without finish(): the temporary goes away.
    }
    EXPECT_TRUE(dir.entries().empty());
  }
}

TEST(CliWriter, ExistingFileNeedsOverwrite) {
  ScratchDir dir;
  const fs::path path = dir / "old.cli";
  writeText(path, "$$HEADERSTART\n// written by toposlice //\nold");
  try {
    makeCliWriter(path, sampleJob(), true, false);
    FAIL() << "no OutputError";
  } catch (const OutputError& e) {
    EXPECT_EQ(std::string(e.what()), path.string() + ": already exists (use --force to overwrite)");
  }
  EXPECT_EQ(readFile(path), "$$HEADERSTART\n// written by toposlice //\nold");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"old.cli"});

  const auto layers = sampleLayers();
  auto sink = makeCliWriter(path, sampleJob(), false, true);
  sink->writeLayer(0, layers[0]);
  sink->writeLayer(1, layers[1]);
  EXPECT_EQ(readFile(path), "$$HEADERSTART\n// written by toposlice //\nold");  // replaced only by finish()
  sink->finish();
  EXPECT_EQ(readFile(path).rfind("$$HEADERSTART\n// written by toposlice //\n$$ASCII\n", 0), 0u);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"old.cli"});
}

TEST(OutputFile, CommitWritesAllBytes) {
  ScratchDir dir;
  std::string expected;
  {
    OutputFile file(dir / "f.bin", false);
    EXPECT_FALSE(fs::exists(dir / "f.bin"));
    EXPECT_TRUE(fs::exists(file.tempPath()));
    // Small writes (buffered), one larger than the buffer (direct), and some crossing the buffer's end.
    for (std::size_t size : {std::size_t{1}, std::size_t{1000}, OutputFile::kBufferSize + 17,
                             OutputFile::kBufferSize - 5, std::size_t{4096}, std::size_t{3}}) {
      std::string chunk(size, '\0');
      for (std::size_t i = 0; i < size; ++i) chunk[i] = static_cast<char>('a' + (expected.size() + i) % 26);
      file.write(chunk.data(), chunk.size());
      expected += chunk;
    }
    EXPECT_EQ(file.bytesWritten(), expected.size());
    file.commit();
    EXPECT_TRUE(file.committed());
    EXPECT_FALSE(fs::exists(file.tempPath()));
  }
  EXPECT_EQ(readFile(dir / "f.bin"), expected);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"f.bin"});
}

TEST(OutputFile, AnotherThreadAdoptingTheTransactionStagesItsFilesThere) {
  // A job's outputs opened on another thread (slice jobs set their outputs up beside the topology)
  // join the job's transaction: they appear at its commit, or never.
  ScratchDir dir;
  for (const bool commit : {false, true}) {
    const fs::path path = dir / (commit ? "kept.bin" : "dropped.bin");
    {
      OutputTransaction transaction;
      std::thread other([&] {
        const OutputTransaction::Adopt use(&transaction);
        EXPECT_EQ(OutputTransaction::current(), &transaction);
        OutputFile file(path, false);
        file.write("abc", 3);
        file.commit();  // staged in the transaction, not yet in place
      });
      other.join();
      EXPECT_EQ(OutputTransaction::current(), &transaction);
      EXPECT_FALSE(fs::exists(path));
      ASSERT_EQ(transaction.staged().size(), 1u);
      if (commit) transaction.commit();
    }
    EXPECT_EQ(fs::exists(path), commit);
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"kept.bin"});
  EXPECT_EQ(OutputTransaction::current(), nullptr);
}

TEST(OutputFile, DestructorRemovesTemporary) {
  ScratchDir dir;
  {
    OutputFile file(dir / "f.bin", false);
    file.write("abc", 3);
    EXPECT_EQ(dir.entries().size(), 1u);
  }
  EXPECT_TRUE(dir.entries().empty());
}

// A temporary the destructor cannot remove (its folder made read-only under the job; here, as root can
// unlink anything there, a folder put in its place) is noted, so that the command says what it left.
TEST(OutputFile, ATemporaryThatCannotBeRemovedIsNoted) {
  ScratchDir dir;
  takeUnremovedTemporaries();
  std::filesystem::path temp;
  {
    OutputFile file(dir / "f.bin", false);
    temp = file.tempPath();
    std::filesystem::remove(temp);
    std::filesystem::create_directories(temp / "in");
  }
  const std::vector<std::string> noted = takeUnremovedTemporaries();
  ASSERT_EQ(noted.size(), 1u);
  EXPECT_EQ(noted[0].rfind(temp.string() + " could not be removed (", 0), 0u) << noted[0];
  EXPECT_TRUE(takeUnremovedTemporaries().empty());
  {
    OutputFile file(dir / "g.bin", false);  // removed as usual: nothing noted
  }
  EXPECT_TRUE(takeUnremovedTemporaries().empty());
}

TEST(OutputFile, TemporaryNamesAreUnique) {
  ScratchDir dir;
  OutputFile a(dir / "f.bin", true);
  OutputFile b(dir / "f.bin", true);
  EXPECT_NE(a.tempPath(), b.tempPath());
  EXPECT_EQ(a.tempPath().parent_path(), dir.path());
  // a stays empty: toposlice writes no .bin files, so b may replace only an empty one (checkReplaceable).
  b.write("b", 1);
  a.commit();
  b.commit();
  EXPECT_EQ(readFile(dir / "f.bin"), "b");
}

TEST(OutputFile, RefusesExistingPath) {
  ScratchDir dir;
  writeText(dir / "f.bin", "keep");
  EXPECT_THROW(OutputFile(dir / "f.bin", false), OutputError);
  // A file that appears while writing is not clobbered either.
  {
    OutputFile file(dir / "g.bin", false);
    file.write("new", 3);
    writeText(dir / "g.bin", "other");
    try {
      file.commit();
      FAIL() << "no OutputError";
    } catch (const OutputError& e) {
      EXPECT_EQ(std::string(e.what()),
                (dir / "g.bin").string() + ": already exists (use --force to overwrite)");
    }
  }
  EXPECT_EQ(readFile(dir / "f.bin"), "keep");
  EXPECT_EQ(readFile(dir / "g.bin"), "other");
  EXPECT_EQ(dir.entries(), (std::vector<std::string>{"f.bin", "g.bin"}));
}

TEST(OutputFile, ReportsCreateFailure) {
  ScratchDir dir;
  const fs::path path = dir / "missing" / "f.bin";
  try {
    OutputFile file(path, false);
    FAIL() << "no OutputError";
  } catch (const OutputError& e) {
    const std::string what = e.what();
    // Names the output and the missing folder, never the temporary.
    EXPECT_EQ(what,
              path.string() + ": cannot create: folder '" + (dir / "missing").string() + "' does not exist");
  }
}

TEST(OutputFile, WriteFailureThrowsAndLeavesNothing) {
  ScratchDir dir;
  // A file size limit makes write(2) fail with EFBIG, standing in for a full disk.
  rlimit old{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old), 0);
  const auto oldHandler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = old;
  small.rlim_cur = 1 << 20;
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  bool threw = false;
  {
    OutputFile file(dir / "big.bin", false);
    const std::string chunk(OutputFile::kBufferSize * 3, 'x');
    try {
      file.write(chunk.data(), chunk.size());
      file.commit();
    } catch (const OutputError& e) {
      threw = true;
      EXPECT_EQ(std::string(e.what()).rfind((dir / "big.bin").string() + ": cannot write: ", 0), 0u)
          << e.what();
    }
    EXPECT_THROW(file.commit(), OutputError);  // a failed file cannot be committed
  }
  ::setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, oldHandler);
  EXPECT_TRUE(threw);
  EXPECT_TRUE(dir.entries().empty());
}

TEST(OutputFile, RemovePendingOutputsUnlinksLiveTemporaries) {
  ScratchDir dir;
  OutputFile done(dir / "done.bin", false);
  done.write("d", 1);
  done.commit();
  OutputFile a(dir / "a.bin", false);
  OutputFile b(dir / "b.bin", false);
  EXPECT_EQ(dir.entries().size(), 3u);
  removePendingOutputs();
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"done.bin"});
}

void removeOutputsAndDie(int sig) {
  removePendingOutputs();
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

TEST(OutputFile, InterruptedRunLeavesNoTemporary) {
  ScratchDir dir;
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    std::signal(SIGTERM, removeOutputsAndDie);
    try {
      OutputFile file(dir / "f.bin", false);
      file.write("partial", 7);
      std::raise(SIGTERM);  // destructors never run: only the handler can clean up
    } catch (...) {
    }
    ::_exit(3);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status;
  EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
}  // namespace toposlice
