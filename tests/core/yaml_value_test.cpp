#include "hanzo/fusion/core/yaml_value.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion {
namespace {

using ::testing::HasSubstr;

YamlValue parse(const std::string& text) { return YamlValue::load_string(text, "test.yaml").value(); }

TEST(YamlValue, ErrorsNameFileLineAndKeyPath) {
  const YamlValue root = parse("a:\n  b:\n    c: [1, 2, 3]\n    d: hello\n");
  const Result<std::vector<double>> c = root["a"]["b"]["c"].as_doubles(4, "(w, x, y, z)");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.error().message, "test.yaml:3: a.b.c: expected 4 numbers (w, x, y, z), got 3");
  EXPECT_EQ(c.error().field, "a.b.c");
  const Result<double> d = root["a"]["b"]["d"].as_double();
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.error().message, "test.yaml:4: a.b.d: expected a number, got 'hello'");
  // A missing key is reported at the line of its parent key.
  const Result<double> missing = root["a"]["b"]["e"].as_double();
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.error().message, "test.yaml:2: a.b.e: missing (expected a number)");
}

TEST(YamlValue, RejectsNonFiniteNumbersAndBadIntegers) {
  const YamlValue root = parse("x: .nan\ny: .inf\nz: [1, .nan]\nn: 12.5\nbig: 99999999999999999999\n");
  EXPECT_THAT(root["x"].as_double().error().message, HasSubstr("expected a finite number, got '.nan'"));
  EXPECT_FALSE(root["y"].as_double().ok());
  EXPECT_THAT(root["z"].as_doubles().error().message, HasSubstr("item 1: expected a finite number"));
  EXPECT_THAT(root["n"].as_int64().error().message, HasSubstr("expected an integer, got '12.5'"));
  EXPECT_THAT(root["big"].as_int64().error().message, HasSubstr("out of the 64-bit range"));
}

TEST(YamlValue, SyntaxErrorsNameLineAndColumn) {
  const Result<YamlValue> root = YamlValue::load_string("a: [1, 2\nb: 3\n", "broken.yaml");
  ASSERT_FALSE(root.ok());
  EXPECT_THAT(root.error().message, HasSubstr("broken.yaml:"));
  EXPECT_THAT(root.error().message, HasSubstr("YAML syntax error"));
  EXPECT_THAT(YamlValue::load_file("/nonexistent/file.yaml").error().message, HasSubstr("cannot open file"));
}

TEST(YamlValue, CheckKeysCatchesTypos) {
  const YamlValue root = parse("rotation: [1, 0, 0, 0]\ntranslaton: [0, 0, 0]\n");
  const Status status = root.check_keys({"rotation", "translation"});
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().message, "test.yaml:2: translaton: unknown key (expected one of: rotation, translation)");
}

TEST(YamlValue, FormatDoubleRoundTripsExactly) {
  for (double value : {0.1, 458.654, -0.2834, 1e-5, 1.0, 0.0, -5000000.0, 1.0 / 3.0, 6.02214076e23}) {
    const std::string text = format_double(value);
    EXPECT_EQ(parse("x: " + text)["x"].as_double().value(), value) << text;
  }
  EXPECT_EQ(format_double(0.1), "0.1");
  EXPECT_EQ(format_double(200.0), "200.0");
}

TEST(YamlValue, ScalarQuotesOnlyWhenNeeded) {
  EXPECT_EQ(yaml::scalar("/sensors/imu"), "/sensors/imu");
  for (const std::string text : {"a: b", "- x", "#comment", "true", "", "multi\nline"}) {
    const Result<std::string> back = parse("x: " + yaml::scalar(text))["x"].as_string();
    ASSERT_TRUE(back.ok()) << back.error().message;
    EXPECT_EQ(back.value(), text);
  }
}

TEST(YamlValue, AtomicWriteReplacesTheFile) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "hanzo_yaml_value_test.yaml";
  ASSERT_TRUE(yaml::write_file_atomically(path.string(), "a: 1\n").ok());
  ASSERT_TRUE(yaml::write_file_atomically(path.string(), "a: 2\n").ok());
  EXPECT_EQ(YamlValue::load_file(path.string()).value()["a"].as_int64().value(), 2);
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".tmp"));
  EXPECT_FALSE(yaml::write_file_atomically("/nonexistent/dir/x.yaml", "a: 1\n").ok());
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion
