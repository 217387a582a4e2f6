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

const byChannel = new Map(); // channel id -> topic, for a subscription tried again
const retries = new Map(); // channel id -> subscriptions tried again

function subscribe(channelId, topic) {
  bySubscription.set(client.subscribe(channelId), topic);
}

client.on("advertise", (channels) => {
  for (const channel of channels) {
    if (wanted.includes(channel.topic) && !(channel.topic in seen)) {
      seen[channel.topic] = {
        schemaName: channel.schemaName, encoding: channel.encoding, messages: 0, first: null,
      };
      byChannel.set(channel.id, channel.topic);
      subscribe(channel.id, channel.topic);
    }
  }
});

// The SDK's server can refuse a subscription to a channel it has just advertised
// ("Unknown channel ID: N", once in several CI runs, while the view was creating its
// first channels as the client connected). A client that gives up then never sees
// the topic; this one asks again, as a viewer left open would want.
client.on("status", (status) => {
  process.stderr.write(`server status: ${JSON.stringify(status)}\n`);
  const refused = /Unknown channel ID: (\d+)/.exec(status.message ?? "");
  if (refused === null) return;
  const channelId = Number(refused[1]);
  const topic = byChannel.get(channelId);
  const tried = retries.get(channelId) ?? 0;
  if (topic === undefined || tried >= 20) return;
  retries.set(channelId, tried + 1);
  setTimeout(() => subscribe(channelId, topic), 250);
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
