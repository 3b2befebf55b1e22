// Every closed model in ../shared/models, sliced at a coarse height by all three methods: every loop
// closed, holes and outer boundaries oriented by their nesting, the per-layer signed area equal to the
// area computed facet by facet, and cp, sr-lazy and sr identical bit for bit.
#include <gtest/gtest.h>

#include <cmath>

#include "core/mesh/mesh_info.h"
#include "core/slicing/planes.h"
#include "io/readers/stl_reader.h"
#include "tests/fixtures/models.h"

namespace toposlice {
namespace {

struct ClosedModel {
  const char* file;
  bool nestingCheck;  // no self-intersections, so loops nest cleanly and orientation follows depth
  bool insideOut;     // the whole mesh is inside out (negative volume): every orientation flips
};

const ClosedModel kClosedModels[] = {
    {"dental_teeth_upper_case0.stl", false, false},
    {"dental_teeth_lower_case0.stl", false, false},
    {"dental_teeth_upper_case1.stl", false, false},
    {"dental_teeth_lower_case1.stl", false, false},
    {"spine_lumbar_L2-L5_ssm_mean.stl.gz", false, false},
    {"knee_femur_ssm_S001.stl", true, false},
    {"knee_femur_ssm_S002.stl", true, false},
    {"knee_femur_ssm_S003.stl", true, false},
    {"knee_femur_ssm_mean.stl", true, false},
    {"knee_tibia_ssm_S001.stl", true, false},
    {"knee_tibia_ssm_S002.stl", true, false},
    {"human_body_smpl_male.stl", false, false},
    {"human_body_smpl_female.stl", false, false},
    {"hand_smpl_closed.stl", true, false},
    {"skull.stl", true, false},
    {"head_with_pinnae_mesh2hrtf.stl", true, false},
    {"bunny_closed.stl", true, false},
    {"armadillo.stl", true, false},
    {"igea.stl.gz", true, false},
    {"nefertiti.stl", true, false},
    {"horse_cyberware.stl", false, true},
    {"elephant_refined.stl", true, false},
    {"amo_statue.stl.gz", true, false},
    {"gearwheel_ascii.stl", true, false},
    {"derived/aligner_upper_case0.stl.gz", false, false},
    {"derived/aligner_upper_case0_stage2.stl.gz", false, false},
    {"derived/spine_L2-L5_sub1.stl.gz", false, false},
    {"derived/spine_L2-L5_sub1_bent.stl.gz", false, false},
    {"derived/femur_S001_sub2.stl.gz", true, false},
    {"derived/femur_S002_sub2.stl.gz", true, false},
};

// Crossing-number test: is p inside the closed polygon?
bool inside(Point2d p, std::span<const Point2d> loop) {
  bool in = false;
  for (std::size_t i = 0, j = loop.size() - 1; i < loop.size(); j = i++) {
    const Point2d a = loop[i], b = loop[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) in = !in;
  }
  return in;
}

class SliceModels : public ::testing::TestWithParam<ClosedModel> {};

TEST_P(SliceModels, AllMethodsAgreeAndLoopsAreValid) {
  const ClosedModel& model = GetParam();
  const FacetSoup soup = readStl(fixtures::modelPath(model.file));
  const BoundingBox box = boundsOf(soup.corners);
  PlaneSpec spec;
  spec.layers = 24;
  std::string error;
  const std::vector<double> planes = makePlanes(spec, box.min.z, box.max.z, error);
  ASSERT_TRUE(error.empty()) << error;
  const double scale = (double{box.max.x} - box.min.x) * (double{box.max.y} - box.min.y);

  std::vector<LayerContours> reference;
  for (const SliceMethod method :
       {SliceMethod::SelfReuse, SliceMethod::SelfReuseLazy, SliceMethod::ClosestPoint}) {
    SliceStats stats;
    const auto layers = fixtures::sliceToVector(soup, planes, method, 0, &stats);
    EXPECT_EQ(stats.openPolylines, 0u) << sliceMethodName(method);
    if (reference.empty()) {
      reference = layers;
      continue;
    }
    for (std::size_t k = 0; k < layers.size(); ++k)
      ASSERT_TRUE(layers[k] == reference[k]) << sliceMethodName(method) << " differs from sr at layer " << k;
  }

  {  // Bands started from Embree's BVH and odd band sizes: the same layers.
    SliceSettings settings;
    settings.candidates = CandidateSearch::Embree;
    settings.bandLayers = 5;
    const auto layers = fixtures::sliceToVector(soup, planes, settings);
    for (std::size_t k = 0; k < layers.size(); ++k)
      ASSERT_TRUE(layers[k] == reference[k]) << "Embree candidates differ at layer " << k;
  }

  double totalArea = 0;
  for (std::size_t k = 0; k < reference.size(); ++k) {
    const LayerContours& layer = reference[k];
    for (const uint8_t closed : layer.loopClosed) ASSERT_EQ(closed, 1);
    const double area = layerSignedArea(layer);
    EXPECT_NEAR(area, fixtures::facetwiseArea(soup.corners, planes[k]), 1e-9 * scale + 1e-12)
        << "layer " << k;
    totalArea += area;
    if (!model.nestingCheck) continue;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto loop = layer.loopPoints(l);
      if (loop.size() < 3 || std::abs(signedArea(loop)) < 1e-12 * scale) continue;
      int depth = 0;
      for (std::size_t m = 0; m < layer.loopCount(); ++m)
        if (m != l && layer.loopPoints(m).size() >= 3 && inside(loop[0], layer.loopPoints(m))) ++depth;
      const bool outer = depth % 2 == 0;
      EXPECT_EQ(signedArea(loop) > 0, outer) << "layer " << k << " loop " << l << " depth " << depth;
    }
  }
  if (model.insideOut) {
    EXPECT_LT(totalArea, 0.0);
  } else {
    EXPECT_GT(totalArea, 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Shared, SliceModels, ::testing::ValuesIn(kClosedModels),
                         [](const ::testing::TestParamInfo<ClosedModel>& param) {
                           std::string name = param.param.file;
                           for (char& c : name)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return name;
                         });

}  // namespace
}  // namespace toposlice
