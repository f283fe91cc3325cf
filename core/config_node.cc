#include "core/config_node.h"

#include <fmt/format.h>
#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/parser.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <type_traits>
#include <vector>

#include "core/file_util.h"
#include "core/utf8.h"

namespace facedyn {
namespace {

std::string Describe(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "null";
  if (node.IsMap()) return "a map";
  if (node.IsSequence()) return "a list";
  return "'" + node.Scalar() + "'";
}

// A quoted scalar (tag "!") is a string even when it looks like a number.
bool IsPlainScalar(const YAML::Node& node) { return node.IsScalar() && node.Tag() != "!"; }

template <typename T>
bool ConvertScalar(const YAML::Node& node, T* out, std::string* expected) {
  if constexpr (std::is_same_v<T, std::string>) {
    *expected = "a string";
    if (!node.IsScalar()) return false;
    *out = node.Scalar();
    return true;
  } else if constexpr (std::is_same_v<T, bool>) {
    *expected = "true or false";
    if (!IsPlainScalar(node)) return false;
    const std::string& s = node.Scalar();
    if (s == "true")
      *out = true;
    else if (s == "false")
      *out = false;
    else
      return false;
    return true;
  } else if constexpr (std::is_floating_point_v<T>) {
    *expected = "a number";
    if (!IsPlainScalar(node)) return false;
    try {
      size_t used = 0;
      const double value = std::stod(node.Scalar(), &used);
      if (used != node.Scalar().size() || !std::isfinite(value)) return false;
      *out = static_cast<T>(value);
      return true;
    } catch (const std::exception&) {
      return false;
    }
  } else {
    static_assert(std::is_integral_v<T>);
    *expected = "an integer";
    if (!IsPlainScalar(node)) return false;
    try {
      size_t used = 0;
      const long long value = std::stoll(node.Scalar(), &used);
      if (used != node.Scalar().size()) return false;
      if (value < static_cast<long long>(std::numeric_limits<T>::min()) ||
          value > static_cast<long long>(std::numeric_limits<T>::max())) {
        return false;
      }
      *out = static_cast<T>(value);
      return true;
    } catch (const std::exception&) {
      return false;
    }
  }
}

template <typename T>
struct IsVector : std::false_type {};
template <typename T>
struct IsVector<std::vector<T>> : std::true_type {};

// A pass over the parser's events before the document is built, for what yaml-cpp accepts
// silently but a config must not: a key given twice in one map (yaml-cpp keeps the first, so
// `max_hz: 11` then `max_hz: 8` meant 11) and aliases (`*name`), which make self-referential or
// exponentially nested documents (a "billion laughs") that crash or exhaust the builder. No
// shipped config uses anchors; refusing aliases costs nothing.
//
// It also bounds the number of events by the length of the text: yaml-cpp 0.7 never returns on a
// ',' outside brackets where a block node is expected (a document "," or "- 1\n,", or "'a' ,"),
// emitting null nodes and allocating until memory runs out (found by fuzz/take_json). Every
// event of a real document consumes at least a character or so (a key and its null value take
// "a:"), so more than 4 events per byte means the parser is not progressing; the pass then
// stops with an error naming the line.
class StrictYamlCheck : public YAML::EventHandler {
 public:
  explicit StrictYamlCheck(size_t text_bytes) : max_events_(4 * text_bytes + 16) {}

  // Thrown out of the parser when the event budget is spent (the parser would not return).
  struct NotProgressing {};

  std::string error;  // first problem, "line:column: message"

