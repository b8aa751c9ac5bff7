// Reads a run.mcap with @mcap/core (the MCAP reference reader in TypeScript) with its CRC
// checks on, and prints the message count per topic, the chunk compressions and whether
// every channel offers a reliable QoS profile (issue 41.3: three independent readers).
//
//   npm install --prefix /tmp/mcapjs @mcap/core fzstd
//   cp tools/mcap_core_read.mjs /tmp/mcapjs/ && node /tmp/mcapjs/mcap_core_read.mjs runs/<run>/run.mcap
//   (ES modules resolve packages from the script's folder, not from NODE_PATH)
//
// (rosbags writes chunk CRCs as 0, "not computed" in the MCAP spec: @mcap/core checks
// every CRC that is not 0.)
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";
import { open } from "node:fs/promises";
const path = process.argv[2];
const handle = await open(path, "r");
const size = (await handle.stat()).size;
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data, size) => decompress(data, new Uint8Array(Number(size))) },
});
const counts = {};
for await (const msg of reader.readMessages({ validateCrcs: true })) {
  const topic = reader.channelsById.get(msg.channelId).topic;
  counts[topic] = (counts[topic] ?? 0) + 1;
}
const compressions = [...new Set(reader.chunkIndexes.map((c) => c.compression))];
console.log(JSON.stringify({ counts, compressions, chunks: reader.chunkIndexes.length,
  qos: [...reader.channelsById.values()].map((c) => [c.topic, c.metadata.get("offered_qos_profiles")?.includes("reliability: reliable")]) }));
await handle.close();
