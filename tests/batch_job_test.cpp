// Batch job files: a full job and the bundled example parse into the expected fields; every kind of bad
// job (invalid JSON, unknown or repeated keys, wrong types, bad values, clashing names and paths) fails
// with an InputError naming the file and the JSON path of the problem.
#include "io/jobs/batch_job.h"

#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "io/errors.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

// A valid job using every key.
Json fullJob() {
  return Json::parse(R"({
    "version": 1,
    "description": "two stages",
    "template": {"model": "models/template.stl", "table": "out/template.topo"},
    "settings": {
      "layer_height": 0.001, "layers": 14000, "z0": -3.5,
      "method": "sr-lazy", "join_tolerance": 1e-5,
      "printer": "prusa-sl1s", "pixel": 0.05, "origin": [-60, -34], "resolution": [2560, 1440],
      "mirror": "x", "antialias": true, "threads": 8, "overwrite": true
    },
    "variants": [
      {"name": "v1", "model": "models/v1.stl.gz", "contours": "out/v1.cli", "masks": "out/v1.sl1",
       "report": "out/v1.csv", "add": ["features/monogram.stl"], "remove": ["features/engraving.stl"]},
      {"name": "v2", "model": "/abs/v2.stl", "masks": "out/v2.EXR"}
    ]
  })");
}

Json minimalJob() {
  return Json::parse(R"({"template": {"model": "t.stl"}, "settings": {"layer_height": 0.05},
                         "variants": [{"name": "a", "model": "a.stl", "contours": "a.cli"}]})");
}

BatchJob parse(const Json& job) {
  return parseBatchJob(job.dump(2), "/jobs", "job.json");
}

// Expects the job to fail with "job.json: <where>: ..." containing `what` (where empty: "job.json: ...").
void expectError(const std::string& text, const std::string& where, const std::string& what) {
  try {
    parseBatchJob(text, "/jobs", "job.json");
    ADD_FAILURE() << "accepted: " << text;
  } catch (const InputError& e) {
    const std::string message = e.what();
    const std::string prefix = "job.json: " + (where.empty() ? "" : where + ": ");
    EXPECT_EQ(message.rfind(prefix, 0), 0u) << message << "\n  expected prefix: " << prefix;
    EXPECT_NE(message.find(what), std::string::npos) << message << "\n  expected: " << what;
  }
}

void expectError(const std::function<void(Json&)>& edit, const std::string& where, const std::string& what) {
  Json job = fullJob();
  edit(job);
  expectError(job.dump(2), where, what);
}

TEST(BatchJob, ParsesEveryField) {
  const BatchJob job = parse(fullJob());
  EXPECT_EQ(job.description, "two stages");
  EXPECT_EQ(job.templateModel, fs::path("/jobs/models/template.stl"));
  EXPECT_EQ(job.templateFile, fs::path("/jobs/out/template.topo"));
  EXPECT_EQ(job.layerHeight, 0.001);
  EXPECT_EQ(job.layers, 14000u);
  EXPECT_EQ(job.z0, -3.5);
  EXPECT_TRUE(job.explicitZ.empty());
  EXPECT_EQ(job.method, "sr-lazy");
  EXPECT_EQ(job.joinTolerance, 1e-5);
  EXPECT_EQ(job.printer, "prusa-sl1s");
  EXPECT_EQ(job.pixel, 0.05);
  ASSERT_TRUE(job.origin.has_value());
  EXPECT_EQ((*job.origin)[0], -60.0);
  EXPECT_EQ((*job.origin)[1], -34.0);
  ASSERT_TRUE(job.resolution.has_value());
  EXPECT_EQ((*job.resolution)[0], 2560u);
  EXPECT_EQ((*job.resolution)[1], 1440u);
  EXPECT_EQ(job.mirrorX, true);
  EXPECT_EQ(job.mirrorY, false);
  EXPECT_TRUE(job.antialias);
  EXPECT_EQ(job.threads, 8u);
  EXPECT_TRUE(job.overwrite);
  ASSERT_EQ(job.variants.size(), 2u);
  const BatchVariant& v1 = job.variants[0];
  EXPECT_EQ(v1.name, "v1");
  EXPECT_EQ(v1.model, fs::path("/jobs/models/v1.stl.gz"));
  EXPECT_EQ(v1.contours, fs::path("/jobs/out/v1.cli"));
  EXPECT_EQ(v1.masks, fs::path("/jobs/out/v1.sl1"));
  EXPECT_EQ(v1.report, fs::path("/jobs/out/v1.csv"));
  EXPECT_EQ(v1.add, std::vector<fs::path>{"/jobs/features/monogram.stl"});
  EXPECT_EQ(v1.remove, std::vector<fs::path>{"/jobs/features/engraving.stl"});
  const BatchVariant& v2 = job.variants[1];
  EXPECT_EQ(v2.model, fs::path("/abs/v2.stl")) << "absolute paths are kept";
  EXPECT_TRUE(v2.contours.empty());
  EXPECT_EQ(v2.masks, fs::path("/jobs/out/v2.EXR")) << "extensions are matched in any case";
  EXPECT_TRUE(v2.add.empty() && v2.remove.empty());
}

