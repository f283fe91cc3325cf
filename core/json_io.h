// Writing JSON: pretty, key order kept, atomically replaced on disk. Reading goes through
// ConfigNode (core/config_node.h) so errors can name lines.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "core/status.h"

namespace facedyn {

using Json = nlohmann::ordered_json;

Status WriteJsonFile(const std::string& path, const Json& json);

}  // namespace facedyn
