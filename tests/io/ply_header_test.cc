// The PLY header parser shared by the whole-cloud and streaming readers (io/ply_header.h): what it reads from
// well-formed headers, and the message it gives for each malformed one.
#include "fmv3d/io/ply_header.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sstream>

#include "fmv3d/core/error.h"

namespace fmv3d::io::ply {
namespace {

std::string ErrorOf(const std::string& text) {
  std::istringstream in(text);
  try {
    ReadHeader(in, "f.ply");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(PlyHeader, ReadsElementsPropertiesAndListsAndStopsAtTheData) {
  std::istringstream in(
      "ply\r\nformat binary_big_endian 1.0\ncomment by hand\nelement vertex 7\nproperty double x\n"
      "property float32 y\nproperty uchar red\nproperty list uint8 int visibility\nelement face 2\n"
      "property list uchar int vertex_indices\nend_header\nDATA");
  const Header h = ReadHeader(in, "f.ply");
  EXPECT_EQ(h.format, Format::kBinaryBigEndian);
  ASSERT_EQ(h.elements.size(), 2u);
  const Element& v = h.elements[0];
  EXPECT_EQ(v.name, "vertex");
  EXPECT_EQ(v.count, 7u);
  ASSERT_EQ(v.properties.size(), 4u);
  EXPECT_EQ(v.properties[0].type, Scalar::kF64);
  EXPECT_EQ(v.properties[1].type, Scalar::kF32);
  EXPECT_EQ(v.properties[2].type, Scalar::kU8);
  EXPECT_TRUE(v.properties[3].is_list);
  EXPECT_EQ(v.properties[3].count_type, Scalar::kU8);
  EXPECT_EQ(v.properties[3].type, Scalar::kI32);
  EXPECT_EQ(v.Find("y"), 1);
  EXPECT_EQ(v.Find("visibility"), -1);  // a list is found only as a list
  EXPECT_EQ(v.Find("visibility", true), 3);
  EXPECT_EQ(v.Find("nx"), -1);
  EXPECT_EQ(h.elements[1].count, 2u);
  std::string rest;
  in >> rest;
  EXPECT_EQ(rest, "DATA");
}

TEST(PlyHeader, MalformedHeadersAreNamedErrors) {
  using ::testing::HasSubstr;
  EXPECT_THAT(ErrorOf("obj\n"), HasSubstr("f.ply: not a PLY file"));
  EXPECT_THAT(ErrorOf("ply\nformat ascii 1.0\nelement vertex 1\n"), HasSubstr("no end_header"));
  EXPECT_THAT(ErrorOf("ply\nformat binary_middle_endian 1.0\nend_header\n"), HasSubstr("unknown PLY format"));
  EXPECT_THAT(ErrorOf("ply\nelement vertex 1\nproperty float x\nend_header\n"), HasSubstr("no format line"));
  EXPECT_THAT(ErrorOf("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n"), HasSubstr("bad PLY element count"));
  EXPECT_THAT(ErrorOf("ply\nformat ascii 1.0\nelement vertex 99999999999999\nend_header\n"),
              HasSubstr("bad PLY element count"));
  EXPECT_THAT(ErrorOf("ply\nformat ascii 1.0\nproperty float x\nend_header\n"), HasSubstr("before any element"));
  EXPECT_THAT(ErrorOf("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n"),
              HasSubstr("unknown PLY property type 'quad'"));
}

TEST(PlyHeader, CountsMustFitTheBytesAfterTheHeader) {
  std::istringstream in(
      "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n");
  const Header h = ReadHeader(in, "f.ply");
  EXPECT_NO_THROW(CheckCountsFit(h, 120, "f.ply"));  // 10 vertices of 3 floats
  try {
    CheckCountsFit(h, 119, "f.ply");
    FAIL() << "a count needing more bytes than the file has was accepted";
  } catch (const Error& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("needs at least 120 bytes of data, the file has 119"));
  }
}

}  // namespace
}  // namespace fmv3d::io::ply
