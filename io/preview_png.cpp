// RGB PNG encoding of previews with libspng (preview_png.h).
#include "io/preview_png.h"

#include <spng.h>

#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>

#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {

void encodeRgbPng(const RgbImage& image, std::vector<uint8_t>& out) {
  std::unique_ptr<spng_ctx, decltype(&spng_ctx_free)> ctx(spng_ctx_new(SPNG_CTX_ENCODER), &spng_ctx_free);
  if (!ctx) throw OutputError("preview: cannot start the PNG encoder");
  spng_ihdr ihdr{};
  ihdr.width = image.width;
  ihdr.height = image.height;
  ihdr.bit_depth = 8;
  ihdr.color_type = SPNG_COLOR_TYPE_TRUECOLOR;
  int rc = spng_set_option(ctx.get(), SPNG_ENCODE_TO_BUFFER, 1);
  // The sub filter alone at zlib level 1: the SL1 thumbnails of the aligner in 7 ms instead of 31 ms
  // (every filter tried at level 6, libspng's default), for 10 % more bytes (124 kB against 113 kB).
  if (rc == 0) rc = spng_set_option(ctx.get(), SPNG_FILTER_CHOICE, SPNG_FILTER_CHOICE_SUB);
  if (rc == 0) rc = spng_set_option(ctx.get(), SPNG_IMG_COMPRESSION_LEVEL, 1);
  if (rc == 0) rc = spng_set_ihdr(ctx.get(), &ihdr);
  spng_text software{};  // how --force knows the file (checkReplaceable)
  std::memcpy(software.keyword, "Software", 9);
  software.type = SPNG_TEXT;
  software.length = kSoftwareName.size();
  software.text = const_cast<char*>(kSoftwareName.data());
  if (rc == 0) rc = spng_set_text(ctx.get(), &software, 1);
  if (rc == 0)
    rc = spng_encode_image(ctx.get(), image.rgb.data(), image.rgb.size(), SPNG_FMT_PNG, SPNG_ENCODE_FINALIZE);
  std::size_t size = 0;
  void* png = rc == 0 ? spng_get_png_buffer(ctx.get(), &size, &rc) : nullptr;
  if (png == nullptr) throw OutputError(std::string("preview: PNG encoding failed: ") + spng_strerror(rc));
  const auto* bytes = static_cast<const uint8_t*>(png);
  out.assign(bytes, bytes + size);
  std::free(png);
}

std::vector<uint8_t> previewPng(std::span<const Point3f> corners, uint32_t width, uint32_t height,
                                const ChunkRunner& runner) {
  RgbImage image;
  renderPreview(corners, width, height, image, runner);
  std::vector<uint8_t> png;
  encodeRgbPng(image, png);
  return png;
}

}  // namespace toposlice
