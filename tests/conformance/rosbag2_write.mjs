// Writes a ROS 2 bag (rosbag2_writing.mjs) holding every sensor type the importer reads, in the
// layouts of the common ROS 2 drivers, and prints one JSON object with the values written, for
// tests/io/rosbag2_conformance_test.cpp to compare the import against.
// Usage: node rosbag2_write.mjs DIR mcap|sqlite3
import { mkdir } from "node:fs/promises";
import { deflateSync } from "node:zlib";
import { crc32 } from "@foxglove/crc";
import { ros2Name, serialize, writeBag } from "./rosbag2_writing.mjs";

const [dir, storage] = process.argv.slice(2);
await mkdir(dir, { recursive: true });

const T0 = 1700000000n * 1000000000n;  // header stamps start here (ns)
const time = (ns) => ({ sec: Number(ns / 1000000000n), nanosec: Number(ns % 1000000000n) });
const messages = [];  // { topic, type, recordTime (ns), data }
const written = {};   // per topic: what the test compares against
function add(topic, type, recordTime, message, expected) {
  messages.push({ topic, type, recordTime, data: serialize(type, message) });
  (written[topic] ??= { type: ros2Name(type), messages: [] }).messages.push(expected);
}
const header = (ns, frame_id) => ({ stamp: time(ns), frame_id });

// IMU at 100 Hz, with covariances; the record time lags the stamp by 2 ms.
for (let i = 0; i < 50; i++) {
  const stamp = T0 + BigInt(i) * 10000000n;
  const w = [0.01 * i, -0.02, 0.3 + 0.001 * i], a = [0.1, -0.05 * i, 9.81];
  add("/imu/data", "sensor_msgs/Imu", stamp + 2000000n, {
    header: header(stamp, "imu_link"),
    orientation: { x: 0, y: 0, z: Math.sin(0.01 * i), w: Math.cos(0.01 * i) },
    orientation_covariance: [0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01],
    angular_velocity: { x: w[0], y: w[1], z: w[2] },
    angular_velocity_covariance: [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4],
    linear_acceleration: { x: a[0], y: a[1], z: a[2] },
    linear_acceleration_covariance: [0, 0, 0, 0, 0, 0, 0, 0, 0],
  }, { stamp: stamp.toString(), angular_velocity: w, linear_acceleration: a, orientation_z: Math.sin(0.01 * i) });
}

// GNSS at 5 Hz; the second fix has no fix.
for (let i = 0; i < 5; i++) {
  const stamp = T0 + BigInt(i) * 200000000n;
  const lla = [48.1 + 1e-6 * i, 11.5 - 2e-6 * i, 520.25 + i];
  add("/gps/fix", "sensor_msgs/NavSatFix", stamp, {
    header: header(stamp, "gps"), status: { status: i === 1 ? -1 : 0, service: 1 },
    latitude: lla[0], longitude: lla[1], altitude: lla[2],
    position_covariance: [0.25, 0, 0, 0, 0.25, 0, 0, 0, 1.0], position_covariance_type: 2,
  }, { stamp: stamp.toString(), lla, fix: i !== 1 });
}

// Point clouds in the layouts of the common ROS 2 LiDAR drivers. `time(k, stampNs)` is the value
// stored for point k; `expected(k)` its absolute time in ns.
const FLOAT32 = 7, FLOAT64 = 8, UINT8 = 2, UINT16 = 4, UINT32 = 6;
const SIZE = { [UINT8]: 1, [UINT16]: 2, [UINT32]: 4, [FLOAT32]: 4, [FLOAT64]: 8 };
function cloud(topic, frame, pointStep, fields, values, count) {
  for (let scan = 0; scan < 3; scan++) {
    const stamp = T0 + BigInt(scan) * 100000000n;
    const data = new Uint8Array(pointStep * count);
    const view = new DataView(data.buffer);
    const points = [];
    for (let k = 0; k < count; k++) {
      const v = values(k, stamp);
      for (const f of fields) {
        const at = k * pointStep + f.offset, x = v[f.name];
        if (f.datatype === FLOAT32) view.setFloat32(at, x, true);
        else if (f.datatype === FLOAT64) view.setFloat64(at, x, true);
        else if (f.datatype === UINT32) view.setUint32(at, x, true);
        else if (f.datatype === UINT16) view.setUint16(at, x, true);
        else view.setUint8(at, x);
      }
      points.push({ xyz: [Math.fround(v.x), Math.fround(v.y), Math.fround(v.z)], time: v.expected.toString(), ring: v.ring_id });
    }
    add(topic, "sensor_msgs/PointCloud2", stamp + 50000000n, {
      header: header(stamp, frame), height: 1, width: count,
      fields: fields.map((f) => ({ name: f.name, offset: f.offset, datatype: f.datatype, count: 1 })),
      is_bigendian: false, point_step: pointStep, row_step: pointStep * count, data, is_dense: true,
    }, { stamp: stamp.toString(), points });
  }
}
const xyz = (k) => ({ x: 1 + 0.5 * k, y: -2 + 0.25 * k, z: 0.125 * k });
// velodyne_driver: float32 seconds after the stamp in "time", ring uint16.
cloud("/velodyne_points", "velodyne", 22,
      [{ name: "x", offset: 0, datatype: FLOAT32 }, { name: "y", offset: 4, datatype: FLOAT32 },
       { name: "z", offset: 8, datatype: FLOAT32 }, { name: "intensity", offset: 12, datatype: FLOAT32 },
       { name: "ring", offset: 16, datatype: UINT16 }, { name: "time", offset: 18, datatype: FLOAT32 }],
      (k, stamp) => ({ ...xyz(k), intensity: 10 * k, ring: k % 16, ring_id: k % 16, time: k * 0.00125,
                       expected: stamp + BigInt(Math.round(Math.fround(k * 0.00125) * 1e9)) }), 40);
