// What `facedyn process` reads back from its output folder, which a crash, a full disk or a hand
// may have damaged: the plan (JobGraphFromJson) and a job state's file-digest cache
// (FileHashCache::FromJson).
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>

#include "process/content_hash.h"
#include "process/job_graph.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  facedyn::Json json;
  try {
    json = facedyn::Json::parse(text);
  } catch (const facedyn::Json::exception&) {
    return 0;
  }
  const auto graph = facedyn::process::JobGraphFromJson(json, "plan.json");
  if (graph.ok()) {
    // Accepted means every dependency names an earlier job.
    std::set<std::string> seen;
    for (const auto& job : graph->jobs) {
      for (const auto& dep : job.deps) {
        if (seen.count(dep) == 0) __builtin_trap();
      }
      seen.insert(job.id);
    }
  }
  (void)facedyn::process::FileHashCache::FromJson(json);
  if (json.is_object() && json.contains("files")) {
    (void)facedyn::process::FileHashCache::FromJson(json["files"]);
  }
  return 0;
}
