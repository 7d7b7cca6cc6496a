#include "hanzo/fusion/sim/world.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace hanzo::fusion::sim {
namespace {

constexpr double kMinimumDistance = 1e-6;  // metres: a ray does not hit the surface it starts on

struct Aabb {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max = Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity());
  void extend(const Aabb& other) {
    min = min.cwiseMin(other.min);
    max = max.cwiseMax(other.max);
  }
  Eigen::Vector3d center() const { return 0.5 * (min + max); }
};

Aabb bounds_of(const Box& box) {
  const double c = std::abs(std::cos(box.yaw)), s = std::abs(std::sin(box.yaw));
  const Eigen::Vector3d extent(c * box.half_size.x() + s * box.half_size.y(), s * box.half_size.x() + c * box.half_size.y(),
                               box.half_size.z());
  return {box.center - extent, box.center + extent};
}

Aabb bounds_of(const Cylinder& cylinder) {
  const Eigen::Vector3d r(cylinder.radius, cylinder.radius, 0.0);
  return {cylinder.base_center - r, cylinder.base_center + r + Eigen::Vector3d(0.0, 0.0, cylinder.height)};
}

// Slab test: the ray's parameter interval inside the box, clipped to [0, max_distance]. A zero
// direction component gives infinite slab distances (or NaN exactly on a face, which std::max /
// std::min with the NaN second ignore).
bool ray_hits_bounds(const Aabb& box, const Eigen::Vector3d& origin, const Eigen::Vector3d& inverse_direction,
                     double max_distance, double* entry) {
  double near = 0.0, far = max_distance;
  for (int axis = 0; axis < 3; ++axis) {
    const double t1 = (box.min[axis] - origin[axis]) * inverse_direction[axis];
    const double t2 = (box.max[axis] - origin[axis]) * inverse_direction[axis];
    near = std::max(near, std::min(t1, t2));
    far = std::min(far, std::max(t1, t2));
  }
  *entry = near;
  return near <= far;
}

// Whether the box lies wholly on the negative side of the plane through origin with the given
// normal (its corner furthest along the normal is behind the plane).
bool outside_plane(const Aabb& box, const Eigen::Vector3d& origin, const Eigen::Vector3d& normal) {
  double furthest = 0.0;
  for (int axis = 0; axis < 3; ++axis) {
    furthest += normal[axis] * ((normal[axis] > 0.0 ? box.max[axis] : box.min[axis]) - origin[axis]);
  }
  return furthest < 0.0;
}

// Euclidean distance from a point to the box (0 inside): no surface in the box is nearer.
double distance_to(const Aabb& box, const Eigen::Vector3d& point) {
  return (box.min - point).cwiseMax(point - box.max).cwiseMax(0.0).norm();
}

// Ray against an upright box with yaw given as (cos, sin); fills hit when nearer than hit->distance.
bool intersect_box(const Box& box, double cos_yaw, double sin_yaw, const Eigen::Vector3d& origin,
                   const Eigen::Vector3d& direction, RayHit* hit) {
  const Eigen::Vector3d offset = origin - box.center;
  const Eigen::Vector3d o(cos_yaw * offset.x() + sin_yaw * offset.y(), -sin_yaw * offset.x() + cos_yaw * offset.y(), offset.z());
  const Eigen::Vector3d d(cos_yaw * direction.x() + sin_yaw * direction.y(), -sin_yaw * direction.x() + cos_yaw * direction.y(),
                          direction.z());
  const Eigen::Vector3d& h = box.half_size;
  double near = -std::numeric_limits<double>::infinity(), far = std::numeric_limits<double>::infinity();
  int entry_axis = -1;
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(d[axis]) < 1e-15) {
      if (std::abs(o[axis]) > h[axis]) return false;
      continue;
    }
    double t1 = (-h[axis] - o[axis]) / d[axis], t2 = (h[axis] - o[axis]) / d[axis];
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > near) {
      near = t1;
      entry_axis = axis;
    }
    far = std::min(far, t2);
    if (near > far) return false;
  }
  if (entry_axis < 0 || near < kMinimumDistance || near >= hit->distance) return false;
  Eigen::Vector3d normal_local = Eigen::Vector3d::Zero();
  normal_local[entry_axis] = d[entry_axis] > 0.0 ? -1.0 : 1.0;
  const Eigen::Vector3d p = o + near * d + h;  // from the lower corner
  static constexpr std::array<std::array<int, 2>, 3> kFaceAxes{{{1, 2}, {0, 2}, {0, 1}}};
  hit->distance = near;
  hit->normal = Eigen::Vector3d(cos_yaw * normal_local.x() - sin_yaw * normal_local.y(),
                                sin_yaw * normal_local.x() + cos_yaw * normal_local.y(), normal_local.z());
  hit->surface_uv = {p[kFaceAxes[entry_axis][0]], p[kFaceAxes[entry_axis][1]]};
  hit->material = &box.material;
  return true;
}

