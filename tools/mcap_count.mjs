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
//    "cdr_decoded": number of "cdr" messages decoded by their ros2msg schema (float64 fields only, nested
//                   sub-messages flattened in order: the 4-byte little-endian CDR header 00 01 00 00, then
//                   one float64 per leaf field, t first),
//    "cdr_errors": "cdr" messages of another size or header, or whose t is not the message's log time,
//    "ros2msg_bad_names": ["<schema name>: <field>", ...] that Foxglove's ros2msg parser refuses,
//    "row_fields": the leaf fields of the /row schema (format 8) as dotted paths ("t", "state.y", ...), [] if none,
//    "metadata": [names], "attachments": [names]}
//
// A ros2msg schema is read as ROS 2 (rosbag2) and Foxglove (@foxglove/rosmsg) write and read it: the top-level
// definition first, then each dependency after a line of "=" and a line "MSG: <type>"; a field whose type is not
// float64 names one of those types exactly. A field name Foxglove's parser would refuse (ROS 2's rule,
// ^[a-z](?:_?[a-z0-9]+)*$) is listed in "ros2msg_bad_names" as "<schema>: <field>" (format 7 wrote V and J as
// they are; format 8 lower-cases them). Format 7's row topics are flat (no dependency), format 8's /row is nested.
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
    const badNames = [];
    const fieldsOf = new Map(); // schema id -> the float64 leaf fields of a ros2msg schema, dotted, in order
    for (const schema of reader.schemasById.values()) {
      if (schema.encoding !== "ros2msg") continue;
      fieldsOf.set(schema.id, ros2msgLeaves(schema.name, decoder.decode(schema.data), badNames));
    }
    let rowFields = [];
    for (const channel of reader.channelsById.values()) {
      if (channel.topic === "/row") rowFields = fieldsOf.get(channel.schemaId) ?? [];
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
      ros2msg_bad_names: badNames,
      row_fields: rowFields,
      metadata,
      attachments,
    };
  } finally {
    await handle.close();
  }
}

const FIELD_NAME = /^[a-z](?:_?[a-z0-9]+)*$/;

// The float64 leaves of a ros2msg text with dependent definitions, depth first in field order, as dotted paths;
// field names Foxglove would refuse are pushed onto badNames.
function ros2msgLeaves(schemaName, text, badNames) {
  const definitions = new Map(); // type name ("" for the top level) -> [[type, field], ...]
  let name = "";
  let fields = [];
  const close = () => {
    if (definitions.has(name)) throw new Error(`ros2msg ${schemaName}: ${name || "the top level"} defined twice`);
    definitions.set(name, fields);
  };
  for (const raw of text.split("\n")) {
    const line = raw.trim();
    if (line === "" || line.startsWith("#")) continue;
    if (line.startsWith("==")) {
      close();
      name = null; // the next line must be MSG: <type>
      fields = [];
      continue;
    }
    if (name === null) {
      const match = /^MSG: ([^ ]+)\s*(?:#.*)?$/.exec(line);
      if (!match) throw new Error(`ros2msg ${schemaName}: expected "MSG: <type>" after a separator, got ${line}`);
      name = match[1];
      continue;
    }
    const words = line.split("#")[0].trim().split(/\s+/).filter((w) => w);
    if (words.length !== 2 || !/^[A-Za-z][A-Za-z0-9_]*$/.test(words[1])) {
      throw new Error(`ros2msg ${schemaName}: ${line}`);
    }
    if (!FIELD_NAME.test(words[1])) badNames.push(`${schemaName}: ${words[1]}`);
    fields.push(words);
  }
  close();
  const leaves = [];
  const walk = (type, prefix, depth) => {
    const body = definitions.get(type);
    if (body === undefined) throw new Error(`ros2msg ${schemaName}: no definition of ${type}`);
    if (depth > 16) throw new Error(`ros2msg ${schemaName}: ${type} nests too deep`);
    for (const [fieldType, field] of body) {
      if (fieldType === "float64") leaves.push(prefix + field);
      else walk(fieldType, `${prefix}${field}.`, depth + 1);
    }
  };
  walk("", "", 0);
  return leaves;
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
