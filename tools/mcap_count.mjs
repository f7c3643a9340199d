#!/usr/bin/env node
// Count the messages per topic of an MCAP log with the TypeScript reader
// (@mcap/core), independently of the Python `mcap` package that wrote it.
//
//   npm ci --prefix tools
//   node tools/mcap_count.mjs logs/run.mcap
//
// Prints one JSON object on stdout:
//   {"library": <header library>,
//    "counts": {topic: messages read, ...},             read through the index, CRCs checked
//    "statistics": {topic: count in the Statistics record, ...},
//    "schemas": {topic: [schema name, schema encoding, message encoding]},
//    "json_errors": number of "json" messages whose data is not a JSON object,
//    "cdr_decoded": number of "cdr" messages decoded by their ros2msg schema (float64 fields only: the
//                   4-byte little-endian CDR header 00 01 00 00, then one float64 per field, t first),
//    "cdr_errors": "cdr" messages of another size or header, or whose t is not the message's log time,
//    "metadata": [names], "attachments": [names]}
// Exit status 1 (message on stderr) if the file cannot be read.
import { open } from "node:fs/promises";

import { McapIndexedReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { decompress } from "fzstd";

const decompressHandlers = {
  zstd: (buffer, decompressedSize) => decompress(buffer, new Uint8Array(Number(decompressedSize))),
};

async function count(path) {
  const handle = await open(path, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileHandleReadable(handle),
      decompressHandlers,
    });
    const counts = {};
    const schemas = {};
    for (const channel of reader.channelsById.values()) {
      counts[channel.topic] = 0;
      const schema = reader.schemasById.get(channel.schemaId);
      schemas[channel.topic] = [schema?.name ?? null, schema?.encoding ?? null, channel.messageEncoding];
    }
    const decoder = new TextDecoder("utf-8", { fatal: true });
    const fieldsOf = new Map(); // schema id -> float64 field names of a ros2msg schema
    for (const schema of reader.schemasById.values()) {
      if (schema.encoding !== "ros2msg") continue;
      const fields = [];
      for (const line of decoder.decode(schema.data).split("\n")) {
        const words = line.split("#")[0].trim().split(/\s+/).filter((w) => w);
        if (words.length === 0) continue;
        if (words.length !== 2 || words[0] !== "float64") throw new Error(`ros2msg ${schema.name}: ${line}`);
        fields.push(words[1]);
      }
      fieldsOf.set(schema.id, fields);
    }
    let jsonErrors = 0;
    let cdrDecoded = 0;
    let cdrErrors = 0;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      const channel = reader.channelsById.get(message.channelId);
      counts[channel.topic] += 1;
      if (channel.messageEncoding === "cdr") {
        const fields = fieldsOf.get(channel.schemaId) ?? [];
        const data = message.data;
        const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
        const header = [0, 1, 0, 0].every((b, i) => data[i] === b);
        if (!header || data.byteLength !== 4 + 8 * fields.length || fields[0] !== "t") {
          cdrErrors += 1;
          continue;
        }
        const payload = Object.fromEntries(fields.map((f, i) => [f, view.getFloat64(4 + 8 * i, true)]));
        if (BigInt(Math.round(payload.t * 1e9)) !== message.logTime) cdrErrors += 1;
        else cdrDecoded += 1;
        continue;
      }
      try {
        const payload = JSON.parse(decoder.decode(message.data));
        if (payload === null || typeof payload !== "object" || Array.isArray(payload)) jsonErrors += 1;
      } catch {
        jsonErrors += 1;
      }
    }
    const statistics = {};
    for (const [id, n] of reader.statistics?.channelMessageCounts ?? []) {
      statistics[reader.channelsById.get(id).topic] = Number(n);
    }
    const metadata = [];
    for await (const record of reader.readMetadata()) metadata.push(record.name);
    const attachments = [];
    for await (const record of reader.readAttachments()) attachments.push(record.name);
    return {
      library: reader.header.library,
      counts,
      statistics,
      schemas,
      json_errors: jsonErrors,
      cdr_decoded: cdrDecoded,
      cdr_errors: cdrErrors,
      metadata,
      attachments,
    };
  } finally {
    await handle.close();
  }
}

const path = process.argv[2];
if (!path) {
  process.stderr.write("usage: node tools/mcap_count.mjs LOG.mcap\n");
  process.exit(2);
}
try {
  process.stdout.write(JSON.stringify(await count(path)) + "\n");
} catch (error) {
  process.stderr.write(`mcap_count: ${path}: ${error.message ?? error}\n`);
  process.exit(1);
}
