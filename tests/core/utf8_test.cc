// IsValidUtf8 against Unicode's table 3-7 and JSON dumping of a byte that slipped past.
#include "core/utf8.h"

#include <gtest/gtest.h>

#include <string>

#include "core/json_io.h"

namespace facedyn {
namespace {

TEST(IsValidUtf8, AcceptsWellFormedText) {
  EXPECT_TRUE(IsValidUtf8(""));
  EXPECT_TRUE(IsValidUtf8("plain ASCII, 0-9"));
  EXPECT_TRUE(IsValidUtf8("caf\xC3\xA9"));                   // U+00E9
  EXPECT_TRUE(IsValidUtf8("\xE2\x82\xAC"));                  // U+20AC
  EXPECT_TRUE(IsValidUtf8("\xED\x9F\xBF"));                  // U+D7FF, last before surrogates
  EXPECT_TRUE(IsValidUtf8("\xEE\x80\x80"));                  // U+E000, first after them
  EXPECT_TRUE(IsValidUtf8("\xF0\x9F\x98\x80"));              // U+1F600
  EXPECT_TRUE(IsValidUtf8("\xF4\x8F\xBF\xBF"));              // U+10FFFF
  EXPECT_TRUE(IsValidUtf8(std::string("nul\0inside", 10)));  // U+0000 is a character
}

TEST(IsValidUtf8, RejectsIllFormedSequencesAndSaysWhere) {
  struct Case {
    std::string text;
    size_t offset;
  };
  const Case cases[] = {
      {"complet\xE5", 7},       // lead byte at the end (the fuzz finding)
      {"ab\x80", 2},            // lone continuation byte
      {"\xC0\xAF", 0},          // overlong '/'
      {"\xC1\xBF", 0},          // overlong
      {"\xE0\x80\xAF", 0},      // overlong 3-byte
      {"\xED\xA0\x80", 0},      // surrogate U+D800
      {"\xF0\x80\x80\xAF", 0},  // overlong 4-byte
      {"\xF4\x90\x80\x80", 0},  // U+110000
      {"\xF5\x80\x80\x80", 0},  // lead beyond F4
      {"x\xE2\x82", 1},         // truncated 3-byte
      {"x\xE2\x28\xA1", 1},     // bad second byte
      {"\xF0\x9F\x98\x28", 0},  // bad fourth byte
      {"\xFF", 0},
  };
  for (const Case& c : cases) {
    size_t offset = 999;
    EXPECT_FALSE(IsValidUtf8(c.text, &offset)) << c.text;
    EXPECT_EQ(offset, c.offset) << c.text;
  }
}

TEST(EscapeInvalidUtf8, WritesIllFormedBytesAsHexAndKeepsTheRest) {
  EXPECT_EQ(EscapeInvalidUtf8("plain caf\xC3\xA9"), "plain caf\xC3\xA9");
  EXPECT_EQ(EscapeInvalidUtf8("escape: \xD3 end"), "escape: \\xd3 end");
  EXPECT_EQ(EscapeInvalidUtf8("\xFF\xFE\xE2\x82"), "\\xff\\xfe\\xe2\\x82");
  EXPECT_TRUE(IsValidUtf8(EscapeInvalidUtf8("\xC0\xAF\xED\xA0\x80ok")));
}

TEST(JsonDump, AByteThatSlippedPastComesOutAsReplacementNotAThrow) {
  const Json json = {{"status", std::string("complet\xE5")}};
  EXPECT_THROW((void)json.dump(), Json::type_error);  // why every dump passes the handler
  const std::string text = json.dump(-1, ' ', false, kJsonReplaceInvalidUtf8);
  EXPECT_EQ(text, "{\"status\":\"complet\xEF\xBF\xBD\"}");
  EXPECT_TRUE(IsValidUtf8(text));
}

}  // namespace
}  // namespace facedyn
