// Numbers as text: the shortest decimal form that reads back to the same double (std::to_chars), so
// settings print as a user typed them ("0.01", not "0.009999999999999998") and round-trip exactly.
#pragma once

#include <charconv>
#include <string>

namespace toposlice {

inline std::string formatNumber(double value) {
  char text[32];
  const auto [end, ec] = std::to_chars(text, text + sizeof text, value);
  return ec == std::errc{} ? std::string(text, end) : std::string("?");
}

// A mesh coordinate (float) as the file holds it: "6.2", not the double of that float, 6.199999809265137.
inline std::string formatNumber(float value) {
  char text[32];
  const auto [end, ec] = std::to_chars(text, text + sizeof text, value);
  return ec == std::errc{} ? std::string(text, end) : std::string("?");
}

}  // namespace toposlice
