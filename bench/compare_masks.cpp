// Compares two mask stacks pixel by pixel (bench/prusa_compare.sh runs it on PrusaSlicer's and
// toposlice's SL1 archives):
//   compare_masks A B [CSV] [--transpose] [--first-b N] [--threads N]
// A and B are SL1 archives (any zip whose top-level .png entries are the layers) or directories of
// PNG layers; layers are taken in name order (both writers zero-pad the index), thumbnails and other
// folders are ignored. Pixels are compared as lit (value >= 128) or dark. The first min(layers of A,
// layers of B - first-b) layers are compared: A's layer k with B's layer k + first-b.
//   --transpose   B is A transposed (PrusaSlicer's portrait orientation): B's pixel (column c, row r
//                 from the bottom) is compared with A's pixel (column r, row c from the bottom).
// Prints a summary (layer counts, per-layer agreement min / median / mean, overall agreement, the
// worst layers, and the offset of the lit pixels' centroid of B from A's in pixels: a grid misplaced by
// d pixels shows about d there, while two rasterization rules on the same grid leave ~0.01) and, with
// CSV, one line per layer. Also the sums of pixel values of both (for anti-aliased stacks: the covered
// area in 1/255 pixels), overall and per layer. Exit status 0 when the comparison ran, 1 on any error.
#include <zip.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "core/raster/mask_image.h"
#include "io/coders/mask_png.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

bool isLayerName(const std::string& name) {
  return name.size() > 4 && name.compare(name.size() - 4, 4, ".png") == 0 &&
         name.find('/') == std::string::npos;
}

// One reader per thread: libzip handles must not be shared between threads.
class LayerSource {
 public:
  explicit LayerSource(const fs::path& path) : path_(path) {
    if (fs::is_directory(path_)) {
      for (const auto& entry : fs::directory_iterator(path_))
        if (entry.is_regular_file() && isLayerName(entry.path().filename().string()))
          names_.push_back(entry.path().filename().string());
    } else {
      int error = 0;
      zip_ = zip_open(path_.c_str(), ZIP_RDONLY, &error);
      if (!zip_)
        throw std::runtime_error(path_.string() + ": not a readable zip archive (libzip error " +
                                 std::to_string(error) + ")");
      const zip_int64_t n = zip_get_num_entries(zip_, 0);
      for (zip_int64_t i = 0; i < n; ++i) {
        const char* name = zip_get_name(zip_, static_cast<zip_uint64_t>(i), 0);
        if (name && isLayerName(name)) names_.emplace_back(name);
      }
    }
    std::sort(names_.begin(), names_.end());
  }
  ~LayerSource() {
    if (zip_) zip_discard(zip_);
  }
  LayerSource(const LayerSource&) = delete;
  LayerSource& operator=(const LayerSource&) = delete;

  size_t size() const { return names_.size(); }
  const std::string& name(size_t k) const { return names_[k]; }

  void read(size_t k, std::vector<uint8_t>& bytes) {
    bytes.clear();
    if (!zip_) {
      std::ifstream in(path_ / names_[k], std::ios::binary);
      bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
      if (!in.good() && !in.eof()) throw std::runtime_error((path_ / names_[k]).string() + ": read failed");
      return;
    }
    zip_stat_t st;
    if (zip_stat(zip_, names_[k].c_str(), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE))
      throw std::runtime_error(path_.string() + ": " + names_[k] + ": " + zip_strerror(zip_));
    bytes.resize(static_cast<size_t>(st.size));
    zip_file_t* f = zip_fopen(zip_, names_[k].c_str(), 0);
    if (!f) throw std::runtime_error(path_.string() + ": " + names_[k] + ": " + zip_strerror(zip_));
    const zip_int64_t got = zip_fread(f, bytes.data(), st.size);
    zip_fclose(f);
    if (got < 0 || static_cast<zip_uint64_t>(got) != st.size)
      throw std::runtime_error(path_.string() + ": " + names_[k] + ": short read");
  }