// ouster-ros: uint32 ns after the stamp in "t", ring uint16, padding after z.
cloud("/ouster/points", "os_sensor", 48,
      [{ name: "x", offset: 0, datatype: FLOAT32 }, { name: "y", offset: 4, datatype: FLOAT32 },
       { name: "z", offset: 8, datatype: FLOAT32 }, { name: "intensity", offset: 16, datatype: FLOAT32 },
       { name: "t", offset: 20, datatype: UINT32 }, { name: "reflectivity", offset: 24, datatype: UINT16 },
       { name: "ring", offset: 26, datatype: UINT16 }, { name: "ambient", offset: 28, datatype: UINT16 },
       { name: "range", offset: 32, datatype: UINT32 }],
      (k, stamp) => ({ ...xyz(k), intensity: 100 + k, t: k * 781250, reflectivity: 7, ring: k % 64, ring_id: k % 64,
                       ambient: 3, range: 1000 * k, expected: stamp + BigInt(k * 781250) }), 40);
// livox_ros_driver2: float64 absolute ns in "timestamp", laser line uint8 in "line".
cloud("/livox/lidar", "livox_frame", 26,
      [{ name: "x", offset: 0, datatype: FLOAT32 }, { name: "y", offset: 4, datatype: FLOAT32 },
       { name: "z", offset: 8, datatype: FLOAT32 }, { name: "intensity", offset: 12, datatype: FLOAT32 },
       { name: "tag", offset: 16, datatype: UINT8 }, { name: "line", offset: 17, datatype: UINT8 },
       { name: "timestamp", offset: 18, datatype: FLOAT64 }],
      (k, stamp) => ({ ...xyz(k), intensity: 30, tag: 0, line: k % 4, ring_id: k % 4,
                       timestamp: Number(stamp + BigInt(k) * 10000n),
                       // float64 holds ns since 1970 to 256 ns: the value stored is the expected one
                       expected: BigInt(Number(stamp + BigInt(k) * 10000n)) }), 40);
// HesaiLidar_ROS_2.0: float64 absolute seconds in "timestamp" (microsecond steps), ring uint16.
cloud("/hesai/pandar", "hesai_lidar", 48,
      [{ name: "x", offset: 0, datatype: FLOAT32 }, { name: "y", offset: 4, datatype: FLOAT32 },
       { name: "z", offset: 8, datatype: FLOAT32 }, { name: "intensity", offset: 16, datatype: FLOAT32 },
       { name: "timestamp", offset: 24, datatype: FLOAT64 }, { name: "ring", offset: 32, datatype: UINT16 }],
      (k, stamp) => {
        const seconds = Number(stamp / 1000000000n) + Number(stamp % 1000000000n) / 1e9 + k * 5e-5;
        // The importer rounds absolute seconds to the microsecond (a float64's precision there).
        return { ...xyz(k), intensity: 50, timestamp: seconds, ring: k % 32, ring_id: k % 32,
                 expected: stamp + BigInt(k) * 50000n };
      }, 40);

