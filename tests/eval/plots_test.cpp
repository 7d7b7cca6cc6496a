#include "hanzo/fusion/eval/plots.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::eval {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

io::Trajectory square() {
  io::Trajectory trajectory;
  const std::vector<Eigen::Vector3d> corners = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0}};
  for (std::size_t i = 0; i < corners.size(); ++i) {
    trajectory.timestamps.push_back(Timestamp::from_nanoseconds(static_cast<int64_t>(i + 1) * 1'000'000'000));
    io::PoseMatrix pose = io::PoseMatrix::Identity();
    pose.block<3, 1>(0, 3) = corners[i];
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

TEST(Plots, TopViewDrawsBothTrajectoriesWithAnErrorColourBar) {
  const std::string svg = trajectory_top_view_svg(square(), square(), {0.0, 0.5, 1.0, 2.0}, {"APE <test>", "APE (m)"});
  EXPECT_THAT(svg, HasSubstr("<svg xmlns=\"http://www.w3.org/2000/svg\""));
  EXPECT_THAT(svg, HasSubstr("APE &lt;test&gt;"));  // escaped
  EXPECT_THAT(svg, HasSubstr("<polyline"));           // the reference
  EXPECT_THAT(svg, HasSubstr("stroke=\"#fde725\""));  // the largest error is yellow
  EXPECT_THAT(svg, HasSubstr(">2</text>"));           // colour bar maximum
  EXPECT_THAT(svg, Not(HasSubstr("nan")));
  EXPECT_EQ(svg.substr(svg.size() - 7), "</svg>\n");
}

TEST(Plots, ErrorOverTimeShowsTheStatistics) {
  const std::vector<double> errors = {0.1, 0.3, 0.2};
  const std::string svg = error_over_time_svg({10.0, 11.0, 12.0}, errors, compute_statistics(errors), {"t", "APE (m)"});
  EXPECT_THAT(svg, HasSubstr("rmse 0.216"));
  EXPECT_THAT(svg, HasSubstr("median 0.2"));
  EXPECT_THAT(svg, HasSubstr("time (s)"));
}

TEST(Plots, DegenerateInputStillGivesAValidPicture) {
  io::Trajectory one = square();
  one.poses.resize(1);
  one.timestamps.resize(1);
  const std::string svg = trajectory_top_view_svg(one, one, {0.0}, {"single", "e"});
  EXPECT_THAT(svg, Not(HasSubstr("nan")));
  EXPECT_THAT(svg, Not(HasSubstr("inf")));
  const std::string empty = error_over_time_svg({}, {}, {}, {"empty", "e"});
  EXPECT_THAT(empty, Not(HasSubstr("nan")));
}

}  // namespace
}  // namespace hanzo::fusion::eval
