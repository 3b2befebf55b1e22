// Numbers as text: the shortest decimal form that reads back to the same double (std::to_chars), so
// settings print as a user typed them ("0.01", not "0.009999999999999998") and round-trip exactly; in
// fixed notation where that takes at most 40 characters ("100000" and "0.00001", not "1e+05" and
// "1e-05"), the exponent form beyond.
#pragma once

#include <charconv>
#include <string>

namespace toposlice {

namespace number_text_detail {
template <class Number>
std::string shortestEitherNotation(Number value) {
  char text[32];
  const auto [end, ec] = std::to_chars(text, text + sizeof text, value);
  return ec == std::errc{} ? std::string(text, end) : std::string("?");
}
template <class Number>
std::string shortest(Number value) {
  char fixed[40];
  if (const auto [end, ec] = std::to_chars(fixed, fixed + sizeof fixed, value, std::chars_format::fixed);
      ec == std::errc{})
    return std::string(fixed, end);
  return shortestEitherNotation(value);
}
}  // namespace number_text_detail

inline std::string formatNumber(double value) {
  return number_text_detail::shortest(value);
}

// A mesh coordinate (float) as the file holds it: "6.2", not the double of that float, 6.199999809265137.
inline std::string formatNumber(float value) {
  return number_text_detail::shortest(value);
}

// For messages: the shortest text that reads back exactly, in fixed or exponent notation, whichever is
// shorter ("-5.077714e-17" where a mesh holds that, not 26 characters of zeros).
inline std::string readableNumber(double value) {
  return number_text_detail::shortestEitherNotation(value);
}
inline std::string readableNumber(float value) {
  return number_text_detail::shortestEitherNotation(value);
}

}  // namespace toposlice
