#pragma once
// World: the simulated scene every ray-casting sensor (LiDAR, camera, radar) looks at.
//
// Frames and units: world ENU, metres, radians; times are absolute Timestamps. The scene is
// a ground plane z = ground_height plus static upright boxes (walls, shelves, buildings,
// parked cars: rotated about the vertical only), vertical cylinders (pillars, trees, poles)
// and boxes that walk along a path (people, carts). Each surface carries a Material: its
// procedural texture (what cameras see), LiDAR reflectivity and radar cross section.
//
// Surface coordinates (u, v) in metres, which textures are functions of: ground (x, y);
// box faces: the face's two in-plane box axes measured from the box's lower corner (x faces:
// (y, z); y faces: (x, z); z faces: (x, y)); cylinder side: (arc length from the +x axis,
// height above the base); cylinder top: (x, y) relative to the axis.
//
// Ray casting uses a bounding volume hierarchy over the static objects (surface area
// heuristic), so a cast costs O(log objects); moving boxes are tested one by one. Many
// coherent rays from one origin (a camera image tile) are cheaper through a RayGroup: the
// objects inside their cone are collected once, and each ray then tests only those, nearest
// first, until the next one cannot be nearer than its hit.
// A World is immutable after construction and safe to cast from several threads.

#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/sim/texture.hpp"

namespace hanzo::fusion::sim {

struct Material {
  Texture texture;
  double reflectivity = 0.5;         ///< LiDAR intensity of a face-on, white-textured surface, [0, 1]
  double radar_cross_section = 0.0;  ///< dBsm of the object as one radar target
};

/// An upright box: centre, half extents along its own axes, yaw about the world z axis.
struct Box {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::Vector3d half_size{0.5, 0.5, 0.5};  ///< metres, each > 0
  double yaw = 0.0;                          ///< radians
  Material material;
  std::string class_name = "box";            ///< its segmentation class (ground-truth segmentation)
};

/// A vertical cylinder standing on base_center.
struct Cylinder {
  Eigen::Vector3d base_center = Eigen::Vector3d::Zero();
  double radius = 0.1;  ///< metres, > 0
  double height = 1.0;  ///< metres, > 0
  Material material;
  std::string class_name = "pillar";  ///< its segmentation class
};

/// A box walking a polyline back and forth at constant speed, starting at path[0] at
/// start_time (before it, it stands there). Its yaw follows the walking direction. The box's
/// `center` is ignored; its centre is (path point, ground_height + half_size.z).
struct MovingBox {
  Box box;
  std::string class_name = "person";  ///< what a detector calls it (ground-truth detections)
  std::vector<Eigen::Vector2d> path;  ///< >= 2 points, world x, y
  double speed = 1.2;                 ///< m/s, > 0
  Timestamp start_time;

  /// Centre and velocity (world) at `time`, for a box standing on the ground at ground_height.
  Eigen::Vector3d center_at(Timestamp time, double ground_height) const;
  Eigen::Vector3d velocity_at(Timestamp time) const;
  double yaw_at(Timestamp time) const;
};

struct WorldDescription {
  bool has_ground = true;
  double ground_height = 0.0;
  Material ground;
  std::string ground_class = "ground";  ///< the ground's segmentation class
  std::vector<Box> boxes;
  std::vector<Cylinder> cylinders;
  std::vector<MovingBox> moving_boxes;
};

/// A LiDAR return that no surface made (a weather episode's phantom), as an object id.
inline constexpr int kPhantomReturn = -2;

/// What a ray hit.
struct RayHit {
  double distance = 0.0;                             ///< along the (unit) ray direction, metres
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   ///< world
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ(); ///< outward unit surface normal, world
  Eigen::Vector2d surface_uv = Eigen::Vector2d::Zero();
  const Material* material = nullptr;
  /// -1 the ground, then boxes [0, B), cylinders [B, B + C), moving boxes [B + C, ...).
  int object_id = -1;
  Eigen::Vector3d object_velocity = Eigen::Vector3d::Zero();  ///< world m/s (moving boxes)
};

class World;

/// The objects that rays from one origin with directions inside one convex cone can hit, each
/// with the distance from the origin to its bounds, nearest first (WorldSnapshot::group).
/// Reuse one group for many cones to keep its storage.
class RayGroup {
 public:
  std::size_t size() const { return candidates_.size(); }

