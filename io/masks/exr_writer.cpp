// OpenEXR mask stack writer: ZIP chunks coded from the mask's runs (OpenEXR file layout, "ZIP_COMPRESSION":
// byte split, delta predictor, zlib), files assembled in memory by openexr_core; read back with the
// OpenEXR 3.1 C++ API (Imf::InputFile) for checks.
#include "io/masks/exr_writer.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cstddef>
#include <cstring>
#include <exception>

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompressionAttribute.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/openexr.h>

#include "core/prefetch.h"
#include "io/coders/deflate_runs.h"
#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

constexpr const char* kChannel = "Y";

// Low and high byte of the HALF that stores pixel value v (v / 255, as Imath::half rounds it).
struct HalfBytes {
  std::array<uint8_t, 256> low{}, high{};
  HalfBytes() {
    for (int v = 0; v < 256; ++v) {
      const uint16_t bits = Imath::half(static_cast<float>(v) / 255.0f).bits();
      low[v] = static_cast<uint8_t>(bits & 0xFF);
      high[v] = static_cast<uint8_t>(bits >> 8);
    }
  }
};

const HalfBytes& halfBytes() {
  static const HalfBytes table;
  return table;
}

// Pixel runs of stored row `stored`, left to right, as value << 24 | length (length < 2^24), appended
// to `runs`. With extents, dark pixels are not read; with fills, the insides of lit regions are not.
// Each stretch read is prefetched in the row read a few rows later (rowAhead).
void appendRowRuns(const MaskImage& mask, size_t stored, std::vector<uint32_t>& runs) {
  const size_t width = mask.width;
  const uint8_t* row = mask.pixels.data() + stored * width;
  const uint8_t* aheadRow = rowAhead(mask, stored);
  size_t begin = 0, end = width;
  if (mask.hasExtents()) {
    begin = mask.litBegin[stored];
    end = mask.litEnd[stored];
    if (begin >= end) begin = end = width;
  }
  if (begin > 0) runs.push_back(static_cast<uint32_t>(begin));
  // Runs stay maximal: one that continues the row's last run (a fill after pixels of its value, or the
  // other way round) joins it.
  const size_t first = runs.size();
  const auto put = [&](size_t a, size_t b, uint8_t value) {
    if (runs.size() > first && runs.back() >> 24 == value) {
      runs.back() += static_cast<uint32_t>(b - a);
    } else {
      runs.push_back(uint32_t{value} << 24 | static_cast<uint32_t>(b - a));
    }
  };
  // The fills of an anti-aliased layer are not read.
  forEachRowStretch(mask, stored, begin, end, put, [&](size_t a, size_t b) {
    prefetch(aheadRow + a);
    while (a < b) {
      const uint8_t v = row[a];
      const size_t e = runEnd(row, a + 1, b, v);
      put(a, e, v);
      a = e;
    }
  });
  if (end < width) runs.push_back(static_cast<uint32_t>(width - end));
}