bool intersect_cylinder(const Cylinder& cylinder, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) {
  const Eigen::Vector3d o = origin - cylinder.base_center;
  bool found = false;
  const double a = direction.x() * direction.x() + direction.y() * direction.y();
  if (a > 1e-15) {
    const double b = 2.0 * (o.x() * direction.x() + o.y() * direction.y());
    const double c = o.x() * o.x() + o.y() * o.y() - cylinder.radius * cylinder.radius;
    const double discriminant = b * b - 4.0 * a * c;
    if (discriminant >= 0.0 && c > 0.0) {
      const double t = (-b - std::sqrt(discriminant)) / (2.0 * a);
      const double z = o.z() + t * direction.z();
      if (t >= kMinimumDistance && t < hit->distance && z >= 0.0 && z <= cylinder.height) {
        const Eigen::Vector2d radial(o.x() + t * direction.x(), o.y() + t * direction.y());
        hit->distance = t;
        hit->normal = Eigen::Vector3d(radial.x(), radial.y(), 0.0) / cylinder.radius;
        hit->surface_uv = {std::atan2(radial.y(), radial.x()) * cylinder.radius, z};
        found = true;
      }
    }
  }
  if (direction.z() < 0.0 && o.z() > cylinder.height) {  // the top cap, seen from above
    const double t = (cylinder.height - o.z()) / direction.z();
    const Eigen::Vector2d radial(o.x() + t * direction.x(), o.y() + t * direction.y());
    if (t >= kMinimumDistance && t < hit->distance && radial.squaredNorm() <= cylinder.radius * cylinder.radius) {
      hit->distance = t;
      hit->normal = Eigen::Vector3d::UnitZ();
      hit->surface_uv = radial;
      found = true;
    }
  }
  if (found) hit->material = &cylinder.material;
  return found;
}

// Where a ping-pong walk along the polyline is after `distance` metres: the point and the unit
// walking direction.
void walk(const std::vector<Eigen::Vector2d>& path, double distance, Eigen::Vector2d* point, Eigen::Vector2d* heading) {
  double length = 0.0;
  for (std::size_t i = 1; i < path.size(); ++i) length += (path[i] - path[i - 1]).norm();
  if (length <= 0.0) {
    *point = path.front();
    *heading = Eigen::Vector2d::UnitX();
    return;
  }
  double s = std::fmod(std::max(0.0, distance), 2.0 * length);
  const bool returning = s > length;
  if (returning) s = 2.0 * length - s;
  for (std::size_t i = 1; i < path.size(); ++i) {
    const Eigen::Vector2d segment = path[i] - path[i - 1];
    const double segment_length = segment.norm();
    if (segment_length <= 0.0) continue;
    if (s <= segment_length || i + 1 == path.size()) {
      *point = path[i - 1] + segment * std::min(1.0, s / segment_length);
      *heading = (returning ? -segment : segment) / segment_length;
      return;
    }
    s -= segment_length;
  }
}

}  // namespace

Eigen::Vector3d MovingBox::center_at(Timestamp time, double ground_height) const {
  Eigen::Vector2d point = Eigen::Vector2d::Zero(), heading = Eigen::Vector2d::UnitX();
  walk(path, speed * (time - start_time).seconds(), &point, &heading);
  return {point.x(), point.y(), ground_height + box.half_size.z()};
}

Eigen::Vector3d MovingBox::velocity_at(Timestamp time) const {
  if (time < start_time) return Eigen::Vector3d::Zero();
  Eigen::Vector2d point = Eigen::Vector2d::Zero(), heading = Eigen::Vector2d::UnitX();
  walk(path, speed * (time - start_time).seconds(), &point, &heading);
  return {speed * heading.x(), speed * heading.y(), 0.0};
}

