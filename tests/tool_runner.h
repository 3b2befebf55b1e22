// The `toposlice` program run as a user runs it, for the end-to-end tests (cli_tool_test.cpp,
// output_safety_test.cpp): each test runs the real binary (fork + exec, stdout and stderr captured to
// files, exit status checked) in a fresh temporary directory, and checks what it prints and what it
// leaves on disk. The binary is $TOPOSLICE_BIN (set by ctest) or, when the tests run outside ctest, the
// build's own toposlice (TOPOSLICE_BIN_PATH).
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zip.h>  // libzip: reads archives back independently of the writers' minizip

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/coders/mask_png.h"

namespace toposlice::tool_test {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// ---------------------------------------------------------------------------------------------------
// Paths

inline fs::path toposliceBinary() {
  if (const char* env = std::getenv("TOPOSLICE_BIN"); env != nullptr && *env != '\0')
    return fs::absolute(env);
  return fs::absolute(TOPOSLICE_BIN_PATH);
}

inline fs::path sharedModel(const std::string& relative) {
  return fs::absolute(fs::path(TOPOSLICE_MODELS_DIR) / relative).lexically_normal();
}

inline fs::path examplePart() {
  return fs::absolute(fs::path(TOPOSLICE_SOURCE_DIR) / "examples" / "example_part.stl").lexically_normal();
}

// ---------------------------------------------------------------------------------------------------
// Files

inline std::string readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

inline void writeBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

inline uint32_t le32(const std::string& b, std::size_t at) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<uint8_t>(b.at(at + static_cast<std::size_t>(i)));
  return v;
}

inline uint16_t le16(const std::string& b, std::size_t at) {
  return static_cast<uint16_t>(static_cast<uint8_t>(b.at(at)) | (static_cast<uint8_t>(b.at(at + 1)) << 8));
}

// Names in `dir` that look like an output temporary (`<final>.tmp-<pid>-<n>` or `...-d<n>`).
inline std::vector<std::string> temporariesIn(const fs::path& dir) {
  std::vector<std::string> found;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().filename().string().find(".tmp-") != std::string::npos)
      found.push_back(entry.path().filename().string());
  return found;
}

// Every regular file of a directory: name -> bytes.
inline std::map<std::string, std::string> directoryContents(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.is_regular_file()) files[entry.path().filename().string()] = readBytes(entry.path());
  return files;
}

// Entry names of a zip archive, read from its central directory (classic end record; no Zip64 needed
// for the small archives made here).
inline std::vector<std::string> zipEntryNames(const std::string& zip) {
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

// An entry of a zip archive, read with libzip (not the writer's minizip); empty when it is missing.
inline std::string zipEntry(const fs::path& archive, const char* name) {
  int err = 0;
  zip_t* zip = zip_open(archive.c_str(), ZIP_RDONLY, &err);
  if (zip == nullptr) return {};
  std::string text;
  if (zip_file_t* f = zip_fopen(zip, name, 0)) {
    char buffer[4096];
    for (zip_int64_t n; (n = zip_fread(f, buffer, sizeof buffer)) > 0;)
      text.append(buffer, static_cast<std::size_t>(n));
    zip_fclose(f);
  }
  zip_close(zip);
  return text;
}

// Lit (non-zero) pixels of every PNG of a mask directory, decoded with the project's decoder.
inline uint64_t litPixelsInDirectory(const fs::path& dir, std::size_t* images = nullptr) {
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

inline std::vector<std::string> splitLines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Runs a shell command (another program, e.g. a decoder that is not ours); its exit status in `rc`, its
// standard output and error as the result.
inline std::string runTool(const std::string& command, int& rc) {
  char name[] = "/tmp/toposlice-tool-XXXXXX";
  const int fd = mkstemp(name);
  if (fd >= 0) close(fd);
  rc = std::system((command + " > " + name + " 2>&1").c_str());
  std::ifstream in(name);
  std::stringstream text;
  text << in.rdbuf();
  std::remove(name);
  return text.str();
}

inline std::string jsonString(const std::string& s) {
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
      if (fileSizeLimit_ > 0) {  // writes past it fail with EFBIG, as on a full disk
        struct rlimit limit {};
        limit.rlim_cur = limit.rlim_max = fileSizeLimit_;
        ::setrlimit(RLIMIT_FSIZE, &limit);
        struct sigaction ignore {};
        ignore.sa_handler = ignoreXfsz_ ? SIG_IGN : SIG_DFL;
        ::sigaction(SIGXFSZ, &ignore, nullptr);
      }
      if (memoryLimit_ > 0) {  // allocations past it fail (std::bad_alloc)
        struct rlimit limit {};
        limit.rlim_cur = limit.rlim_max = memoryLimit_;
        ::setrlimit(RLIMIT_AS, &limit);
      }
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

  // A limit on the size of every file the program writes (RLIMIT_FSIZE; 0: none): a write past it fails
  // with EFBIG, a disk-full failure without a full disk.
  // With ignoreSignal false, SIGXFSZ keeps its default action (the program must ignore it itself).
  void setFileSizeLimit(rlim_t bytes, bool ignoreSignal = true) {
    fileSizeLimit_ = bytes;
    ignoreXfsz_ = ignoreSignal;
  }

  // A limit on the program's address space (RLIMIT_AS; 0: none): allocations past it fail. Not with the
  // sanitizers, whose shadow memory needs terabytes of address space.
  void setMemoryLimit(rlim_t bytes) { memoryLimit_ = bytes; }

  fs::path root_, dir_;
  rlim_t fileSizeLimit_ = 0, memoryLimit_ = 0;
  bool ignoreXfsz_ = true;
  int runs_ = 0;
  std::string outPath_, errPath_;
};

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

}  // namespace toposlice::tool_test
