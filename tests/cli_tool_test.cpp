// The `toposlice` program end to end: each test runs the real binary (fork + exec, stdout and stderr
// captured to files, exit status checked) in a fresh temporary directory, and checks what it prints and
// what it leaves on disk (README.md, docs/DESIGN.md "Errors and outputs", docs/FORMATS.md "Output files",
// docs/TEMPLATES.md, docs/MASKS.md).
//
// The binary is $TOPOSLICE_BIN (set by ctest) or, when the tests run outside ctest, the build's own
// toposlice (TOPOSLICE_BIN_PATH).
#include <fcntl.h>
#include <gtest/gtest.h>
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

#include "io/masks/exr_writer.h"
#include "io/masks/mask_png.h"
#include "tests/tinyexr_read.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// ---------------------------------------------------------------------------------------------------
// Paths

fs::path toposliceBinary() {
  if (const char* env = std::getenv("TOPOSLICE_BIN"); env != nullptr && *env != '\0')
    return fs::absolute(env);
  return fs::absolute(TOPOSLICE_BIN_PATH);
}

fs::path sharedModel(const std::string& relative) {
  return fs::absolute(fs::path(TOPOSLICE_MODELS_DIR) / relative).lexically_normal();
}

fs::path examplePart() {
  return fs::absolute(fs::path(TOPOSLICE_SOURCE_DIR) / "examples" / "example_part.stl").lexically_normal();
}

// ---------------------------------------------------------------------------------------------------
// Files

std::string readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void writeBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

uint32_t le32(const std::string& b, std::size_t at) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(b.at(at + static_cast<std::size_t>(i)));
  return v;
}

uint16_t le16(const std::string& b, std::size_t at) {
  return static_cast<uint16_t>(static_cast<uint8_t>(b.at(at)) | (static_cast<uint8_t>(b.at(at + 1)) << 8));
}

// Names in `dir` that look like an output temporary (`<final>.tmp-<pid>-<n>` or `...-d<n>`).
std::vector<std::string> temporariesIn(const fs::path& dir) {
  std::vector<std::string> found;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().filename().string().find(".tmp-") != std::string::npos)
      found.push_back(entry.path().filename().string());
  return found;
}

// Every regular file of a directory: name -> bytes.
std::map<std::string, std::string> directoryContents(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.is_regular_file()) files[entry.path().filename().string()] = readBytes(entry.path());
  return files;
}

// Entry names of a zip archive, read from its central directory (classic end record; no Zip64 needed
// for the small archives made here).
std::vector<std::string> zipEntryNames(const std::string& zip) {
  std::vector<std::string> names;
  if (zip.size() < 22) {
    ADD_FAILURE() << "not a zip: " << zip.size() << " bytes";
    return names;
  }
  std::size_t end = std::string::npos;
  for (std::size_t p = zip.size() - 22;; --p) {
    if (le32(zip, p) == 0x06054b50u) {
      end = p;
      break;
    }
    if (p == 0 || zip.size() - p > 22 + 65535) break;
  }
  if (end == std::string::npos) {
    ADD_FAILURE() << "no zip end-of-central-directory record";
    return names;
  }
  const uint16_t entries = le16(zip, end + 10);
  std::size_t p = le32(zip, end + 16);
  for (uint16_t i = 0; i < entries; ++i) {
    if (p + 46 > zip.size() || le32(zip, p) != 0x02014b50u) {
      ADD_FAILURE() << "central directory entry " << i << " is not where the end record says";
      break;
    }
    const std::size_t nameLength = le16(zip, p + 28), extra = le16(zip, p + 30), comment = le16(zip, p + 32);
    names.push_back(zip.substr(p + 46, nameLength));
    p += 46 + nameLength + extra + comment;
  }
  return names;
}

// Lit (non-zero) pixels of every PNG of a mask directory, decoded with the project's decoder.
uint64_t litPixelsInDirectory(const fs::path& dir, std::size_t* images = nullptr) {
  uint64_t lit = 0;
  std::size_t count = 0;
  for (const auto& [name, bytes] : directoryContents(dir)) {
    if (!name.ends_with(".png")) continue;
    MaskImage mask;
    const auto* data = reinterpret_cast<const uint8_t*>(bytes.data());
    if (!decodeMaskPng(std::span<const uint8_t>(data, bytes.size()), mask)) {
      ADD_FAILURE() << name << ": not a decodable PNG";
      continue;
    }
    ++count;
    lit += static_cast<uint64_t>(
        std::count_if(mask.pixels.begin(), mask.pixels.end(), [](uint8_t v) { return v != 0; }));
  }
  if (images) *images = count;
  return lit;
}

std::vector<std::string> splitLines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