// OpenEXR's ZIP chunk of file rows [y0, y0 + lines) (file row y is stored row height-1-y): the raw
// block is the rows' halves, little-endian; its bytes are split (even bytes, the low bytes of all
// pixels, first; then the odd, high bytes), each byte but the first replaced by (byte - previous byte
// + 128) mod 256, and the result zlib-compressed. This appends that stream to `deflater` (ending it)
// and returns its Adler-32. `runs` is scratch.
uint32_t tokenizeZipChunk(const MaskImage& mask, uint32_t y0, uint32_t lines, bool copies,
                          std::vector<uint32_t>& runs, RunDeflater& deflater) {
  const HalfBytes& half = halfBytes();
  const uint32_t width = mask.width, height = mask.height;
  // Pixel runs of every line, and where each line's runs start.
  runs.clear();
  std::array<size_t, kExrLinesPerChunk + 1> lineStart{};
  std::array<bool, kExrLinesPerChunk> sameAsAbove{};
  for (uint32_t i = 0; i < lines; ++i) {
    const size_t stored = height - 1 - (y0 + i);
    lineStart[i] = runs.size();
    appendRowRuns(mask, stored, runs);
    // Runs are maximal, so two lines are equal exactly when their run lists are.
    sameAsAbove[i] =
        i > 0 && std::equal(runs.begin() + static_cast<std::ptrdiff_t>(lineStart[i - 1]),
                            runs.begin() + static_cast<std::ptrdiff_t>(lineStart[i]),
                            runs.begin() + static_cast<std::ptrdiff_t>(lineStart[i]), runs.end());
  }
  lineStart[lines] = runs.size();

  RunAdler32 adler;
  int previous = -1;  // the raw byte before, -1 at the start of the chunk
  for (const std::array<uint8_t, 256>* bytes : {&half.low, &half.high}) {
    // A plane of one byte value (the low bytes of a binary mask: 0 and 1.0 are 0x0000 and 0x3C00) is
    // its first delta and then 128s: the same bytes and tokens as line by line, without the lines.
    const uint8_t planeRaw = (*bytes)[runs.front() >> 24];
    if (std::all_of(runs.begin(), runs.end(), [&](uint32_t r) { return (*bytes)[r >> 24] == planeRaw; })) {
      const uint64_t size = uint64_t{width} * lines;
      const auto delta = static_cast<uint8_t>(previous < 0 ? planeRaw : (planeRaw - previous + 128) & 0xFF);
      previous = planeRaw;
      adler.addRun(delta, 128, size);
      deflater.putBytes(delta, 1);
      if (size > 1) deflater.putBytes(128, size - 1);
      continue;
    }
    for (uint32_t i = 0; i < lines; ++i) {
      const std::span<const uint32_t> line(runs.data() + lineStart[i], lineStart[i + 1] - lineStart[i]);
      // A line equal to the one above has the same deltas after its first byte: that byte, then a copy.
      // Lines of one byte value stay runs (as many tokens, without the copy distance's extra bits).
      const uint8_t firstRaw = (*bytes)[line.front() >> 24];
      const bool uniform =
          std::all_of(line.begin(), line.end(), [&](uint32_t r) { return (*bytes)[r >> 24] == firstRaw; });
      const bool copy = copies && sameAsAbove[i] && !uniform;
      uint8_t lastDelta = 0;
      for (size_t k = 0; k < line.size(); ++k) {
        const uint8_t raw = (*bytes)[line[k] >> 24];
        const uint32_t length = line[k] & 0xFFFFFF;
        const auto delta = static_cast<uint8_t>(previous < 0 ? raw : (raw - previous + 128) & 0xFF);
        previous = raw;
        adler.addRun(delta, 128, length);
        lastDelta = length > 1 ? 128 : delta;
        if (!copy) {
          deflater.putBytes(delta, 1);
          if (length > 1) deflater.putBytes(128, length - 1);
        } else if (k == 0) {
          deflater.putBytes(delta, 1);
        }
      }
      if (copy) deflater.putCopy(width - 1, lastDelta);
    }
  }
  deflater.endStream();
  return adler.value();
}

// Chunk `stream` of the deflater as zlib stream into `chunk` (replaced), or, when that is not smaller
// than the raw block, the raw block, as the format requires.
void writeZipChunk(const MaskImage& mask, uint32_t y0, uint32_t lines, RunDeflater& deflater, size_t stream,
                   uint32_t check, std::vector<uint8_t>& chunk) {
  const HalfBytes& half = halfBytes();
  const uint32_t width = mask.width, height = mask.height;
  const uint64_t rawSize = uint64_t{2} * width * lines;
  chunk.resize(2);
  chunk[0] = 0x78;  // CMF: deflate, 32 KiB window
  chunk[1] = 0x01;  // FLG: no dictionary, check bits ((0x78 << 8) | 0x01) % 31 == 0
  const size_t blockBytes = deflater.writeStream(stream, chunk, 2, DeflateCode::smallest);
  chunk.resize(2 + blockBytes + 4);
  for (int b = 0; b < 4; ++b) chunk[2 + blockBytes + b] = static_cast<uint8_t>(check >> (24 - 8 * b));
  if (chunk.size() < rawSize) return;
  chunk.resize(rawSize);
  for (uint32_t i = 0; i < lines; ++i) {
    const uint8_t* row = mask.pixels.data() + size_t{height - 1 - (y0 + i)} * width;
    uint8_t* out = chunk.data() + size_t{2} * width * i;
    for (uint32_t x = 0; x < width; ++x) {
      out[2 * x] = half.low[row[x]];
      out[2 * x + 1] = half.high[row[x]];
    }
  }
}

// openexr_core writes through these into a byte vector.
struct MemoryStream {
  std::vector<uint8_t>* out;
  std::string error;
};

