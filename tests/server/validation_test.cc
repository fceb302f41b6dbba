// Request validation (server/validation.h): names, paths kept inside their root, bodies, query values.
#include "fmv3d/server/validation.h"

#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"

namespace fmv3d::server {
namespace {

namespace fs = std::filesystem;

TEST(Validation, WorkspaceNames) {
  EXPECT_TRUE(IsValidWorkspaceName("flight 01_a-b.c"));
  for (const char* bad : {"", ".", "..", ".hidden", "a/b", "a\\b", "x\ny", "é", "a:b"})
    EXPECT_FALSE(IsValidWorkspaceName(bad)) << bad;
  EXPECT_FALSE(IsValidWorkspaceName(std::string("a\0b", 3)));
  EXPECT_FALSE(IsValidWorkspaceName(std::string(129, 'a')));
}

TEST(Validation, ResolveInsideRefusesEveryEscape) {
  fmv3d::test::TempDir tmp("resolve");
  fs::create_directories(tmp / "root" / "sub");
  std::ofstream(tmp / "root" / "sub" / "f.txt") << "x";
  std::ofstream(tmp / "secret.txt") << "s";
  fs::create_directory_symlink(tmp.path(), tmp / "root" / "out");
  fs::create_directory_symlink(tmp / "root" / "sub", tmp / "root" / "in");
  const fs::path root = fs::canonical(tmp / "root");
  ASSERT_TRUE(ResolveInside(root, "sub/f.txt"));
  EXPECT_EQ(ResolveInside(root, "sub/f.txt").refusal, PathRefusal::kNone);
  EXPECT_EQ(*ResolveInside(root, "sub/f.txt"), root / "sub" / "f.txt");
  EXPECT_EQ(*ResolveInside(root, "in/f.txt"), root / "sub" / "f.txt");  // a symlink within the root is fine
  EXPECT_TRUE(ResolveInside(root, "sub/not-yet.txt"));
  const std::pair<std::string, PathRefusal> refused[] = {
      {"../secret.txt", PathRefusal::kDotDot},
      {"sub/../../secret.txt", PathRefusal::kDotDot},
      {"sub/..", PathRefusal::kDotDot},
      {"/etc/passwd", PathRefusal::kAbsolute},
      {std::string("sub/f.txt\0.png", 14), PathRefusal::kNulByte},
      {"sub\\..\\..\\secret.txt", PathRefusal::kBackslash},
      {"", PathRefusal::kEmpty},
      {"out/secret.txt", PathRefusal::kLeavesRoot},
      {"out", PathRefusal::kLeavesRoot},
  };
  for (const auto& [rel, why] : refused) {
    const ResolvedPath p = ResolveInside(root, rel);
    EXPECT_FALSE(p) << rel;
    EXPECT_EQ(p.refusal, why) << rel;
  }
  // The texts are what API errors say.
  EXPECT_STREQ(PathRefusalText(PathRefusal::kDotDot), "'..' in path");
  EXPECT_STREQ(PathRefusalText(PathRefusal::kLeavesRoot), "path leaves its root");
}

TEST(Validation, IsWithinComparesComponents) {
  EXPECT_TRUE(IsWithin("/a/b", "/a/b"));
  EXPECT_TRUE(IsWithin("/a/b", "/a/b/c"));
  EXPECT_FALSE(IsWithin("/a/b", "/a/bc"));
  EXPECT_FALSE(IsWithin("/a/b", "/a"));
}

TEST(Validation, ConstantTimeEquals) {
  EXPECT_TRUE(ConstantTimeEquals("abcdef", "abcdef"));
  EXPECT_FALSE(ConstantTimeEquals("abcdef", "abcdeg"));
  EXPECT_FALSE(ConstantTimeEquals("abcdef", "abcde"));
  EXPECT_FALSE(ConstantTimeEquals("", "a"));
  EXPECT_FALSE(ConstantTimeEquals(std::string("ab\0", 3), "ab"));
}

TEST(Validation, JobRequests) {
  JobRequest r =
      ParseJobRequest(R"({"inputs": ["uploads/a.mp4", "b"], "from": "dense", "until": "tiles", "fast": true})");
  EXPECT_EQ(r.inputs, (std::vector<std::string>{"uploads/a.mp4", "b"}));
  EXPECT_EQ(r.from, "dense");
  EXPECT_EQ(r.until, "tiles");
  EXPECT_TRUE(r.fast);
  r = ParseJobRequest("{}");
  EXPECT_TRUE(r.inputs.empty() && r.from.empty() && !r.fast);
  struct Bad {
    const char* body;
    const char* field;
  };
  for (const Bad& b :
       {Bad{"", "body"}, Bad{"{", "body"}, Bad{"[]", "body"}, Bad{"\"x\"", "body"},
        Bad{R"({"inputs": "a.mp4"})", "inputs"}, Bad{R"({"inputs": [1]})", "inputs"},
        Bad{R"({"inputs": [""]})", "inputs"}, Bad{R"({"from": "bogus"})", "from"}, Bad{R"({"from": 3})", "from"},
        Bad{R"({"until": "frames", "from": "dense"})", "until"}, Bad{R"({"fast": "yes"})", "fast"},
        Bad{R"({"fast": 1})", "fast"}, Bad{R"({"shell": "rm -rf /"})", "shell"}}) {
    try {
      ParseJobRequest(b.body);
      ADD_FAILURE() << "accepted " << b.body;
    } catch (const RequestError& e) {
      EXPECT_EQ(e.status(), 400) << b.body;
      EXPECT_EQ(e.field(), b.field) << b.body << ": " << e.what();
    }
  }
}

TEST(Validation, CreateWorkspaceAndQueryValues) {
  EXPECT_EQ(ParseCreateWorkspace(R"({"name": "flight-2"})"), "flight-2");
  for (const char* bad : {R"({})", R"({"name": 2})", R"({"name": "../x"})", R"({"name": ".x"})", "nope"})
    EXPECT_THROW(ParseCreateWorkspace(bad), RequestError) << bad;
  const LatLon p = ParseLatLon("47.5,-8.25", "from");
  EXPECT_DOUBLE_EQ(p.lat, 47.5);
  EXPECT_DOUBLE_EQ(p.lon, -8.25);
  for (const char* bad : {"", "47.5", "91,0", "0,181", "a,b", "1,2,3", "nan,0", "inf,0"})
    EXPECT_THROW(ParseLatLon(bad, "to"), RequestError) << bad;
  EXPECT_EQ(ParseBoundedInt("200", 2, 5000, "n"), 200);
  for (const char* bad : {"", "1", "5001", "12x", "-3", " 5"})
    EXPECT_THROW(ParseBoundedInt(bad, 2, 5000, "n"), RequestError);
}

TEST(Validation, UploadNames) {
  EXPECT_EQ(SanitiseUploadName("flight.mp4"), "flight.mp4");
  EXPECT_EQ(SanitiseUploadName("../../etc/passwd"), "passwd");
  EXPECT_EQ(SanitiseUploadName("C:\\x\\clip 1.MOV"), "clip 1.MOV");
  EXPECT_EQ(SanitiseUploadName(".bashrc"), "bashrc");
  EXPECT_EQ(SanitiseUploadName("a;b$(c).ts"), "a_b__c_.ts");
  EXPECT_THROW(SanitiseUploadName(".."), RequestError);
  EXPECT_THROW(SanitiseUploadName(""), RequestError);
  EXPECT_THROW(SanitiseUploadName("dir/"), RequestError);
}

}  // namespace
}  // namespace fmv3d::server
