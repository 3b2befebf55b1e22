// Contours as a 3MF package with the Slice Extension (docs/FORMATS.md, "Contours: 3MF slice stack").
//
// Package (a zip, entries in this order, all deflated, every entry time 1980-01-01 00:00:00):
//   [Content_Types].xml, _rels/.rels, 3D/3dmodel.model.
// The model holds, in this order: one <s:slicestack id="1"> with one <s:slice> per layer, the object
// id="2" (type "model", s:slicestackid="1") with a mesh, and one build item for it (no transform).
// - Slice k: ztop = z_k + h/2 when a layer height h > 0 is given (planes z_k = z0 + (k + 1/2) h, so
//   ztop is the top of the layer's slab and zbottom = z_0 - h/2). Without h (explicit, possibly uneven
//   planes) slab boundaries lie halfway between neighbouring planes, the first and last slab reaching
//   half a neighbouring gap beyond their plane; a single plane without h reaches down to the model's
//   lowest z and as far above (or 0.5 um each way when the plane is not above the lowest z).
// - Each loop with at least 2 points is one <s:polygon>: its points are written once each into the
//   slice's <s:vertices> (no sharing between loops), startv is its first point and one <s:segment v2>
//   per following point; a closed loop ends with a segment back to startv, an open polyline (defective
//   meshes only) does not. The extension wants every polygon of a "model" object closed, so lib3mf 1.8
//   refuses a package holding an open polyline (NMR_ERROR_SLICEPOLYGONNOTCLOSED). Loops with fewer
//   than 2 points are dropped; a layer without loops is an empty <s:slice ztop=.../>. Numbers: fixed
//   notation, at most 6 decimals (1 nm), trailing zeros dropped.
// - Mesh: with `mesh` (the sliced model's facet soup), its corners welded (bit-identical coordinates),
//   each facet with three distinct vertices as one triangle, meshresolution "fullres" (the slices can
//   be regenerated from it). Without a mesh, or when no facet has three distinct corners, the 12
//   triangles of job.bounds, meshresolution "lowres" and requiredextensions="s", as the extension
//   demands for low-resolution meshes. Mesh coordinates: the float32 values, shortest exact form.
// - Features (job.features, part p = 1, 2, ...): after the model's stack, one <s:slicestack id="2p+1">
//   per feature with a slice at every ztop of the model's, then after the model's object one object
//   id="2p+2" per feature (name "add <feature>" / "remove <feature>") with its own mesh from
//   `featureMeshes` (lowres: its own bounding box). A removal's loops are written reversed (a closed
//   loop keeps its first point: p0, p(n-1), ..., p1) and its triangles reversed (v1 v3 v2): inside it
//   the winding is -1. The solid at a ztop is where the winding numbers of all objects' polygons at that
//   ztop add up to more than zero. Build items: the model and each add-on; removals are resources only,
//   so that a consumer printing the build never prints them as solids.
//
// Streaming: the model entry is deflated into the archive while layers arrive (minizip); memory is one
// layer's text plus about 1 MiB of output (one more layer without h: the slice tag waits for the next
// plane), independent of the layer count. A feature's stack goes to an unnamed temporary file
// (tmpfile(), about 1 MiB buffered per feature) and is copied into the model entry by finish(). The archive
// is written under OutputFile's temporary name and renamed by finish(). Same input, same bytes (for the same
// zlib: deflate level 1).
#pragma once

#include <filesystem>
#include <memory>
#include <span>

#include "core/mesh/mesh.h"
#include "io/contours/contour_sink.h"

namespace toposlice {

// `mesh` may be null; when not, it is read by finish() and must stay valid until then. `layerHeight`:
// the uniform layer height h of the planes (> 0), or 0 when the planes are not uniform or h is unknown.
// Throws OutputError when the file exists and !overwrite, or cannot be created; I/O failures of
// writeLayer()/finish() are OutputErrors naming the file.
// `featureMeshes`: empty, or one soup per job.features entry (same order), each also read by finish().
std::unique_ptr<ContourSink> makeThreeMfWriter(const std::filesystem::path& path, const ContourJob& job,
                                               const FacetSoup* mesh, bool overwrite,
                                               double layerHeight = 0.0,
                                               std::span<const FacetSoup> featureMeshes = {});

}  // namespace toposlice
