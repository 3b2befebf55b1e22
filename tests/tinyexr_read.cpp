#include "tests/tinyexr_read.h"

#include <tinyexr.h>

#include <Imath/half.h>
#include <cmath>
#include <cstring>

namespace toposlice {

TinyExrLayer readExrWithTinyExr(const std::filesystem::path& file) {
  TinyExrLayer out;
  const char* error = nullptr;
  EXRVersion version;
  EXRHeader header;
  InitEXRHeader(&header);
  if (ParseEXRVersionFromFile(&version, file.c_str()) != TINYEXR_SUCCESS) {
    out.error = "not an EXR file";
    return out;
  }
  if (ParseEXRHeaderFromFile(&header, &version, file.c_str(), &error) != TINYEXR_SUCCESS) {
    out.error = error != nullptr ? error : "bad header";
    FreeEXRErrorMessage(error);
    return out;
  }
  switch (header.compression_type) {
    case TINYEXR_COMPRESSIONTYPE_NONE:
      out.compression = "none";
      break;
    case TINYEXR_COMPRESSIONTYPE_RLE:
      out.compression = "rle";
      break;
    case TINYEXR_COMPRESSIONTYPE_ZIPS:
      out.compression = "zips";
      break;
    case TINYEXR_COMPRESSIONTYPE_ZIP:
      out.compression = "zip";
      break;
    case TINYEXR_COMPRESSIONTYPE_PIZ:
      out.compression = "piz";
      break;
    default:
      out.compression = "other";
      break;
  }
  for (int i = 0; i < header.num_custom_attributes; ++i) {
    const EXRAttribute& a = header.custom_attributes[i];
    if (std::strcmp(a.name, "z") == 0 && a.size == 4) std::memcpy(&out.z, a.value, 4);
    if (std::strcmp(a.name, "layer") == 0 && a.size == 4) std::memcpy(&out.layer, a.value, 4);
    if (std::strcmp(a.type, "string") == 0 && a.size >= 0)
      out.strings[a.name] = std::string(reinterpret_cast<const char*>(a.value), static_cast<size_t>(a.size));
  }
  for (int c = 0; c < header.num_channels; ++c) header.requested_pixel_types[c] = TINYEXR_PIXELTYPE_FLOAT;
  EXRImage image;
  InitEXRImage(&image);
  if (header.num_channels != 1 ||
      LoadEXRImageFromFile(&image, &header, file.c_str(), &error) != TINYEXR_SUCCESS) {
    out.error = error != nullptr ? error : "not one channel";
    FreeEXRErrorMessage(error);
    FreeEXRHeader(&header);
    return out;
  }
  const EXRBox2i display = header.display_window, data = header.data_window;
  const int width = display.max_x - display.min_x + 1, height = display.max_y - display.min_y + 1;
  out.mask.width = static_cast<uint32_t>(width);
  out.mask.height = static_cast<uint32_t>(height);
  out.mask.pixels.assign(static_cast<size_t>(width) * height, 0);
  const auto* values = reinterpret_cast<const float*>(image.images[0]);
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      const float f = values[static_cast<size_t>(y) * image.width + x];
      const long v = std::lround(f * 255.0f);
      const int fx = data.min_x + x - display.min_x,
                fy = data.min_y + y - display.min_y;  // file row, top-down
      if (v < 0 || v > 255 || fx < 0 || fx >= width || fy < 0 || fy >= height) {
        out.exact = false;
        continue;
      }
      out.exact = out.exact && f == static_cast<float>(Imath::half(static_cast<float>(v) / 255.0f));
      out.mask.pixels[static_cast<size_t>(height - 1 - fy) * width + fx] = static_cast<uint8_t>(v);
    }
  }
  FreeEXRImage(&image);
  FreeEXRHeader(&header);
  return out;
}

}  // namespace toposlice
