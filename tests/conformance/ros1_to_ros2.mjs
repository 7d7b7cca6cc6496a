// Converts a ROS 1 bag into a ROS 2 bag with Foxglove's libraries: @foxglove/rosbag reads and
// deserializes the ROS 1 messages, rosbag2_writing.mjs writes them as CDR (ROS 2 Humble layouts:
// std_msgs/Header without seq, builtin_interfaces/Time {sec, nanosec}). Topics whose type has
// no ROS 2 definition are left out. Prints one JSON object: { file, topics: {topic: count} }.
// Usage: node ros1_to_ros2.mjs IN.bag OUT_DIR mcap|sqlite3
import { mkdir } from "node:fs/promises";
import { createRequire } from "node:module";
import { Bag } from "@foxglove/rosbag";
import { loadDecompressHandlers } from "@mcap/support";
import { ros2humble } from "@foxglove/rosmsg-msgs-common";
import { serialize, writeBag } from "./rosbag2_writing.mjs";

const require = createRequire(import.meta.url);
const { FileReader } = require("@foxglove/rosbag/node");

const [input, dir, storage] = process.argv.slice(2);
await mkdir(dir, { recursive: true });
const { bz2, lz4 } = await loadDecompressHandlers();
const reader = new FileReader(input);
const bag = new Bag(reader, { decompress: { bz2, lz4 } });
await bag.open();

// A ROS 1 message object as its ROS 2 counterpart: times {sec, nsec} -> {sec, nanosec}, no seq.
function toRos2(value) {
  if (Array.isArray(value) || ArrayBuffer.isView(value) || value === null || typeof value !== "object") return value;
  if (Object.keys(value).length === 2 && "sec" in value && "nsec" in value) return { sec: value.sec, nanosec: value.nsec };
  const out = {};
  for (const [key, field] of Object.entries(value)) {
    if (key !== "seq") out[key] = Array.isArray(field) ? field.map(toRos2) : toRos2(field);
  }
  return out;
}

const messages = [];
const topics = {};
for await (const result of bag.messageIterator()) {
  const type = bag.connections.get(result.connectionId).type;
  if (!ros2humble[type]) continue;
  const recordTime = BigInt(result.timestamp.sec) * 1000000000n + BigInt(result.timestamp.nsec);
  messages.push({ topic: result.topic, type, recordTime, data: serialize(type, toRos2(result.message)) });
  topics[result.topic] = (topics[result.topic] ?? 0) + 1;
}
await reader.close();
const file = await writeBag(dir, storage, messages);
console.log(JSON.stringify({ file, topics }));
