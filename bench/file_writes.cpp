// file_writes: how fast one large output file (the binary CLI of the aligner at 1 um is 389 MB in layers
// of about 36 KB) reaches the page cache, by three strategies, at several thread counts:
//   write  one thread appends the pieces in order through a 1 MiB buffer (what OutputFile does today)
//   writev one thread hands the pieces themselves to the kernel, 16 at a time (no copy of its own)
//   pwrite N threads each write whole pieces at their known offsets
//   mmap   the file is sized and allocated first (ftruncate + fallocate), mapped shared, and N threads
//          copy the pieces into the mapping; then unmapped
// Each run writes a fresh file in DIR, timed from open to close (no fsync: toposlice does not sync), and
// removes it untimed. Prints one line per strategy and thread count: the median and the fastest of the
// repetitions.
//
//   build/bench/file_writes [--mb 389] [--piece-kb 36] [--threads 1,2,4,8,16] [--repeat 5] [--dir /tmp]

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/uio.h>
#include <unistd.h>

namespace {

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "file_writes: %s: %s\n", what.c_str(), std::strerror(errno));
  std::exit(1);
}

struct Setup {
  std::size_t bytes = std::size_t{389} << 20;
  std::size_t piece = 36 << 10;
  std::vector<int> threads{1, 2, 4, 8, 16};
  int repeat = 5;
  std::string dir = "/tmp";
};

