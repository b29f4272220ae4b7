#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/tum_text.hpp"
#include "test_util.hpp"

namespace sp::io {
namespace {

// Runs `fn` and returns the InputError it throws (fails the test when none is thrown).
template <typename Fn>
InputError expect_input_error(Fn fn) {
  try {
    fn();
  } catch (const InputError& e) {
    return e;
  }
  ADD_FAILURE() << "no InputError thrown";
  return InputError("", 0, "");
}

TEST(TumText, SkipsCommentsAndBlankLinesAndAcceptsTabsCommasCrlf) {
  const auto f = test::write_text(test::scratch_dir() / "rgb.txt",
                                  "# color images\n"
                                  "# timestamp filename\n"
                                  "\n"
                                  "1.5 rgb/1.5.png\r\n"
                                  "   \n"
                                  "2.25\trgb/2.25.png\n"
                                  "  # indented comment\n"
                                  "3.0,rgb/3.0.png\n");
  const auto list = read_tum_file_list(f);
  ASSERT_EQ(list.size(), 3u);
  EXPECT_DOUBLE_EQ(list[0].stamp, 1.5);
  EXPECT_EQ(list[0].path, "rgb/1.5.png");
  EXPECT_DOUBLE_EQ(list[1].stamp, 2.25);
  EXPECT_EQ(list[1].path, "rgb/2.25.png");
  EXPECT_EQ(list[2].path, "rgb/3.0.png");
  const auto records = read_tum_text(f, 2);
  EXPECT_EQ(records[1].line, 6);
}

TEST(TumText, WrongColumnCountNamesFileAndLine) {
  const auto f = test::write_text(test::scratch_dir() / "depth.txt", "# c\n1.0 a.png\n2.0 b.png extra\n");
  const auto e = expect_input_error([&] { (void)read_tum_file_list(f); });
  EXPECT_EQ(e.line(), 3);
  EXPECT_EQ(e.file(), f.string());
  EXPECT_NE(std::string(e.what()).find("depth.txt:3"), std::string::npos) << e.what();
  EXPECT_NE(std::string(e.what()).find("columns"), std::string::npos) << e.what();
}

TEST(TumText, NonNumericStampNamesFileAndLine) {
  const auto f = test::write_text(test::scratch_dir() / "rgb.txt", "1.0 a.png\n\n1.2x b.png\n");
  const auto e = expect_input_error([&] { (void)read_tum_file_list(f); });
  EXPECT_EQ(e.line(), 3);
  EXPECT_NE(std::string(e.what()).find("1.2x"), std::string::npos) << e.what();
}

TEST(TumText, OutOfOrderOrRepeatedStampsAreErrors) {
  const auto dir = test::scratch_dir();
  const auto f = test::write_text(dir / "rgb.txt", "1.0 a.png\n2.0 b.png\n1.5 c.png\n");
  EXPECT_EQ(expect_input_error([&] { (void)read_tum_file_list(f); }).line(), 3);
  const auto g = test::write_text(dir / "rgb2.txt", "1.0 a.png\n1.0 b.png\n");
  EXPECT_EQ(expect_input_error([&] { (void)read_tum_file_list(g); }).line(), 2);
}

TEST(TumText, MissingFileIsAnInputError) {
  EXPECT_THROW((void)read_tum_file_list(test::scratch_dir() / "nope.txt"), InputError);
}

TEST(TumText, ParseDoubleRejectsTrailingJunkAndNonFinite) {
  double v = 0;
  EXPECT_TRUE(parse_double("1341846056.033309", v));
  EXPECT_DOUBLE_EQ(v, 1341846056.033309);
  EXPECT_TRUE(parse_double("-1e-3", v));
  EXPECT_DOUBLE_EQ(v, -1e-3);
  EXPECT_FALSE(parse_double("1.0abc", v));
  EXPECT_FALSE(parse_double("", v));
  EXPECT_FALSE(parse_double("nan", v));
  EXPECT_FALSE(parse_double("inf", v));
}

}  // namespace
}  // namespace sp::io