 private:
  fs::path path_;
  zip_t* zip_ = nullptr;
  std::vector<std::string> names_;
};

struct LayerResult {
  uint64_t pixels = 0, differ = 0, litA = 0, litB = 0, litEither = 0;
  uint64_t valueA = 0, valueB = 0;  // sums of pixel values (anti-aliased masks: covered area x 255)
  double sumAx = 0, sumAy = 0, sumBx = 0, sumBy = 0;  // lit pixel coordinates in A's frame
  double agreement() const { return pixels ? 1.0 - double(differ) / double(pixels) : 1.0; }
};

// B transposed into A's frame (bt[j * w + i] = B's pixel (column j, row i)), in cache-sized blocks.
void transposeInto(const MaskImage& b, std::vector<uint8_t>& bt) {
  const uint32_t w = b.height, h = b.width;  // A's size
  bt.resize(size_t{w} * h);
  constexpr uint32_t kBlock = 64;
  for (uint32_t i0 = 0; i0 < w; i0 += kBlock)
    for (uint32_t j0 = 0; j0 < h; j0 += kBlock)
      for (uint32_t i = i0; i < std::min(w, i0 + kBlock); ++i)
        for (uint32_t j = j0; j < std::min(h, j0 + kBlock); ++j)
          bt[size_t{j} * w + i] = b.pixels[size_t{i} * h + j];
}

// `b` holds B's pixels in A's frame (row j of A's width at b + j * width).
LayerResult compareLayer(const MaskImage& a, const uint8_t* b) {
  LayerResult r;
  const uint32_t w = a.width, h = a.height;
  if (w > 65536) throw std::runtime_error("images wider than 65,536 pixels are not supported");
  r.pixels = uint64_t{w} * h;
  for (uint32_t j = 0; j < h; ++j) {
    const uint8_t* rowA = a.pixels.data() + size_t{j} * w;
    const uint8_t* rowB = b + size_t{j} * w;
    // Branch-free 32-bit sums, so that the loop vectorizes (the sums of i fit: width <= 65,536).
    uint32_t rowLitA = 0, rowLitB = 0, rowDiffer = 0, rowEither = 0, rowSumA = 0, rowSumB = 0;
    uint32_t rowValueA = 0, rowValueB = 0;  // 255 * 65,536 fits
    for (uint32_t i = 0; i < w; ++i) {
      const uint32_t la = rowA[i] >> 7, lb = rowB[i] >> 7;  // value >= 128
      rowValueA += rowA[i];
      rowValueB += rowB[i];
      rowLitA += la;
      rowLitB += lb;
      rowSumA += la * i;
      rowSumB += lb * i;
      rowDiffer += la ^ lb;
      rowEither += la | lb;
    }
    r.differ += rowDiffer;
    r.valueA += rowValueA;
    r.valueB += rowValueB;
    r.litEither += rowEither;
    r.sumAx += double(rowSumA);
    r.sumBx += double(rowSumB);
    r.litA += rowLitA;
    r.litB += rowLitB;
    r.sumAy += double(rowLitA) * j;
    r.sumBy += double(rowLitB) * j;
  }
  return r;
}

struct Options {
  std::string a, b, csv;
  bool transpose = false;
  size_t firstB = 0;
  unsigned threads = 0;
};

[[noreturn]] void usage(const char* why, int status = 1) {
  std::fprintf(status ? stderr : stdout,
               "compare_masks: %s\nusage: compare_masks A B [CSV] [--transpose] [--first-b N] [--threads N]\n"
               "  A, B: SL1 archives or directories of PNG layers\n",
               why);
  std::exit(status);
}