double MovingBox::yaw_at(Timestamp time) const {
  Eigen::Vector2d point = Eigen::Vector2d::Zero(), heading = Eigen::Vector2d::UnitX();
  walk(path, speed * (time - start_time).seconds(), &point, &heading);
  return std::atan2(heading.y(), heading.x());
}

struct World::Bvh {
  struct Node {
    Aabb bounds;
    int left = -1;  // children of an inner node
    int right = -1;
    int first = 0;  // leaf: objects [first, first + count)
    int count = 0;
  };
  struct Primitive {
    Aabb bounds;
    int object_id = 0;
    double cos_yaw = 1.0, sin_yaw = 0.0;  // boxes: kept beside the bounds for the leaf loop
  };
  std::vector<Node> nodes;
  std::vector<Primitive> primitives;

  // Surface area heuristic (MacDonald & Booth 1990): split where
  // area(left) * count(left) + area(right) * count(right) is least over every centroid order
  // along x, y and z; stop at one or two objects or when no split beats a leaf. Large objects
  // (warehouse walls, building rows) then sit near the root instead of inflating every node.
  int build(int begin, int end) {
    Node node;
    for (int i = begin; i < end; ++i) node.bounds.extend(primitives[i].bounds);
    const int index = static_cast<int>(nodes.size());
    nodes.push_back(node);
    const int count = end - begin;
    double best_cost = surface_area(node.bounds) * count;  // the cost of a leaf
    int best_axis = -1, best_split = 0;
    if (count > 2) {
      std::vector<double> left_area(count);
      for (int axis = 0; axis < 3; ++axis) {
        std::sort(primitives.begin() + begin, primitives.begin() + end, [axis](const Primitive& a, const Primitive& b) {
          return a.bounds.center()[axis] < b.bounds.center()[axis];
        });
        Aabb left;
        for (int i = 0; i < count; ++i) {
          left.extend(primitives[begin + i].bounds);
          left_area[i] = surface_area(left);
        }
        Aabb right;
        for (int i = count - 1; i > 0; --i) {  // split before element i
          right.extend(primitives[begin + i].bounds);
          const double cost = left_area[i - 1] * i + surface_area(right) * (count - i) + surface_area(node.bounds);
          if (cost < best_cost) {
            best_cost = cost;
            best_axis = axis;
            best_split = i;
          }
        }
      }
    }
    if (best_axis < 0) {
      nodes[index].first = begin;
      nodes[index].count = count;
      return index;
    }
    std::sort(primitives.begin() + begin, primitives.begin() + end, [best_axis](const Primitive& a, const Primitive& b) {
      return a.bounds.center()[best_axis] < b.bounds.center()[best_axis];
    });
    const int left = build(begin, begin + best_split);
    const int right = build(begin + best_split, end);
    nodes[index].left = left;
    nodes[index].right = right;
    return index;
  }

  static double surface_area(const Aabb& box) {
    const Eigen::Vector3d size = (box.max - box.min).cwiseMax(0.0);
    return 2.0 * (size.x() * size.y() + size.y() * size.z() + size.z() * size.x());
  }
};

World::World(WorldDescription description) : description_(std::move(description)), bvh_(std::make_unique<Bvh>()) {
  const int box_count = static_cast<int>(description_.boxes.size());
  for (int i = 0; i < box_count; ++i) {
    const Box& box = description_.boxes[i];
    bvh_->primitives.push_back({bounds_of(box), i, std::cos(box.yaw), std::sin(box.yaw)});
    box_trig_.emplace_back(std::cos(box.yaw), std::sin(box.yaw));
  }
  for (int i = 0; i < static_cast<int>(description_.cylinders.size()); ++i) {
    bvh_->primitives.push_back({bounds_of(description_.cylinders[i]), box_count + i});
  }
  if (!bvh_->primitives.empty()) bvh_->build(0, static_cast<int>(bvh_->primitives.size()));
}

World::~World() = default;
World::World(World&&) noexcept = default;
World& World::operator=(World&&) noexcept = default;

int World::object_count() const {
  return static_cast<int>(description_.boxes.size() + description_.cylinders.size() + description_.moving_boxes.size());
}