int64_t writeToMemory(exr_const_context_t, void* userdata, const void* buffer, uint64_t size, uint64_t offset,
                      exr_stream_error_func_ptr_t) {
  std::vector<uint8_t>& out = *static_cast<MemoryStream*>(userdata)->out;
  if (out.size() < offset + size) out.resize(offset + size);
  std::memcpy(out.data() + offset, buffer, size);
  return static_cast<int64_t>(size);
}

// The stream of the layer being encoded on this thread. OpenEXR calls the error handler while it holds
// the context's lock, so the handler must not call back into the context (exr_get_user_data would wait
// for that lock forever): it finds the stream here instead.
thread_local MemoryStream* tEncodingStream = nullptr;

void keepError(exr_const_context_t, exr_result_t, const char* message) {
  if (tEncodingStream != nullptr && tEncodingStream->error.empty()) tEncodingStream->error = message;
}

class ExrSink final : public LayerFolderSink {
 public:
  ExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : LayerFolderSink(path, job, overwrite, ".exr") {}

 protected:
  void encodeLayerBytes(uint32_t index, double z, const MaskImage& mask, std::vector<uint8_t>& out,
                        MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job().grid, finalPath(), index);
    try {
      encodeExrMaskLayer(mask, job(), index, z, out, scratch);
    } catch (const OutputError& e) {
      throw OutputError(finalPath().string() + ": " + e.what());
    }
  }

  std::string layerFileName(uint32_t index) const override {
    return exrLayerFileName(job().name, index, job().layerCount);
  }
};

}  // namespace

std::string exrLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount) {
  return maskFilePrefix(name) + "." + maskLayerNumber(index, layerCount) + ".exr";
}

void encodeExrMaskLayer(const MaskImage& mask, const MaskJob& job, uint32_t index, double z,
                        std::vector<uint8_t>& out, MaskEncodeScratch& scratch) {
  const uint32_t width = mask.width, height = mask.height;
  assert(width >= 1 && height >= 1 && mask.pixels.size() == size_t{width} * height);
  out.clear();
  MemoryStream stream{&out, {}};
  tEncodingStream = &stream;
  struct Reset {
    ~Reset() { tEncodingStream = nullptr; }
  } reset;
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.user_data = &stream;
  init.write_fn = &writeToMemory;
  init.error_handler_fn = &keepError;
  const std::string name = exrLayerFileName(job.name, index, job.layerCount);
  exr_context_t ctxt = nullptr;
  exr_result_t rc = exr_start_write(&ctxt, name.c_str(), EXR_WRITE_FILE_DIRECTLY, &init);
  int part = 0;
  const exr_attr_v2f_t origin{{{static_cast<float>(job.grid.x0), static_cast<float>(job.grid.y0)}}};
  // Stops at the first failure (each step after it is skipped).
  auto step = [&rc](auto&& call) {
    if (rc == EXR_ERR_SUCCESS) rc = call();
  };
  step([&] { return exr_add_part(ctxt, nullptr, EXR_STORAGE_SCANLINE, &part); });
  step([&] {
    return exr_initialize_required_attr_simple(ctxt, part, static_cast<int32_t>(width),
                                               static_cast<int32_t>(height), EXR_COMPRESSION_ZIP);
  });
  step([&] {
    return exr_add_channel(ctxt, part, kChannel, EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
  });
  // How --force knows the file (checkReplaceable).
  step([&] { return exr_attr_set_string(ctxt, part, "software", kSoftwareName.data()); });
  step([&] { return exr_attr_set_float(ctxt, part, "z", static_cast<float>(z)); });
  step([&] { return exr_attr_set_int(ctxt, part, "layer", static_cast<int32_t>(index)); });
  step([&] { return exr_attr_set_int(ctxt, part, "layerCount", static_cast<int32_t>(job.layerCount)); });
  step([&] { return exr_attr_set_float(ctxt, part, "layerHeight", static_cast<float>(job.layerHeight)); });
  step([&] { return exr_attr_set_float(ctxt, part, "pixelSize", static_cast<float>(job.grid.pixel)); });
  step([&] { return exr_attr_set_v2f(ctxt, part, "origin", &origin); });
  step([&] { return exr_attr_set_int(ctxt, part, "mirrorX", job.grid.mirrorX ? 1 : 0); });
  step([&] { return exr_attr_set_int(ctxt, part, "mirrorY", job.grid.mirrorY ? 1 : 0); });
  for (const auto& setting : job.settings) {              // the printer and material settings (mask_sink.h)
    const std::string attribute = "ts:" + setting.first;  // EXR attribute names have at most 31 bytes
    const char* text = setting.second.c_str();
    step([&] { return exr_attr_set_string(ctxt, part, attribute.c_str(), text); });
  }
  step([&] { return exr_write_header(ctxt); });
  // All chunks are tokenized first, so that they share one Huffman code, planned once per layer.
  const bool copies = width >= 4 && width <= kDeflateMaxDistance;
  RunDeflater deflater(scratch.deflate, copies ? width : 1);
  std::vector<uint32_t> checks;
  checks.reserve((height + kExrLinesPerChunk - 1) / kExrLinesPerChunk);
  for (uint32_t y = 0; y < height; y += kExrLinesPerChunk) {
    checks.push_back(
        tokenizeZipChunk(mask, y, std::min(kExrLinesPerChunk, height - y), copies, scratch.runs, deflater));
  }
  std::vector<uint8_t>& chunk = scratch.bytes;
  for (uint32_t y = 0, i = 0; y < height && rc == EXR_ERR_SUCCESS; y += kExrLinesPerChunk, ++i) {
    writeZipChunk(mask, y, std::min(kExrLinesPerChunk, height - y), deflater, i, checks[i], chunk);
    rc = exr_write_scanline_chunk(ctxt, part, static_cast<int>(y), chunk.data(), chunk.size());
  }
  const exr_result_t finished = exr_finish(&ctxt);
  if (rc == EXR_ERR_SUCCESS) rc = finished;
  if (rc != EXR_ERR_SUCCESS) {
    throw OutputError("cannot encode " + name + ": " +
                      (stream.error.empty() ? exr_get_default_error_message(rc) : stream.error));
  }
}

std::unique_ptr<MaskSink> makeExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return std::make_unique<ExrSink>(path, job, overwrite);
}