TEST(BatchJob, MinimalJobHasDefaults) {
  const BatchJob job = parse(minimalJob());
  EXPECT_EQ(job.templateModel, fs::path("/jobs/t.stl"));
  EXPECT_TRUE(job.templateFile.empty());
  EXPECT_EQ(job.layerHeight, 0.05);
  EXPECT_FALSE(job.layers || job.z0 || job.pixel || job.origin || job.resolution || job.mirrorX ||
               job.mirrorY || job.joinTolerance);
  EXPECT_TRUE(job.method.empty() && job.printer.empty() && job.description.empty());
  EXPECT_FALSE(job.antialias || job.overwrite);
  EXPECT_EQ(job.threads, 0u);
  ASSERT_EQ(job.variants.size(), 1u);
  EXPECT_TRUE(job.variants[0].masks.empty() && job.variants[0].report.empty());
}

TEST(BatchJob, PathsAreNormalisedAndLeftRelativeWithoutBase) {
  Json j = minimalJob();
  j["variants"][0]["contours"] = "out/./sub/../a.cli";
  j["template"]["table"] = "../shared/t.topo";
  const BatchJob based = parse(j);
  EXPECT_EQ(based.variants[0].contours, fs::path("/jobs/out/a.cli"));
  EXPECT_EQ(based.templateFile, fs::path("/shared/t.topo"));
  const BatchJob relative = parseBatchJob(j.dump(), "", "job.json");
  EXPECT_EQ(relative.variants[0].contours, fs::path("out/a.cli"));
  EXPECT_EQ(relative.templateModel, fs::path("t.stl"));
}

TEST(BatchJob, ExplicitPlanes) {
  Json j = minimalJob();
  j["settings"] = Json::parse(R"({"z": [0.1, 0.2, 0.35]})");
  EXPECT_EQ(parse(j).explicitZ, (std::vector<double>{0.1, 0.2, 0.35}));
  j["settings"] = Json::parse(R"({"layers": 100})");
  EXPECT_EQ(parse(j).layers, 100u);
  j["settings"] = Json::parse(R"({"layers": 2e3, "threads": 0})");
  EXPECT_EQ(parse(j).layers, 2000u) << "a whole number written with an exponent is accepted";
}

TEST(BatchJob, BundledExampleParsesAndNamesExistingModels) {
  const fs::path example = fs::path(__FILE__).parent_path().parent_path() / "examples" / "batch_aligner.json";
  const BatchJob job = readBatchJob(example);
  ASSERT_GE(job.variants.size(), 2u);
  EXPECT_TRUE(fs::exists(job.templateModel)) << job.templateModel;
  EXPECT_EQ(job.templateModel.filename(), "aligner_upper_case0.stl.gz");
  EXPECT_EQ(job.templateFile.parent_path().filename(), "out");
  bool stage2 = false;
  for (const BatchVariant& v : job.variants) {
    EXPECT_TRUE(fs::exists(v.model)) << v.model;
    for (const fs::path& f : v.add) EXPECT_TRUE(fs::exists(f)) << f;
    for (const fs::path& f : v.remove) EXPECT_TRUE(fs::exists(f)) << f;
    stage2 = stage2 || v.model.filename() == "aligner_upper_case0_stage2.stl.gz";
    for (const fs::path* out : {&v.contours, &v.masks, &v.report}) {
      if (!out->empty()) {
        EXPECT_EQ(out->parent_path(), example.parent_path().lexically_normal() / "out");
      }
    }
  }
  EXPECT_TRUE(stage2);
}

