// A NATS subscriber built only from the `nats` package of the npm registry (nats.js), as any
// third-party tool would write one: it connects with a user and password, subscribes to a
// subject pattern and prints every message it gets as "<subject> <payload in hex>", one
// per line, until it has `count` of them. The cluster integration test decodes the payloads
// with the project's protobuf code, so what this checks is that a foreign client reads
// mocapd's subjects and bytes unchanged.
//
//   node nats_subscriber.mjs URL USER PASSWORD SUBJECT COUNT TIMEOUT_S
//
// Exit 0 after COUNT messages; 1 on a connection error or when TIMEOUT_S passes first.
import { connect } from "nats";

const [url, user, pass, subject, countArg, timeoutArg] = process.argv.slice(2);
const count = Number(countArg);
const timeoutMs = Number(timeoutArg) * 1000;
if (!url || !subject || !(count > 0) || !(timeoutMs > 0)) {
  console.error("usage: node nats_subscriber.mjs URL USER PASSWORD SUBJECT COUNT TIMEOUT_S");
  process.exit(2);
}

const nc = await connect({ servers: url, user, pass });
const sub = nc.subscribe(subject, { max: count });
// Tell the test the subscription is in place (the server has seen it after the flush).
await nc.flush();
console.error("subscribed");
const timer = setTimeout(() => {
  console.error(`timeout: ${sub.getReceived()} of ${count} messages`);
  process.exit(1);
}, timeoutMs);
const lines = [];
for await (const m of sub) lines.push(`${m.subject} ${Buffer.from(m.data).toString("hex")}`);
clearTimeout(timer);
process.stdout.write(lines.join("\n") + "\n");
await nc.close();
