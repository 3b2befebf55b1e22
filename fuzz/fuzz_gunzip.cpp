// libFuzzer harness for the parallel inflate (io/readers/parallel_gunzip.h) against the serial one
// (byte_input.h gunzip: libdeflate, then zlib). The parallel inflate must refuse a stream, or give exactly
// the serial inflate's bytes where that succeeds; it must never read what the serial one refuses.
// Input: 8 bytes of settings, then a payload.
// - byte 0, bit 0: 1, the payload is deflated by zlib (an independent encoder) with the settings of bytes
//   1 and 2 (level and strategy; memLevel and window), so that most inputs are valid streams of many
//   blocks; 0, the payload is the gzip stream itself;
// - bytes 3-6: when byte 6 is not zero, bit (byte 6 mod 8) of the stream's byte (bytes 3-5 mod its
//   size) is flipped: damage anywhere, in a stream that was valid;
// - byte 7: compressed bytes per part, 16 + 16 * byte 7, so that even small streams are cut into parts.
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <vector>

#include "io/errors.h"
#include "io/readers/byte_input.h"
#include "io/readers/parallel_gunzip.h"

namespace {

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_gunzip: invariant broken: %s\n", what);
  std::abort();
}

std::vector<std::byte> deflated(std::span<const uint8_t> payload, uint8_t a, uint8_t b) {
  constexpr int kStrategies[] = {Z_DEFAULT_STRATEGY, Z_FILTERED, Z_HUFFMAN_ONLY, Z_RLE, Z_FIXED};
  z_stream z{};
  if (deflateInit2(&z, a % 10, Z_DEFLATED, 16 + 9 + (b >> 4) % 7, 1 + (b & 15) % 9,
                   kStrategies[(a >> 4) % 5]) != Z_OK)
    return {};
  std::vector<std::byte> out(deflateBound(&z, static_cast<uLong>(payload.size())) + 64);
  z.next_in = const_cast<Bytef*>(payload.data());
  z.avail_in = static_cast<uInt>(payload.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  const int rc = deflate(&z, Z_FINISH);
  out.resize(rc == Z_STREAM_END ? z.total_out : 0);
  deflateEnd(&z);
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  constexpr std::size_t kSettings = 8;
  if (size < kSettings) return 0;
  const std::span<const uint8_t> payload(data + kSettings, size - kSettings);
  std::vector<std::byte> stream;
  if (data[0] & 1) {
    stream = deflated(payload, data[1], data[2]);
  } else {
    stream.assign(reinterpret_cast<const std::byte*>(payload.data()),
                  reinterpret_cast<const std::byte*>(payload.data()) + payload.size());
  }
  if (data[6] != 0 && !stream.empty()) {
    const std::size_t at = (data[3] | data[4] << 8 | data[5] << 16) % stream.size();
    stream[at] ^= static_cast<std::byte>(1u << (data[6] % 8));
  }
  const std::size_t partBytes = 16 + 16 * std::size_t{data[7]};

  toposlice::ByteBuffer parallel;
  const bool handled = toposlice::gunzipParallel(stream, toposlice::serialChunkRunner(), parallel, partBytes);
  toposlice::ByteBuffer serial;
  bool serialRead = true;
  try {
    serial = toposlice::gunzip(stream, "fuzz.gz");
  } catch (const toposlice::InputError&) {
    serialRead = false;
  }
  if (handled) {
    require(serialRead, "the parallel inflate reads only what the serial inflate reads");
    require(parallel.size == serial.size &&
                (serial.size == 0 || std::memcmp(parallel.data.get(), serial.data.get(), serial.size) == 0),
            "the parallel inflate gives the serial inflate's bytes");
  }
  return 0;
}
