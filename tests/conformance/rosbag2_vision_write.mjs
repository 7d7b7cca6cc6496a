// Writes a ROS 2 bag (rosbag2_writing.mjs) with a detector's and a segmenter's output beside two
// cameras, as ROS 2 vision pipelines publish them (vision_msgs 4, ROS 2 Humble): boxes as
// vision_msgs/Detection2DArray, a label image as sensor_msgs/Image (mono8, half the camera's
// resolution), the class names as vision_msgs/LabelInfo. Prints one JSON object with the
// detections each camera image must get, for tests/io/rosbag2_conformance_test.cpp.
// Usage: node rosbag2_vision_write.mjs DIR mcap|sqlite3
import { mkdir } from "node:fs/promises";
import { addDefinition, serialize, writeBag } from "./rosbag2_writing.mjs";

// vision_msgs 4.x (ROS 2 Humble and later), the fields of each message.
addDefinition("vision_msgs/Point2D", "float64 x\nfloat64 y");
addDefinition("vision_msgs/Pose2D", "vision_msgs/Point2D position\nfloat64 theta");
addDefinition("vision_msgs/BoundingBox2D", "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y");
addDefinition("vision_msgs/ObjectHypothesis", "string class_id\nfloat64 score");
addDefinition("vision_msgs/ObjectHypothesisWithPose", "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose");
addDefinition("vision_msgs/Detection2D",
              "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\nstring id");
addDefinition("vision_msgs/Detection2DArray", "std_msgs/Header header\nvision_msgs/Detection2D[] detections");
addDefinition("vision_msgs/VisionClass", "uint16 class_id\nstring class_name");
addDefinition("vision_msgs/LabelInfo", "std_msgs/Header header\nvision_msgs/VisionClass[] class_map\nfloat32 threshold");

const [dir, storage] = process.argv.slice(2);
await mkdir(dir, { recursive: true });

const T0 = 1700000000n * 1000000000n;
const time = (ns) => ({ sec: Number(ns / 1000000000n), nanosec: Number(ns % 1000000000n) });
const header = (ns, frame_id) => ({ stamp: time(ns), frame_id });
const messages = [];
const add = (topic, type, recordTime, message) => messages.push({ topic, type, recordTime, data: serialize(type, message) });
const expected = { "/camera/detections": [], "/rear/detections": [] };  // log topic -> per image

const W = 64, H = 48;
const image = (stamp, frame) => ({ header: header(stamp, frame), height: H, width: W, encoding: "rgb8", is_bigendian: 0, step: 3 * W,
                                   data: new Uint8Array(3 * W * H).map((_, k) => (k * 7) % 256) });
const pose = { pose: { position: { x: 0, y: 0, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } }, covariance: new Array(36).fill(0) };
const hypothesis = (class_id, score) => ({ hypothesis: { class_id, score }, pose });
const detection = (stamp, frame, results, cx, cy, sx, sy, theta, id) => ({
  header: header(stamp, frame), results, bbox: { center: { position: { x: cx, y: cy }, theta }, size_x: sx, size_y: sy }, id,
});

// The segmenter's class names (ids 3 and 4 unnamed).
add("/camera/label_info", "vision_msgs/LabelInfo", T0 - 1000000n, {
  header: header(T0, "camera_optical_frame"), threshold: 0.5,
  class_map: [{ class_id: 0, class_name: "person" }, { class_id: 1, class_name: "floor" }, { class_id: 2, class_name: "car" },
              { class_id: 5, class_name: "wall" }],
});
const classes = ["person", "floor", "car", "3", "4", "wall"];

for (let i = 0; i < 5; i++) {
  const stamp = T0 + BigInt(i) * 100000000n;
  add("/camera/image_raw", "sensor_msgs/Image", stamp + 5000000n, image(stamp, "camera_optical_frame"));
  add("/rear/image_raw", "sensor_msgs/Image", stamp + 6000000n, image(stamp, "rear_optical_frame"));
  const boxes = [];
  // Boxes for images 0 to 3 (the detector skipped image 4), 30 ms after their image.
  if (i < 4) {
    add("/camera/detections", "vision_msgs/Detection2DArray", stamp + 30000000n, {
      header: header(stamp, "camera_optical_frame"),
      detections: [
        // class id "0" named by the LabelInfo; the highest-scoring hypothesis counts
        detection(stamp, "camera_optical_frame", [hypothesis("2", 0.25), hypothesis("0", 0.75)], 10 + i, 20, 8, 16, 0, "7"),
        // a rotated box (a quarter turn: 10 x 4 becomes 4 x 10), class by name, tracker id as text
        detection(stamp, "camera_optical_frame", [hypothesis("forklift", 0.5)], 40, 20, 10, 4, Math.PI / 2, "alpha"),
        // over the image's right edge: clipped
        detection(stamp, "camera_optical_frame", [hypothesis("2", 1.0)], 62, 30, 10, 6, 0, ""),
      ],
    });
    boxes.push({ class_name: "person", score: 0.75, box: [6 + i, 12, 14 + i, 28], track_id: 7 },
               { class_name: "forklift", score: 0.5, box: [38, 15, 42, 25], track_id: 0 },
               { class_name: "car", score: 1.0, box: [57, 27, W - 0.5, 33], track_id: -1 });
  }
  // Label images at half resolution for every image, 60 ms after it: a person (0) on the left,
  // car (2) at the bottom right, wall (5) at the top right, unlabelled (255) in between.
  const labels = new Uint8Array((W / 2) * (H / 2)).map((_, k) => {
    const c = k % (W / 2), r = Math.floor(k / (W / 2));
    return c < 8 ? 0 : c >= 24 ? (r >= 12 ? 2 : 5) : c === 12 + i ? 1 : 255;
  });
  add("/camera/segmentation", "sensor_msgs/Image", stamp + 60000000n, {
    header: header(stamp, "camera_optical_frame"), height: H / 2, width: W / 2, encoding: "mono8", is_bigendian: 0, step: W / 2, data: labels,
  });
  const segmentation = [];
  for (let r = 0; r < H; r++) for (let c = 0; c < W; c++) segmentation.push(labels[(r >> 1) * (W / 2) + (c >> 1)]);
  expected["/camera/detections"].push({ stamp: stamp.toString(), boxes, segmentation, classes });

  // The rear camera's detector shares no namespace with it: its frame tells. Image 2's output
  // holds a box wholly outside the image (refused).
  add("/yolo/detections", "vision_msgs/Detection2DArray", stamp + 20000000n, {
    header: header(stamp, "rear_optical_frame"),
    detections: [detection(stamp, "rear_optical_frame", [hypothesis("person", 0.9)], i === 2 ? 200 : 30, 30, 6, 12, 0, "12")],
  });
  if (i !== 2) {
    expected["/rear/detections"].push({ stamp: stamp.toString(), boxes: [{ class_name: "person", score: 0.9, box: [27, 24, 33, 36], track_id: 12 }] });
  }
}
// A ROS 1 style topic that is not read.
add("/chatter", "std_msgs/String", T0, { data: "not a detection" });

const file = await writeBag(dir, storage, messages);
console.log(JSON.stringify({ file, messages: messages.length, expected }));
