// Read an MCAP file with Foxglove's own indexed reader (@mcap/core):
//   node read_mcap.mjs FILE
// prints one JSON object: the profile, each topic's message encoding, schema and message
// count, and the first and last log times, read through the file's summary and index.
import { McapIndexedReader } from "@mcap/core";
import { decompress } from "fzstd";
import { open } from "node:fs/promises";

const handle = await open(process.argv[2], "r");
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, length) => {
    const buffer = new Uint8Array(Number(length));
    await handle.read(buffer, 0, Number(length), Number(offset));
    return buffer;
  },
};
const reader = await McapIndexedReader.Initialize({
  readable,
  decompressHandlers: { zstd: (data) => decompress(data) },
});
const topics = {};
for (const channel of reader.channelsById.values()) {
  const schema = reader.schemasById.get(channel.schemaId);
  topics[channel.topic] = {
    encoding: channel.messageEncoding, schema: schema?.name ?? "", count: 0, first: null, last: null,
  };
}
for await (const message of reader.readMessages()) {
  const topic = topics[reader.channelsById.get(message.channelId).topic];
  topic.count += 1;
  topic.first ??= Number(message.logTime);
  topic.last = Number(message.logTime);
}
await handle.close();
process.stdout.write(JSON.stringify({ profile: reader.header.profile, topics }) + "\n");
