// Writing JSON: pretty, key order kept, atomically replaced on disk. Reading goes through
// ConfigNode (core/config_node.h) so errors can name lines.
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "core/status.h"

namespace facedyn {

using Json = nlohmann::ordered_json;

// Pass to every dump(): text facedyn read is checked for UTF-8 where it enters (core/utf8.h), and
// this makes a byte that slipped past come out as U+FFFD instead of throwing type_error.316 in
// the middle of writing a report or a log record.
inline constexpr Json::error_handler_t kJsonReplaceInvalidUtf8 = Json::error_handler_t::replace;

Status WriteJsonFile(const std::string& path, const Json& json);

}  // namespace facedyn
