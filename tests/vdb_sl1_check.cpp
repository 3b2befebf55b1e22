// Checks a mask VDB against the SL1 archive of the same job (tests/vdb_blender_check.sh):
//   vdb_sl1_check FILE.vdb FILE.sl1
// Passes when the VDB holds exactly one grid, covering as many layers as the archive has PNG layers,
// and every layer k read back from the grid (readVdbLayer: 255 where a mask grid is active, round(255 v)
// for a float grid) equals the archive's layer k pixel for pixel. Prints one PASS or FAIL line; exit
// status 0 on PASS, 1 on FAIL or any error.
#include <zip.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <stdexcept>
#include <string>
#include <vector>

#include "io/coders/mask_png.h"
#include "io/masks/vdb_writer.h"

namespace {

std::vector<uint8_t> readEntry(zip_t* zip, const std::string& name) {
  zip_stat_t st;
  if (zip_stat(zip, name.c_str(), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE))
    throw std::runtime_error(name + ": " + zip_strerror(zip));
  std::vector<uint8_t> bytes(static_cast<size_t>(st.size));
  zip_file_t* f = zip_fopen(zip, name.c_str(), 0);
  if (!f) throw std::runtime_error(name + ": " + zip_strerror(zip));
  const zip_int64_t got = zip_fread(f, bytes.data(), st.size);
  zip_fclose(f);
  if (got < 0 || static_cast<zip_uint64_t>(got) != st.size) throw std::runtime_error(name + ": short read");
  return bytes;
}

int check(const std::string& vdb, const std::string& sl1) {
  int error = 0;
  zip_t* zip = zip_open(sl1.c_str(), ZIP_RDONLY, &error);
  if (!zip) throw std::runtime_error(sl1 + ": not a readable zip archive");
  std::vector<std::string> layers;  // top-level PNGs; thumbnails sit in a folder
  for (zip_int64_t i = 0; i < zip_get_num_entries(zip, 0); ++i) {
    const std::string name = zip_get_name(zip, static_cast<zip_uint64_t>(i), 0);
    if (name.size() > 4 && name.ends_with(".png") && name.find('/') == std::string::npos)
      layers.push_back(name);
  }
  std::sort(layers.begin(), layers.end());

  const auto grids = toposlice::readVdbSlabs(vdb);
  std::string why;
  if (grids.size() != 1) {
    why = std::to_string(grids.size()) + " grids, expected 1";
  } else if (grids[0].firstLayer != 0 || grids[0].lastLayer + 1 != static_cast<int>(layers.size())) {
    why = "grid covers layers " + std::to_string(grids[0].firstLayer) + ".." +
          std::to_string(grids[0].lastLayer) + ", the archive has " + std::to_string(layers.size());
  }
  toposlice::MaskImage expected;
  uint64_t lit = 0;
  for (size_t k = 0; k < layers.size() && why.empty(); ++k) {
    if (!toposlice::decodeMaskPng(readEntry(zip, layers[k]), expected))
      throw std::runtime_error(sl1 + ": " + layers[k] + ": not a grayscale PNG");
    const toposlice::MaskImage got =
        toposlice::readVdbLayer(vdb, static_cast<uint32_t>(k), expected.width, expected.height);
    for (size_t p = 0; p < expected.pixels.size() && why.empty(); ++p) {
      lit += expected.pixels[p] != 0;
      if (got.pixels[p] != expected.pixels[p])
        why = "layer " + std::to_string(k) + " pixel (" + std::to_string(p % expected.width) + ", " +
              std::to_string(p / expected.width) + "): VDB " + std::to_string(got.pixels[p]) + ", SL1 " +
              std::to_string(expected.pixels[p]);
    }
  }
  zip_discard(zip);
  if (!why.empty()) {
    std::printf("FAIL: %s vs %s: %s\n", vdb.c_str(), sl1.c_str(), why.c_str());
    return 1;
  }
  std::printf("PASS: %s: grid '%s' (%s), %zu layers equal to %s pixel for pixel (%llu lit pixels)\n",
              vdb.c_str(), grids[0].name.c_str(), grids[0].valueType.c_str(), layers.size(), sl1.c_str(),
              static_cast<unsigned long long>(lit));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: vdb_sl1_check FILE.vdb FILE.sl1\n");
    return 1;
  }
  try {
    return check(argv[1], argv[2]);
  } catch (const std::exception& e) {
    std::printf("FAIL: %s\n", e.what());
    return 1;
  }
}
