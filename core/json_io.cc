#include "core/json_io.h"

#include "core/file_util.h"

namespace facedyn {

Status WriteJsonFile(const std::string& path, const Json& json) {
  return WriteFileAtomic(path, json.dump(2, ' ', false, kJsonReplaceInvalidUtf8) + "\n");
}

}  // namespace facedyn
