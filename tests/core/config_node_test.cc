// ConfigNode: typed access to YAML and JSON whose errors name file, line and field path.
#include "core/config_node.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cstdint>
#include <string>
#include <vector>

#include "tests/support/test_support.h"

namespace facedyn {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;
using ::testing::AllOf;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

// Line numbers below refer to this document (1-based).
constexpr char kRigYaml[] =
    "name: bench rig\n"               // 1
    "drive:\n"                        // 2
    "  profile: sim\n"                // 3
    "  max_hz: 11.5\n"                // 4
    "  min_hz: fast\n"                // 5
    "  slave_id: 7\n"                 // 6
    "  enabled: true\n"               // 7
    "  quoted_hz: \"9\"\n"            // 8
    "  single: '10'\n"                // 9
    "  nothing: ~\n"                  // 10
    "frequencies_hz: [6, 7.5, 11]\n"  // 11
    "labels:\n"                       // 12
    "  - left\n"                      // 13
    "  - right\n"                     // 14
    "cameras:\n"                      // 15
    "  - serial: 1234\n"              // 16
    "    exposure_us: 800\n"          // 17
    "  - serial: 5678\n"              // 18
    "    exposure_us: long\n"         // 19
    "big: 3000000000\n"               // 20
    "not_finite: nan\n"               // 21
    "fraction: 2.5\n";                // 22

ConfigNode ParseOrDie(const std::string& text, const std::string& source = "rig.yaml") {
  auto parsed = ConfigNode::Parse(text, source);
  EXPECT_TRUE(parsed.ok()) << parsed.status().message();
  return parsed.ok() ? *parsed : *ConfigNode::Parse("{}", source);
}

TEST(ConfigNodeParse, YamlStructure) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  EXPECT_TRUE(root.IsMap());
  EXPECT_EQ(root.source(), "rig.yaml");
  EXPECT_EQ(root.line(), 1);
  EXPECT_EQ(root.field_path(), "");
  EXPECT_THAT(root.Keys(), ElementsAre("name", "drive", "frequencies_hz", "labels", "cameras",
                                       "big", "not_finite", "fraction"));
  EXPECT_TRUE(root.Has("drive"));
  EXPECT_FALSE(root.Has("missing"));
  const auto drive = root.Child("drive");
  ASSERT_TRUE(drive.ok());
  EXPECT_TRUE(drive->IsMap());
  EXPECT_EQ(drive->field_path(), "drive");
  EXPECT_EQ(drive->line(), 3);
  EXPECT_FALSE(drive->Has("nothing"));  // null counts as absent
  const auto cameras = root.Child("cameras");
  ASSERT_TRUE(cameras.ok());
  EXPECT_TRUE(cameras->IsSequence());
  EXPECT_EQ(cameras->size(), 2u);
  const auto name = root.Child("name");
  ASSERT_TRUE(name.ok());
  EXPECT_TRUE(name->IsScalar());
}

TEST(ConfigNodeParse, Json) {
  const std::string json =
      "{\n"
      "  \"fps\": 128,\n"
      "  \"units\": \"mm\",\n"
      "  \"platform_hz\": null,\n"
      "  \"channels\": [\"quasistatic\", \"dynamic_offset\"],\n"
      "  \"metadata\": {\"seed\": 3, \"ok\": false}\n"
      "}\n";
  const ConfigNode root = ParseOrDie(json, "take.json");
  EXPECT_EQ(*root.Get<int>("fps"), 128);
  EXPECT_EQ(*root.Get<double>("fps"), 128.0);
  EXPECT_EQ(*root.Get<std::string>("units"), "mm");
  EXPECT_FALSE(root.Has("platform_hz"));
  EXPECT_THAT(*root.Get<std::vector<std::string>>("channels"),
              ElementsAre("quasistatic", "dynamic_offset"));
  const auto metadata = root.Child("metadata");
  ASSERT_TRUE(metadata.ok());
  EXPECT_EQ(*metadata->Get<int>("seed"), 3);
  EXPECT_EQ(*metadata->Get<bool>("ok"), false);
  EXPECT_EQ(metadata->line(), 6);
  // JSON strings are quoted scalars: "mm" is a string, never a number.
  const auto units = root.Child("units");
  ASSERT_TRUE(units.ok());
  EXPECT_FALSE(units->As<double>().ok());
}