std::vector<int> parseList(const char* text) {
  std::vector<int> out;
  for (const char* p = text; *p;) {
    char* end = nullptr;
    out.push_back(static_cast<int>(std::strtol(p, &end, 10)));
    p = *end == ',' ? end + 1 : end;
    if (end == p && *p) break;
  }
  return out;
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Runs body(t) on t = 0 .. n-1, each on its own thread (the caller's being one of them).
template <typename Body>
void onThreads(int n, Body body) {
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(body, t);
  body(0);
  for (std::thread& th : pool) th.join();
}

// A new file (never an existing one) opened with `access` (O_WRONLY or O_RDWR).
int createFile(const std::string& path, int access) {
  const int fd = ::open(path.c_str(), access | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) die("open " + path);
  return fd;
}

// Closes fd; the seconds from start, the close included.
double closedAfter(int fd, std::chrono::steady_clock::time_point start) {
  if (::close(fd) != 0) die("close");
  return secondsSince(start);
}

double writeSerial(const Setup& s, const std::string& path, const char* data) {
  const auto start = std::chrono::steady_clock::now();
  const int fd = createFile(path, O_WRONLY);
  std::vector<char> buffer(std::size_t{1} << 20);
  std::size_t used = 0;
  auto flush = [&] {
    for (std::size_t done = 0; done < used;) {
      const ssize_t n = ::write(fd, buffer.data() + done, used - done);
      if (n < 0) die("write");
      done += static_cast<std::size_t>(n);
    }
    used = 0;
  };
  for (std::size_t at = 0; at < s.bytes; at += s.piece) {
    const std::size_t n = std::min(s.piece, s.bytes - at);
    if (used + n > buffer.size()) flush();
    std::memcpy(buffer.data() + used, data + at, n);
    used += n;
  }
  flush();
  return closedAfter(fd, start);
}

// The pieces themselves, 16 at a time, with writev: no copy into a buffer of our own.
double writeGathered(const Setup& s, const std::string& path, const char* data) {
  const auto start = std::chrono::steady_clock::now();
  const int fd = createFile(path, O_WRONLY);
  constexpr int kGather = 16;
  iovec pieces[kGather];
  for (std::size_t at = 0; at < s.bytes;) {
    int n = 0;
    std::size_t total = 0;
    for (; n < kGather && at < s.bytes; ++n) {
      const std::size_t size = std::min(s.piece, s.bytes - at);
      pieces[n] = {const_cast<char*>(data + at), size};
      at += size;
      total += size;
    }
    const ssize_t w = ::writev(fd, pieces, n);
    if (w < 0 || static_cast<std::size_t>(w) != total) die("writev");
  }
  return closedAfter(fd, start);
}

double writeParallel(const Setup& s, const std::string& path, const char* data, int threads) {
  const auto start = std::chrono::steady_clock::now();
  const int fd = createFile(path, O_WRONLY);
  std::atomic<std::size_t> next{0};
  onThreads(threads, [&](int) {
    for (std::size_t at; (at = next.fetch_add(s.piece)) < s.bytes;) {
      const std::size_t n = std::min(s.piece, s.bytes - at);
      for (std::size_t done = 0; done < n;) {
        const ssize_t w = ::pwrite(fd, data + at + done, n - done, static_cast<off_t>(at + done));
        if (w < 0) die("pwrite");
        done += static_cast<std::size_t>(w);
      }
    }
  });
  return closedAfter(fd, start);
}

double writeMapped(const Setup& s, const std::string& path, const char* data, int threads) {
  const auto start = std::chrono::steady_clock::now();
  const int fd = createFile(path, O_RDWR);
  if (::fallocate(fd, 0, 0, static_cast<off_t>(s.bytes)) != 0) die("fallocate");
  void* map = ::mmap(nullptr, s.bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (map == MAP_FAILED) die("mmap");
  char* out = static_cast<char*>(map);
  std::atomic<std::size_t> next{0};
  onThreads(threads, [&](int) {
    for (std::size_t at; (at = next.fetch_add(s.piece)) < s.bytes;)
      std::memcpy(out + at, data + at, std::min(s.piece, s.bytes - at));
  });
  if (::munmap(map, s.bytes) != 0) die("munmap");
  return closedAfter(fd, start);
}

}  // namespace

int main(int argc, char** argv) {
  Setup s;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string opt = argv[i];
    if (opt == "--mb")
      s.bytes = std::strtoull(argv[i + 1], nullptr, 10) << 20;
    else if (opt == "--piece-kb")
      s.piece = std::strtoull(argv[i + 1], nullptr, 10) << 10;
    else if (opt == "--threads")
      s.threads = parseList(argv[i + 1]);
    else if (opt == "--repeat")
      s.repeat = std::atoi(argv[i + 1]);
    else if (opt == "--dir")
      s.dir = argv[i + 1];
    else {
      std::fprintf(stderr, "file_writes: unknown option %s\n", opt.c_str());
      return 2;
    }
  }
  if (s.bytes == 0 || s.piece == 0 || s.repeat < 1 || s.threads.empty()) {
    std::fprintf(stderr, "file_writes: bad options\n");
    return 2;
  }
  std::vector<char> data(s.bytes);
  std::uint64_t x = 0x9E3779B97F4A7C15ull;  // bytes that no layer of the page cache can share
  for (std::size_t i = 0; i < data.size(); i += 8) {
    x ^= x << 13, x ^= x >> 7, x ^= x << 17;
    std::memcpy(data.data() + i, &x, std::min<std::size_t>(8, data.size() - i));
  }
  const std::string path = s.dir + "/file_writes-" + std::to_string(::getpid()) + ".bin";
  std::printf("%zu MiB in pieces of %zu KiB, %d repetitions, into %s\n", s.bytes >> 20, s.piece >> 10,
              s.repeat, s.dir.c_str());
  std::printf("%-7s %7s %10s %10s %9s\n", "method", "threads", "median s", "best s", "GB/s");
  struct Config {
    const char* name;
    int threads;
  };
  std::vector<Config> configs{{"write", 1}, {"writev", 1}};
  for (const int t : s.threads) configs.push_back({"pwrite", t});
  for (const int t : s.threads) configs.push_back({"mmap", t});
  std::vector<std::vector<double>> times(configs.size());
  for (int r = 0; r < s.repeat; ++r) {  // repetitions outermost: a slow moment hits every method alike
    for (std::size_t c = 0; c < configs.size(); ++c) {
      const Config& config = configs[c];
      const std::string name = config.name;
      double t = 0;
      if (name == "write")
        t = writeSerial(s, path, data.data());
      else if (name == "writev")
        t = writeGathered(s, path, data.data());
      else if (name == "pwrite")
        t = writeParallel(s, path, data.data(), config.threads);
      else
        t = writeMapped(s, path, data.data(), config.threads);
      times[c].push_back(t);
      ::unlink(path.c_str());
    }
  }
  for (std::size_t c = 0; c < configs.size(); ++c) {
    std::vector<double>& v = times[c];
    std::sort(v.begin(), v.end());
    const double median = v[v.size() / 2];
    std::printf("%-7s %7d %10.4f %10.4f %9.2f\n", configs[c].name, configs[c].threads, median, v.front(),
                static_cast<double>(s.bytes) / median / 1e9);
  }
  return 0;
}
