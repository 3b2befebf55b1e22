// Reproduces the layout of the paper's Table 3 (closest point vs self reuse) and Table 4 (template
// reuse) on the derived models at 1 um layers, timing each stage separately:
//   paper_tables [--threads N] [--cp-sample K] [--models DIR] [--table3] [--table4]
// cp runs on every K-th layer and is extrapolated (x K) since a full run takes many minutes.
// Slicing output is consumed (counted) but not written, so the numbers are the slicing stages alone;
// the end-to-end command times with file output are measured with the toposlice binary (BENCHMARKS.md).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/mesh_info.h"
#include "core/mesh/variant_check.h"
#include "core/mesh/weld.h"
#include "core/slicing/planes.h"
#include "io/jobs/template_file.h"
#include "io/readers/stl_reader.h"
#include "parallel/band_slicer.h"
#include "parallel/parallel.h"
#include "parallel/variant_screen.h"

namespace toposlice {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

struct Model {
  const char* name;
  const char* file;
  const char* variant;  // same-connectivity variant for Table 4
  uint32_t layers;      // 0: 1 um layers over the model height
};

std::vector<double> planesFor(const FacetSoup& soup, uint32_t layers) {
  const BoundingBox box = boundsOf(soup.corners);
  PlaneSpec spec;
  if (layers)
    spec.layers = layers;
  else
    spec.layerHeight = 0.001;
  std::string error;
  return makePlanes(spec, box.min.z, box.max.z, error);
}

double sliceSeconds(const FacetSoup& soup, std::span<const int32_t> table, std::span<const double> planes,
                    SliceMethod method, uint64_t* segments = nullptr) {
  SliceSettings settings;
  settings.method = method;
  const auto start = Clock::now();
  const SliceStats stats =
      sliceModel(soup.corners, table, planes, settings, [](uint32_t, const LayerContours&) {});
  if (segments) *segments = stats.segments;
  return since(start);
}

std::string minutes(double s) {
  char buf[64];
  if (s >= 60)
    std::snprintf(buf, sizeof buf, "%dm%04.1fs", static_cast<int>(s / 60), s - 60 * static_cast<int>(s / 60));
  else
    std::snprintf(buf, sizeof buf, "%.2fs", s);
  return buf;
}

}  // namespace
}  // namespace toposlice

