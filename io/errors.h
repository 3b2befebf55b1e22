// Errors at the io/ boundary. Bad input (a malformed or unreadable file) becomes an InputError whose
// message names the file and what is wrong, ready to print as the one-line reason of a failed command.
#pragma once

#include <stdexcept>
#include <string>

namespace toposlice {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace toposlice
