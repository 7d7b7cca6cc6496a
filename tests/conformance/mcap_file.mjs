// An MCAP file opened for @mcap/core's indexed reader (footer, summary, chunk indexes).
import { open } from "node:fs/promises";
import { McapIndexedReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";

// Returns { reader, handle }; close the handle when done.
export async function openIndexedMcap(path, decompressHandlers) {
  const handle = await open(path, "r");
  const size = BigInt((await handle.stat()).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: decompressHandlers ?? await loadDecompressHandlers() });
  return { reader, handle };
}
