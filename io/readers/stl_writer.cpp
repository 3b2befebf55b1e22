#include "io/readers/stl_writer.h"

#include <cmath>
#include <cstring>
#include <vector>

#include "io/output_file.h"

namespace toposlice {

void writeBinaryStl(const std::filesystem::path& path, const FacetSoup& soup, const std::string& header,
                    bool overwrite) {
  OutputFile file(path, overwrite);
  char head[80] = {};
  std::memcpy(head, header.data(), std::min<std::size_t>(header.size(), sizeof head));
  file.write(head, sizeof head);
  const auto count = static_cast<uint32_t>(soup.facetCount());
  file.write(&count, 4);  // little-endian hosts only (x86-64, aarch64)
  std::vector<char> record(50, 0);
  for (std::size_t f = 0; f < soup.facetCount(); ++f) {
    const Point3f* c = &soup.corners[3 * f];
    const double ux = double{c[1].x} - c[0].x, uy = double{c[1].y} - c[0].y, uz = double{c[1].z} - c[0].z;
    const double vx = double{c[2].x} - c[0].x, vy = double{c[2].y} - c[0].y, vz = double{c[2].z} - c[0].z;
    double n[3] = {uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx};
    const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    float normal[3] = {0, 0, 0};
    if (len > 0)
      for (int i = 0; i < 3; ++i) normal[i] = static_cast<float>(n[i] / len);
    std::memcpy(record.data(), normal, 12);
    std::memcpy(record.data() + 12, c, 36);
    file.write(record.data(), record.size());
  }
  file.commit();
}

}  // namespace toposlice
