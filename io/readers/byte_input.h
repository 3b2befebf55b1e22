// Bytes in, for every mesh reader (io/readers/): a whole file in memory, gzip streams inflated.
//
// - readWholeFile reads a file in one buffer ("<path>: cannot open: ...", "is a directory", "read error").
// - A gzip stream is recognised by its magic 1f 8b, never by the file name. Several concatenated members
//   are one stream. A corrupt, truncated or trailing-garbage stream is an InputError ("corrupt gzip
//   stream ...", "truncated gzip stream").
// - Sizes taken from a gzip trailer are hints only, capped by deflate's maximum ratio, so a forged
//   trailer cannot force a huge allocation.
#pragma once

#include <zlib.h>

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <thread>

namespace toposlice {

// Throws InputError("<name>: <what>").
[[noreturn]] void throwInputError(const std::string& name, const std::string& what);

// A token quoted for an error message: at most 32 characters, non-printable bytes as '?'; an empty
// token is "end of file".
std::string quoteToken(std::string_view token);

// A byte buffer that is not zero-filled on allocation (it is always overwritten).
struct ByteBuffer {
  std::unique_ptr<std::byte[]> data;
  std::size_t size = 0;
  std::size_t capacity = 0;

  void reserveExactly(std::size_t newCapacity);
  std::span<const std::byte> view() const { return {data.get(), size}; }
};

ByteBuffer readWholeFile(const std::filesystem::path& path);

bool isGzip(std::span<const std::byte> bytes);

// The length of the gzip member header `in` starts with, when it is the common case that every inflater
// here reads alike -- method 8, no reserved flag bit (libdeflate and zlib refuse those, ISA-L reads on),
// its optional fields whole and room for the 8-byte trailer after it -- and 0 otherwise.
std::size_t plainGzipHeaderLength(std::span<const std::byte> in);

// The last member's ISIZE trailer (the uncompressed size mod 2^32), capped; 0 when too short. A hint only.
std::size_t gzipSizeHint(std::span<const std::byte> in);

// Inflates one or more concatenated gzip members, on demand, into caller-owned memory.
class GzipReader {
 public:
  GzipReader(std::span<const std::byte> in, const std::string& name);
  ~GzipReader();
  GzipReader(const GzipReader&) = delete;
  GzipReader& operator=(const GzipReader&) = delete;

  std::size_t sizeHint() const { return gzipSizeHint(in_); }

  // Fills out[0, size); returns fewer bytes only at the end of the stream.
  std::size_t read(std::byte* out, std::size_t size);

  // The whole (remaining) stream, in one buffer sized from the trailer.
  ByteBuffer readAll();

 private:
  z_stream stream_{};
  std::span<const std::byte> in_;
  const std::string& name_;
  std::size_t fed_ = 0;  // bytes of in_ handed to zlib so far
  bool finished_ = false;
};

// The whole stream in one call of libdeflate (about twice zlib's speed), for the common case of one gzip
// member whose trailer gives the exact size. Returns false for anything else -- several members, a size
// over 4 GiB, any damage -- and the caller then reads it with GzipReader, which names the problem.
bool inflateWhole(std::span<const std::byte> in, std::size_t sizeHint, ByteBuffer& out);

// A gzip stream inflated on a thread of its own, a chunk at a time, into a small ring that a reader takes
// the chunks from in order, so that it parses what has arrived while the rest inflates (issue "Scale
// with cores": decompression overlapped with parsing). The inflated bytes never exist whole: a model's
// tens of megabytes are neither faulted in (every fresh page is a kernel entry and a page to zero, on
// the inflating thread that bounds the read) nor read back from memory, and the chunks in flight stay
// in cache. ISA-L's igzip inflates. It handles the common case only: one member whose trailer gives the
// exact size. Anything else -- several members, another size, any damage -- ends it as not handled, and
// the reader goes the general way (gunzip, whose messages name the damage).
class GzipChunks {
 public:
  // The stream's first headBytes bytes come as its head(), the rest as chunks of chunkBytes (the last
  // one shorter) from next(); at most `slots` chunks are inflated ahead of the reader. Starts inflating.
  GzipChunks(std::span<const std::byte> in, std::size_t headBytes, std::size_t chunkBytes,
             std::size_t slots = 8);
  ~GzipChunks();  // stops inflating, and waits for its thread
  GzipChunks(const GzipChunks&) = delete;
  GzipChunks& operator=(const GzipChunks&) = delete;

  std::size_t expectedSize() const { return capacity_; }  // the trailer's size
  // Blocks until the head is inflated; empty when the stream ended before it was whole.
  std::span<const std::byte> head();
  // Blocks until the next chunk is inflated; empty when the stream ended (cleanly or not) before it.
  // The chunk returned before is given back to the inflater: its bytes may change from here on.
  std::span<const std::byte> next();
  // Takes no more chunks (the rest of an unfinished stream is abandoned) and waits for the inflater.
  // True when every chunk was taken and the stream inflated cleanly to exactly expectedSize() bytes:
  // one member, its CRC-32 and size as the trailer says, nothing after it.
  bool finish();

 private:
  static constexpr uint64_t kEnded = uint64_t{1} << 63, kHandled = uint64_t{1} << 62;
  static constexpr uint64_t kStop = uint64_t{1} << 62;  // in taken_: the reader takes no more
  void inflateAll();
  void publish(uint64_t state);
  std::size_t chunkBegin(uint64_t c) const;            // chunk c's first byte in the stream
  std::span<const std::byte> chunk(uint64_t c) const;  // chunk c (0: the head) in its slot
  uint64_t waitForChunks(uint64_t chunks);  // blocks until that many are inflated or the end; how many are

  std::span<const std::byte> in_;
  std::size_t capacity_ = 0, headBytes_, chunkBytes_, slots_;
  std::unique_ptr<std::byte[]> head_, ring_;
  std::atomic<uint64_t> state_{0};  // chunks inflated (the head counts), with kEnded (and kHandled)
  std::atomic<uint64_t> taken_{0};  // chunks after the head the reader is done with, or kStop
  uint64_t current_ = 0;            // the chunk the reader holds (0: none yet, or the head)
  bool exhausted_ = false;          // next() returned the end
  std::thread thread_;
};

// The whole gzip stream `in` inflated: inflateWhole, else GzipReader::readAll (which names any damage).
ByteBuffer gunzip(std::span<const std::byte> in, const std::string& name);

}  // namespace toposlice