const std::string& World::object_class(int object_id) const {
  static const std::string phantom = "phantom";
  const int boxes = static_cast<int>(description_.boxes.size());
  const int cylinders = static_cast<int>(description_.cylinders.size());
  if (object_id == -1) return description_.ground_class;
  if (object_id < -1 || object_id >= object_count()) return phantom;
  if (object_id < boxes) return description_.boxes[static_cast<std::size_t>(object_id)].class_name;
  if (object_id < boxes + cylinders) return description_.cylinders[static_cast<std::size_t>(object_id - boxes)].class_name;
  return description_.moving_boxes[static_cast<std::size_t>(object_id - boxes - cylinders)].class_name;
}

bool World::is_moving(int object_id) const {
  return object_id >= static_cast<int>(description_.boxes.size() + description_.cylinders.size()) && object_id < object_count();
}

bool World::intersect_object(int object_id, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const {
  const int box_count = static_cast<int>(description_.boxes.size());
  const bool found = object_id < box_count
                         ? intersect_box(description_.boxes[object_id], box_trig_[object_id].x(), box_trig_[object_id].y(), origin,
                                         direction, hit)
                         : intersect_cylinder(description_.cylinders[object_id - box_count], origin, direction, hit);
  if (found) hit->object_id = object_id;
  return found;
}

bool World::cast_ground(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const {
  if (!description_.has_ground || direction.z() >= 0.0 || origin.z() <= description_.ground_height) return false;
  const double t = (description_.ground_height - origin.z()) / direction.z();
  if (t >= hit->distance) return false;
  hit->distance = t;
  hit->normal = Eigen::Vector3d::UnitZ();
  hit->material = &description_.ground;
  hit->surface_uv = (origin + t * direction).head<2>();
  hit->object_id = -1;
  return true;
}

bool World::cast_static(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, int hint, RayHit* hit) const {
  bool found = cast_ground(origin, direction, hit);
  if (bvh_->nodes.empty()) return found;
  if (hint >= 0 && hint < static_cast<int>(bvh_->primitives.size())) found = intersect_object(hint, origin, direction, hit) || found;
  const int box_count = static_cast<int>(description_.boxes.size());
  const Eigen::Vector3d inverse_direction = direction.cwiseInverse();
  std::array<int, 64> stack;  // not zeroed: only pushed entries are read
  int depth = 0;
  stack[depth++] = 0;
  while (depth > 0) {
    const Bvh::Node& node = bvh_->nodes[stack[--depth]];
    double entry = 0.0;
    if (!ray_hits_bounds(node.bounds, origin, inverse_direction, hit->distance, &entry)) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        const Bvh::Primitive& primitive = bvh_->primitives[i];
        if (primitive.object_id == hint) continue;  // tested first
        const bool hit_this =
            primitive.object_id < box_count
                ? intersect_box(description_.boxes[primitive.object_id], primitive.cos_yaw, primitive.sin_yaw, origin, direction, hit)
                : intersect_cylinder(description_.cylinders[primitive.object_id - box_count], origin, direction, hit);
        if (hit_this) {
          hit->object_id = primitive.object_id;
          found = true;
        }
      }
      continue;
    }
    // Visit the nearer child first (pushed last) so the far one is often culled.
    double left_entry = 0.0, right_entry = 0.0;
    const bool left = ray_hits_bounds(bvh_->nodes[node.left].bounds, origin, inverse_direction, hit->distance, &left_entry);
    const bool right = ray_hits_bounds(bvh_->nodes[node.right].bounds, origin, inverse_direction, hit->distance, &right_entry);
    if (left && right) {
      stack[depth++] = left_entry < right_entry ? node.right : node.left;
      stack[depth++] = left_entry < right_entry ? node.left : node.right;
    } else if (left) {
      stack[depth++] = node.left;
    } else if (right) {
      stack[depth++] = node.right;
    }
  }
  return found;
}

WorldSnapshot World::at(Timestamp time) const {
  WorldSnapshot snapshot;
  snapshot.world_ = this;
  for (const MovingBox& moving : description_.moving_boxes) {
    WorldSnapshot::PlacedBox placed;
    placed.box = moving.box;
    placed.box.center = moving.center_at(time, description_.ground_height);
    placed.box.yaw = moving.yaw_at(time);
    placed.cos_yaw = std::cos(placed.box.yaw);
    placed.sin_yaw = std::sin(placed.box.yaw);
    placed.velocity = moving.velocity_at(time);
    placed.material = &moving.box.material;
    snapshot.moving_.push_back(placed);
  }
  snapshot.first_moving_ = object_count() - static_cast<int>(description_.moving_boxes.size());
  return snapshot;
}

