#include "io/jobs/json_reader.h"

#include <cerrno>
#include <fstream>
#include <iterator>
#include <system_error>

#include "core/number_text.h"
#include "io/jobs/profile.h"

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

std::vector<std::pair<std::string, std::string>> JsonReader::printSettings(const Json& v,
                                                                           const std::string& at) {
  object(v, at);
  std::vector<std::pair<std::string, std::string>> settings;
  PrintSettings check;
  for (const auto& [k, value] : v.items()) {
    const std::string where = childPath(at, k);
    std::string text;
    if (value.is_string())
      text = value.get<std::string>();
    else if (value.is_boolean())
      text = value.get<bool>() ? "true" : "false";  // flags only: a number refuses it
    else if (value.is_number_float())
      text = formatNumber(value.get<double>());
    else if (value.is_number())
      text = value.dump();
    else
      wrongType(value, where, "a number, a string or true/false");
    if (k == "light_map" && !text.empty()) text = input(value, where).string();
    try {
      assignSetting(check, k, text, "print_settings");
    } catch (const InputError& e) {
      std::string what = e.what();
      if (what.starts_with("print_settings: ")) what = what.substr(16);
      fail(where, what);
    }
    settings.emplace_back(k, text);
  }
  return settings;
}

}  // namespace toposlice::jobjson
