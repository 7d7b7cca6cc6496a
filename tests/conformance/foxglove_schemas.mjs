// Checks the Foxglove mirror channels of an MCAP file against Foxglove's published schemas
// (@foxglove/schemas): every field our stored schema declares must exist in the official schema
// with the same number, type and label, and the first message of each channel is decoded with
// the official definition (point clouds: the first points unpacked from their packed fields).
// Prints one JSON object. Usage: node foxglove_schemas.mjs FILE
import { readFile } from "node:fs/promises";
import protobuf from "protobufjs";
import schemas from "@foxglove/schemas/internal.js";
import { McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers, protobufFromBinaryDescriptor } from "@mcap/support";

// The official definitions, generated as Foxglove generates its .proto files.
const official = new protobuf.Root();
official.addJSON(protobuf.common["google/protobuf/timestamp.proto"].nested);
official.addJSON(protobuf.common["google/protobuf/duration.proto"].nested);
for (const schema of Object.values(schemas.foxgloveMessageSchemas)) {
  const enums = [...new Set(schema.fields.filter((f) => f.type.type === "enum").map((f) => f.type.enum))];
  protobuf.parse(schemas.generateProto(schema, enums), official, { keepCase: true });
}
official.resolveAll();

const mismatches = [];
let fieldsCompared = 0;
function compare(ours, theirs, path) {
  for (const field of ours.fieldsArray) {
    field.resolve();
    const other = theirs.fields[field.name];
    const where = `${path}.${field.name}`;
    if (!other) { mismatches.push(`${where}: not in the official schema`); continue; }
    other.resolve();
    fieldsCompared++;
    if (other.id !== field.id) mismatches.push(`${where}: number ${field.id}, official ${other.id}`);
    if (other.repeated !== field.repeated) mismatches.push(`${where}: repeated ${field.repeated}, official ${other.repeated}`);
    const ourType = field.resolvedType ? field.resolvedType.fullName : field.type;
    const theirType = other.resolvedType ? other.resolvedType.fullName : other.type;
    if (ourType !== theirType) { mismatches.push(`${where}: type ${ourType}, official ${theirType}`); continue; }
    if (field.resolvedType instanceof protobuf.Type) compare(field.resolvedType, other.resolvedType, where);
    if (field.resolvedType instanceof protobuf.Enum) {
      for (const [name, value] of Object.entries(field.resolvedType.values)) {
        if (other.resolvedType.values[name] !== value) mismatches.push(`${where}: enum ${name} = ${value} differs`);
      }
    }
  }
}

const readers = { 1: "getUint8", 2: "getInt8", 3: "getUint16", 4: "getInt16", 5: "getUint32", 6: "getInt32", 7: "getFloat32", 8: "getFloat64" };
function firstPoints(cloud, count) {
  const view = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
  const points = [];
  for (let i = 0; i < count && (i + 1) * cloud.point_stride <= cloud.data.byteLength; i++) {
    const point = {};
    for (const f of cloud.fields) point[f.name] = view[readers[f.type]](i * cloud.point_stride + f.offset, true);
    points.push(point);
  }
  return points;
}

const stream = new McapStreamReader({ decompressHandlers: await loadDecompressHandlers(), validateCrcs: true });
stream.append(new Uint8Array(await readFile(process.argv[2])));
const schemasById = new Map(), channelsById = new Map(), channels = {};
let record;
while ((record = stream.nextRecord())) {
  if (record.type === "Schema") schemasById.set(record.id, record);
  if (record.type === "Channel") channelsById.set(record.id, record);
  if (record.type !== "Message") continue;
  const channel = channelsById.get(record.channelId);
  const schema = schemasById.get(channel.schemaId);
  if (!schema.name.startsWith("foxglove.")) continue;
  if (channel.topic in channels) { channels[channel.topic].messages++; continue; }
  const theirs = official.lookupType(schema.name);
  compare(protobufFromBinaryDescriptor(schema.data).lookupType(schema.name), theirs, schema.name);
  const message = theirs.decode(record.data);
  const entry = { schema: schema.name, messages: 1, mirror_of: channel.metadata.get("mirror_of") ?? "",
                  first: theirs.toObject(message, { longs: String, enums: String, defaults: true, bytes: String }) };
  if (schema.name === "foxglove.PointCloud") {
    entry.first_points = firstPoints(message, 3);
    entry.first.data = `${message.data.length} bytes`;
  }
  if (schema.name === "foxglove.RawImage" || schema.name === "foxglove.CompressedImage") entry.first.data = `${message.data.length} bytes`;
  channels[channel.topic] = entry;
}
console.log(JSON.stringify({ channels, fieldsCompared, mismatches }));