std::optional<RayHit> World::cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
                                  Timestamp time) const {
  return at(time).cast(origin, direction, max_distance);
}

bool WorldSnapshot::intersect(int object_id, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const {
  if (object_id < first_moving_) return world_->intersect_object(object_id, origin, direction, hit);
  const PlacedBox& placed = moving_[static_cast<std::size_t>(object_id - first_moving_)];
  if (!intersect_box(placed.box, placed.cos_yaw, placed.sin_yaw, origin, direction, hit)) return false;
  hit->material = placed.material;
  hit->object_id = object_id;
  hit->object_velocity = placed.velocity;
  return true;
}

std::optional<RayHit> WorldSnapshot::finish(bool found, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit hit,
                                            int* object_hint) const {
  if (object_hint != nullptr) *object_hint = found ? hit.object_id : -1;
  if (!found) return std::nullopt;
  if (hit.object_id < first_moving_) hit.object_velocity.setZero();
  hit.point = origin + hit.distance * direction;
  return hit;
}

std::optional<RayHit> WorldSnapshot::cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
                                          int* object_hint) const {
  RayHit hit;
  hit.distance = max_distance;
  bool found = world_->cast_static(origin, direction, object_hint != nullptr ? *object_hint : -1, &hit);
  for (int i = 0; i < static_cast<int>(moving_.size()); ++i) found = intersect(first_moving_ + i, origin, direction, &hit) || found;
  return finish(found, origin, direction, hit, object_hint);
}

void WorldSnapshot::group(const Eigen::Vector3d& origin, std::span<const Eigen::Vector3d> inward_normals, double max_distance,
                          RayGroup* group) const {
  group->origin_ = origin;
  group->max_distance_ = max_distance;
  group->candidates_.clear();
  // Hits are strictly nearer than max_distance, so bounds at or beyond it hold nothing to hit.
  auto visible = [&](const Aabb& bounds, double* distance) {
    for (const Eigen::Vector3d& normal : inward_normals) {
      if (outside_plane(bounds, origin, normal)) return false;
    }
    *distance = distance_to(bounds, origin);
    return *distance < max_distance;
  };
  const World::Bvh& bvh = *world_->bvh_;
  double distance = 0.0;
  if (!bvh.nodes.empty()) {
    std::array<int, 64> stack;  // not zeroed: only pushed entries are read
    int depth = 0;
    stack[depth++] = 0;
    while (depth > 0) {
      const World::Bvh::Node& node = bvh.nodes[stack[--depth]];
      if (!visible(node.bounds, &distance)) continue;
      if (node.count == 0) {
        stack[depth++] = node.left;
        stack[depth++] = node.right;
        continue;
      }
      for (int i = node.first; i < node.first + node.count; ++i) {
        if (visible(bvh.primitives[i].bounds, &distance)) group->candidates_.push_back({distance, bvh.primitives[i].object_id});
      }
    }
  }
  for (int i = 0; i < static_cast<int>(moving_.size()); ++i) {
    if (visible(bounds_of(moving_[i].box), &distance)) group->candidates_.push_back({distance, first_moving_ + i});
  }
  std::sort(group->candidates_.begin(), group->candidates_.end(), [](const RayGroup::Candidate& a, const RayGroup::Candidate& b) {
    return a.bound_distance < b.bound_distance || (a.bound_distance == b.bound_distance && a.object_id < b.object_id);
  });
}

std::optional<RayHit> WorldSnapshot::cast(const RayGroup& group, const Eigen::Vector3d& direction, int* object_hint) const {
  const Eigen::Vector3d& origin = group.origin_;
  RayHit hit;
  hit.distance = group.max_distance_;
  bool found = world_->cast_ground(origin, direction, &hit);
  const int hint = object_hint != nullptr ? *object_hint : -1;
  if (hint >= 0 && hint < world_->object_count()) found = intersect(hint, origin, direction, &hit) || found;
  for (const RayGroup::Candidate& candidate : group.candidates_) {
    if (candidate.bound_distance >= hit.distance) break;  // this and every later object lie beyond the hit
    if (candidate.object_id != hint) found = intersect(candidate.object_id, origin, direction, &hit) || found;
  }
  return finish(found, origin, direction, hit, object_hint);
}

}  // namespace hanzo::fusion::sim
