// EXR layers read back with tinyexr (Debian libtinyexr-dev), a decoder independent of the OpenEXR
// library that writes them: the tests' second opinion on the EXR stacks.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include "core/raster/mask_image.h"

namespace toposlice {

struct TinyExrLayer {
  MaskImage mask;           // display window size, rows bottom-up; pixel = round(value * 255)
  bool exact = true;        // every value was exactly the HALF of pixel / 255
  std::string compression;  // "zip", "zips", "rle", "none", "piz", "other"
  float z = 0;
  int layer = -1;
  std::map<std::string, std::string> strings;  // the header's string attributes, by name
  std::string error;                           // empty when read
};

TinyExrLayer readExrWithTinyExr(const std::filesystem::path& file);

}  // namespace toposlice