std::string jsonString(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

// ---------------------------------------------------------------------------------------------------
// Running the program

struct RunResult {
  int status = -1;  // raw wait status
  std::string out, err;

  bool exited() const { return WIFEXITED(status); }
  int code() const { return WIFEXITED(status) ? WEXITSTATUS(status) : -1; }
  bool signalled(int signal) const { return WIFSIGNALED(status) && WTERMSIG(status) == signal; }
  std::string describe() const {
    std::string d = WIFEXITED(status)     ? "exit " + std::to_string(WEXITSTATUS(status))
                    : WIFSIGNALED(status) ? "signal " + std::to_string(WTERMSIG(status))
                                          : "status " + std::to_string(status);
    return d + "\n--- stdout:\n" + out + "--- stderr:\n" + err;
  }
};

class CliToolBase : public testing::Test {
 public:
  void SetUp() override {
    std::string pattern = (fs::temp_directory_path() / "toposlice-cli-XXXXXX").string();
    ASSERT_NE(::mkdtemp(pattern.data()), nullptr) << "mkdtemp: " << std::strerror(errno);
    root_ = pattern;
    dir_ = root_ / "work";
    fs::create_directory(dir_);
    ASSERT_TRUE(fs::exists(toposliceBinary())) << "toposlice binary not found: " << toposliceBinary();
  }

  void TearDown() override {
    std::error_code ignored;
    if (!root_.empty()) fs::remove_all(root_, ignored);
  }

  // Starts toposlice with `args` in the work directory; stdout and stderr go to files beside it (so they
  // never show up in the work directory's listing), stdin is /dev/null.
  pid_t start(const std::vector<std::string>& args) {
    ++runs_;
    outPath_ = (root_ / ("stdout-" + std::to_string(runs_))).string();
    errPath_ = (root_ / ("stderr-" + std::to_string(runs_))).string();
    const std::string binary = toposliceBinary().string(), cwd = dir_.string();
    std::vector<std::string> all{binary};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    const char *out = outPath_.c_str(), *err = errPath_.c_str();

    const pid_t pid = ::fork();
    if (pid == 0) {  // child: async-signal-safe calls only
      const int in = ::open("/dev/null", O_RDONLY);
      const int o = ::open(out, O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int e = ::open(err, O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (in < 0 || o < 0 || e < 0 || ::dup2(in, 0) < 0 || ::dup2(o, 1) < 0 || ::dup2(e, 2) < 0) ::_exit(126);
      if (::chdir(cwd.c_str()) != 0) ::_exit(126);
      struct sigaction defaults {};
      defaults.sa_handler = SIG_DFL;
      ::sigaction(SIGINT, &defaults, nullptr);
      ::sigaction(SIGTERM, &defaults, nullptr);
      sigset_t none;
      ::sigemptyset(&none);
      ::sigprocmask(SIG_SETMASK, &none, nullptr);
      ::execv(binary.c_str(), argv.data());
      ::_exit(127);
    }
    EXPECT_GT(pid, 0) << "fork: " << std::strerror(errno);
    return pid;
  }

  // Waits for the child started last (killing it after `timeout`) and collects its output.
  RunResult finish(pid_t pid, std::chrono::seconds timeout = 120s) {
    RunResult r;
    if (pid <= 0) return r;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      const pid_t done = ::waitpid(pid, &r.status, WNOHANG);
      if (done == pid) break;
      if (done < 0) {
        ADD_FAILURE() << "waitpid: " << std::strerror(errno);
        break;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid, SIGKILL);
        ::waitpid(pid, &r.status, 0);
        ADD_FAILURE() << "toposlice did not finish within " << timeout.count() << " s";
        break;
      }
      std::this_thread::sleep_for(2ms);
    }
    r.out = readBytes(outPath_);
    r.err = readBytes(errPath_);
    return r;
  }

  RunResult run(const std::vector<std::string>& args) { return finish(start(args)); }

  fs::path path(const std::string& name) const { return dir_ / name; }

  // A failing command: exit 1, and stderr is exactly one line starting "toposlice: error:".
  static void expectOneErrorLine(const RunResult& r) {
    EXPECT_EQ(r.code(), 1) << r.describe();
    EXPECT_TRUE(r.err.starts_with("toposlice: error: ")) << r.describe();
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.describe();
    EXPECT_TRUE(r.err.ends_with("\n")) << r.describe();
  }

  void expectNoTemporaries() const {
    const auto left = temporariesIn(dir_);
    EXPECT_TRUE(left.empty()) << "temporaries left: " << testing::PrintToString(left);
  }

  fs::path root_, dir_;
  int runs_ = 0;
  std::string outPath_, errPath_;
};

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

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

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

// ---------------------------------------------------------------------------------------------------
// 4. existing outputs

TEST_F(CliToolOverwrite, ExistingOutputIsKeptWithoutForceAndReplacedWithIt) {
  const std::string old = "not a CLI file, keep me\n";
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
  EXPECT_TRUE(cli.starts_with("$$HEADERSTART\n$$ASCII\n")) << cli.substr(0, 100);
  EXPECT_TRUE(contains(cli, "$$LAYERS/16\n"));  // ceil(7.7 / 0.5)
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
      EXPECT_TRUE(cli.starts_with("$$HEADERSTART\n$$BINARY\n"));
      EXPECT_TRUE(contains(cli, "$$LAYERS/154\n"));  // ceil(7.7 / 0.05)
      EXPECT_EQ(png.size(), 154u);
      continue;
    }
    EXPECT_TRUE(cli == refCli) << tag << ": binary CLI differs from " << variants[0].first;
    EXPECT_TRUE(sl1 == refSl1) << tag << ": SL1 differs from " << variants[0].first;
    EXPECT_EQ(png.size(), refPng.size()) << tag;
    EXPECT_TRUE(png == refPng) << tag << ": PNG directory differs from " << variants[0].first;
  }
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
    if (!name.ends_with(".png")) continue;
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

