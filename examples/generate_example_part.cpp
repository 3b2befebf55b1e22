// Writes the bundled example part (examples/example_part.stl): a square frame with a through hole, a
// torus resting on it and a sphere standing beside it, generated from the analytic test shapes
// (tests/fixtures/shapes.h, examplePart). Built as a test helper; regenerate the committed file with
// `build/tests/generate_example_part examples/example_part.stl`. A test checks it equals a fresh one.
#include <cstdio>
#include <exception>

#include "io/readers/stl_writer.h"
#include "tests/fixtures/shapes.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: generate_example_part OUT.stl\n");
    return 2;
  }
  try {
    toposlice::writeBinaryStl(argv[1], toposlice::fixtures::examplePart(), "toposlice example part", true);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "generate_example_part: %s\n", e.what());
    return 1;
  }
  return 0;
}