TEST(ConfigNodeParse, JsonSyntaxErrorNamesLineAndColumn) {
  const auto parsed =
      ConfigNode::Parse("{\n  \"a\": 1,\n  \"b\": 2,\n  \"c\": 3]\n}\n", "take.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(parsed.status().message(), HasSubstr("take.json:4:9: syntax error"));
}

TEST(ConfigNodeParse, YamlSyntaxErrorNamesLine) {
  const auto parsed = ConfigNode::Parse("a: 1\nb:\n  c: 2\n d: 3\n", "rig.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), HasSubstr("rig.yaml:4:"));
  EXPECT_THAT(parsed.status().message(), HasSubstr("syntax error"));
}

TEST(ConfigNodeReadFile, ReadsAndNamesTheFile) {
  TempDir dir;
  const std::string path = dir.Join("sweep.yaml");
  WriteBytes(path, "hz: [6, 7]\nseconds: 2\n");
  const auto read = ConfigNode::ReadFile(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->source(), path);
  EXPECT_THAT(*read->Get<std::vector<double>>("hz"), ElementsAre(6.0, 7.0));
  EXPECT_THAT(read->Get<std::string>("missing").status().message(), HasSubstr(path + ":1:"));

  WriteBytes(path, "hz: [6, 7\nseconds: 2\n");
  const auto bad = ConfigNode::ReadFile(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.status().message(), AllOf(HasSubstr(path + ":2:"), HasSubstr("syntax error")));
}

TEST(ConfigNodeReadFile, MissingFile) {
  TempDir dir;
  const auto read = ConfigNode::ReadFile(dir.Join("absent.yaml"));
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(read.status().message(), HasSubstr(dir.Join("absent.yaml")));
}

TEST(ConfigNodeGet, TypedScalars) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  const ConfigNode drive = *root.Child("drive");
  EXPECT_EQ(*root.Get<std::string>("name"), "bench rig");
  EXPECT_DOUBLE_EQ(*drive.Get<double>("max_hz"), 11.5);
  EXPECT_FLOAT_EQ(*drive.Get<float>("max_hz"), 11.5f);
  EXPECT_EQ(*drive.Get<int>("slave_id"), 7);
  EXPECT_EQ(*drive.Get<int64_t>("slave_id"), 7);
  EXPECT_EQ(*drive.Get<double>("slave_id"), 7.0);  // an integer is also a number
  EXPECT_EQ(*drive.Get<bool>("enabled"), true);
  EXPECT_EQ(*drive.Get<std::string>("slave_id"), "7");  // any scalar reads as a string
  EXPECT_EQ(*root.Get<int64_t>("big"), 3000000000LL);
}

TEST(ConfigNodeGet, Vectors) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  EXPECT_THAT(*root.Get<std::vector<double>>("frequencies_hz"), ElementsAre(6.0, 7.5, 11.0));
  EXPECT_THAT(*root.Get<std::vector<std::string>>("labels"), ElementsAre("left", "right"));
  const auto ints = root.Get<std::vector<int>>("frequencies_hz");
  ASSERT_FALSE(ints.ok());
  EXPECT_THAT(ints.status().message(),
              AllOf(HasSubstr("rig.yaml:11:"), HasSubstr("field 'frequencies_hz'"),
                    HasSubstr("entry 1: expected an integer, got '7.5'")));
  const auto not_a_list = root.Get<std::vector<double>>("fraction");
  ASSERT_FALSE(not_a_list.ok());
  EXPECT_THAT(not_a_list.status().message(),
              AllOf(HasSubstr("field 'fraction'"), HasSubstr("expected a list, got '2.5'")));
}