Options parse(int argc, char** argv) {
  Options o;
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto number = [&](const char* what) {
      if (i + 1 >= argc) usage((std::string(what) + " needs a number").c_str());
      char* end = nullptr;
      errno = 0;
      const unsigned long long v = std::strtoull(argv[++i], &end, 10);
      if (errno || !end || *end) usage((std::string(what) + ": not a number").c_str());
      return v;
    };
    if (arg == "--transpose")
      o.transpose = true;
    else if (arg == "--first-b")
      o.firstB = static_cast<size_t>(number("--first-b"));
    else if (arg == "--threads")
      o.threads = static_cast<unsigned>(number("--threads"));
    else if (arg == "-h" || arg == "--help")
      usage("compares two mask stacks pixel by pixel", 0);
    else if (arg.size() > 1 && arg[0] == '-')
      usage(("unknown option " + arg).c_str());
    else
      positional.push_back(arg);
  }
  if (positional.size() < 2 || positional.size() > 3) usage("expected A B [CSV]");
  o.a = positional[0];
  o.b = positional[1];
  if (positional.size() == 3) o.csv = positional[2];
  return o;
}

int run(const Options& o) {
  LayerSource listA(o.a), listB(o.b);
  const size_t layersB = listB.size() > o.firstB ? listB.size() - o.firstB : 0;
  const size_t n = std::min(listA.size(), layersB);
  std::printf("A: %s: %zu layers\nB: %s: %zu layers%s\n", o.a.c_str(), listA.size(), o.b.c_str(),
              listB.size(), o.transpose ? " (compared transposed)" : "");
  if (o.firstB) std::printf("A's layer k is compared with B's layer k + %zu\n", o.firstB);
  if (n == 0) throw std::runtime_error("no layers to compare");

  std::vector<LayerResult> results(n);
  std::atomic<size_t> next{0};
  std::mutex errorMutex;
  std::string error;
  unsigned threads = o.threads ? o.threads : std::max(1u, std::thread::hardware_concurrency());
  threads = static_cast<unsigned>(std::min<size_t>(threads, n));
  auto worker = [&] {
    try {
      LayerSource a(o.a), b(o.b);
      std::vector<uint8_t> bytes;
      MaskImage ma, mb;
      std::vector<uint8_t> bt;
      for (size_t k; (k = next.fetch_add(1)) < n;) {
        a.read(k, bytes);
        if (!decodeMaskPng(bytes, ma))
          throw std::runtime_error(o.a + ": " + a.name(k) + ": not a grayscale PNG");
        b.read(k + o.firstB, bytes);
        if (!decodeMaskPng(bytes, mb))
          throw std::runtime_error(o.b + ": " + b.name(k + o.firstB) + ": not a grayscale PNG");
        const bool sizeOk = o.transpose ? (mb.width == ma.height && mb.height == ma.width)
                                        : (mb.width == ma.width && mb.height == ma.height);
        if (!sizeOk)
          throw std::runtime_error("layer " + std::to_string(k) + ": A is " + std::to_string(ma.width) + "x" +
                                   std::to_string(ma.height) + ", B is " + std::to_string(mb.width) + "x" +
                                   std::to_string(mb.height) + (o.transpose ? " (transposed expected)" : ""));
        if (o.transpose) transposeInto(mb, bt);
        results[k] = compareLayer(ma, o.transpose ? bt.data() : mb.pixels.data());
      }
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(errorMutex);
      if (error.empty()) error = e.what();
      next.store(n);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < threads; ++t) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  if (!error.empty()) throw std::runtime_error(error);

  if (!o.csv.empty()) {
    std::FILE* f = std::fopen(o.csv.c_str(), "w");
    if (!f) throw std::runtime_error(o.csv + ": cannot write");
    std::fprintf(f, "layer,name_a,name_b,pixels,differ,lit_a,lit_b,agreement,value_sum_a,value_sum_b\n");
    for (size_t k = 0; k < n; ++k) {
      const LayerResult& r = results[k];
      std::fprintf(f, "%zu,%s,%s,%llu,%llu,%llu,%llu,%.9f,%llu,%llu\n", k, listA.name(k).c_str(),
                   listB.name(k + o.firstB).c_str(), static_cast<unsigned long long>(r.pixels),
                   static_cast<unsigned long long>(r.differ), static_cast<unsigned long long>(r.litA),
                   static_cast<unsigned long long>(r.litB), r.agreement(),
                   static_cast<unsigned long long>(r.valueA), static_cast<unsigned long long>(r.valueB));
    }
    if (std::fclose(f) != 0) throw std::runtime_error(o.csv + ": write failed");
  }

  std::vector<double> agreement(n), valueRatio;
  uint64_t pixels = 0, differ = 0, litA = 0, litB = 0, litEither = 0, valueA = 0, valueB = 0;
  double sumAx = 0, sumAy = 0, sumBx = 0, sumBy = 0, mean = 0;
  for (size_t k = 0; k < n; ++k) {
    const LayerResult& r = results[k];
    agreement[k] = r.agreement();
    mean += agreement[k];
    pixels += r.pixels;
    differ += r.differ;
    litA += r.litA;
    litB += r.litB;
    litEither += r.litEither;
    valueA += r.valueA;
    valueB += r.valueB;
    if (r.valueA) valueRatio.push_back(std::abs(double(r.valueB) / double(r.valueA) - 1.0));
    sumAx += r.sumAx;
    sumAy += r.sumAy;
    sumBx += r.sumBx;
    sumBy += r.sumBy;
  }
  std::vector<double> sorted = agreement;
  std::sort(sorted.begin(), sorted.end());
  const double median = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
  std::printf("layers compared: %zu\n", n);
  std::printf("per-layer agreement: min %.6f %%  median %.6f %%  mean %.6f %%\n", 100 * sorted.front(),
              100 * median, 100 * mean / double(n));
  std::printf("overall agreement: %.6f %% (%llu of %llu pixels differ)\n",
              100 * (1.0 - double(differ) / double(pixels)), static_cast<unsigned long long>(differ),
              static_cast<unsigned long long>(pixels));
  std::printf("lit pixels: A %llu, B %llu; differing / lit in either: %.6f %%\n",
              static_cast<unsigned long long>(litA), static_cast<unsigned long long>(litB),
              litEither ? 100.0 * double(differ) / double(litEither) : 0.0);
  if (valueA) {
    std::sort(valueRatio.begin(), valueRatio.end());
    std::printf(
        "pixel value sums: A %llu, B %llu; B / A - 1: %+.4f %%; per layer |B / A - 1|: median %.4f %%  "
        "max %.4f %%\n",
        static_cast<unsigned long long>(valueA), static_cast<unsigned long long>(valueB),
        100.0 * (double(valueB) / double(valueA) - 1.0), 100.0 * valueRatio[valueRatio.size() / 2],
        100.0 * valueRatio.back());
  }
  if (litA && litB)
    std::printf("lit centroid of B - A (pixels, A's frame): dx %+.4f  dy %+.4f\n",
                sumBx / double(litB) - sumAx / double(litA), sumBy / double(litB) - sumAy / double(litA));
  std::vector<size_t> order(n);
  for (size_t k = 0; k < n; ++k) order[k] = k;
  std::sort(order.begin(), order.end(), [&](size_t x, size_t y) {
    return results[x].differ > results[y].differ || (results[x].differ == results[y].differ && x < y);
  });
  std::printf("worst layers (layer: differing pixels, lit A / B):");
  for (size_t m = 0; m < std::min<size_t>(5, n); ++m) {
    const LayerResult& r = results[order[m]];
    std::printf(" %zu: %llu (%llu / %llu)%s", order[m], static_cast<unsigned long long>(r.differ),
                static_cast<unsigned long long>(r.litA), static_cast<unsigned long long>(r.litB),
                m + 1 < std::min<size_t>(5, n) ? "," : "\n");
  }
  return 0;
}

}  // namespace
}  // namespace toposlice

int main(int argc, char** argv) {
  try {
    return toposlice::run(toposlice::parse(argc, argv));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "compare_masks: error: %s\n", e.what());
    return 1;
  }
}
