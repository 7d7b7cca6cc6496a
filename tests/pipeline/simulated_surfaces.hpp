#pragma once
// The simulated world's static surfaces for tests that check a map against the simulator: the
// nearest surface (the ground, a box face, a cylinder's side or top) to a world point, with its
// outward normal and segmentation class. Moving boxes are not static surfaces.

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Geometry>

#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::pipeline::testing {

struct NearestSurface {
  double distance = std::numeric_limits<double>::infinity();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  std::string class_name;  // the simulated object's segmentation class
};

inline void offer(NearestSurface& nearest, double distance, const Eigen::Vector3d& normal, const std::string& class_name) {
  if (distance < nearest.distance) nearest = {distance, normal, class_name};
}

// The nearest face of an upright box: distances to each face's rectangle, in the box's frame.
inline void nearest_box_face(const sim::Box& box, const Eigen::Vector3d& point, NearestSurface& nearest) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(box.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d local = R.transpose() * (point - box.center);
  for (int axis = 0; axis < 3; ++axis) {
    for (const double side : {-1.0, 1.0}) {
      Eigen::Vector3d on_face = local.cwiseMax(-box.half_size).cwiseMin(box.half_size);
      on_face(axis) = side * box.half_size(axis);
      offer(nearest, (local - on_face).norm(), R * (side * Eigen::Vector3d::Unit(axis)), box.class_name);
    }
  }
}

inline void nearest_cylinder_surface(const sim::Cylinder& cylinder, const Eigen::Vector3d& point, NearestSurface& nearest) {
  const Eigen::Vector2d radial = (point - cylinder.base_center).head<2>();
  const double height = std::clamp(point.z() - cylinder.base_center.z(), 0.0, cylinder.height);
  const double radius = radial.norm();
  const Eigen::Vector2d direction = radius > 1e-9 ? Eigen::Vector2d(radial / radius) : Eigen::Vector2d::UnitX();
  const Eigen::Vector3d on_side(cylinder.base_center.x() + cylinder.radius * direction.x(), cylinder.base_center.y() + cylinder.radius * direction.y(),
                                cylinder.base_center.z() + height);
  offer(nearest, (point - on_side).norm(), Eigen::Vector3d(direction.x(), direction.y(), 0.0), cylinder.class_name);
  const Eigen::Vector2d on_top_radial = radius > cylinder.radius ? Eigen::Vector2d(direction * cylinder.radius) : radial;
  const Eigen::Vector3d on_top(cylinder.base_center.x() + on_top_radial.x(), cylinder.base_center.y() + on_top_radial.y(),
                               cylinder.base_center.z() + cylinder.height);
  offer(nearest, (point - on_top).norm(), Eigen::Vector3d::UnitZ(), cylinder.class_name);
}

inline NearestSurface nearest_surface(const sim::WorldDescription& world, const Eigen::Vector3d& point) {
  NearestSurface nearest;
  if (world.has_ground) offer(nearest, std::abs(point.z() - world.ground_height), Eigen::Vector3d::UnitZ(), world.ground_class);
  for (const sim::Box& box : world.boxes) nearest_box_face(box, point, nearest);
  for (const sim::Cylinder& cylinder : world.cylinders) nearest_cylinder_surface(cylinder, point, nearest);
  return nearest;
}

}  // namespace hanzo::fusion::pipeline::testing
