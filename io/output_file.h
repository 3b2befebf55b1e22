// An output file that appears under its final name complete or not at all.
//
// Bytes go to a temporary file beside the final one, named "<final>.tmp-<pid>-<counter>" (same directory,
// so the final rename stays on one file system and is atomic). commit() writes out the buffer, closes the
// file and renames it to the final name; a reader never sees a partial file under the final name. An
// OutputFile destroyed without commit() (an exception, a cancelled run) removes its temporary.
//
// Overwrite policy: without `overwrite`, an existing final path is an error, checked when the file is
// opened and again, atomically, by the commit (renameat2 RENAME_NOREPLACE where the file system has it).
// Durability: commit() does not fsync; it protects against interruption and failed writes, not against
// a power loss right after the rename.
//
// Signals: every live temporary is also listed in a fixed, process-wide table of C strings (at most
// kMaxPendingOutputs at once; a further one still works, it is just not listed). A SIGINT/SIGTERM
// handler calls removePendingOutputs(), which only reads that table and calls unlink(2), so an
// interrupted run leaves no temporary behind. Typical handler:
//     void onSignal(int sig) { removePendingOutputs(); signal(sig, SIG_DFL); raise(sig); }
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>

namespace toposlice {

class OutputFile {
 public:
  static constexpr std::size_t kBufferSize = std::size_t{1} << 20;

  // Creates the temporary beside finalPath. Throws OutputError "<path>: already exists (use --force to
  // overwrite)" when finalPath exists and !overwrite, or "<path>: cannot create <temp>: <reason>".
  OutputFile(std::filesystem::path finalPath, bool overwrite);
  ~OutputFile();  // removes the temporary unless committed; never throws
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  // Appends size bytes. Small writes are buffered (kBufferSize), a large one goes out in one system
  // call. Throws OutputError "<path>: cannot write: <reason>" (disk full, I/O error); after a failure
  // the file can only be abandoned. Not allowed after commit().
  void write(const void* data, std::size_t size);

  // Writes out the buffer, closes and renames the temporary to the final path. Throws OutputError on
  // failure (the temporary is then removed by the destructor). Call at most once.
  void commit();

  const std::filesystem::path& finalPath() const { return finalPath_; }
  const std::filesystem::path& tempPath() const { return tempPath_; }
  std::uint64_t bytesWritten() const { return bytesWritten_ + used_; }
  bool committed() const { return committed_; }

 private:
  void flushBuffer();
  void writeAll(const char* data, std::size_t size);
  [[noreturn]] void fail(const char* what, int err);

  std::filesystem::path finalPath_;
  std::filesystem::path tempPath_;
  bool overwrite_;
  int fd_ = -1;
  int registrySlot_ = -1;
  bool committed_ = false;
  bool failed_ = false;
  std::unique_ptr<char[]> buffer_;
  std::size_t used_ = 0;
  std::uint64_t bytesWritten_ = 0;  // bytes handed to the kernel
};

inline constexpr std::size_t kMaxPendingOutputs = 64;

// Unlinks every temporary of a live, uncommitted OutputFile in this process. Async-signal-safe: reads a
// fixed array through lock-free atomics and calls only unlink(2). The OutputFile objects stay valid
// (their destructors find the temporary already gone, which is fine).
void removePendingOutputs() noexcept;

// Whether anything (file, folder, link, even a dangling one) occupies `path`: the test every writer uses
// before refusing to replace an output.
bool outputPathExists(const std::filesystem::path& path);

// "<path>: already exists (use --force to overwrite)", the one message for a refused output.
std::string outputExistsMessage(const std::filesystem::path& path);

}  // namespace toposlice