TEST(ConfigNodeGet, QuotedNumberIsNotANumber) {
  const ConfigNode drive = *ParseOrDie(kRigYaml).Child("drive");
  const auto quoted = drive.Get<double>("quoted_hz");
  ASSERT_FALSE(quoted.ok());
  EXPECT_EQ(quoted.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(quoted.status().message(),
              AllOf(HasSubstr("rig.yaml:8:"), HasSubstr("field 'drive.quoted_hz'"),
                    HasSubstr("expected a number, got '9'")));
  EXPECT_FALSE(drive.Get<int>("single").ok());
  EXPECT_EQ(*drive.Get<std::string>("quoted_hz"), "9");
  const ConfigNode quoted_bool = ParseOrDie("flag: \"true\"\n");
  EXPECT_FALSE(quoted_bool.Get<bool>("flag").ok());
}

TEST(ConfigNodeGet, WrongTypeNamesFieldLineAndValue) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  const ConfigNode drive = *root.Child("drive");
  const auto fast = drive.Get<double>("min_hz");
  ASSERT_FALSE(fast.ok());
  EXPECT_EQ(fast.status().message(),
            "rig.yaml:5: field 'drive.min_hz': expected a number, got 'fast'");
  EXPECT_THAT(drive.Get<bool>("profile").status().message(),
              AllOf(HasSubstr("rig.yaml:3:"), HasSubstr("expected true or false, got 'sim'")));
  EXPECT_THAT(root.Get<int>("fraction").status().message(),
              AllOf(HasSubstr("rig.yaml:22:"), HasSubstr("expected an integer, got '2.5'")));
  EXPECT_THAT(root.Get<int>("big").status().message(),
              HasSubstr("expected an integer, got '3000000000'"));
  EXPECT_THAT(root.Get<double>("not_finite").status().message(),
              HasSubstr("expected a number, got 'nan'"));
  EXPECT_THAT(root.Get<double>("drive").status().message(),
              HasSubstr("expected a number, got a map"));
  EXPECT_THAT(root.Get<std::string>("labels").status().message(),
              HasSubstr("expected a string, got a list"));
  EXPECT_FALSE(ParseOrDie("answer: yes\n").Get<bool>("answer").ok());  // YAML 1.1 booleans are not
}

TEST(ConfigNodeGet, MissingRequiredFieldNamesPathAndLine) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  const auto missing = root.Get<double>("seconds");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().message(), "rig.yaml:1: field 'seconds': required field is missing");
  const ConfigNode drive = *root.Child("drive");
  EXPECT_EQ(drive.Get<int>("port").status().message(),
            "rig.yaml:3: field 'drive.port': required field is missing");
  // A null value is as good as missing for a required field.
  EXPECT_THAT(drive.Get<std::string>("nothing").status().message(),
              AllOf(HasSubstr("field 'drive.nothing'"), HasSubstr("required field is missing")));
}

TEST(ConfigNodeGetOr, FallbackWhenAbsentOrNull) {
  const ConfigNode drive = *ParseOrDie(kRigYaml).Child("drive");
  EXPECT_EQ(*drive.GetOr<double>("absent_hz", 8.0), 8.0);
  EXPECT_EQ(*drive.GetOr<std::string>("nothing", "default"), "default");
  EXPECT_EQ(*drive.GetOr<double>("max_hz", 8.0), 11.5);
  EXPECT_EQ(*drive.GetOr<std::vector<int>>("absent", {1, 2}), (std::vector<int>{1, 2}));
}

TEST(ConfigNodeGetOr, WrongTypeIsAnErrorNotTheFallback) {
  const ConfigNode drive = *ParseOrDie(kRigYaml).Child("drive");
  const auto fast = drive.GetOr<double>("min_hz", 6.0);
  ASSERT_FALSE(fast.ok());
  EXPECT_THAT(fast.status().message(),
              AllOf(HasSubstr("rig.yaml:5:"), HasSubstr("field 'drive.min_hz'")));
  EXPECT_FALSE(drive.GetOr<int>("quoted_hz", 1).ok());
}

TEST(ConfigNodeGetInRange, BoundsAreInclusive) {
  const ConfigNode drive = *ParseOrDie(kRigYaml).Child("drive");
  EXPECT_EQ(*drive.GetInRange("max_hz", 6.0, 11.5), 11.5);
  EXPECT_EQ(*drive.GetInRange("max_hz", 11.5, 20.0), 11.5);
  const auto high = drive.GetInRange("max_hz", 6.0, 11.0);
  ASSERT_FALSE(high.ok());
  EXPECT_EQ(high.status().message(),
            "rig.yaml:4: field 'drive.max_hz': 11.5 is outside the allowed range [6, 11]");
  EXPECT_THAT(drive.GetInRange("min_hz", 0, 1).status().message(), HasSubstr("expected a number"));
  EXPECT_THAT(drive.GetInRange("absent", 0, 1).status().message(),
              HasSubstr("required field is missing"));
}