int main(int argc, char** argv) {
  using namespace toposlice;
  unsigned threads = 0;
  uint32_t cpSample = 50;
  std::string dir = TOPOSLICE_MODELS_DIR "/derived/";
  bool table3 = false, table4 = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--threads" && i + 1 < argc)
      threads = static_cast<unsigned>(std::atoi(argv[++i]));
    else if (a == "--cp-sample" && i + 1 < argc)
      cpSample = static_cast<uint32_t>(std::atoi(argv[++i]));
    else if (a == "--models" && i + 1 < argc)
      dir = std::string(argv[++i]) + "/";
    else if (a == "--table3")
      table3 = true;
    else if (a == "--table4")
      table4 = true;
    else {
      std::fprintf(
          stderr, "usage: paper_tables [--threads N] [--cp-sample K] [--models DIR] [--table3] [--table4]\n");
      return 2;
    }
  }
  if (!table3 && !table4) table3 = table4 = true;
  ThreadLimit limit(threads);
  const Model models[] = {
      {"aligner", "aligner_upper_case0.stl.gz", "aligner_upper_case0_stage2.stl.gz", 0},
      {"vertebral column", "spine_L2-L5_sub1.stl.gz", "spine_L2-L5_sub1_bent.stl.gz", 10000},
      {"femur", "femur_S001_sub2.stl.gz", "femur_S002_sub2.stl.gz", 0},
  };
  std::printf("threads: %u, cp on every %u-th layer, extrapolated\n\n", ThreadLimit::available(), cpSample);
  if (table3) {
    std::printf(
        "| model | facets | layers | segments | read | weld+adjacency | closest point (cp) | self reuse, "
        "paper (sr-lazy) | self reuse (sr) | cp / sr |\n");
    std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for (const Model& m : models) {
      auto t = Clock::now();
      const FacetSoup soup = readStl(dir + m.file);
      const double read = since(t);
      const auto planes = planesFor(soup, m.layers);
      t = Clock::now();
      const IndexedMesh mesh = weldCorners(soup.corners);
      std::vector<int32_t> table(soup.corners.size());
      buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table);
      const double topo = since(t);
      uint64_t segments = 0;
      const double sr = sliceSeconds(soup, table, planes, SliceMethod::SelfReuse, &segments);
      const double lazy = sliceSeconds(soup, {}, planes, SliceMethod::SelfReuseLazy);
      std::vector<double> sample;
      for (std::size_t k = 0; k < planes.size(); k += cpSample) sample.push_back(planes[k]);
      const double cp = sliceSeconds(soup, {}, sample, SliceMethod::ClosestPoint) *
                        static_cast<double>(planes.size()) / static_cast<double>(sample.size());
      std::printf("| %s | %zu | %zu | %llu | %.3fs | %.3fs | %s (est.) | %s | %s | %.0fx |\n", m.name,
                  soup.facetCount(), planes.size(), static_cast<unsigned long long>(segments), read, topo,
                  minutes(cp).c_str(), minutes(lazy + topo * 0).c_str(), minutes(sr + topo).c_str(),
                  cp / (sr + topo));
      std::fflush(stdout);
    }
    std::printf(
        "\nsr includes weld+adjacency; sr-lazy builds its table while slicing; read excluded from all.\n\n");
  }
  if (table4) {
    std::printf(
        "| variant | facets | layers | closest point (cp) | self reuse from scratch (sr) | template reuse "
        "(sr + .topo) | topology stage: build / verify | scratch / template |\n");
    std::printf("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    const std::string topo = "/tmp/paper_tables_template.topo";
    for (const Model& m : models) {
      {  // The template's table, saved once (not timed: done once per product line).
        const FacetSoup templ = readStl(dir + m.file);
        writeTemplateFile(topo, buildTemplateTable(weldCorners(templ.corners)), true);
      }
      // Each column end to end from the variant file: read + topology + slice. The two are run
      // alternately, kRepeats times each, and the best of each is kept (the machines are shared).
      constexpr int kRepeats = 3;
      double read = 0, build = 0, scratch = 1e300, templ = 1e300, verify = 0;
      FacetSoup soup;
      std::vector<double> planes;
      for (int repeat = 0; repeat < kRepeats; ++repeat) {
        auto t = Clock::now();
        soup = readStl(dir + m.variant);
        const double readNow = since(t);
        planes = planesFor(soup, m.layers);
        t = Clock::now();
        const IndexedMesh mesh = weldCorners(soup.corners);
        std::vector<int32_t> table(soup.corners.size());
        buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table);
        const double buildNow = since(t);
        const double scratchNow =
            readNow + buildNow + sliceSeconds(soup, table, planes, SliceMethod::SelfReuse);
        if (scratchNow < scratch) {
          scratch = scratchNow;
          read = readNow;
          build = buildNow;
        }
        // As `toposlice slice --template` does: the table is read while the variant is, then verified.
        t = Clock::now();
        FacetSoup soup2;
        TemplateTable loaded;
        parallelInvoke([&] { loaded = readTemplateFile(topo); }, [&] { soup2 = readStl(dir + m.variant); });
        const double read2 = since(t);
        t = Clock::now();
        if (checkVariantConnectivityParallel(soup2.corners, loaded.adjacency)) {
          std::fprintf(stderr, "%s does not match its template\n", m.variant);
          return 1;
        }
        const double verifyNow = since(t);
        const double templNow =
            read2 + verifyNow + sliceSeconds(soup2, loaded.adjacency, planes, SliceMethod::SelfReuse);
        if (templNow < templ) {
          templ = templNow;
          verify = verifyNow;
        }
      }
      std::vector<double> sample;
      for (std::size_t k = 0; k < planes.size(); k += cpSample) sample.push_back(planes[k]);
      const double cp = read + sliceSeconds(soup, {}, sample, SliceMethod::ClosestPoint) *
                                   static_cast<double>(planes.size()) / static_cast<double>(sample.size());
      std::printf("| %s | %zu | %zu | %s (est.) | %s | %s | %.3fs / %.3fs | %.2fx |\n", m.variant,
                  soup.facetCount(), planes.size(), minutes(cp).c_str(), minutes(scratch).c_str(),
                  minutes(templ).c_str(), build, verify, scratch / templ);
      std::fflush(stdout);
    }
    std::remove(topo.c_str());
  }
  return 0;
}
