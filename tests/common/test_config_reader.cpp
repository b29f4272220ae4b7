#include <gtest/gtest.h>

#include "stillpoint/common/config_reader.hpp"

namespace sp {
namespace {

TEST(ConfigReader, ReadsTypedValuesAndKeepsDefaults) {
  auto cfg = ConfigReader::from_string("a: 3\nb: 2.5\nsub:\n  name: orb\n", "test.yaml");
  int a = 0;
  double b = 0;
  double c = 7.0;
  cfg.read("a", a);
  cfg.read("b", b, 0.0, 10.0);
  cfg.read("c", c);
  std::string name = "x";
  cfg.section("sub").read("name", name);
  EXPECT_EQ(a, 3);
  EXPECT_DOUBLE_EQ(b, 2.5);
  EXPECT_DOUBLE_EQ(c, 7.0);
  EXPECT_EQ(name, "orb");
  EXPECT_NO_THROW(cfg.finish());
}

TEST(ConfigReader, UnknownKeyNamesFileKeyAndLine) {
  auto cfg = ConfigReader::from_string("a: 1\nsub:\n  typo: 2\n", "cfg.yaml");
  int a = 0;
  cfg.read("a", a);
  (void)cfg.section("sub");
  try {
    cfg.finish();
    FAIL() << "expected an error";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "sub.typo");
    EXPECT_EQ(e.line(), 3);
    EXPECT_NE(std::string(e.what()).find("cfg.yaml:3"), std::string::npos);
  }
}

TEST(ConfigReader, MissingRequiredKeyIsAnError) {
  auto cfg = ConfigReader::from_string("a: 1\n", "cfg.yaml");
  EXPECT_THROW((void)cfg.require<double>("fx"), ConfigError);
}

TEST(ConfigReader, OutOfRangeAndWrongTypeAreErrors) {
  auto cfg = ConfigReader::from_string("a: 11\nb: hello\n", "cfg.yaml");
  int a = 0;
  EXPECT_THROW(cfg.read("a", a, 0, 10), ConfigError);
  double b = 0;
  try {
    cfg.read("b", b);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.line(), 2);
    EXPECT_NE(std::string(e.what()).find("hello"), std::string::npos);
  }
}

TEST(ConfigReader, ChoiceMustBeListed) {
  auto cfg = ConfigReader::from_string("mode: fast\n", "cfg.yaml");
  std::string mode = "slow";
  EXPECT_THROW(cfg.read_choice("mode", mode, {"slow", "exact"}), ConfigError);
}

TEST(ConfigReader, MissingFileAndSyntaxErrorNameTheFile) {
  EXPECT_THROW((void)ConfigReader::from_file("/nonexistent/stillpoint.yaml"), ConfigError);
  try {
    (void)ConfigReader::from_string("a: [1, 2\nb: 3\n", "bad.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "bad.yaml");
  }
}

}  // namespace
}  // namespace sp

namespace sp {
namespace {

TEST(ConfigReader, NanFailsTheRangeCheck) {
  auto cfg = ConfigReader::from_string("fx: .nan\n", "cam.yaml");
  double fx = 500;
  EXPECT_THROW(cfg.read("fx", fx, 1.0, 10000.0), ConfigError);
  EXPECT_THROW((void)cfg.require("fx", 1.0, 10000.0), ConfigError);
}

TEST(ConfigReader, NonScalarKeyIsAConfigError) {
  auto cfg = ConfigReader::from_string("[a, b]: 1\n", "bad.yaml");
  EXPECT_THROW(cfg.finish(), ConfigError);
}

}  // namespace
}  // namespace sp

namespace sp {
namespace {

// Fuzzing found inputs on which yaml-cpp's scanner runs for minutes; they are refused up front.
TEST(ConfigReaderText, ControlCharactersAndBrokenUtf8AreRefusedWithTheLine) {
  constexpr char kNul[] = "a: 1\n!\0\0\0\tIII\n";
  const std::string nul(kNul, sizeof(kNul) - 1);  // the literal's own NULs included, not its terminator
  try {
    (void)ConfigReader::from_string(nul, "bad.yaml");
    FAIL() << "NUL bytes accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.yaml"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find(":2"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)ConfigReader::from_string("a: \xff\xfe\n", "bad.yaml"), InputError);
  EXPECT_THROW((void)ConfigReader::from_string("a: \xc3\n", "bad.yaml"), InputError);  // truncated sequence
  // Valid UTF-8, tabs and CRLF are fine.
  const auto r = ConfigReader::from_string("name: \"caf\xc3\xa9\"\r\nvalue:\t3\n", "ok.yaml");
  std::string name;
  int value = 0;
  r.read("name", name);
  r.read("value", value, 0, 10);
  EXPECT_EQ(name, "caf\xc3\xa9");
  EXPECT_EQ(value, 3);
}

}  // namespace
}  // namespace sp
