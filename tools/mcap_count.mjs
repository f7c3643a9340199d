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
//    "json_errors": number of messages whose data is not a JSON object,
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
    let jsonErrors = 0;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      const topic = reader.channelsById.get(message.channelId).topic;
      counts[topic] += 1;
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
