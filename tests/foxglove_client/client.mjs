// A Foxglove WebSocket client for tests/test_live.py, on the protocol's own client
// library (@foxglove/ws-protocol): connect to URL, subscribe to the TOPICS, and print
// as JSON each topic's schema, message count and first message (base64) once every
// topic has COUNT messages, or whatever came when TIMEOUT_S ran out (exit code 1).
import protocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = protocol;

const [url, topicList, countArg, timeoutArg] = process.argv.slice(2);
const wanted = topicList.split(",");
const count = Number(countArg);
const seen = {};
const bySubscription = new Map();

// The SDK's server speaks the same protocol under its new name, foxglove.sdk.v1; the
// client offers both and the server picks.
const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.sdk.v1"]),
});

function report(code) {
  process.stdout.write(JSON.stringify(seen) + "\n");
  client.close();
  process.exit(code);
}

client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (wanted.includes(channel.topic) && !(channel.topic in seen)) {
      seen[channel.topic] = {
        schemaName: channel.schemaName, encoding: channel.encoding, messages: 0, first: null,
      };
      bySubscription.set(client.subscribe(channel.id), channel.topic);
    }
  }
});

client.on("message", ({ subscriptionId, data }) => {
  const topic = bySubscription.get(subscriptionId);
  if (topic === undefined) return;
  const entry = seen[topic];
  entry.messages += 1;
  if (entry.first === null) {
    entry.first = Buffer.from(data.buffer, data.byteOffset, data.byteLength).toString("base64");
  }
  if (wanted.every((t) => t in seen && seen[t].messages >= count)) report(0);
});

client.on("error", (err) => {
  process.stderr.write(`client error: ${err}\n`);
});

setTimeout(() => report(1), Number(timeoutArg) * 1000);
