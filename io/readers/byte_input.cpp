#include "io/readers/byte_input.h"

#include <fcntl.h>
#include <isa-l/igzip_lib.h>
#include <libdeflate.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdint>
#include <cstring>
#include <system_error>

#include "core/memory_advice.h"
#include "io/errors.h"

namespace toposlice {

void throwInputError(const std::string& name, const std::string& what) {
  throw InputError(name + ": " + what);
}

std::string quoteToken(std::string_view token) {
  if (token.empty()) return "end of file";
  std::string text = "'";
  for (std::size_t i = 0; i < token.size() && i < 32; ++i) {
    const char c = token[i];
    text += c >= ' ' && c <= '~' ? c : '?';
  }
  if (token.size() > 32) text += "...";
  return text + "'";
}

void ByteBuffer::reserveExactly(std::size_t newCapacity) {
  auto grown = std::make_unique_for_overwrite<std::byte[]>(newCapacity);
  adviseHugePages(grown.get(), newCapacity);  // a whole file or model: written once, read by every stage
  if (size > 0) std::memcpy(grown.get(), data.get(), size);
  data = std::move(grown);
  capacity = newCapacity;
}

ByteBuffer readWholeFile(const std::filesystem::path& path) {
  const std::string name = path.string();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throwInputError(name, "cannot open: " + std::generic_category().message(errno));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat info {};
  if (::fstat(fd, &info) != 0)
    throwInputError(name, "cannot stat: " + std::generic_category().message(errno));
  if (S_ISDIR(info.st_mode)) throwInputError(name, "is a directory");

  ByteBuffer buffer;
  // One byte more than a regular file's size, so the read that sees the end needs no growth.
  const std::size_t expected = S_ISREG(info.st_mode) ? static_cast<std::size_t>(info.st_size) : 0;
  buffer.reserveExactly(std::max<std::size_t>(expected + 1, 4096));
  for (;;) {
    if (buffer.size == buffer.capacity) buffer.reserveExactly(buffer.capacity * 2);
    const ssize_t got = ::read(fd, buffer.data.get() + buffer.size, buffer.capacity - buffer.size);
    if (got < 0) {
      if (errno == EINTR) continue;
      throwInputError(name, "read error: " + std::generic_category().message(errno));
    }
    if (got == 0) break;
    buffer.size += static_cast<std::size_t>(got);
  }
  return buffer;
}

bool isGzip(std::span<const std::byte> bytes) {
  return bytes.size() >= 2 && bytes[0] == std::byte{0x1F} && bytes[1] == std::byte{0x8B};
}

std::size_t plainGzipHeaderLength(std::span<const std::byte> bytes) {
  constexpr uint8_t kDeflate = 8, kHcrc = 2, kExtra = 4, kName = 8, kComment = 16, kReserved = 0xE0;
  const std::span<const uint8_t> in(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  if (in.size() < 18 || !isGzip(bytes) || in[2] != kDeflate || (in[3] & kReserved) != 0) return 0;
  std::size_t at = 10;
  const uint8_t flags = in[3];
  if (flags & kExtra) {
    if (at + 2 > in.size()) return 0;
    at += 2 + (in[at] | in[at + 1] << 8);
  }
  for (const uint8_t flag : {kName, kComment}) {
    if (!(flags & flag)) continue;
    while (at < in.size() && in[at] != 0) ++at;
    ++at;
  }
  if (flags & kHcrc) at += 2;
  return at + 8 <= in.size() ? at : 0;
}

std::size_t gzipSizeHint(std::span<const std::byte> in) {
  if (in.size() < 18) return 0;
  const std::byte* p = in.data() + in.size() - 4;
  uint32_t trailer = 0;
  for (int i = 3; i >= 0; --i) trailer = (trailer << 8) | std::to_integer<uint32_t>(p[i]);
  const std::size_t maxBytes = in.size() <= SIZE_MAX / 1100 ? in.size() * 1100 : SIZE_MAX / 2;
  return std::min<std::size_t>(trailer, maxBytes);
}

GzipReader::GzipReader(std::span<const std::byte> in, const std::string& name) : in_(in), name_(name) {
  if (inflateInit2(&stream_, 16 + MAX_WBITS) != Z_OK) throwInputError(name_, "cannot initialise zlib");
}

GzipReader::~GzipReader() {
  inflateEnd(&stream_);
}

std::size_t GzipReader::read(std::byte* out, std::size_t size) {
  std::size_t done = 0;
  while (done < size && !finished_) {
    if (stream_.avail_in == 0 && fed_ < in_.size()) {
      const std::size_t chunk = std::min<std::size_t>(in_.size() - fed_, UINT_MAX);
      // zlib's API is not const-correct; it never writes through next_in.
      stream_.next_in = const_cast<Bytef*>(reinterpret_cast<const Bytef*>(in_.data() + fed_));
      stream_.avail_in = static_cast<uInt>(chunk);
      fed_ += chunk;
    }
    const auto room = static_cast<uInt>(std::min<std::size_t>(size - done, UINT_MAX));
    stream_.next_out = reinterpret_cast<Bytef*>(out + done);
    stream_.avail_out = room;
    const int rc = inflate(&stream_, Z_NO_FLUSH);
    done += room - stream_.avail_out;
    if (rc == Z_STREAM_END) {
      const std::size_t rest = stream_.avail_in + (in_.size() - fed_);
      if (rest == 0) {
        finished_ = true;
      } else if (isGzip(in_.subspan(in_.size() - rest))) {
        inflateReset(&stream_);  // the next member of a multi-member file
      } else {
        throwInputError(name_,
                        "corrupt gzip stream: " + std::to_string(rest) + " unexpected bytes after its end");
      }
    } else if (rc == Z_BUF_ERROR) {
      // No progress with room to write: the input ran out before the end of the stream.
      if (stream_.avail_in == 0 && fed_ == in_.size()) throwInputError(name_, "truncated gzip stream");
    } else if (rc == Z_MEM_ERROR) {
      throwInputError(name_, "out of memory while decompressing gzip");
    } else if (rc != Z_OK) {
      throwInputError(name_,
                      std::string("corrupt gzip stream: ") + (stream_.msg ? stream_.msg : "invalid data"));
    }
  }
  return done;
}

ByteBuffer GzipReader::readAll() {
  ByteBuffer out;
  out.reserveExactly(std::max<std::size_t>(sizeHint() + 1, 4096));
  for (;;) {
    const std::size_t room = out.capacity - out.size;
    const std::size_t got = read(out.data.get() + out.size, room);
    out.size += got;
    if (got < room) return out;
    out.reserveExactly(out.capacity * 2);
  }
}

bool inflateWhole(std::span<const std::byte> in, std::size_t sizeHint, ByteBuffer& out) {
  if (sizeHint == 0) return false;
  struct Freer {
    void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
  };
  const std::unique_ptr<libdeflate_decompressor, Freer> decompressor(libdeflate_alloc_decompressor());
  if (!decompressor) return false;
  out.reserveExactly(sizeHint + 1);
  std::size_t inUsed = 0, outSize = 0;
  const libdeflate_result rc = libdeflate_gzip_decompress_ex(decompressor.get(), in.data(), in.size(),
                                                             out.data.get(), sizeHint, &inUsed, &outSize);
  if (rc != LIBDEFLATE_SUCCESS || inUsed != in.size() || outSize != sizeHint) return false;
  out.size = outSize;
  return true;
}

GzipChunks::GzipChunks(std::span<const std::byte> in, std::size_t headBytes, std::size_t chunkBytes,
                       std::size_t slots)
    : in_(in), capacity_(gzipSizeHint(in)), headBytes_(headBytes), chunkBytes_(chunkBytes), slots_(slots) {
  // ISA-L counts input and output in 32 bits; a size of 0 (an empty or forged trailer) is not the common
  // case. Nor is a header that is not plain (plainGzipHeaderLength): the result must not depend on which
  // inflater read the stream.
  if (plainGzipHeaderLength(in) == 0 || capacity_ == 0 || in.size() > UINT32_MAX || headBytes_ > UINT32_MAX ||
      chunkBytes_ == 0 || chunkBytes_ > UINT32_MAX || slots_ == 0) {
    publish(kEnded);
    return;
  }
  head_ = std::make_unique_for_overwrite<std::byte[]>(std::max<std::size_t>(headBytes_, 1));
  ring_ = std::make_unique_for_overwrite<std::byte[]>(slots_ * chunkBytes_);
  thread_ = std::thread([this] { inflateAll(); });
}

GzipChunks::~GzipChunks() {
  finish();
}

void GzipChunks::publish(uint64_t state) {
  state_.store(state, std::memory_order_release);
  state_.notify_all();
}

std::size_t GzipChunks::chunkBegin(uint64_t c) const {
  return c == 0 ? 0 : headBytes_ + (c - 1) * chunkBytes_;
}

std::span<const std::byte> GzipChunks::chunk(uint64_t c) const {
  if (c == 0) return {head_.get(), std::min(headBytes_, capacity_)};
  return {ring_.get() + ((c - 1) % slots_) * chunkBytes_, std::min(chunkBytes_, capacity_ - chunkBegin(c))};
}

void GzipChunks::inflateAll() {
  inflate_state s;
  isal_inflate_init(&s);
  s.crc_flag = ISAL_GZIP;  // header parsed, CRC-32 checked against the trailer
  s.next_in = const_cast<uint8_t*>(reinterpret_cast<const uint8_t*>(in_.data()));
  s.avail_in = static_cast<uint32_t>(in_.size());
  uint64_t c = 0;  // the chunk being inflated
  for (; c == 0 || chunkBegin(c) < capacity_; ++c) {
    // A chunk after the head takes the slot of the one `slots_` before it, once the reader is done with it.
    for (uint64_t taken = taken_.load(std::memory_order_acquire); taken != kStop && c > slots_ + taken;
         taken = taken_.load(std::memory_order_acquire))
      taken_.wait(taken, std::memory_order_acquire);
    if (taken_.load(std::memory_order_acquire) == kStop) break;
    const std::span<const std::byte> target = chunk(c);
    auto* const out = const_cast<uint8_t*>(reinterpret_cast<const uint8_t*>(target.data()));
    std::size_t filled = 0;
    while (filled < target.size()) {
      s.next_out = out + filled;
      s.avail_out = static_cast<uint32_t>(target.size() - filled);
      const uint32_t room = s.avail_out, input = s.avail_in;
      const int rc = isal_inflate(&s);
      filled += room - s.avail_out;
      // Damage, an end before the trailer's size, or no progress (input cut short): not handled.
      if (rc != ISAL_DECOMP_OK || (filled < target.size() && s.block_state == ISAL_BLOCK_FINISH) ||
          (s.avail_out == room && s.avail_in == input)) {
        publish(c | kEnded);
        return;
      }
    }
    publish(c + 1);
  }
  if (taken_.load(std::memory_order_acquire) == kStop) {
    publish(c | kEnded);
    return;
  }
  // Every byte the trailer promises is out: the stream must end here, with nothing after it.
  uint8_t beyond = 0;
  s.next_out = &beyond;
  s.avail_out = 1;
  const int rc = isal_inflate(&s);
  const bool handled =
      rc == ISAL_DECOMP_OK && s.avail_out == 1 && s.block_state == ISAL_BLOCK_FINISH && s.avail_in == 0;
  publish(c | kEnded | (handled ? kHandled : 0));
}

uint64_t GzipChunks::waitForChunks(uint64_t chunks) {
  uint64_t state = state_.load(std::memory_order_acquire);
  while ((state & ~(kEnded | kHandled)) < chunks && (state & kEnded) == 0) {
    state_.wait(state, std::memory_order_acquire);
    state = state_.load(std::memory_order_acquire);
  }
  return state & ~(kEnded | kHandled);
}

std::span<const std::byte> GzipChunks::head() {
  return waitForChunks(1) >= 1 ? chunk(0) : std::span<const std::byte>{};
}

std::span<const std::byte> GzipChunks::next() {
  if (exhausted_) return {};
  if (current_ > 0) {  // done with the chunk held: its slot may be refilled
    taken_.store(current_, std::memory_order_release);
    taken_.notify_all();
  }
  if (waitForChunks(current_ + 2) < current_ + 2) {
    exhausted_ = true;
    return {};
  }
  return chunk(++current_);
}

bool GzipChunks::finish() {
  if (thread_.joinable()) {
    if (!exhausted_) {  // abandoned: stop the inflater, wherever it waits
      taken_.store(kStop, std::memory_order_release);
      taken_.notify_all();
    }
    thread_.join();
  }
  const uint64_t state = state_.load(std::memory_order_acquire);
  return exhausted_ && (state & kHandled) != 0;
}

ByteBuffer gunzip(std::span<const std::byte> in, const std::string& name) {
  ByteBuffer whole;
  if (inflateWhole(in, gzipSizeHint(in), whole)) return whole;
  return GzipReader(in, name).readAll();
}

}  // namespace toposlice