TEST(BatchJob, ReadsAFileRelativeToItsFolder) {
  const fs::path dir =
      fs::temp_directory_path() /
      ("toposlice_batch_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
  fs::create_directories(dir / "jobs");
  {
    std::ofstream(dir / "jobs" / "job.json") << minimalJob().dump();
    std::ofstream(dir / "jobs" / "broken.json")
        << "{\n  \"template\": {\n    \"model\": \"t.stl\",\n  }\n}\n";
  }
  const BatchJob job = readBatchJob(dir / "jobs" / "job.json");
  EXPECT_EQ(job.templateModel, dir / "jobs" / "t.stl");
  EXPECT_EQ(job.variants[0].contours, dir / "jobs" / "a.cli");
  try {
    readBatchJob(dir / "jobs" / "broken.json");
    ADD_FAILURE() << "accepted a trailing comma";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind((dir / "jobs" / "broken.json").string() + ":4:3: invalid JSON", 0),
              0u)
        << e.what();
  }
  EXPECT_THROW(readBatchJob(dir / "jobs" / "missing.json"), InputError);
  EXPECT_THROW(readBatchJob(dir / "jobs"), InputError);
  fs::remove_all(dir);
}

// Expects "job.json:<line>:<column>: invalid JSON: ..." containing `what`.
void expectInvalidJson(const std::string& text, const std::string& position, const std::string& what) {
  try {
    parseBatchJob(text, "/jobs", "job.json");
    ADD_FAILURE() << "accepted: " << text;
  } catch (const InputError& e) {
    const std::string message = e.what();
    EXPECT_EQ(message.rfind("job.json:" + position + ": invalid JSON: ", 0), 0u) << message;
    EXPECT_NE(message.find(what), std::string::npos) << message;
  }
}

TEST(BatchJob, RejectsInvalidJsonNamingLineAndColumn) {
  expectInvalidJson("", "1:1", "unexpected end of input");
  expectInvalidJson("{\"template\": }", "1:14", "unexpected '}'");
  expectInvalidJson("{\n  \"a\": 1,\n  \"b\": tru\n}", "3:11", "invalid literal");
  expectInvalidJson("{\n  \"a\": [1, 2,]\n}", "2:14", "unexpected ']'");
  expectInvalidJson("{} trailing", "1:6", "expected end of input");
  expectInvalidJson("{\"a\": 1} // comment", "1:10", "expected end of input");
  expectError(R"({"settings": {"layer_height": 1e999}})", "", "invalid JSON: number overflow");
  expectError("[1, 2]", "", "expected a JSON object at the top, got array");
  expectError("\"job\"", "", "expected a JSON object at the top, got string");
}

TEST(BatchJob, RejectsDuplicateKeys) {
  expectError(R"({"template": {"model": "a.stl", "model": "b.stl"}})", "template.model", "duplicate key");
  expectError(R"({"variants": [{"name": "a"}, {"name": "b", "masks": "x", "masks": "y"}]})",
              "variants[1].masks", "duplicate key");
  expectError(R"({"settings": {"z": [1, [2, 3], {"a": 1, "a": 2}]}})", "settings.z[2].a", "duplicate key");
  expectError(R"({"variants": [], "variants": []})", "variants", "duplicate key");
}

TEST(BatchJob, RejectsUnknownKeysNamingThem) {
  expectError([](Json& j) { j["templates"] = Json::object(); }, "templates", "unknown key");
  expectError([](Json& j) { j["template"]["mesh"] = "x.stl"; }, "template.mesh",
              "expected one of: model, table");
  expectError([](Json& j) { j["settings"]["layer_hieght"] = 0.1; }, "settings.layer_hieght", "layer_height");
  expectError([](Json& j) { j["variants"][1]["mask"] = "x.sl1"; }, "variants[1].mask", "unknown key");
}

TEST(BatchJob, RejectsMissingParts) {
  expectError([](Json& j) { j.erase("template"); }, "template", "missing");
  expectError([](Json& j) { j["template"] = Json::object(); }, "template", "give model");
  expectError([](Json& j) { j.erase("variants"); }, "variants", "missing");
  expectError([](Json& j) { j["variants"] = Json::array(); }, "variants", "at least one variant");
  expectError([](Json& j) { j.erase("settings"); }, "settings", "missing");
  expectError([](Json& j) { j["settings"] = Json::parse(R"({"z0": 1, "pixel": 0.05})"); }, "settings",
              "give the slicing planes");
  expectError([](Json& j) { j["variants"][1].erase("name"); }, "variants[1].name", "missing");
  expectError([](Json& j) { j["variants"][0].erase("model"); }, "variants[0].model", "missing");
  expectError([](Json& j) { j["variants"][1].erase("masks"); }, "variants[1]", "no output");
}

