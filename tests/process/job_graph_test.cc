// The job graph of a session: which takes, which jobs, their dependencies, inputs and outputs,
// and the plan file's round trip and refusal of a damaged plan.

#include "process/job_graph.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>

#include "tests/support/test_support.h"

namespace facedyn::process {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::Contains;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

// A session folder as capture/ writes it, with empty camera files (the graph reads manifests only).
void WriteTake(const TempDir& dir, const std::string& name, const std::string& status,
               const std::string& extra = "") {
  const std::string take = dir.Join("s/takes/" + name);
  WriteBytes(take + "/cam0/frames.fdr", "frames of " + name);
  WriteBytes(take + "/ground_truth/take/take.json", "{}");
  WriteBytes(take + "/capture.json",
             R"({"format": "facedyn-capture-take", "version": 1, "name": ")" + name +
                 R"(", "status": ")" + status + R"(", "reason": "", "fps": 128.0,
  "triggers_requested": 2, "triggers_emitted": 2, "cameras": [])" +
                 extra + "}");
}

void WriteSession(const TempDir& dir, const std::vector<std::string>& names) {
  std::string takes;
  for (const auto& n : names) {
    takes += std::string(takes.empty() ? "" : ",") + R"({"name": ")" + n + R"(", "dir": "takes/)" +
             n + R"(", "status": "complete"})";
  }
  WriteBytes(dir.Join("s/session.json"),
             R"({"format": "facedyn-session", "version": 1, "name": "s", "clock": "virtual",
  "cameras": [], "calibration": "calibration.yaml", "takes": [)" +
                 takes + "]}");
  WriteBytes(dir.Join("s/calibration.yaml"), "%YAML:1.0\n");
}

std::vector<std::string> Ids(const JobGraph& graph) {
  std::vector<std::string> ids;
  for (const Job& j : graph.jobs) ids.push_back(j.id);
  return ids;
}

TEST(JobGraph, EveryStepForEveryCompleteTake) {
  TempDir dir;
  WriteSession(dir, {"smile", "speech", "broken", "redo_old", "redo"});
  WriteTake(dir, "smile", "complete");
  WriteTake(dir, "speech", "complete");
  WriteTake(dir, "broken", "stopped");
  WriteTake(dir, "redo_old", "complete");
  WriteTake(dir, "redo", "complete", R"(, "supersedes": ["redo_old"])");
  ProcessConfig config;
  config.removal.train_takes = {"smile", "redo"};
  config.exports.formats = {"pc2", "glb"};
  const auto graph = BuildJobGraph(dir.Join("s"), config, dir.Join("out"));
  ASSERT_TRUE(graph.ok()) << graph.status().ToString();
  EXPECT_THAT(graph->takes, ElementsAre("smile", "speech", "redo"));
  ASSERT_EQ(graph->skipped.size(), 2u);
  EXPECT_EQ(graph->skipped[0].take, "broken");
  EXPECT_THAT(graph->skipped[0].reason, HasSubstr("stopped"));
  EXPECT_EQ(graph->skipped[1].take, "redo_old");
  EXPECT_THAT(graph->skipped[1].reason, HasSubstr("superseded by redo"));
  EXPECT_THAT(Ids(*graph),
              ElementsAre("reconstruct/smile", "reconstruct/speech", "reconstruct/redo",
                          "train-removal", "train-synthesis", "train-solver", "remove/smile",
                          "remove/speech", "remove/redo", "solve/smile", "solve/speech",
                          "solve/redo", "export/smile", "export/speech", "export/redo"));

  // Training waits only for its own takes; per-take steps for their take and the models.
  const Job* train = graph->Find("train-removal");
  ASSERT_NE(train, nullptr);
  EXPECT_THAT(train->deps, ElementsAre("reconstruct/smile", "reconstruct/redo"));
  EXPECT_THAT(graph->Find("remove/speech")->deps,
              ElementsAre("reconstruct/speech", "train-removal"));
  EXPECT_THAT(graph->Find("solve/speech")->deps, ElementsAre("remove/speech", "train-solver"));
  EXPECT_THAT(graph->Find("export/speech")->deps, ElementsAre("remove/speech"));
  EXPECT_EQ(graph->Find("export/speech")->commands.size(), 2u);  // one per format

  // Reconstruct reads the capture and the calibration, never the simulator's ground truth.
  const Job* rec = graph->Find("reconstruct/smile");
  EXPECT_THAT(rec->inputs, Contains(dir.Join("s/takes/smile/cam0")));
  EXPECT_THAT(rec->inputs, Contains(dir.Join("s/calibration.yaml")));
  for (const std::string& input : rec->inputs)
    EXPECT_THAT(input, ::testing::Not(HasSubstr("ground_truth")));
  EXPECT_THAT(rec->outputs, ElementsAre(dir.Join("out/takes/smile/reconstructed")));

  // Slurm array index i of a per-take step is the i-th take for every step.
  for (const std::string step : {"reconstruct", "remove", "solve", "export"}) {
    const auto jobs = graph->JobsOfStep(step);
    ASSERT_EQ(jobs.size(), 3u) << step;
    for (size_t i = 0; i < jobs.size(); ++i) EXPECT_EQ(jobs[i]->take, graph->takes[i]) << step;
  }
}

