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
// Transactions: an OutputFile created on a thread while an OutputTransaction is current there joins it.
// Its commit() then writes out and closes the temporary but does not rename it: the transaction renames
// all of its outputs together at its own commit(), or removes every temporary when it is destroyed
// uncommitted, so a job's outputs appear together or not at all.
//
// Replacing (overwrite): only what toposlice writes is replaced. An existing final path that is a
// folder, or a file whose first bytes are not those of the format its extension names (see
// checkReplaceable), is refused even with overwrite.
//
// Signals: every live temporary is also listed in a fixed, process-wide table of C strings (at most
// kMaxPendingOutputs at once; a further one still works, it is just not listed). A SIGINT/SIGTERM
// handler calls removePendingOutputs(), which only reads that table and calls unlink(2), so an
// interrupted run leaves no temporary behind. Typical handler:
//     void onSignal(int sig) { removePendingOutputs(); signal(sig, SIG_DFL); raise(sig); }
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

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

  // Replaces size bytes already written, at `offset` (offset + size <= bytesWritten()): a header whose
  // counts are known only at the end. Writes out the buffer first. Throws OutputError like write().
  void rewriteAt(std::uint64_t offset, const void* data, std::size_t size);

  // Writes out the buffer, closes and renames the temporary to the final path (or, in a transaction,
  // hands the closed temporary to it). Throws OutputError on failure (the temporary is then removed by
  // the destructor). Call at most once.
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
  class OutputTransaction* transaction_ = nullptr;
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

// Temporaries a failed or interrupted job could not remove as it unwound (their folder made read-only
// under it, say): noted by the destructors, so that the command can say what it left instead of
// claiming it left nothing. Thread-safe; `take` empties the list.
void noteUnremovedTemporary(const std::filesystem::path& temp, int err) noexcept;
std::vector<std::string> takeUnremovedTemporaries();

// Whether anything (file, folder, link, even a dangling one) occupies `path`: the test every writer uses
// before refusing to replace an output.
bool outputPathExists(const std::filesystem::path& path);

// `path` as the file it names, for comparing two spellings of one file: absolute, with the links in its
// existing folders resolved ("same/o.cli" with same -> . is "<cwd>/o.cli"); the path itself may not exist.
std::filesystem::path resolvedPath(const std::filesystem::path& path);

// "<path>: already exists (use --force to overwrite)", the one message for a refused output.
std::string outputExistsMessage(const std::filesystem::path& path);

// What that message tells the user to do (default "use --force to overwrite"), and what a refusal of
// another program's file says was not enough (default "--force"): commands whose jobs say it in their
// JSON set them once at the start, before any thread runs.
void setOverwriteHint(std::string hint, std::string forceName = "--force");

// The reason a file or folder cannot be created at `path`, naming the folder rather than a temporary:
// "<path>: cannot create: folder 'out' does not exist" (ENOENT), "...: no permission to write in folder
// 'out'" (EACCES/EPERM), or "<path>: cannot create: <strerror>".
std::string cannotCreateMessage(const std::filesystem::path& path, int err);

// The reason to give when a library that writes `file` itself (OpenVDB, OpenEXR) reports a failed write
// in its own words ("IoError: write failed"): the system's reason when `savedErrno` (errno as the
// exception was caught) names a write failure, or "No space left on device" when the file system of
// `file` has no free block left, else the library's message.
std::string writeFailureReason(const std::filesystem::path& file, int savedErrno,
                               const std::string& libraryMessage);

// The extension of `path` in lower case, with its dot (".cli"); empty when there is none. Output kinds
// are chosen by it.
std::string lowerExtension(const std::filesystem::path& path);

// How checkReplaceable tells the files toposlice wrote from other programs' files of the same format,
// which start alike (a PrusaSlicer .sl1, a CAD .3mf, a photo at a preview's path): every file toposlice
// writes carries one of these marks where its format has room for a note (FORMATS.md, "Overwrite
// policy"). They view string literals, so data() is a C string.
// - The archive comment of every zip (SL1, NanoDLP, 3MF).
inline constexpr std::string_view kZipComment = "written by toposlice";
// - The comment line right after $$HEADERSTART of a CLI file (ASCII and binary).
inline constexpr std::string_view kCliMarkLine = "// written by toposlice //\n";
// - The comment right after an SVG file's XML declaration.
inline constexpr std::string_view kSvgMarkLine = "<!-- written by toposlice -->\n";
// - The program's name as the writing software: a PNG's tEXt chunk "Software", an EXR layer's string
//   attribute "software", a GOO header's software field, a VDB file's metadata "creator".
inline constexpr std::string_view kSoftwareName = "toposlice";

// What an output is, for the overwrite check.
enum class OutputKind { File, LayerFolder };

