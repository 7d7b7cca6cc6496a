// Writes an MCAP file with Foxglove's own writer (@mcap/core) and prints one JSON object
// listing what it wrote, for tests/io/mcap_conformance_test.cpp to read back with the C++
// reader. Usage: node mcap_write.mjs FILE chunked|unchunked
import { open } from "node:fs/promises";
import { crc32 } from "@foxglove/crc";
import { McapWriter } from "@mcap/core";

const [path, mode] = process.argv.slice(2);
const handle = await open(path, "w");
let position = 0n;
const writable = {
  position: () => position,
  write: async (buffer) => { await handle.write(buffer); position += BigInt(buffer.byteLength); },
};
const writer = new McapWriter({ writable, useChunks: mode === "chunked", chunkSize: 2048 });
await writer.start({ profile: "", library: "@mcap/core conformance" });
const schemaId = await writer.registerSchema({ name: "example.Blob", encoding: "jsonschema",
                                               data: new TextEncoder().encode('{"type":"object"}') });
const topics = ["/a", "/b"];
const channelIds = [];
for (const topic of topics) {
  channelIds.push(await writer.registerChannel({ topic, schemaId, messageEncoding: "json", metadata: new Map([["k", topic]]) }));
}
const written = [];
for (let i = 0; i < 400; i++) {
  const channel = i % 2;
  // Times go back now and then, so the reader has to sort.
  const logTime = 1_000_000_000n + BigInt(i) * 1000n - (i % 7 === 3 ? 2500n : 0n);
  const data = new TextEncoder().encode(JSON.stringify({ i, text: "x".repeat(i % 50) }));
  await writer.addMessage({ channelId: channelIds[channel], sequence: i, logTime, publishTime: logTime, data });
  written.push({ topic: topics[channel], logTime: logTime.toString(), sequence: i, crc32: crc32(data), size: data.length });
}
await writer.addMetadata({ name: "origin", metadata: new Map([["writer", "@mcap/core"]]) });
await writer.end();
await handle.close();
console.log(JSON.stringify({ written }));