TEST(ConfigNodeChild, NestedPathsInMessages) {
  const ConfigNode root = ParseOrDie("a:\n  b:\n    c: 1\n    d: x\n");
  const auto b = root.Child("a").value().Child("b");
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->field_path(), "a.b");
  EXPECT_EQ(b->Get<int>("d").status().message(),
            "rig.yaml:4: field 'a.b.d': expected an integer, got 'x'");
  EXPECT_EQ(b->Child("e").status().message(),
            "rig.yaml:3: field 'a.b.e': required field is missing");
  // Child of a scalar.
  const auto c = b->Child("c");
  ASSERT_TRUE(c.ok());
  EXPECT_THAT(
      c->Child("deeper").status().message(),
      AllOf(HasSubstr("field 'a.b.c'"), HasSubstr("expected a map with field 'deeper', got '1'")));
  EXPECT_THAT(b->Error("custom problem").message(),
              HasSubstr("rig.yaml:3: field 'a.b': custom problem"));
  EXPECT_EQ(root.Error("top level").message(), "rig.yaml:1: top level");
}

TEST(ConfigNodeAt, IndexesSequencesAndNamesElements) {
  const ConfigNode root = ParseOrDie(kRigYaml);
  const ConfigNode cameras = *root.Child("cameras");
  const auto second = cameras.At(1);
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->field_path(), "cameras[1]");
  EXPECT_EQ(*second->Get<int>("serial"), 5678);
  EXPECT_EQ(second->Get<int>("exposure_us").status().message(),
            "rig.yaml:19: field 'cameras[1].exposure_us': expected an integer, got 'long'");
  const auto out_of_range = cameras.At(2);
  ASSERT_FALSE(out_of_range.ok());
  EXPECT_THAT(
      out_of_range.status().message(),
      AllOf(HasSubstr("field 'cameras'"), HasSubstr("index 2 out of range (list has 2 entries)")));
  const auto not_a_list = root.Child("drive")->At(0);
  ASSERT_FALSE(not_a_list.ok());
  EXPECT_THAT(not_a_list.status().message(),
              AllOf(HasSubstr("field 'drive'"), HasSubstr("expected a list, got a map")));
}

TEST(ConfigNodeToJson, ConvertsScalarsByContent) {
  const ConfigNode root = ParseOrDie(
      "int: 42\n"
      "negative: -7\n"
      "real: 2.5\n"
      "exp: 1e3\n"
      "yes_no: true\n"
      "null_value: ~\n"
      "word: hello\n"
      "quoted_number: \"12\"\n"
      "list: [1, two, 3.5, false]\n"
      "nested: {a: {b: [ ]}}\n");
  const Json expected = Json::parse(R"({
      "int": 42, "negative": -7, "real": 2.5, "exp": 1000.0, "yes_no": true, "null_value": null,
      "word": "hello", "quoted_number": "12", "list": [1, "two", 3.5, false],
      "nested": {"a": {"b": []}}})");
  const Json json = root.ToJson();
  EXPECT_EQ(json, expected) << json.dump();
  EXPECT_TRUE(json.at("int").is_number_integer());
  EXPECT_TRUE(json.at("real").is_number_float());
  EXPECT_TRUE(json.at("quoted_number").is_string());
  // Key order is the document's.
  std::vector<std::string> keys;
  for (const auto& item : json.items()) keys.push_back(item.key());
  EXPECT_THAT(keys, ElementsAre("int", "negative", "real", "exp", "yes_no", "null_value", "word",
                                "quoted_number", "list", "nested"));
}

TEST(ConfigNodeToJson, SubtreeOnly) {
  const ConfigNode cameras = *ParseOrDie(kRigYaml).Child("cameras");
  EXPECT_EQ(cameras.ToJson(), Json::parse(R"([{"serial": 1234, "exposure_us": 800},
                                              {"serial": 5678, "exposure_us": "long"}])"));
}