TEST(BatchJob, RejectsWrongTypes) {
  expectError([](Json& j) { j["template"] = "t.stl"; }, "template", "expected an object, got string");
  expectError([](Json& j) { j["template"]["model"] = 3; }, "template.model", "expected a string, got number");
  expectError([](Json& j) { j["settings"] = Json::array(); }, "settings", "expected an object, got array");
  expectError([](Json& j) { j["settings"]["layer_height"] = "0.001"; }, "settings.layer_height",
              "expected a number, got string");
  expectError([](Json& j) { j["settings"]["layers"] = true; }, "settings.layers", "expected a whole number");
  expectError([](Json& j) { j["settings"]["antialias"] = 1; }, "settings.antialias",
              "expected true or false");
  expectError([](Json& j) { j["settings"]["origin"] = Json::parse("[1]"); }, "settings.origin", "[x0, y0]");
  expectError([](Json& j) { j["settings"]["origin"] = Json::parse("[1, \"2\"]"); }, "settings.origin[1]",
              "expected a number");
  expectError([](Json& j) { j["settings"]["resolution"] = Json::parse("[1920, 1080.5]"); },
              "settings.resolution[1]", "whole number");
  expectError([](Json& j) { j["variants"] = Json::object(); }, "variants", "expected an array");
  expectError([](Json& j) { j["variants"][0] = "v1.stl"; }, "variants[0]", "expected an object, got string");
  expectError([](Json& j) { j["variants"][0]["name"] = nullptr; }, "variants[0].name", "got null");
  expectError([](Json& j) { j["variants"][0]["add"] = "m.stl"; }, "variants[0].add",
              "expected an array of paths");
  expectError([](Json& j) { j["variants"][0]["remove"] = Json::parse("[\"a.stl\", 7]"); },
              "variants[0].remove[1]", "expected a string");
}

TEST(BatchJob, RejectsBadValues) {
  expectError([](Json& j) { j["version"] = 2; }, "version", "unsupported batch job version 2");
  expectError([](Json& j) { j["settings"]["layer_height"] = 0; }, "settings.layer_height",
              "must be positive");
  expectError([](Json& j) { j["settings"]["layer_height"] = -0.1; }, "settings.layer_height",
              "must be positive");
  expectError([](Json& j) { j["settings"]["layers"] = 0; }, "settings.layers", "between 1 and");
  expectError([](Json& j) { j["settings"]["layers"] = -5; }, "settings.layers", "between 1 and");
  expectError([](Json& j) { j["settings"]["layers"] = 1.5; }, "settings.layers", "whole number");
  expectError([](Json& j) { j["settings"]["layers"] = 5000000000ull; }, "settings.layers",
              "between 1 and 4294967295");
  expectError([](Json& j) { j["settings"]["pixel"] = 0; }, "settings.pixel", "must be positive");
  expectError([](Json& j) { j["settings"]["join_tolerance"] = -1; }, "settings.join_tolerance",
              "must be positive");
  // 0 too: every variant failed with slice's "--join-tolerance 0: expected a distance > 0 mm".
  expectError([](Json& j) { j["settings"]["join_tolerance"] = 0; }, "settings.join_tolerance",
              "must be positive");
  // Settings that cannot apply: mask settings when no variant writes masks, binary CLI without .cli
  // contours, a join tolerance for the default method, settings the masks' formats do not carry.
  const auto contoursOnly = [](Json& j) {
    j["variants"][0].erase("masks");
    j["variants"].erase(1);
  };
  expectError([&](Json& j) { contoursOnly(j); }, "settings.printer", "does nothing in this job");
  expectError(
      [&](Json& j) {
        contoursOnly(j);
        for (const char* k : {"printer", "pixel", "origin", "resolution", "mirror"}) j["settings"].erase(k);
      },
      "settings.antialias", "needs a variant with masks");
  expectError([](Json& j) { j["settings"]["method"] = "sr"; }, "settings.join_tolerance", "does nothing");
  expectError(
      [](Json& j) {
        j["variants"].erase(1);  // only v1's .sl1 masks, which do not carry the lift speed (.exr would)
        j["settings"]["print_settings"] = {{"lift_speed", 10}};
      },
      "settings.print_settings.lift_speed", "do not carry it");
  expectError([](Json& j) { j["settings"]["method"] = "marching"; }, "settings.method",
              "unknown slicing method \"marching\" (expected sr, sr-lazy or cp)");
  expectError([](Json& j) { j["settings"]["mirror"] = "z"; }, "settings.mirror", "expected none, x, y or xy");
  expectError([](Json& j) { j["settings"]["printer"] = ""; }, "settings.printer", "must not be empty");
  expectError([](Json& j) { j["settings"]["resolution"] = Json::parse("[0, 10]"); }, "settings.resolution[0]",
              "between 1 and");
  expectError([](Json& j) { j["settings"]["z"] = Json::parse("[0.1, 0.2]"); }, "settings.z",
              "cannot be combined");
  expectError([](Json& j) { j["settings"] = Json::parse(R"({"z": [0.1, 0.3, 0.3]})"); }, "settings.z[2]",
              "strictly ascending");
  expectError([](Json& j) { j["settings"] = Json::parse(R"({"z": []})"); }, "settings.z",
              "at least one plane");
  expectError([](Json& j) { j["settings"] = Json::parse(R"({"z": [0.5, 1, 3], "printer": "sl1"})"); },
              "settings.z", "not evenly spaced");
  expectError([](Json& j) { j["settings"]["method"] = "cp"; }, "settings.method", "uses no adjacency table");
  expectError([](Json& j) { j["variants"][0]["name"] = ""; }, "variants[0].name", "must not be empty");
  expectError([](Json& j) { j["variants"][0]["model"] = ""; }, "variants[0].model", "must not be empty");
  expectError([](Json& j) { j["variants"][0]["contours"] = "out/v1.txt"; }, "variants[0].contours",
              "unknown contour format \".txt\" (expected .cli, .3mf or .svg)");
  expectError([](Json& j) { j["variants"][0]["masks"] = "out/v1"; }, "variants[0].masks",
              "unknown mask format");
  expectError([](Json& j) { j["variants"][0]["report"] = "out/v1.txt"; }, "variants[0].report",
              "unknown report format \".txt\" (expected .csv)");
  expectError([](Json& j) { j["variants"][0]["masks"] = "out/"; }, "variants[0].masks", "names a folder");
}