// Throws OutputError unless the existing entry at `path` may be replaced by a toposlice output of that
// kind: a File output replaces a regular file (or a link) that starts as toposlice writes the format of its
// extension and carries toposlice's mark (above): .cli and .svg with the mark line, .goo with the software
// field, .png, .exr and .vdb with the mark in their first 4 KiB, a .3mf, .sl1, .sl1s or .nanodlp zip that
// ends with the comment kZipComment, a .topo table, a .csv that starts with the per-layer report's header,
// a .json whose first key is "toposlice"; or any empty file. A file of any other extension is never
// replaced (toposlice writes none). A LayerFolder output replaces a folder holding only regular files named
// <anything><digits>.<ext> for the folder's layer extension `layerExt` (".png", ".exr"), each empty or
// one toposlice wrote by the rule above. The message names one entry toposlice would not have written. A
// missing path is fine.
void checkReplaceable(const std::filesystem::path& path, OutputKind kind, std::string_view layerExt = {});

// Folders a job makes for its outputs, taken away again when it fails: `note(folder)` before making
// `folder` records the outermost of its ancestors that does not exist yet; `removeEmpty()` removes each
// recorded folder that holds no file (folders only), as a failed job leaves none of its outputs.
class MadeFolders {
 public:
  void note(const std::filesystem::path& folder);
  void removeEmpty() const noexcept;

 private:
  std::vector<std::filesystem::path> made_;
};

// Whether an existing output at `path` (one that checkReplaceable finds toposlice's) is whole as far as
// its format tells: a file not empty and ending as a complete one does (a zip with toposlice's comment,
// an SVG's </svg>, a PNG's IEND chunk, a GOO's ending string, an ASCII CLI's $$GEOMETRYEND, a report's
// last line break; EXR, VDB and template files only not empty); a folder of layers of `layerExt` with at
// least one layer, each whole, numbered without a gap. For batch resumes: a variant whose outputs are
// not whole is sliced again.
bool outputLooksWhole(const std::filesystem::path& path, std::string_view layerExt = {});

// The check every writer makes when it opens `path`, made up front by a command before its long work: a
// missing path is fine; an existing one is refused without `overwrite` (outputExistsMessage) and, with
// it, unless checkReplaceable allows it. Throws OutputError. The writers check again when they open and
// commit (a file may appear meanwhile).
void checkOutputAllowed(const std::filesystem::path& path, bool overwrite, OutputKind kind = OutputKind::File,
                        std::string_view layerExt = {});

// A group of outputs that appear together or not at all (see the transactions paragraph above). While
// an OutputTransaction is alive it is the calling thread's current one (a later one nests inside it and
// restores it when destroyed). Not copyable or movable.
class OutputTransaction {
 public:
  OutputTransaction();
  ~OutputTransaction();  // not committed: removes every temporary handed to it; never throws
  OutputTransaction(const OutputTransaction&) = delete;
  OutputTransaction& operator=(const OutputTransaction&) = delete;

  // The calling thread's current transaction, or null.
  static OutputTransaction* current();

  // Makes `transaction` the calling thread's current one for the scope (work of one job handed to
  // another thread, which opens some of its outputs there), restoring the previous one after.
  class Adopt {
   public:
    explicit Adopt(OutputTransaction* transaction);
    ~Adopt();
    Adopt(const Adopt&) = delete;
    Adopt& operator=(const Adopt&) = delete;

   private:
    OutputTransaction* previous_;
  };

  // Moves every staged output under its final name. First every replaced entry is checked
  // (checkReplaceable) and moved aside, then each temporary is renamed into place (without overwrite,
  // refusing an existing final path atomically); any failure undoes the renames done so far and puts the
  // moved entries back, then throws OutputError: nothing of the transaction is left. Only then are the
  // old entries deleted. `cancel`, when given and set before the first rename, makes it throw instead
  // (an interrupted job commits nothing). Call at most once.
  void commit(const std::atomic<bool>* cancel = nullptr);

  // Final paths of the outputs committed (after commit()).
  const std::vector<std::filesystem::path>& committed() const { return committedPaths_; }

  // Used by OutputFile and StagedDirectory: takes over a closed temporary (file or folder) that is to
  // become `finalPath`. `registrySlot` is the temporary's entry in the signal table (-1: none); the
  // transaction releases it.
  struct Staged {
    std::filesystem::path temp, final;
    bool overwrite = false;
    OutputKind kind = OutputKind::File;
    std::string layerExt;
    int registrySlot = -1;
  };
  void stage(Staged staged);

  // The outputs staged so far, in staging order (toposlice-mpi sends them to rank 0, which commits the
  // outputs of every rank in one transaction).
  const std::vector<Staged>& staged() const { return staged_; }

  // Hands every staged output over without removing it: the transaction forgets them, and the caller
  // stages them in another transaction (or, after another process has committed them, releases their
  // signal-table slots with unregisterPendingOutput).
  std::vector<Staged> release();

 private:
  std::vector<Staged> staged_;
  std::vector<std::filesystem::path> committedPaths_;
  OutputTransaction* previous_ = nullptr;
  bool done_ = false;
};

// Registers a temporary path in the signal table (see above), made absolute so that a later change of
// the working directory does not matter; returns the slot or -1. Releases one. A folder's entry
// (folder = true) is a staged folder of files: the handler removes its files, then the folder.
int registerPendingOutput(const std::filesystem::path& path, bool folder = false);
void unregisterPendingOutput(int slot) noexcept;

}  // namespace toposlice