ExrMaskLayer readExrMaskLayer(const std::filesystem::path& file) {
  ExrMaskLayer layer;
  try {
    Imf::InputFile in(file.c_str());
    const Imf::Header& header = in.header();
    const Imath::Box2i window = header.dataWindow();
    const Imf::ChannelList& channels = header.channels();
    if (channels.begin() == channels.end()) throw InputError(file.string() + ": no channel");
    layer.channel = channels.begin().name();
    switch (header.compression()) {
      case Imf::NO_COMPRESSION:
        layer.compression = "none";
        break;
      case Imf::RLE_COMPRESSION:
        layer.compression = "rle";
        break;
      case Imf::ZIPS_COMPRESSION:
        layer.compression = "zips";
        break;
      case Imf::ZIP_COMPRESSION:
        layer.compression = "zip";
        break;
      case Imf::PIZ_COMPRESSION:
        layer.compression = "piz";
        break;
      default:
        layer.compression = "other";
        break;
    }
    const auto* z = header.findTypedAttribute<Imf::FloatAttribute>("z");
    const auto* index = header.findTypedAttribute<Imf::IntAttribute>("layer");
    if (z == nullptr || index == nullptr) throw InputError(file.string() + ": no z or layer attribute");
    layer.z = z->value();
    layer.layer = index->value();
    if (const auto* p = header.findTypedAttribute<Imf::FloatAttribute>("pixelSize"))
      layer.pixelSize = p->value();
    if (const auto* h = header.findTypedAttribute<Imf::FloatAttribute>("layerHeight")) {
      layer.layerHeight = h->value();
    }
    layer.width = static_cast<uint32_t>(window.max.x - window.min.x + 1);
    layer.height = static_cast<uint32_t>(window.max.y - window.min.y + 1);
    std::vector<float> topDown(size_t{layer.width} * layer.height);
    // Slice base addresses pixel (0, 0) of the file's coordinate system.
    char* base =
        reinterpret_cast<char*>(topDown.data()) - (static_cast<std::ptrdiff_t>(window.min.x) +
                                                   static_cast<std::ptrdiff_t>(window.min.y) * layer.width) *
                                                      static_cast<std::ptrdiff_t>(sizeof(float));
    Imf::FrameBuffer frame;
    frame.insert(layer.channel, Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * layer.width));
    in.setFrameBuffer(frame);
    in.readPixels(window.min.y, window.max.y);
    layer.values.resize(topDown.size());
    for (uint32_t r = 0; r < layer.height; ++r) {
      std::copy_n(topDown.data() + size_t{r} * layer.width, layer.width,
                  layer.values.data() + size_t{layer.height - 1 - r} * layer.width);
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(file.string() + ": " + e.what());
  }
  return layer;
}

}  // namespace toposlice
