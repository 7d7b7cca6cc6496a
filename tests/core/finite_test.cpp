#include "hanzo/fusion/core/finite.hpp"

#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

namespace hanzo::fusion {
namespace {

template <typename Float>
void expect_each_non_finite_value_found_at_every_position() {
  for (const Float bad : {std::numeric_limits<Float>::quiet_NaN(), std::numeric_limits<Float>::infinity(),
                          -std::numeric_limits<Float>::infinity(), -std::numeric_limits<Float>::quiet_NaN()}) {
    for (std::size_t position = 0; position < 37; ++position) {
      std::vector<Float> values(37, Float(1.5));
      values[position] = bad;
      EXPECT_FALSE(all_finite(values.data(), values.size())) << "position " << position;
    }
  }
}

TEST(Finite, FindsNaNAndInfinityAnywhereInFloatAndDoubleArrays) {
  expect_each_non_finite_value_found_at_every_position<float>();
  expect_each_non_finite_value_found_at_every_position<double>();
}

TEST(Finite, AcceptsFiniteExtremesAndEmptyArrays) {
  const std::vector<float> floats = {0.0F, -0.0F, std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest(),
                                     std::numeric_limits<float>::denorm_min(), std::numeric_limits<float>::min()};
  EXPECT_TRUE(all_finite(floats.data(), floats.size()));
  const std::vector<double> doubles = {std::numeric_limits<double>::max(), std::numeric_limits<double>::lowest(),
                                       std::numeric_limits<double>::denorm_min()};
  EXPECT_TRUE(all_finite(doubles.data(), doubles.size()));
  EXPECT_TRUE(all_finite(static_cast<const float*>(nullptr), 0));
}

TEST(Finite, WithinRejectsValuesOutsideTheRangeAndNaN) {
  std::vector<float> values(20, 0.5F);
  values.front() = 0.0F;
  values.back() = 1.0F;
  EXPECT_TRUE(all_within(values.data(), values.size(), 0.0F, 1.0F));
  for (const float bad : {-1e-7F, 1.0000001F, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    values[11] = bad;
    EXPECT_FALSE(all_within(values.data(), values.size(), 0.0F, 1.0F)) << bad;
  }
  EXPECT_TRUE(all_within(values.data(), 0, 0.0F, 1.0F));
}

}  // namespace
}  // namespace hanzo::fusion
