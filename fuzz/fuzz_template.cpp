// libFuzzer harness for the template reader (io/jobs/template_file.h). Each input is parsed twice:
// 1. as given, which exercises the header, size and checksum checks;
// 2. with its last 8 bytes replaced by the right checksum (templateChecksum), so that mutated tables get
//    past the checksum and reach the flag, count and adjacency validation behind it.
// InputError is the expected answer to bad input; any other exception, a sanitizer report or a table that
// breaks the format's invariants is a crash. A loaded table must satisfy:
// - adjacency.size() == 3 * facetCount, vertexCount <= 3 * facetCount, facetCount < 2^31;
// - every entry in [-1, facetCount), never the facet itself, and symmetric: facet k names i exactly as
//   often as i names k;
// - written back in the file layout, it is the input byte for byte (nothing repaired or dropped).
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <vector>

#include "io/errors.h"
#include "io/jobs/template_file.h"

namespace {

using toposlice::kTemplateChecksumSize;
using toposlice::kTemplateHeaderSize;

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_template: invariant broken: %s\n", what);
  std::abort();
}

void checkTable(std::span<const std::byte> bytes, const toposlice::TemplateTable& table) {
  const std::size_t t = table.facetCount;
  require(t <= std::size_t{INT32_MAX}, "facetCount < 2^31");
  require(table.adjacency.size() == 3 * t, "3 adjacency entries per facet");
  require(uint64_t{table.vertexCount} <= uint64_t{3} * t, "vertexCount <= 3 * facetCount");
  const std::span<const int32_t> adj(table.adjacency);
  for (std::size_t i = 0; i < t; ++i) {
    for (std::size_t j = 0; j < 3; ++j) {
      const int32_t k = adj[3 * i + j];
      if (k == -1) continue;
      require(k >= 0 && static_cast<std::size_t>(k) < t, "entries are in [-1, facetCount)");
      const auto ku = static_cast<std::size_t>(k);
      require(ku != i, "no entry names its own facet");
      const auto ii = static_cast<int32_t>(i);
      const auto fromI = std::count(adj.begin() + 3 * i, adj.begin() + 3 * i + 3, k);
      const auto fromK = std::count(adj.begin() + 3 * ku, adj.begin() + 3 * ku + 3, ii);
      require(fromI == fromK, "the table is symmetric");
    }
  }

  // The file layout (io/jobs/template_file.h), rebuilt from the table: it must be the input.
  require(bytes.size() == kTemplateHeaderSize + 12 * t + kTemplateChecksumSize, "file size is 40 + 12 t");
  std::vector<std::byte> file(bytes.size());
  const uint32_t header[4] = {toposlice::kTemplateFormatVersion, table.facetCount, table.vertexCount, 0};
  std::memcpy(file.data(), "TOPOSLC", 8);
  std::memcpy(file.data() + 8, header, sizeof header);
  std::memcpy(file.data() + 24, &table.fingerprint, 8);
  if (t > 0) std::memcpy(file.data() + kTemplateHeaderSize, table.adjacency.data(), 12 * t);
  const std::size_t body = bytes.size() - kTemplateChecksumSize;
  const uint64_t checksum = toposlice::templateChecksum(std::span<const std::byte>(file).first(body));
  std::memcpy(file.data() + body, &checksum, 8);
  require(std::equal(file.begin(), file.end(), bytes.begin()), "the table written back is the input");
}

void parseAndCheck(std::span<const std::byte> bytes) {
  try {
    checkTable(bytes, toposlice::parseTemplate(bytes, "fuzz.topo"));
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  parseAndCheck(bytes);
  if (size < kTemplateHeaderSize + kTemplateChecksumSize) return 0;

  std::vector<std::byte> fixed(bytes.begin(), bytes.end());
  const std::size_t body = size - kTemplateChecksumSize;
  const uint64_t checksum = toposlice::templateChecksum(bytes.first(body));
  std::memcpy(fixed.data() + body, &checksum, sizeof checksum);
  parseAndCheck(fixed);
  return 0;
}
