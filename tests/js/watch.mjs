// Watch a Foxglove WebSocket server with Foxglove's own client (@foxglove/ws-protocol):
//   node watch.mjs URL SECONDS MIN_SCENES
// subscribes to every channel, decodes /scene (protobuf, with the schema the server
// advertises) and the JSON plot channels, and prints one JSON object on stdout.
import wsProtocol from "@foxglove/ws-protocol";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, seconds, minScenes] = [process.argv[2], Number(process.argv[3]), Number(process.argv[4])];
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const out = { protocol: null, serverName: null, channels: {}, scenes: [], plots: {} };
const bySubscription = new Map();
const decoders = new Map();

function decoderFor(channel) {
  if (channel.encoding === "json") {
    const text = new TextDecoder();
    return (bytes) => JSON.parse(text.decode(bytes));
  }
  const bytes = Buffer.from(channel.schema, "base64");
  const root = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(bytes));
  const type = root.lookupType(channel.schemaName);
  return (data) => type.toObject(type.decode(data), { longs: Number });
}

function finish(code) {
  client.close();
  process.stdout.write(JSON.stringify(out) + "\n");
  process.exit(code);
}

client.on("open", () => { out.protocol = ws.protocol; });
client.on("serverInfo", (info) => { out.serverName = info.name; });
client.on("error", (err) => { process.stderr.write(String(err) + "\n"); finish(2); });
client.on("close", () => finish(out.scenes.length >= minScenes ? 0 : 3));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    out.channels[channel.topic] = { encoding: channel.encoding, schemaName: channel.schemaName };
    decoders.set(channel.id, decoderFor(channel));
    bySubscription.set(client.subscribe(channel.id), channel);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = bySubscription.get(subscriptionId);
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  const message = decoders.get(channel.id)(bytes);
  if (channel.topic === "/scene") {
    out.scenes.push({
      timestamp: Number(timestamp),
      ids: message.entities.map((e) => e.id),
      caption: (message.entities.find((e) => e.id === "arena")?.texts ?? [{}])[0].text ?? "",
    });
    if (out.scenes.length >= minScenes) finish(0);
  } else {
    (out.plots[channel.topic] ??= []).push(message);
  }
});
setTimeout(() => finish(out.scenes.length >= minScenes ? 0 : 3), seconds * 1000);
