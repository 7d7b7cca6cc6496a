// Reads a ROS 2 bag's storage file with Foxglove's libraries alone: MCAP by @mcap/core, each
// schema's ROS 2 message definition as stored in the bag parsed by @foxglove/rosmsg; sqlite3
// (.db3, which stores no definitions) by sql.js with the definitions of
// @foxglove/rosmsg-msgs-common (ROS 2 Humble); the CDR decoded by @foxglove/rosmsg2-serialization.
// Prints one JSON object: the profile, each topic's schema name and encoding, and its decoded
// messages (PointCloud2 data as points, OccupancyGrid data as numbers), for
// tests/io/rosbag2_export_conformance_test.cpp.
// Usage: node rosbag2_read.mjs FILE.mcap|FILE.db3
import { readFile } from "node:fs/promises";
import { openIndexedMcap } from "./mcap_file.mjs";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { createRequire } from "node:module";
import { definitions } from "./rosbag2_writing.mjs";

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
const topics = {};
function add(topic, schema, schemaEncoding, messageEncoding, logTime, decoded) {
  if (schema === "sensor_msgs/msg/PointCloud2") {
    decoded.points = cloudPoints(decoded);
    delete decoded.data;
  }
  topics[topic] ??= { schema, schemaEncoding, messageEncoding, logTimes: [], messages: [] };
  topics[topic].logTimes.push(logTime.toString());
  topics[topic].messages.push(plain(decoded));
}

if (process.argv[2].endsWith(".db3")) {
  const SQL = await createRequire(import.meta.url)("sql.js")();
  const db = new SQL.Database(await readFile(process.argv[2]));
  const types = new Map();
  for (const [id, name, type, format] of db.exec("SELECT id, name, type, serialization_format FROM topics")[0].values) {
    types.set(id, { name, type, format, reader: new MessageReader(definitions(type.replace("/msg/", "/"))) });
  }
  for (const [topicId, timestamp, data] of db.exec("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id")[0].values) {
    const topic = types.get(topicId);
    add(topic.name, topic.type, "", topic.format, timestamp, topic.reader.readMessage(data));
  }
  const schema = db.exec("SELECT schema_version, ros_distro FROM schema")[0].values[0];
  console.log(JSON.stringify({ profile: "", schema_version: schema[0], ros_distro: schema[1], topics }));
  process.exit(0);
}

const { reader, handle } = await openIndexedMcap(process.argv[2]);
const decoders = new Map();
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  const schema = reader.schemasById.get(channel.schemaId);
  if (!decoders.has(schema.id)) {
    decoders.set(schema.id, new MessageReader(parse(new TextDecoder().decode(schema.data), { ros2: true })));
  }
  add(channel.topic, schema.name, schema.encoding, channel.messageEncoding, message.logTime, decoders.get(schema.id).readMessage(message.data));
}
await handle.close();
console.log(JSON.stringify({ profile: reader.header.profile, topics }));
