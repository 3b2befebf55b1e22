// Contours of chosen layers as one SVG, for looking at them (docs/FORMATS.md, "Contours: SVG").
//
// One panel per chosen layer, in layer order, in a grid of ceil(sqrt(count)) columns; every panel shows
// the model's xy bounding box (job.bounds) at 1 SVG unit = 1 mm, +y up, with the caption
// "layer k, z = <z>". Per panel:
//   - one <path class="solid"> holding every closed loop, filled light blue with fill-rule nonzero and a
//     dark outline: holes (clockwise) cancel the outer loops (counter-clockwise) and show the white
//     background;
//   - one <polygon class="hole"> per hole (signedArea <= 0) as a red dashed outline, unfilled;
//   - one <polyline class="open"> per open polyline, orange, unfilled.
// With features (job.features), the solid path holds every part's closed loops, a removal's reversed
// (p0, p(n-1), ..., p1); with a removal it is clipped (<clipPath id="clip-layer-k">, nonzero) to the
// model's and add-ons' loops, so that a removal reaching beyond them stays empty (positive rule). Then
// one <g id="layer-k-part-<id>" class="part <role>"><title><role> <name></title> per part (ids as in the
// CLI: 1 the model, then the features): the model's holes and open lines, an add-on's loops as green
// <polygon class="add"> outlines, a removal's as purple dashed <polygon class="remove">. Without
// features none of this is written.
// Same input, same bytes. Layers not chosen are ignored by writeLayer.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "io/contours/contour_sink.h"

namespace toposlice {

// `layers` may be in any order and hold duplicates; indices >= job.layerCount are dropped. Opens `path`
// through OutputFile (a temporary until finish()); throws OutputError when the file exists and
// !overwrite, or cannot be created.
std::unique_ptr<ContourSink> makeSvgWriter(const std::filesystem::path& path, const ContourJob& job,
                                           std::vector<uint32_t> layers, bool overwrite);

// Parses a layer list such as "0,10,20-30,last": comma-separated items, each a layer index, `last`
// (layerCount-1), `mid` (layerCount/2, the layer holding half the height) or a range "a-b" of those with
// a <= b (inclusive). Spaces around items are ignored. On success fills `out` sorted without duplicates
// and returns true; otherwise returns false, empties `out` and sets `error` to a one-line reason naming
// the bad item but not the whole list, for the caller to prefix ("item 2 is empty", "\"abc\" is not a
// layer number, ...", "layer 120 is out of range (layers 0-99)", "range \"8-3\" runs backwards").
bool parseLayerList(const std::string& text, uint32_t layerCount, std::vector<uint32_t>& out,
                    std::string& error);

}  // namespace toposlice
