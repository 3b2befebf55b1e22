#include "io/jobs/template_file.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <memory>
#include <system_error>

#include "core/mesh/adjacency.h"
#include "core/prefetch.h"
#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {

// The file is little-endian and entries are copied with memcpy; every platform toposlice targets
// (x86-64, AArch64) is little-endian.
static_assert(std::endian::native == std::endian::little, "template files are decoded by memcpy");

namespace {

constexpr char kMagic[8] = {'T', 'O', 'P', 'O', 'S', 'L', 'C', '\0'};
constexpr uint64_t kFingerprintSeed = 0x544F504F2D434F4Eull;  // "TOPO-CON"
constexpr uint64_t kChecksumSeed = 0x544F504F2D53554Dull;     // "TOPO-SUM"
constexpr uint64_t kMul1 = 0x9E3779B97F4A7C15ull;
constexpr uint64_t kMul2 = 0xD6E8FEB86659FD93ull;
constexpr std::size_t kBlock = 32;

// The format's 64-bit hash (docs/FORMATS.md): four lanes, each absorbing every fourth little-endian
// 64-bit word of the zero-padded input with v = xorshift32((v ^ w) * kMul2); then the lanes and the
// length are folded together. Every step is invertible in the lane, so a change confined to one aligned
// 8-byte word always changes the result. Streaming: every update but the last must be a whole number
// of 32-byte blocks (the header is one block, so header and entries can be hashed from separate buffers).
class Hash64 {
 public:
  explicit Hash64(uint64_t seed) {
    for (uint64_t l = 0; l < 4; ++l) lanes_[l] = seed + (l + 1) * kMul1;
  }

  void update(std::span<const std::byte> bytes) {
    assert(!tail_ && "only the last update may end in a partial block");
    length_ += bytes.size();
    const std::size_t whole = bytes.size() - bytes.size() % kBlock;
    for (std::size_t b = 0; b < whole; b += kBlock) absorb(bytes.data() + b);
    if (whole < bytes.size()) {
      std::byte last[kBlock] = {};
      std::memcpy(last, bytes.data() + whole, bytes.size() - whole);
      absorb(last);
      tail_ = true;
    }
  }

  uint64_t finish() const {
    uint64_t h = length_ * kMul1;
    for (const uint64_t lane : lanes_) {
      h ^= lane;
      h *= kMul2;
      h ^= h >> 29;
    }
    h ^= h >> 32;
    h *= kMul1;
    return h ^ (h >> 29);
  }

 private:
  void absorb(const std::byte* block) {
    uint64_t w[4];
    std::memcpy(w, block, kBlock);
    for (int l = 0; l < 4; ++l) {
      uint64_t v = (lanes_[l] ^ w[l]) * kMul2;
      lanes_[l] = v ^ (v >> 32);
    }
  }