TEST(BatchJob, RejectsClashingNamesAndPaths) {
  expectError([](Json& j) { j["variants"][1]["name"] = "v1"; }, "variants[1].name",
              "\"v1\" is already the name of variants[0]");
  expectError([](Json& j) { j["variants"][1]["masks"] = "out/v1.sl1"; }, "variants[1].masks",
              "is already written by variants[0].masks");
  expectError([](Json& j) { j["variants"][1]["masks"] = "out/sub/../v1.sl1"; }, "variants[1].masks",
              "/jobs/out/v1.sl1 is already written by variants[0].masks");
  expectError([](Json& j) { j["variants"][1]["masks"] = "/jobs/out/v1.sl1"; }, "variants[1].masks",
              "already written");
  expectError([](Json& j) { j["variants"][0]["report"] = "out/template.topo"; }, "variants[0].report",
              "already written by template.table");
  // JSON can hold a NUL; a path cannot (the system read the path cut short: another file).
  expectError([](Json& j) { j["variants"][0]["model"] = std::string("a.stl\0x", 7); }, "variants[0].model",
              "a path holds no NUL character");
  // An EXR stack is a folder made and replaced as a whole: nothing of the job inside it.
  expectError(
      [](Json& j) {
        j["variants"][0]["masks"] = "out/v1.exr";
        j["variants"][1]["contours"] = "out/v1.exr/v2.cli";
      },
      "variants[1].contours", "lies inside /jobs/out/v1.exr (variants[0].masks)");
  // Meshes are recognised by content: a model may have an output's extension.
  expectError(
      [](Json& j) {
        j["template"]["model"] = "models/template.csv";
        j["variants"][0]["report"] = "models/template.csv";
      },
      "variants[0].report", "is also an input (template.model)");
  expectError([](Json& j) { j["template"]["table"] = "features/monogram.stl"; }, "template.table",
              "unknown table format \".stl\" (expected .topo)");
}

TEST(BatchJob, SharedInputsAreFine) {
  Json j = fullJob();
  j["variants"][1]["model"] = "models/template.stl";                      // slicing the template itself
  j["variants"][1]["add"] = Json::parse(R"(["features/monogram.stl"])");  // one feature on several variants
  j["variants"][1]["contours"] = "models/v1.stl.gz.cli";
  EXPECT_NO_THROW(parse(j));
}

}  // namespace
}  // namespace toposlice
