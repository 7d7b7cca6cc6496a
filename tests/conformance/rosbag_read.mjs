// Reads a ROS1 bag with Foxglove's reader (@foxglove/rosbag, messages deserialized with
// @foxglove/rosmsg-serialization from the bag's own message definitions) and prints one JSON
// object per topic: type, count and, for Imu and Odometry, the values the importer turns into
// hanzo-fusion messages. Usage: node rosbag_read.mjs FILE.bag
import { createRequire } from "node:module";
import { Bag } from "@foxglove/rosbag";
import { loadDecompressHandlers } from "@mcap/support";

const require = createRequire(import.meta.url);
const { FileReader } = require("@foxglove/rosbag/node");

const { bz2, lz4 } = await loadDecompressHandlers();  // the same wasm decompressors Foxglove uses
const bag = new Bag(new FileReader(process.argv[2]), { decompress: { bz2, lz4 } });
await bag.open();
const topics = {};
for (const connection of bag.connections.values()) {
  topics[connection.topic] ??= { type: connection.type, count: 0, imu: [], odometry: [] };
}
const nanoseconds = (t) => (BigInt(t.sec) * 1000000000n + BigInt(t.nsec)).toString();
for await (const result of bag.messageIterator()) {
  const topic = topics[result.topic];
  topic.count += 1;
  const m = result.message;
  if (topic.type === "sensor_msgs/Imu") {
    topic.imu.push({ stamp: nanoseconds(m.header.stamp), frame_id: m.header.frame_id,
                     orientation: [m.orientation.w, m.orientation.x, m.orientation.y, m.orientation.z],
                     angular_velocity: [m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z],
                     linear_acceleration: [m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z],
                     gyroscope_covariance_xx: m.angular_velocity_covariance[0] });
  } else if (topic.type === "nav_msgs/Odometry") {
    topic.odometry.push({ stamp: nanoseconds(m.header.stamp), forward_speed: m.twist.twist.linear.x,
                          yaw_rate: m.twist.twist.angular.z });
  }
}
console.log(JSON.stringify({ topics }));