  uint64_t lanes_[4];
  uint64_t length_ = 0;
  bool tail_ = false;
};

struct Header {
  uint32_t version = 0, facetCount = 0, vertexCount = 0, flags = 0;
  uint64_t fingerprint = 0;
};

template <typename T>
T loadLe(const std::byte* p) {
  T value;
  std::memcpy(&value, p, sizeof value);
  return value;
}

template <typename T>
void storeLe(std::byte* p, T value) {
  std::memcpy(p, &value, sizeof value);
}

uint64_t expectedFileSize(uint32_t facetCount) {
  return kTemplateHeaderSize + uint64_t{12} * facetCount + kTemplateChecksumSize;
}

std::string hex64(uint64_t v) {
  char text[24];
  std::snprintf(text, sizeof text, "0x%016" PRIx64, v);
  return text;
}

[[noreturn]] void fail(const std::string& name, const std::string& what) {
  throw InputError(name + ": " + what);
}

// Checks what the first bytes of a file (up to the 32-byte header) and its size can tell: magic,
// version and a size matching the facet count. `head` holds min(fileSize, 32) bytes.
Header checkHeader(std::span<const std::byte> head, uint64_t fileSize, const std::string& name) {
  if (fileSize == 0) fail(name, "empty file, not a toposlice template");
  if (std::memcmp(head.data(), kMagic, std::min<std::size_t>(head.size(), sizeof kMagic)) != 0) {
    fail(name, "not a toposlice template (no TOPOSLC magic at the start)");
  }
  if (fileSize < kTemplateHeaderSize) {
    fail(name, "truncated: " + std::to_string(fileSize) + " bytes, shorter than the " +
                   std::to_string(kTemplateHeaderSize) + "-byte header");
  }
  Header h;
  h.version = loadLe<uint32_t>(head.data() + 8);
  h.facetCount = loadLe<uint32_t>(head.data() + 12);
  h.vertexCount = loadLe<uint32_t>(head.data() + 16);
  h.flags = loadLe<uint32_t>(head.data() + 20);
  h.fingerprint = loadLe<uint64_t>(head.data() + 24);
  if (h.version != kTemplateFormatVersion) {
    fail(name, "unsupported template version " + std::to_string(h.version) + " (this build reads version " +
                   std::to_string(kTemplateFormatVersion) + ")");
  }
  const uint64_t expected = expectedFileSize(h.facetCount);
  const std::string sizes = std::to_string(fileSize) + " bytes, a table of " + std::to_string(h.facetCount) +
                            " facets needs " + std::to_string(expected);
  if (fileSize < expected) fail(name, "truncated: file has " + sizes);
  if (fileSize > expected) fail(name, "file has " + sizes + " (trailing data or a corrupt facet count)");
  return h;
}

// Branch-light pass over the table with the same rules as findBadEntry: nonzero when some entry is
// bad. Neighbours' rows are prefetched a few dozen facets ahead, since neighbours can lie far apart in
// facet order.
uint32_t screenTable(std::span<const int32_t> adjacency) {
  constexpr std::size_t kAhead = 48;
  const std::size_t t = adjacency.size() / 3;
  uint32_t bad = 0;
  for (std::size_t i = 0; i < t; ++i) {
    if (i + kAhead < t) {
      for (std::size_t e = 3 * (i + kAhead); e < 3 * (i + kAhead) + 3; ++e) {
        const auto ahead = static_cast<std::size_t>(static_cast<uint32_t>(adjacency[e]));
        if (ahead < t) prefetch(&adjacency[3 * ahead]);
      }
    }
    const int32_t* row = &adjacency[3 * i];
    const auto self = static_cast<int32_t>(i);
    for (unsigned j = 0; j < 3; ++j) {
      const int32_t k = row[j];
      const auto ku = static_cast<std::size_t>(static_cast<uint32_t>(k));  // -1 and negatives: huge
      if (ku >= t) {
        bad |= static_cast<uint32_t>(k != -1);
        continue;
      }
      const int32_t* back = &adjacency[3 * ku];
      const int fromI = (row[0] == k) + (row[1] == k) + (row[2] == k);
      const int fromK = (back[0] == self) + (back[1] == self) + (back[2] == self);
      bad |= static_cast<uint32_t>(fromI != fromK) | static_cast<uint32_t>(ku == i);
    }
  }
  return bad;
}

// Linear scan for the first entry that breaks the table's invariants: in [-1, t), not the facet
// itself, and symmetric (facet k names i exactly as often as i names k). Returns the entry's index, or
// adjacency.size() when the table is valid; `why` says what is wrong.
std::size_t findBadEntry(std::span<const int32_t> adjacency, const char*& why) {
  const std::size_t t = adjacency.size() / 3;
  for (std::size_t e = 0; e < adjacency.size(); ++e) {
    const int32_t k = adjacency[e];
    if (k == -1) continue;
    if (k < -1 || static_cast<std::size_t>(k) >= t) {
      why = "is out of range";
      return e;
    }
    const std::size_t i = e / 3, ku = static_cast<std::size_t>(k);
    if (ku == i) {
      why = "names its own facet";
      return e;
    }
    const auto ii = static_cast<int32_t>(i);
    const int fromI = (adjacency[3 * i] == k) + (adjacency[3 * i + 1] == k) + (adjacency[3 * i + 2] == k);
    const int fromK =
        (adjacency[3 * ku] == ii) + (adjacency[3 * ku + 1] == ii) + (adjacency[3 * ku + 2] == ii);
    if (fromI != fromK) {
      why = "is not matched by the neighbour's entries (table not symmetric)";
      return e;
    }
  }
  return adjacency.size();
}

// The checks that follow a good checksum: flags, counts and the table's invariants.
void checkTable(const Header& h, std::span<const int32_t> adjacency, const std::string& name) {
  if (h.flags != 0) {
    fail(name, "uses features this build does not support (flags " + hex64(h.flags) + ")");
  }
  if (h.facetCount > uint32_t{INT32_MAX}) {
    fail(name,
         "facet count " + std::to_string(h.facetCount) + " exceeds the largest table (2^31 - 1 facets)");
  }
  if (uint64_t{h.vertexCount} > uint64_t{3} * h.facetCount) {
    fail(name, "vertex count " + std::to_string(h.vertexCount) + " is impossible for " +
                   std::to_string(h.facetCount) + " facets");
  }
  if (screenTable(adjacency) == 0) return;
  const char* why = "";
  const std::size_t bad = findBadEntry(adjacency, why);
  if (bad != adjacency.size()) {
    fail(name, "facet " + std::to_string(bad / 3) + " edge " + std::to_string(bad % 3) + ": neighbour " +
                   std::to_string(adjacency[bad]) + " " + why + " (" + std::to_string(h.facetCount) +
                   " facets)");
  }
}

void checkChecksum(uint64_t stored, uint64_t computed, const std::string& name) {
  if (stored != computed) {
    fail(name, "corrupt: checksum mismatch (stored " + hex64(stored) + ", computed " + hex64(computed) + ")");
  }
}

TemplateTable tableFrom(const Header& h) {
  TemplateTable table;
  table.facetCount = h.facetCount;
  table.vertexCount = h.vertexCount;
  table.fingerprint = h.fingerprint;
  return table;
}

std::span<const std::byte> bytesOf(std::span<const int32_t> entries) {
  return std::as_bytes(entries);
}

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

}  // namespace