TEST(JobGraph, OptionalStepsAndANamedSolver) {
  TempDir dir;
  WriteSession(dir, {"a"});
  WriteTake(dir, "a", "complete");
  ProcessConfig config;
  config.synthesis.enabled = false;
  config.solve.model = dir.Join("solver");
  config.exports.formats = {};
  const auto graph = BuildJobGraph(dir.Join("s"), config, dir.Join("out"));
  ASSERT_TRUE(graph.ok()) << graph.status().ToString();
  EXPECT_THAT(Ids(*graph), ElementsAre("reconstruct/a", "train-removal", "remove/a", "solve/a"));
  EXPECT_THAT(graph->Find("solve/a")->deps, ElementsAre("remove/a"));
  EXPECT_THAT(graph->Find("solve/a")->inputs, Contains(dir.Join("solver")));
}

TEST(JobGraph, RefusesWhatCannotBeProcessed) {
  TempDir dir;
  WriteSession(dir, {"a"});
  WriteTake(dir, "a", "stopped");
  ProcessConfig config;
  auto graph = BuildJobGraph(dir.Join("s"), config, dir.Join("out"));
  ASSERT_FALSE(graph.ok());
  EXPECT_THAT(graph.status().message(), HasSubstr("no complete take"));

  WriteTake(dir, "a", "complete");
  config.removal.train_takes = {"nothing_*"};
  graph = BuildJobGraph(dir.Join("s"), config, dir.Join("out"));
  ASSERT_FALSE(graph.ok());
  EXPECT_THAT(graph.status().message(), HasSubstr("train_takes"));

  EXPECT_FALSE(BuildJobGraph(dir.Join("no-session"), ProcessConfig{}, dir.Join("out")).ok());
}

TEST(JobGraph, PlanRoundTripsAndADamagedPlanIsRefused) {
  TempDir dir;
  WriteSession(dir, {"a", "b"});
  WriteTake(dir, "a", "complete");
  WriteTake(dir, "b", "complete");
  const auto graph = BuildJobGraph(dir.Join("s"), ProcessConfig{}, dir.Join("out"));
  ASSERT_TRUE(graph.ok()) << graph.status().ToString();
  ASSERT_TRUE(WritePlan(*graph).ok());
  const auto read = ReadPlan(dir.Join("out"));
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(JobGraphToJson(*read).dump(), JobGraphToJson(*graph).dump());

  Json bad = JobGraphToJson(*graph);
  bad["jobs"][0]["deps"] = Json::array({"export/b"});  // a dependency on a later job
  EXPECT_THAT(JobGraphFromJson(bad, "plan.json").status().message(), HasSubstr("depends on"));
  bad = JobGraphToJson(*graph);
  bad["jobs"][1]["commands"] = 3;
  EXPECT_THAT(JobGraphFromJson(bad, "plan.json").status().message(), HasSubstr("plan.json"));
  WriteBytes(dir.Join("out/process/plan.json"), "{\"format\": \"facedyn-process-pl");
  EXPECT_FALSE(ReadPlan(dir.Join("out")).ok());
}

TEST(JobGraph, StateAndLogNamesAreFlat) {
  EXPECT_EQ(JobFileStem("reconstruct/smile_8hz"), "reconstruct--smile_8hz");
  EXPECT_EQ(StatePath("/o", "export/a"), "/o/process/state/export--a.json");
  EXPECT_EQ(LogPath("/o", "train-removal"), "/o/process/logs/train-removal.log");
}

}  // namespace
}  // namespace facedyn::process
