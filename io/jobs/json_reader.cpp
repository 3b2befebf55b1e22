#include "io/jobs/json_reader.h"

#include <cerrno>
#include <fstream>
#include <iterator>
#include <system_error>

namespace toposlice::jobjson {

std::string readJobText(const fs::path& path, const char* kind) {
  constexpr std::uintmax_t kMaxJobFileSize = std::uintmax_t{64} << 20;
  const std::string name = path.string();
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw InputError(name + ": is a directory, not a " + kind + " file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(name + ": cannot open: " + std::generic_category().message(errno));
  const std::uintmax_t size = fs::file_size(path, ec);
  if (!ec && size > kMaxJobFileSize)
    throw InputError(name + ": " + std::to_string(size) + " bytes is too large for a " + kind + " file");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw InputError(name + ": read error");
  return text;
}

}  // namespace toposlice::jobjson