uint64_t connectivityFingerprint(std::span<const uint32_t> facetVertices) {
  Hash64 hash(kFingerprintSeed);
  hash.update(std::as_bytes(facetVertices));
  return hash.finish();
}

uint64_t templateChecksum(std::span<const std::byte> headerAndEntries) {
  Hash64 hash(kChecksumSeed);
  hash.update(headerAndEntries);
  return hash.finish();
}

TemplateTable buildTemplateTable(const IndexedMesh& mesh, const ChunkRunner& runner) {
  assert(mesh.facetCount() <= std::size_t{INT32_MAX});
  TemplateTable table;
  table.facetCount = static_cast<uint32_t>(mesh.facetCount());
  table.vertexCount = static_cast<uint32_t>(mesh.vertices.size());
  table.fingerprint = connectivityFingerprint(mesh.facetVertices);
  table.adjacency.resize(mesh.facetVertices.size());
  buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table.adjacency, runner);
  return table;
}

void writeTemplateFile(const std::filesystem::path& path, const TemplateTable& table, bool overwrite) {
  assert(table.adjacency.size() == std::size_t{3} * table.facetCount);
  std::byte header[kTemplateHeaderSize];
  std::memcpy(header, kMagic, sizeof kMagic);
  storeLe<uint32_t>(header + 8, kTemplateFormatVersion);
  storeLe<uint32_t>(header + 12, table.facetCount);
  storeLe<uint32_t>(header + 16, table.vertexCount);
  storeLe<uint32_t>(header + 20, 0);
  storeLe<uint64_t>(header + 24, table.fingerprint);
  const std::span<const std::byte> entries = bytesOf(table.adjacency);

  Hash64 hash(kChecksumSeed);
  hash.update(header);
  hash.update(entries);
  std::byte checksum[kTemplateChecksumSize];
  storeLe<uint64_t>(checksum, hash.finish());

  OutputFile out(path, overwrite);
  out.write(header, sizeof header);
  out.write(entries.data(), entries.size());
  out.write(checksum, sizeof checksum);
  out.commit();
}

TemplateTable parseTemplate(std::span<const std::byte> bytes, const std::string& name) {
  const Header h = checkHeader(bytes.first(std::min(bytes.size(), kTemplateHeaderSize)), bytes.size(), name);
  const std::size_t body = bytes.size() - kTemplateChecksumSize;
  checkChecksum(loadLe<uint64_t>(bytes.data() + body), templateChecksum(bytes.first(body)), name);
  TemplateTable table = tableFrom(h);
  table.adjacency.resize(std::size_t{3} * h.facetCount);
  if (!table.adjacency.empty())  // memcpy's pointers must be valid even for zero bytes (fuzzer finding)
    std::memcpy(table.adjacency.data(), bytes.data() + kTemplateHeaderSize, body - kTemplateHeaderSize);
  checkTable(h, table.adjacency, name);
  return table;
}

TemplateTable readTemplateFile(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(name, "is a directory, not a template file");
  std::unique_ptr<std::FILE, FileCloser> file(std::fopen(name.c_str(), "rb"));
  if (!file) fail(name, "cannot open: " + std::generic_category().message(errno));
  const uint64_t size = std::filesystem::file_size(path, ec);
  if (ec) fail(name, "cannot read: " + ec.message());
  const auto readFailure = [&]() -> std::string {
    return std::ferror(file.get()) ? "read error: " + std::generic_category().message(errno)
                                   : std::string("file changed while being read");
  };

  // Header first: a wrong or huge file fails before anything else is read or allocated.
  std::byte header[kTemplateHeaderSize];
  const std::size_t headBytes = static_cast<std::size_t>(std::min<uint64_t>(size, kTemplateHeaderSize));
  if (std::fread(header, 1, headBytes, file.get()) != headBytes) fail(name, readFailure());
  const Header h = checkHeader(std::span<const std::byte>(header, headBytes), size, name);

  TemplateTable table = tableFrom(h);
  table.adjacency.resize(std::size_t{3} * h.facetCount);
  std::byte stored[kTemplateChecksumSize];
  if (std::fread(table.adjacency.data(), sizeof(int32_t), table.adjacency.size(), file.get()) !=
          table.adjacency.size() ||
      std::fread(stored, 1, sizeof stored, file.get()) != sizeof stored) {
    fail(name, readFailure());
  }
  if (std::fgetc(file.get()) != EOF) fail(name, "file changed while being read");

  Hash64 hash(kChecksumSeed);
  hash.update(header);
  hash.update(bytesOf(table.adjacency));
  checkChecksum(loadLe<uint64_t>(stored), hash.finish(), name);
  checkTable(h, table.adjacency, name);
  return table;
}

}  // namespace toposlice
