// Reads a ROS 2 bag (MCAP storage) with Foxglove's libraries alone: @mcap/core for the file,
// @foxglove/rosmsg to parse each schema's ROS 2 message definition as stored in the bag,
// @foxglove/rosmsg2-serialization to decode the CDR. Prints one JSON object: the profile, each
// topic's schema name and encoding, and its decoded messages (PointCloud2 data as points,
// OccupancyGrid data as numbers), for tests/io/rosbag2_export_conformance_test.cpp.
// Usage: node rosbag2_read.mjs FILE.mcap
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";

const handle = await open(process.argv[2], "r");
const size = BigInt((await handle.stat()).size);
const readable = {
  size: async () => size,
  read: async (offset, length) => {
    const buffer = new Uint8Array(Number(length));
    await handle.read(buffer, 0, Number(length), Number(offset));
    return buffer;
  },
};
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: await loadDecompressHandlers() });

// Plain JSON of a decoded message: bigints as strings, typed arrays as arrays.
function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value);
  if (Array.isArray(value)) return value.map(plain);
  if (value && typeof value === "object") return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  return value;
}
function cloudPoints(cloud) {
  const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
  const field = (name) => cloud.fields.find((f) => f.name === name);
  const points = [];
  for (let i = 0; i < cloud.width * cloud.height; i++) {
    const at = i * cloud.point_step;
    const point = ["x", "y", "z"].map((n) => view.getFloat32(at + field(n).offset, true));
    if (field("intensity")) point.push(view.getFloat32(at + field("intensity").offset, true));
    points.push(point);
  }
  return points;
}

const decoders = new Map();
const topics = {};
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  const schema = reader.schemasById.get(channel.schemaId);
  if (!decoders.has(schema.id)) {
    decoders.set(schema.id, new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true })));
  }
  const decoded = decoders.get(schema.id).readMessage(message.data);
  if (schema.name === "sensor_msgs/msg/PointCloud2") {
    decoded.points = cloudPoints(decoded);
    delete decoded.data;
  }
  topics[channel.topic] ??= { schema: schema.name, schemaEncoding: schema.encoding, messageEncoding: channel.messageEncoding,
                              logTimes: [], messages: [] };
  topics[channel.topic].logTimes.push(message.logTime.toString());
  topics[channel.topic].messages.push(plain(decoded));
}
await handle.close();
console.log(JSON.stringify({ profile: reader.header.profile, topics }));
