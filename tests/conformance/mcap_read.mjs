// Reads an MCAP file with Foxglove's own MCAP library (@mcap/core, @mcap/support) and prints
// one JSON object describing it, for tests/io/mcap_conformance_test.cpp to compare with what the
// C++ writer wrote. Usage: node mcap_read.mjs FILE
import { readFile } from "node:fs/promises";
import { crc32 } from "@foxglove/crc";
import { McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers, protobufFromBinaryDescriptor } from "@mcap/support";
import { openIndexedMcap } from "./mcap_file.mjs";

const path = process.argv[2];
const decompressHandlers = await loadDecompressHandlers();

// 1. Indexed reading: footer, summary (its CRC is checked), chunk indexes, messages in log-time order.
const { reader, handle } = await openIndexedMcap(path, decompressHandlers);
const channels = [...reader.channelsById.values()].map((c) => {
  const schema = reader.schemasById.get(c.schemaId);
  return { id: c.id, topic: c.topic, messageEncoding: c.messageEncoding, metadata: Object.fromEntries(c.metadata),
           schemaName: schema?.name ?? "", schemaEncoding: schema?.encoding ?? "" };
});
const decoders = new Map();
const messages = [];
const decoded = {};
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  messages.push({ topic: channel.topic, logTime: message.logTime.toString(), sequence: message.sequence,
                  crc32: crc32(message.data), size: message.data.length });
  // Decode the first message of every protobuf channel from the schema stored in the file alone.
  const schema = reader.schemasById.get(channel.schemaId);
  if (schema?.encoding === "protobuf" && !(channel.topic in decoded)) {
    if (!decoders.has(schema.id)) decoders.set(schema.id, protobufFromBinaryDescriptor(schema.data).lookupType(schema.name));
    const type = decoders.get(schema.id);
    decoded[channel.topic] = type.toObject(type.decode(message.data), { longs: String, defaults: true });
  }
}
await handle.close();

// 2. Streaming every record from the start with CRC validation (chunk CRCs), plus the
//    data-section CRC, which McapStreamReader does not check: CRC-32 of all bytes before DataEnd.
const bytes = new Uint8Array(await readFile(path));
const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true, includeChunks: true });
stream.append(bytes);
const recordCounts = {};
let record;
let dataSectionCrc = null;
let offset = 8;  // records after the magic; track offsets to find DataEnd
while ((record = stream.nextRecord())) {
  recordCounts[record.type] = (recordCounts[record.type] ?? 0) + 1;
  if (record.type === "DataEnd") dataSectionCrc = record.dataSectionCrc;
}
let dataEndOffset = null;
for (let position = 8; position + 9 <= bytes.length; ) {
  const view = new DataView(bytes.buffer, position);
  const opcode = bytes[position];
  const length = Number(view.getBigUint64(1, true));
  if (opcode === 0x0f) { dataEndOffset = position; break; }
  position += 9 + length;
}
const computedDataCrc = dataEndOffset == null ? null : crc32(bytes.subarray(0, dataEndOffset));

console.log(JSON.stringify({
  header: reader.header,
  statistics: reader.statistics ? { messageCount: reader.statistics.messageCount.toString(),
                                    chunkCount: reader.statistics.chunkCount,
                                    channelCount: reader.statistics.channelCount } : null,
  chunkIndexes: reader.chunkIndexes.length,
  metadataIndexes: reader.metadataIndexes.map((m) => m.name),
  channels, messages, decoded, recordCounts,
  dataSectionCrc: { stored: dataSectionCrc, computed: computedDataCrc },
}));