 private:
  friend class WorldSnapshot;
  struct Candidate {
    double bound_distance = 0.0;  // metres from the origin to the object's bounding box
    int object_id = 0;            // as RayHit::object_id
  };
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double max_distance_ = 0.0;
  std::vector<Candidate> candidates_;
};

/// The world with its moving boxes placed at one instant: casting many rays at the same time
/// (a camera frame, a LiDAR column) through one snapshot places the moving boxes only once.
/// Valid while its World lives.
class WorldSnapshot {
 public:
  /// As World::cast at the snapshot's time. object_hint (optional, in/out): an object id to
  /// test first, typically what the neighbouring ray hit; it only changes the speed (a near
  /// first hit lets the BVH skip everything behind it), never the result. Receives the id hit.
  std::optional<RayHit> cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
                             int* object_hint = nullptr) const;

  /// Collects into `group` the objects that a ray from `origin` with a unit direction d
  /// satisfying n.dot(d) >= 0 for every n of inward_normals (world-frame normals of planes
  /// through the origin: the sides of a pyramid enclosing the rays) can hit within
  /// max_distance. Conservative: an object is dropped only when its bounding box lies wholly
  /// outside one plane or beyond max_distance. The ground is not a candidate (always tested).
  void group(const Eigen::Vector3d& origin, std::span<const Eigen::Vector3d> inward_normals, double max_distance,
             RayGroup* group) const;
  /// As cast(group origin, direction, group max_distance, object_hint), exactly, for a
  /// direction inside the group's cone; a direction outside it may miss objects.
  std::optional<RayHit> cast(const RayGroup& group, const Eigen::Vector3d& direction, int* object_hint = nullptr) const;

 private:
  friend class World;
  /// Fills hit with object_id's surface when nearer than hit->distance (static or moving).
  bool intersect(int object_id, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const;
  /// Point and velocity of a found hit.
  std::optional<RayHit> finish(bool found, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit hit,
                               int* object_hint) const;

  struct PlacedBox {
    Box box;  // centre and yaw at the snapshot time
    double cos_yaw = 1.0, sin_yaw = 0.0;
    Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
    const Material* material = nullptr;
  };
  const World* world_ = nullptr;
  std::vector<PlacedBox> moving_;
  int first_moving_ = 0;  // object id of moving_[0]
};

class World {
 public:
  explicit World(WorldDescription description);
  ~World();
  World(World&&) noexcept;
  World& operator=(World&&) noexcept;

  /// The nearest surface along origin + s * direction for s in (0, max_distance], seen at
  /// `time` (which places the moving boxes). direction must be a unit vector. Surfaces are hit
  /// from outside only: a ray starting inside a box does not see that box.
  std::optional<RayHit> cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_distance,
                             Timestamp time) const;
  /// The moving boxes placed at `time`, for many casts at that instant.
  WorldSnapshot at(Timestamp time) const;

  const WorldDescription& description() const { return description_; }
  int object_count() const;
  /// The segmentation class of an object id (RayHit::object_id): the ground's, a box's, a
  /// cylinder's, a moving box's class_name; "phantom" for kPhantomReturn.
  const std::string& object_class(int object_id) const;
  /// Whether an object id is one of the moving boxes.
  bool is_moving(int object_id) const;

 private:
  friend class WorldSnapshot;
  struct Bvh;
  /// The ground when nearer than hit->distance.
  bool cast_ground(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const;
  /// The nearest static surface (ground, boxes, cylinders) nearer than hit->distance.
  /// hint: a static object id to test first (or anything else to test none first).
  bool cast_static(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, int hint, RayHit* hit) const;
  bool intersect_object(int object_id, const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, RayHit* hit) const;

  WorldDescription description_;
  std::vector<Eigen::Vector2d> box_trig_;  // (cos, sin) of each box's yaw
  std::unique_ptr<Bvh> bvh_;
};

}  // namespace hanzo::fusion::sim
