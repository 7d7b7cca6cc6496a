// Writing ROS 2 bags the way rosbag2 lays them out (a folder with metadata.yaml and one storage
// file) with Foxglove's libraries: CDR by @foxglove/rosmsg2-serialization from the ROS 2 Humble
// definitions of @foxglove/rosmsg-msgs-common, MCAP by @mcap/core (profile ros2), SQLite by
// sql.js. Used by rosbag2_write.mjs and ros1_to_ros2.mjs.
import { open, writeFile } from "node:fs/promises";
import { createRequire } from "node:module";
import { McapWriter } from "@mcap/core";
import { MessageWriter } from "@foxglove/rosmsg2-serialization";
import { ros2humble } from "@foxglove/rosmsg-msgs-common";
import { stringify } from "@foxglove/rosmsg";

const require = createRequire(import.meta.url);
const initSqlJs = require("sql.js");

// Message definitions beyond ROS 2 Humble's common interfaces (e.g. vision_msgs), by name.
const extraDefinitions = {};
const PRIMITIVES = new Set(["bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
                            "float32", "float64", "string"]);
// Adds the definition of `name` ("vision_msgs/Point2D") from its fields, one "type name" per
// line ("float64 x", "vision_msgs/Point2D[] points", "float64[36] covariance").
export function addDefinition(name, fields) {
  const definitions = fields.trim().split("\n").map((line) => {
    const [declared, field] = line.trim().split(/\s+/);
    const [, type, array, length] = declared.match(/^([^[]+)(\[(\d*)\])?$/);
    return { name: field, type, isComplex: !PRIMITIVES.has(type), isArray: array !== undefined,
             ...(length ? { arrayLength: Number(length) } : {}) };
  });
  extraDefinitions[name] = { name, definitions };
}

// The definition of `type` followed by every type it uses (MessageWriter's input).
export function definitions(type) {
  const out = [];
  const visit = (name) => {
    if (out.some((d) => d.name === name)) return;
    const definition = extraDefinitions[name] ?? ros2humble[name];
    out.push(definition);
    for (const field of definition.definitions) if (field.isComplex) visit(field.type);
  };
  visit(type);
  return out;
}
export const ros2Name = (type) => type.replace("/", "/msg/");  // sensor_msgs/Imu -> sensor_msgs/msg/Imu

const writers = new Map();
// The CDR bytes of `message` of ROS 1-style type name `type` ("sensor_msgs/Imu").
export function serialize(type, message) {
  if (!writers.has(type)) writers.set(type, new MessageWriter(definitions(type)));
  return writers.get(type).writeMessage(message);
}

// Writes `messages` ({ topic, type (ROS 1-style), recordTime (bigint ns), data (CDR) }) as the
// bag folder `dir` with one storage file (storage "mcap" or "sqlite3"); returns its file name.
export async function writeBag(dir, storage, messages) {
  // rosbag2 stores messages by record time.
  messages.sort((a, b) => (a.recordTime < b.recordTime ? -1 : a.recordTime > b.recordTime ? 1 : 0));
  const topics = [...new Set(messages.map((m) => m.topic))].map((topic) => ({
    topic, type: messages.find((m) => m.topic === topic).type, count: messages.filter((m) => m.topic === topic).length,
  }));
  const file = `${dir.split("/").pop()}_0.${storage === "mcap" ? "mcap" : "db3"}`;

  if (storage === "mcap") {
    const handle = await open(`${dir}/${file}`, "w");
    let position = 0n;
    const writable = {
      position: () => position,
      write: async (buffer) => { await handle.write(buffer); position += BigInt(buffer.byteLength); },
    };
    const writer = new McapWriter({ writable, useChunks: true, chunkSize: 4096 });
    await writer.start({ profile: "ros2", library: "rosbag2 conformance (@mcap/core)" });
    const channelIds = {};
    for (const { topic, type } of topics) {
      const schemaId = await writer.registerSchema({ name: ros2Name(type), encoding: "ros2msg",
                                                     data: new TextEncoder().encode(stringify(definitions(type))) });
      channelIds[topic] = await writer.registerChannel({ topic, schemaId, messageEncoding: "cdr",
                                                         metadata: new Map([["offered_qos_profiles", ""]]) });
    }
    let sequence = 0;
    for (const m of messages) {
      await writer.addMessage({ channelId: channelIds[m.topic], sequence: sequence++, logTime: m.recordTime,
                                publishTime: m.recordTime, data: m.data });
    }
    await writer.end();
    await handle.close();
  } else {
    const SQL = await initSqlJs();
    const db = new SQL.Database();
    db.run(`CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
            INSERT INTO schema VALUES (3, 'humble');
            CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
            CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                                serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
            CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
                                  data BLOB NOT NULL);
            CREATE INDEX timestamp_idx ON messages (timestamp ASC);`);
    topics.forEach(({ topic, type }, i) => db.run("INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')", [i + 1, topic, ros2Name(type)]));
    const topicId = Object.fromEntries(topics.map(({ topic }, i) => [topic, i + 1]));
    messages.forEach((m, i) => db.run("INSERT INTO messages VALUES (?, ?, ?, ?)",
                                      [i + 1, topicId[m.topic], m.recordTime.toString(), m.data]));
    await writeFile(`${dir}/${file}`, db.export());
    db.close();
  }

  const first = messages[0].recordTime, last = messages[messages.length - 1].recordTime;
  await writeFile(`${dir}/metadata.yaml`, `rosbag2_bagfile_information:
  version: 5
  storage_identifier: ${storage}
  duration:
    nanoseconds: ${last - first}
  starting_time:
    nanoseconds_since_epoch: ${first}
  message_count: ${messages.length}
  topics_with_message_count:
${topics.map(({ topic, type, count }) => `    - topic_metadata:
        name: ${topic}
        type: ${ros2Name(type)}
        serialization_format: cdr
        offered_qos_profiles: ""
      message_count: ${count}`).join("\n")}
  compression_format: ""
  compression_mode: ""
  relative_file_paths:
    - ${file}
  files:
    - path: ${file}
      starting_time:
        nanoseconds_since_epoch: ${first}
      duration:
        nanoseconds: ${last - first}
      message_count: ${messages.length}
`);
  return file;
}