  void OnDocumentStart(const YAML::Mark& mark) override { Count(mark); }
  void OnDocumentEnd() override { Count(last_mark_); }
  void OnNull(const YAML::Mark& mark, YAML::anchor_t) override {
    Count(mark);
    Value(mark, nullptr);
  }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t) override {
    Count(mark);
    Fail(mark, "aliases (*name) are not supported in facedyn configs; write the value out");
    Value(mark, nullptr);
  }
  void OnScalar(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                const std::string& value) override {
    Count(mark);
    if (!IsValidUtf8(value)) {
      Fail(mark, "a string here is not valid UTF-8 (facedyn files are UTF-8 text)");
    }
    Value(mark, &value);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {
    Count(mark);
    Value(mark, nullptr);
    Push(mark, false);
  }
  void OnSequenceEnd() override {
    Count(last_mark_);
    Pop();
  }
  void OnMapStart(const YAML::Mark& mark, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {
    Count(mark);
    Value(mark, nullptr);
    Push(mark, true);
  }
  void OnMapEnd() override {
    Count(last_mark_);
    Pop();
  }

 private:
  void Count(const YAML::Mark& mark) {
    last_mark_ = mark;
    if (++events_ <= max_events_) return;
    Fail(mark, "syntax error: the YAML parser makes no progress here (a ',' outside [ ] or { }?)");
    throw NotProgressing{};
  }

  size_t events_ = 0;
  size_t max_events_;
  YAML::Mark last_mark_;

  struct Container {
    bool is_map = false;
    bool expecting_key = true;
    std::map<std::string, int> key_lines;  // key -> 1-based line
  };

  void Fail(const YAML::Mark& mark, const std::string& message) {
    if (error.empty()) error = fmt::format("{}:{}: {}", mark.line + 1, mark.column + 1, message);
  }
  // Called for every node as it starts; in a map, alternate nodes are keys.
  void Value(const YAML::Mark& mark, const std::string* scalar) {
    if (stack_.empty() || !stack_.back().is_map) return;
    Container& map = stack_.back();
    const bool is_key = map.expecting_key;
    map.expecting_key = !map.expecting_key;
    if (!is_key || scalar == nullptr) return;
    const auto [it, inserted] = map.key_lines.emplace(*scalar, mark.line + 1);
    if (!inserted) {
      Fail(mark,
           fmt::format("duplicate key '{}' (first on line {}): say it once", *scalar, it->second));
    }
  }
  void Push(const YAML::Mark&, bool is_map) {
    stack_.emplace_back();
    stack_.back().is_map = is_map;
  }
  void Pop() {
    if (!stack_.empty()) stack_.pop_back();
  }

  std::vector<Container> stack_;
};

}  // namespace

StatusOr<ConfigNode> ConfigNode::ReadFile(const std::string& path) {
  FACEDYN_ASSIGN_OR_RETURN(std::string text, ReadFileToString(path));
  return Parse(text, path);
}

StatusOr<ConfigNode> ConfigNode::Parse(const std::string& text, const std::string& source_name) {
  try {
    {
      std::istringstream stream(text);
      YAML::Parser parser(stream);
      StrictYamlCheck check(text.size());
      try {
        while (parser.HandleNextDocument(check) && check.error.empty()) {
        }
      } catch (const StrictYamlCheck::NotProgressing&) {
        // check.error says where.
      }
      if (!check.error.empty())
        return InvalidArgumentError(fmt::format("{}:{}", source_name, check.error));
    }
    YAML::Node root = YAML::Load(text);
    return ConfigNode(std::make_shared<const std::string>(source_name), root, "");
  } catch (const YAML::Exception& e) {
    // yaml-cpp's message can quote the offending byte ("unknown escape character: \xd3").
    return InvalidArgumentError(fmt::format("{}:{}:{}: syntax error: {}", source_name,
                                            e.mark.line + 1, e.mark.column + 1,
                                            EscapeInvalidUtf8(e.msg)));
  }
}

bool ConfigNode::Has(const std::string& key) const {
  return node_.IsMap() && node_[key].IsDefined() && !node_[key].IsNull();
}

std::vector<std::string> ConfigNode::Keys() const {
  std::vector<std::string> keys;
  if (!node_.IsMap()) return keys;
  for (const auto& item : node_) keys.push_back(item.first.Scalar());
  return keys;
}

std::string ConfigNode::ChildPath(const std::string& key) const {
  return path_.empty() ? key : path_ + "." + key;
}

StatusOr<ConfigNode> ConfigNode::Child(const std::string& key) const {
  if (!node_.IsMap())
    return Error(fmt::format("expected a map with field '{}', got {}", key, Describe(node_)));
  const YAML::Node child = node_[key];
  if (!child.IsDefined() || child.IsNull()) return Error(key, "required field is missing");
  return ConfigNode(source_, child, ChildPath(key));
}

StatusOr<ConfigNode> ConfigNode::At(size_t index) const {
  if (!node_.IsSequence()) return Error("expected a list, got " + Describe(node_));
  if (index >= node_.size()) {
    return Error(fmt::format("index {} out of range (list has {} entries)", index, node_.size()));
  }
  return ConfigNode(source_, node_[index], fmt::format("{}[{}]", path_, index));
}

template <typename T>
StatusOr<T> ConfigNode::As() const {
  T value{};
  std::string expected;
  if constexpr (IsVector<T>::value) {
    if (!node_.IsSequence()) return Error("expected a list, got " + Describe(node_));
    for (size_t i = 0; i < node_.size(); ++i) {
      typename T::value_type element{};
      if (!ConvertScalar(node_[i], &element, &expected)) {
        return Error(fmt::format("entry {}: expected {}, got {}", i, expected, Describe(node_[i])));
      }
      value.push_back(element);
    }
    return value;
  } else {
    if (!ConvertScalar(node_, &value, &expected)) {
      return Error(fmt::format("expected {}, got {}", expected, Describe(node_)));
    }
    return value;
  }
}

template <typename T>
StatusOr<T> ConfigNode::Get(const std::string& key) const {
  FACEDYN_ASSIGN_OR_RETURN(ConfigNode child, Child(key));
  return child.As<T>();
}

template <typename T>
StatusOr<T> ConfigNode::GetOr(const std::string& key, T fallback) const {
  if (!Has(key)) return fallback;
  return Get<T>(key);
}

StatusOr<double> ConfigNode::GetInRange(const std::string& key, double min, double max) const {
  FACEDYN_ASSIGN_OR_RETURN(double value, Get<double>(key));
  if (value < min || value > max) {
    return Error(key, fmt::format("{} is outside the allowed range [{}, {}]", value, min, max));
  }
  return value;
}

Status ConfigNode::CheckFields(const std::vector<std::string>& allowed) const {
  for (const std::string& key : Keys()) {
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) {
      std::string list;
      for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
      return Error(key, "unknown field (allowed: " + list + ")");
    }
  }
  return Status::Ok();
}

Status ConfigNode::Error(const std::string& key, const std::string& message) const {
  const YAML::Node child = node_.IsMap() ? node_[key] : YAML::Node();
  const int at_line = child.IsDefined() ? child.Mark().line + 1 : line();
  return InvalidArgumentError(
      fmt::format("{}:{}: field '{}': {}", *source_, at_line, ChildPath(key), message));
}

Status ConfigNode::Error(const std::string& message) const {
  if (path_.empty())
    return InvalidArgumentError(fmt::format("{}:{}: {}", *source_, line(), message));
  return InvalidArgumentError(
      fmt::format("{}:{}: field '{}': {}", *source_, line(), path_, message));
}

Json ConfigNode::ToJson() const {
  if (node_.IsMap()) {
    Json object = Json::object();
    for (const auto& item : node_) {
      object[item.first.Scalar()] =
          ConfigNode(source_, item.second, ChildPath(item.first.Scalar())).ToJson();
    }
    return object;
  }
  if (node_.IsSequence()) {
    Json array = Json::array();
    for (size_t i = 0; i < node_.size(); ++i)
      array.push_back(ConfigNode(source_, node_[i], "").ToJson());
    return array;
  }
  if (!node_.IsDefined() || node_.IsNull()) return nullptr;
  std::string unused;
  if (IsPlainScalar(node_)) {
    bool b;
    long long i;
    double d;
    if (ConvertScalar(node_, &b, &unused)) return b;
    if (ConvertScalar(node_, &i, &unused)) return i;
    if (ConvertScalar(node_, &d, &unused)) return d;
  }
  return node_.Scalar();
}

#define FACEDYN_INSTANTIATE(T)                                       \
  template StatusOr<T> ConfigNode::As<T>() const;                    \
  template StatusOr<T> ConfigNode::Get<T>(const std::string&) const; \
  template StatusOr<T> ConfigNode::GetOr<T>(const std::string&, T) const;
FACEDYN_INSTANTIATE(double)
FACEDYN_INSTANTIATE(float)
FACEDYN_INSTANTIATE(int)
FACEDYN_INSTANTIATE(int64_t)
FACEDYN_INSTANTIATE(bool)
FACEDYN_INSTANTIATE(std::string)
FACEDYN_INSTANTIATE(std::vector<double>)
FACEDYN_INSTANTIATE(std::vector<int>)
FACEDYN_INSTANTIATE(std::vector<std::string>)
#undef FACEDYN_INSTANTIATE

}  // namespace facedyn