// Camera: raw mono8 images with row padding, PNG-compressed images, and its CameraInfo.
const W = 32, H = 24;
const pixel = (i, r, c) => (i * 37 + r * 16 + c * 3) % 256;
for (let i = 0; i < 3; i++) {
  const stamp = T0 + BigInt(i) * 50000000n;
  const step = W + 4;
  const data = new Uint8Array(step * H);
  const pixels = [];
  for (let r = 0; r < H; r++) for (let c = 0; c < W; c++) { data[r * step + c] = pixel(i, r, c); pixels.push(pixel(i, r, c)); }
  add("/camera/image_raw", "sensor_msgs/Image", stamp, {
    header: header(stamp, "camera_optical_frame"), height: H, width: W, encoding: "mono8", is_bigendian: 0, step, data,
  }, { stamp: stamp.toString(), pixels });
}
function png(width, height, rgb) {  // an 8-bit RGB PNG file
  const chunk = (type, body) => {
    const out = new Uint8Array(12 + body.length), view = new DataView(out.buffer);
    view.setUint32(0, body.length);
    out.set(new TextEncoder().encode(type), 4);
    out.set(body, 8);
    view.setUint32(8 + body.length, crc32(out.subarray(4, 8 + body.length)));
    return out;
  };
  const ihdr = new Uint8Array(13), view = new DataView(ihdr.buffer);
  view.setUint32(0, width); view.setUint32(4, height);
  ihdr.set([8, 2, 0, 0, 0], 8);
  const rows = new Uint8Array(height * (1 + 3 * width));
  for (let r = 0; r < height; r++) rows.set(rgb.subarray(r * 3 * width, (r + 1) * 3 * width), r * (1 + 3 * width) + 1);
  const parts = [new Uint8Array([137, 80, 78, 71, 13, 10, 26, 10]), chunk("IHDR", ihdr), chunk("IDAT", deflateSync(rows)),
                 chunk("IEND", new Uint8Array())];
  const file = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  parts.reduce((at, p) => (file.set(p, at), at + p.length), 0);
  return file;
}
for (let i = 0; i < 2; i++) {
  const stamp = T0 + BigInt(i) * 50000000n + 1000000n;
  const rgb = new Uint8Array(W * H * 3).map((_, k) => (k * 11 + i * 5) % 256);
  add("/camera/image_raw/compressed", "sensor_msgs/CompressedImage", stamp, {
    header: header(stamp, "camera_optical_frame"), format: "rgb8; png compressed bgr8", data: png(W, H, rgb),
  }, { stamp: stamp.toString(), rgb: Array.from(rgb) });
}
add("/camera/camera_info", "sensor_msgs/CameraInfo", T0, {
  header: header(T0, "camera_optical_frame"), height: H, width: W, distortion_model: "plumb_bob",
  d: [-0.28, 0.07, 0.0002, -0.0001, 0.0], k: [30.5, 0, 16.2, 0, 30.1, 12.1, 0, 0, 1],
  r: [1, 0, 0, 0, 1, 0, 0, 0, 1], p: [30.5, 0, 16.2, 0, 0, 30.1, 12.1, 0, 0, 0, 1, 0], binning_x: 0, binning_y: 0,
  roi: { x_offset: 0, y_offset: 0, height: 0, width: 0, do_rectify: false },
}, {});

// Wheel odometry as nav_msgs/Odometry and as geometry_msgs/TwistStamped (v, yaw rate).
for (let i = 0; i < 10; i++) {
  const stamp = T0 + BigInt(i) * 50000000n;
  const v = 0.5 + 0.1 * i, w = 0.2 - 0.03 * i;
  const zeros = (n) => new Array(n).fill(0);
  add("/odom", "nav_msgs/Odometry", stamp, {
    header: header(stamp, "odom"), child_frame_id: "base_link",
    pose: { pose: { position: { x: i, y: 0, z: 0 }, orientation: { x: 0, y: 0, z: 0, w: 1 } }, covariance: zeros(36) },
    twist: { twist: { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } }, covariance: zeros(36) },
  }, { stamp: stamp.toString(), v, w });
  add("/wheel/twist", "geometry_msgs/TwistStamped", stamp, {
    header: header(stamp, "base_link"), twist: { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } },
  }, { stamp: stamp.toString(), v, w });
}

// The static transforms: base_link -> imu_link, velodyne, os_sensor, livox_frame, gps,
// camera_link -> camera_optical_frame; hesai_lidar is in no transform.
const transform = (parent, child, t, q) => ({
  header: header(T0, parent), child_frame_id: child,
  transform: { translation: { x: t[0], y: t[1], z: t[2] }, rotation: { x: q[1], y: q[2], z: q[3], w: q[0] } },
});
const s = Math.SQRT1_2;
const transforms = [transform("base_link", "imu_link", [0.1, 0, 0.2], [1, 0, 0, 0]),
                    transform("base_link", "velodyne", [0, 0, 0.8], [s, 0, 0, s]),
                    transform("base_link", "os_sensor", [0, 0.1, 0.9], [1, 0, 0, 0]),
                    transform("base_link", "livox_frame", [0.2, 0, 0.7], [Math.cos(0.1), 0, Math.sin(0.1), 0]),
                    transform("base_link", "gps", [-0.2, 0, 1.1], [1, 0, 0, 0]),
                    transform("base_link", "camera_link", [0.3, 0.05, 0.4], [1, 0, 0, 0]),
                    transform("camera_link", "camera_optical_frame", [0, 0, 0], [0.5, -0.5, 0.5, -0.5])];
add("/tf_static", "tf2_msgs/TFMessage", T0, { transforms }, { transforms: transforms.map((t) => ({
  parent: t.header.frame_id, child: t.child_frame_id,
  translation: [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
  rotation_wxyz: [t.transform.rotation.w, t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z] })) });
add("/chatter", "std_msgs/String", T0, { data: "not a sensor" }, {});

const file = await writeBag(dir, storage, messages);
console.log(JSON.stringify({ file, messages: messages.length, topics: written }));
