// One gzip stream inflated on many threads (issue "Scale with cores": no serial stage left).
//
// A deflate stream is one chain of blocks, each free to copy from the 32 KiB before it, so it cannot
// simply be cut. The compressed bytes are split into parts at fixed offsets; every part after the first
// finds the first block that starts at or after its offset (a dynamic or stored block header whose code
// tables are valid and whose data decodes), and decodes from there without knowing the bytes before it:
// a copy that reaches back before the part's first byte is kept as a marker naming the byte of that
// window, until 32 KiB in a row are free of markers, after which the part is plain bytes. Every part
// decodes until the first block that ends at or after the next part's offset. Then, in stream order:
// a part is used only where the part before it ended exactly where this one was started (so the blocks
// are the stream's own, by induction from the first part, which starts at the stream's start), and its
// markers are replaced by the bytes before it. Finally the CRC-32 and size in the trailer are checked.
//
// The result is exactly the serial inflate's. The common case only: one member whose trailer gives the
// size, big enough to split. Anything else -- a header with a reserved flag or another method, several
// members, damage, a part boundary not confirmed -- returns false, and the caller inflates the serial
// way (which names any damage). Plain serial C++ on a ChunkRunner (core/chunk_runner.h).
#pragma once

#include <cstddef>
#include <span>

#include "core/chunk_runner.h"
#include "io/readers/byte_input.h"

namespace toposlice {

// The smallest part when the caller does not choose. Each part after the first costs about 1.5 ms of
// extra work (finding its start, the marker stretch, resolving it, a copy), measured on the aligner model
// (docs/BENCHMARKS.md, thread scaling, "Session 22"): one part per thread, but none smaller than this.
constexpr std::size_t kGunzipMinPartBytes = std::size_t{256} << 10;

// Inflates `in` into `out` on `runner` (which may be serial), in parts of about `partBytes` compressed
// bytes (0: one part per thread of the runner, at least kGunzipMinPartBytes). False when not handled,
// see above; `out` is then unspecified.
bool gunzipParallel(std::span<const std::byte> in, const ChunkRunner& runner, ByteBuffer& out,
                    std::size_t partBytes = 0);

}  // namespace toposlice
