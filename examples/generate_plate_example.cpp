// Writes the bundled plate example (examples/plate/): an arch-shaped shell template, three customized
// variants of it (same connectivity, moved vertices), a label add-on for one of them, and the
// template's adjacency table. Run as `generate_plate_example OUT_DIR`; a test checks the committed files
// equal fresh ones.
#include <cstdio>
#include <exception>
#include <filesystem>

#include "core/mesh/weld.h"
#include "io/jobs/template_file.h"
#include "io/readers/stl_writer.h"
#include "tests/fixtures/shapes.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: generate_plate_example OUT_DIR\n");
    return 2;
  }
  using toposlice::fixtures::ArchShape;
  namespace fx = toposlice::fixtures;
  try {
    const std::filesystem::path dir = argv[1];
    const ArchShape base;
    ArchShape wide = base, wavy = base, named = base;
    wide.rx = 25.5, wide.ry = 21, wide.flare = 0.6;
    wavy.height = 9, wavy.wave = 0.4;
    named.rx = 23, named.ry = 19.5;
    const toposlice::FacetSoup templ = fx::archShell(base);
    toposlice::writeBinaryStl(dir / "arch_template.stl", templ, "toposlice plate example: template", true);
    toposlice::writeBinaryStl(dir / "arch_wide.stl", fx::archShell(wide), "variant: wider, flared", true);
    toposlice::writeBinaryStl(dir / "arch_wavy.stl", fx::archShell(wavy), "variant: taller, wavy", true);
    toposlice::writeBinaryStl(dir / "arch_named.stl", fx::archShell(named), "variant: narrower, labelled",
                              true);
    toposlice::writeBinaryStl(dir / "arch_named_label.stl", fx::archLabel(named), "label add-on", true);
    toposlice::writeTemplateFile(dir / "arch_template.topo",
                                 toposlice::buildTemplateTable(toposlice::weldCorners(templ.corners)), true);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "generate_plate_example: %s\n", e.what());
    return 1;
  }
  return 0;
}
