// ConfigNode: read-only access to a YAML or JSON document whose errors name the file, the
// line and the field ("rig.yaml:12: field 'drive.max_hz': expected a number, got 'fast'").
//
// JSON is read through yaml-cpp too — JSON is YAML 1.2 flow syntax — because yaml-cpp keeps
// the line of every node and nlohmann-json does not. Writing JSON (take.json, --json output,
// metrics) uses nlohmann-json (core/json_io.h). A ConfigNode is a cheap handle: copies share
// the parsed document.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn {

class ConfigNode {
 public:
  // Reads and parses a YAML or JSON file; a syntax error names file, line and column.
  static StatusOr<ConfigNode> ReadFile(const std::string& path);
  // Parses text; `source_name` stands in for the file name in messages.
  static StatusOr<ConfigNode> Parse(const std::string& text, const std::string& source_name);

  bool IsMap() const { return node_.IsMap(); }
  bool IsSequence() const { return node_.IsSequence(); }
  bool IsScalar() const { return node_.IsScalar(); }
  bool IsNull() const { return !node_.IsDefined() || node_.IsNull(); }
  size_t size() const { return node_.size(); }

  bool Has(const std::string& key) const;
  std::vector<std::string> Keys() const;  // map keys in document order

  // A required child of a map; an error names the missing field.
  StatusOr<ConfigNode> Child(const std::string& key) const;
  // Element i of a sequence.
  StatusOr<ConfigNode> At(size_t index) const;

  // This node's value converted to T (double, float, int, int64_t, bool, std::string, or a
  // std::vector of those). Numbers must be plain (unquoted) scalars and finite.
  template <typename T>
  StatusOr<T> As() const;
  // Required field of a map.
  template <typename T>
  StatusOr<T> Get(const std::string& key) const;
  // Optional field: `fallback` when absent or null, an error when present but wrong.
  template <typename T>
  StatusOr<T> GetOr(const std::string& key, T fallback) const;
  // Required number within [min, max].
  StatusOr<double> GetInRange(const std::string& key, double min, double max) const;

  // OK when every key of this map is in `allowed`; otherwise an error naming the first unknown
  // field and the allowed ones (a misspelt option must not be silently ignored).
  Status CheckFields(const std::vector<std::string>& allowed) const;
  // "<source>:<line>: field '<path>.<key>': <message>" as an InvalidArgument status.
  Status Error(const std::string& key, const std::string& message) const;
  // Same, for this node itself.
  Status Error(const std::string& message) const;

  const std::string& source() const { return *source_; }
  int line() const { return node_.Mark().line + 1; }  // 1-based
  const std::string& field_path() const { return path_; }

  // The subtree as JSON (plain scalars become numbers, booleans or null where they parse so).
  Json ToJson() const;

 private:
  ConfigNode(std::shared_ptr<const std::string> source, YAML::Node node, std::string path)
      : source_(std::move(source)), node_(std::move(node)), path_(std::move(path)) {}
  std::string ChildPath(const std::string& key) const;

  std::shared_ptr<const std::string> source_;
  YAML::Node node_;
  std::string path_;
};

}  // namespace facedyn