// Issue 18, item 7: yaml-cpp keeps the first of two equal keys, so `max_hz: 11` then
// `max_hz: 8` silently meant 11. Both lines are named.
TEST(ConfigNodeParse, DuplicateKeyIsAnErrorNamingBothLines) {
  auto parsed = ConfigNode::Parse("limits:\n  max_hz: 11\n  min_hz: 6\n  max_hz: 8\n", "rig.yaml");
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), HasSubstr("rig.yaml:4:"));
  EXPECT_THAT(parsed.status().message(), HasSubstr("duplicate key 'max_hz' (first on line 2)"));
  // The same key in two different maps is fine.
  EXPECT_TRUE(ConfigNode::Parse("a: {x: 1}\nb: {x: 2}\nc: [{x: 1}, {x: 2}]\n", "ok.yaml").ok());
}

TEST(ConfigNodeParse, DuplicateKeyInJsonIsAnError) {
  auto parsed = ConfigNode::Parse("{\"fps\": 128,\n \"fps\": 64}", "take.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_THAT(parsed.status().message(), HasSubstr("duplicate key 'fps'"));
}

// A self-referential alias segfaulted yaml-cpp's builder; nested anchors ("billion laughs")
// took 2.6 GB. Aliases are refused before anything is built.
TEST(ConfigNodeParse, AliasesAreRefused) {
  auto self = ConfigNode::Parse("a: &x [*x]\n", "take.json");
  ASSERT_FALSE(self.ok());
  EXPECT_THAT(self.status().message(), HasSubstr("aliases"));
  std::string laughs = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n";
  for (int i = 1; i < 12; ++i) {
    laughs += fmt::format("a{}: &a{} [", i, i);
    for (int k = 0; k < 10; ++k) laughs += fmt::format("{}*a{}", k ? ", " : "", i - 1);
    laughs += "]\n";
  }
  auto nested = ConfigNode::Parse(laughs, "bomb.yaml");
  ASSERT_FALSE(nested.ok());
  EXPECT_THAT(nested.status().message(), HasSubstr("bomb.yaml:2:"));
}

// yaml-cpp 0.7 never returns on a ',' where a block node is expected: it emits null nodes and
// allocates until memory runs out (fuzz/take_json). Each of these is now a syntax error naming
// the file and line, returned at once.
TEST(ConfigNodeParse, CommaOutsideBracketsIsASyntaxErrorNotAHang) {
  for (const char* text : {",", " ,\n", "- 1\n,\n", "'a' ,", "# comment\n\"a\" ,\n"}) {
    SCOPED_TRACE(text);
    const auto parsed = ConfigNode::Parse(text, "take.json");
    ASSERT_FALSE(parsed.ok());
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(parsed.status().message(), HasSubstr("take.json:"));
    EXPECT_THAT(parsed.status().message(), HasSubstr("makes no progress"));
  }
  // Commas where YAML allows them still parse.
  const auto fine = ConfigNode::Parse("a: [1, 2]\nb: {c: 3, d: 4}\ne: x, y\n", "ok.yaml");
  ASSERT_TRUE(fine.ok()) << fine.status().message();
  EXPECT_EQ(*fine->Get<std::string>("e"), "x, y");
}

// Strings reach JSON reports, which must be UTF-8: an invalid byte in a capture.json made
// `session check --json` throw nlohmann's type_error.316 (fuzz/session_json). It is refused
// where it is read, with the line, in values and in keys, in JSON and in YAML.
TEST(ConfigNodeParse, InvalidUtf8IsAnErrorNamingTheLine) {
  for (const std::string& text :
       {std::string("{\"name\": \"t1\",\n \"status\": \"complet\xe5\"}"),
        std::string("name: t1\nstatus: \xc0\xaf\n"), std::string("ok: 1\n\xed\xa0\x80: 2\n")}) {
    SCOPED_TRACE(text);
    const auto parsed = ConfigNode::Parse(text, "capture.json");
    ASSERT_FALSE(parsed.ok());
    EXPECT_EQ(parsed.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(parsed.status().message(), HasSubstr("capture.json:2:"));
    EXPECT_THAT(parsed.status().message(), HasSubstr("not valid UTF-8"));
  }
  const auto fine = ConfigNode::Parse("name: caf\xc3\xa9 \xf0\x9f\x98\x80\n", "ok.yaml");
  ASSERT_TRUE(fine.ok()) << fine.status().message();
  EXPECT_EQ(*fine->Get<std::string>("name"), "caf\xc3\xa9 \xf0\x9f\x98\x80");
}

}  // namespace
}  // namespace facedyn