// EXR stacks: the same bytes for every thread count and band size, and every layer, read by tinyexr,
// the pixels of the SL1 layer of the same run (binary and anti-aliased).
TEST_F(CliToolDeterminism, ExrStackIsByteIdenticalAndMatchesTheSl1) {
  for (const bool antiAliased : {false, true}) {
    std::map<std::string, std::string> reference;
    for (const std::vector<std::string>& extra :
         {std::vector<std::string>{"--threads", "1"}, {"--threads", "2"}, {"--band-layers", "7"}}) {
      const std::string tag = (antiAliased ? "aa" : "bin") + extra[0].substr(2, 1) + extra[1];
      std::vector<std::string> args{"slice", examplePart().string(), "-H", "0.1", "--printer", "sl1", "-q"};
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
        ASSERT_EQ(pngs.size(), 77u) << tag;  // ceil(7.7 / 0.1)
        ASSERT_EQ(files.size(), pngs.size()) << tag;
        uint32_t k = 0;
        for (const auto& [name, png] : pngs) {
          MaskImage expected;
          ASSERT_TRUE(decodeMaskPng(png, expected)) << name;
          const TinyExrLayer layer =
              readExrWithTinyExr(path(tag + ".exr") / exrLayerFileName("example_part", k, 77));
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
}

// ---------------------------------------------------------------------------------------------------
// 8. masks and report

TEST_F(CliToolMasks, Sl1ArchiveAndReportOfTheExamplePart) {
  const RunResult r = run({"slice", examplePart().string(), "--masks", "out.sl1", "--printer", "sl1", "-H",
                           "0.05", "--report", "r.csv"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  EXPECT_TRUE(contains(r.out, "resin")) << r.out;

  constexpr std::size_t kLayers = 154;  // ceil(7.7 mm / 0.05 mm)
  const auto names = zipEntryNames(readBytes(path("out.sl1")));
  EXPECT_EQ(names.size(), kLayers + 2);
  EXPECT_EQ(std::count(names.begin(), names.end(), "config.ini"), 1);
  EXPECT_EQ(std::count(names.begin(), names.end(), "prusaslicer.ini"), 1);
  EXPECT_EQ(
      std::count_if(names.begin(), names.end(), [](const std::string& n) { return n.ends_with(".png"); }),
      static_cast<std::ptrdiff_t>(kLayers));

  const auto lines = splitLines(readBytes(path("r.csv")));
  ASSERT_EQ(lines.size(), kLayers + 2);
  EXPECT_TRUE(lines.front().starts_with("layer,")) << lines.front();
  EXPECT_TRUE(lines[1].starts_with("0,")) << lines[1];
  EXPECT_TRUE(lines[kLayers].starts_with(std::to_string(kLayers - 1) + ",")) << lines[kLayers];
  const std::string& last = lines.back();
  ASSERT_TRUE(last.starts_with("# resin volume ")) << last;
  ASSERT_TRUE(last.ends_with(" ml")) << last;
  const double ml = std::stod(last.substr(15));
  // Square frame 12 x 12 with a 6 x 6 hole, 4 mm tall; torus R = 4, r = 1.2; sphere r = 1.5.
  const double pi = std::numbers::pi;
  const double analyticMm3 =
      (12.0 * 12.0 - 6.0 * 6.0) * 4.0 + 2.0 * pi * pi * 4.0 * 1.2 * 1.2 + 4.0 / 3.0 * pi * 1.5 * 1.5 * 1.5;
  EXPECT_NEAR(ml, analyticMm3 / 1000.0, 0.02 * analyticMm3 / 1000.0) << last;
  expectNoTemporaries();
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
  EXPECT_EQ(zipEntryNames(readBytes(path("m.sl1"))).size(), 4u + 2u);
  expectNoTemporaries();
}

// ---------------------------------------------------------------------------------------------------
// 9. features (inter-model reuse)

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

// ---------------------------------------------------------------------------------------------------
// 10. interrupt

// Starts a long slice, waits until an output temporary appears (at most 15 s) and holds bytes (at most
// 1.5 s more), sends `signal`, and checks the run ended early and left nothing behind.
void interruptAndCheck(CliToolBase& t, const std::vector<std::string>& args, int signal,
                       const fs::path& output, RunResult& result) {
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

TEST_F(CliToolInterrupt, SigtermDuringPngFolderOutputLeavesNothing) {
  RunResult r;
  interruptAndCheck(*this,
                    {"slice", sharedModel("derived/aligner_upper_case0.stl.gz").string(), "-H", "0.001",
                     "--masks", "bigpng", "--printer", "sl1", "-q"},
                    SIGTERM, path("bigpng"), r);
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
