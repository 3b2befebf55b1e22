// XML text for the SVG and 3MF writers: the four characters with a meaning in element text and attribute
// values escaped, and every byte the caller does not keep replaced by `replacement`.
#pragma once

#include <string>
#include <string_view>

namespace toposlice {

template <class Keep>
void appendXmlEscaped(std::string& out, std::string_view text, Keep keep, char replacement) {
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += keep(static_cast<unsigned char>(c)) ? c : replacement;
    }
  }
}

}  // namespace toposlice
