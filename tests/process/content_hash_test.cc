// Input hashing: SHA-256 against the standard's test vector, content (not time) decides, the
// size-and-mtime cache spares re-reading, and folders hash their file names too.

#include "process/content_hash.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <utime.h>

#include <filesystem>

#include "tests/support/test_support.h"

namespace facedyn::process {
namespace {

using ::facedyn::testing::TempDir;
using ::facedyn::testing::WriteBytes;

TEST(ContentHash, FileDigestIsSha256) {
  TempDir dir;
  WriteBytes(dir.Join("abc"), "abc");
  FileHashCache cache;
  const auto sha = cache.FileSha256(dir.Join("abc"));
  ASSERT_TRUE(sha.ok());
  // FIPS 180-2, appendix B.1.
  EXPECT_EQ(*sha, "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(cache.bytes_read(), 3);
}

TEST(ContentHash, ContentDecidesNotTime) {
  TempDir dir;
  WriteBytes(dir.Join("in/a.bin"), "first");
  WriteBytes(dir.Join("in/sub/b.bin"), "second");
  FileHashCache cache;
  const auto h1 = HashInputs({dir.Join("in")}, {"cmd"}, &cache);
  ASSERT_TRUE(h1.ok()) << h1.status().ToString();

  // The cache (as a state file carries it) spares reading unchanged files.
  FileHashCache cached = FileHashCache::FromJson(cache.ToJson());
  const auto h2 = HashInputs({dir.Join("in")}, {"cmd"}, &cached);
  ASSERT_TRUE(h2.ok());
  EXPECT_EQ(*h2, *h1);
  EXPECT_EQ(cached.bytes_read(), 0);

  // Rewritten with the same bytes (new mtime): read again, same hash.
  WriteBytes(dir.Join("in/a.bin"), "first");
  struct utimbuf times = {1000000000, 1000000000};
  ASSERT_EQ(utime(dir.Join("in/a.bin").c_str(), &times), 0);
  FileHashCache again = FileHashCache::FromJson(cache.ToJson());
  const auto h3 = HashInputs({dir.Join("in")}, {"cmd"}, &again);
  ASSERT_TRUE(h3.ok());
  EXPECT_EQ(*h3, *h1);
  EXPECT_EQ(again.bytes_read(), 5);

  // Changed content, a renamed file, other command lines: different hashes.
  WriteBytes(dir.Join("in/a.bin"), "First");
  FileHashCache fresh;
  EXPECT_NE(*HashInputs({dir.Join("in")}, {"cmd"}, &fresh), *h1);
  WriteBytes(dir.Join("in/a.bin"), "first");
  EXPECT_EQ(*HashInputs({dir.Join("in")}, {"cmd"}, &fresh), *h1);
  EXPECT_NE(*HashInputs({dir.Join("in")}, {"cmd2"}, &fresh), *h1);
  std::filesystem::rename(dir.Join("in/sub/b.bin"), dir.Join("in/sub/c.bin"));
  EXPECT_NE(*HashInputs({dir.Join("in")}, {"cmd"}, &fresh), *h1);
}

TEST(ContentHash, PartsAreFramed) {
  EXPECT_NE(HashInputs({}, {"ab", "c"}, nullptr).value(),
            HashInputs({}, {"a", "bc"}, nullptr).value());
}

TEST(ContentHash, MissingInputIsNamed) {
  TempDir dir;
  FileHashCache cache;
  const auto h = HashInputs({dir.Join("nothing")}, {}, &cache);
  ASSERT_FALSE(h.ok());
  EXPECT_NE(h.status().message().find(dir.Join("nothing")), std::string::npos);
}

TEST(ContentHash, DamagedCacheEntriesAreIgnored) {
  const Json json = Json::parse(R"([{"path": "/x", "size": "big"}, 3, {"path": "/y", "size": 1,
    "mtime_ns": 2, "sha256": "ab"}])");
  const FileHashCache cache = FileHashCache::FromJson(json);
  EXPECT_EQ(cache.entries().size(), 1u);
  EXPECT_EQ(FileHashCache::FromJson(Json("nonsense")).entries().size(), 0u);
}

}  // namespace
}  // namespace facedyn::process
