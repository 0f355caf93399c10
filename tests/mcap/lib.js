// Reading what `vksonar render` writes, with independent readers: the MCAP file with @mcap/core, its
// messages with Foxglove's ROS 2 .msg parser and CDR deserializer, the per-frame files (.npy, .png,
// .ply, meta.json) with the small parsers below. CommonJS, run with NODE_PATH naming the folder the
// packages of package.json were installed into (tests/mcap/run_check.sh).
"use strict";
const fs = require("fs");
const zlib = require("zlib");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { parse: parseMessageDefinition } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { crc32 } = require("@foxglove/crc");
const fzstd = require("fzstd");

const decompressHandlers = { zstd: (buffer) => fzstd.decompress(buffer) };

// A ROS 2 CDR deserializer for each schema (ros2msg text -> @foxglove/rosmsg -> MessageReader).
function makeDecoders(schemasById) {
  const decoders = new Map();
  for (const [id, schema] of schemasById) {
    if (schema.encoding !== "ros2msg") throw new Error(`schema ${schema.name}: encoding ${schema.encoding}`);
    const text = new TextDecoder().decode(schema.data);
    decoders.set(id, new MessageReader(parseMessageDefinition(text, { ros2: true })));
  }
  return decoders;
}

// The whole file through the summary (the summary CRC is checked by Initialize, chunk CRCs on read).
async function readIndexed(path) {
  const bytes = fs.readFileSync(path);
  const readable = {
    size: async () => BigInt(bytes.length),
    read: async (offset, length) => bytes.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const decoders = makeDecoders(reader.schemasById);
  const messages = [];
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(m.channelId);
    messages.push({ ...m, topic: channel.topic, decoded: decoders.get(channel.schemaId).readMessage(m.data) });
  }
  return { bytes, reader, messages };
}

// Record by record from the start, as a reader recovers a file cut short: the records up to the
// first one that is not whole, and the error that stopped it (null at a clean end).
function readStream(bytes) {
  const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true, includeChunks: true });
  stream.append(bytes);
  const schemas = new Map(), channels = new Map(), messages = [];
  let chunks = 0, error = null, done = false;
  try {
    for (let record; (record = stream.nextRecord()); ) {
      if (record.type === "Schema") schemas.set(record.id, record);
      else if (record.type === "Channel") channels.set(record.id, record);
      else if (record.type === "Message") messages.push(record);
      else if (record.type === "Chunk") chunks++;
    }
    done = stream.done();
  } catch (e) {
    error = e;
  }
  const decoders = makeDecoders(schemas);
  for (const m of messages) {
    const channel = channels.get(m.channelId);
    m.topic = channel.topic;
    m.decoded = decoders.get(channel.schemaId).readMessage(m.data);
  }
  return { messages, chunks, error, done };
}

function readNpy(path) {
  const b = fs.readFileSync(path);
  const headerLength = b.readUInt16LE(8);
  const header = b.subarray(10, 10 + headerLength).toString("latin1");
  const descr = /'descr':\s*'([^']+)'/.exec(header)[1];
  const shape = /'shape':\s*\(([^)]*)\)/.exec(header)[1].split(",").filter((s) => s.trim()).map(Number);
  const data = b.subarray(10 + headerLength);
  const copy = new Uint8Array(data).buffer; // aligned
  const array = descr === "<f4" ? new Float32Array(copy) : descr === "<u2" ? new Uint16Array(copy) : null;
  if (!array) throw new Error(`${path}: dtype ${descr}`);
  return { shape, array, bytes: new Uint8Array(copy) };
}

// An 8-bit RGB or RGBA PNG, not interlaced (what stb_image_write and writePng below write).
function readPng(path) {
  const b = fs.readFileSync(path);
  let width = 0, height = 0, channels = 0;
  const idat = [];
  for (let at = 8; at < b.length; ) {
    const length = b.readUInt32BE(at), type = b.toString("latin1", at + 4, at + 8);
    const body = b.subarray(at + 8, at + 8 + length);
    if (type === "IHDR") {
      width = body.readUInt32BE(0);
      height = body.readUInt32BE(4);
      if (body[8] !== 8 || body[12] !== 0) throw new Error(`${path}: not 8-bit non-interlaced`);
      channels = { 2: 3, 6: 4, 0: 1 }[body[9]];
    } else if (type === "IDAT") idat.push(body);
    at += 12 + length;
  }
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const stride = width * channels, out = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= channels ? out[y * stride + x - channels] : 0;
      const up = y > 0 ? out[(y - 1) * stride + x] : 0;
      const c = y > 0 && x >= channels ? out[(y - 1) * stride + x - channels] : 0;
      let p = line[x];
      if (filter === 1) p += a;
      else if (filter === 2) p += up;
      else if (filter === 3) p += (a + up) >> 1;
      else if (filter === 4) {
        const e = a + up - c, pa = Math.abs(e - a), pb = Math.abs(e - up), pc = Math.abs(e - c);
        p += pa <= pb && pa <= pc ? a : pb <= pc ? up : c;
      }
      out[y * stride + x] = p & 0xff;
    }
  }
  return { width, height, channels, data: out };
}

function writePng(path, width, height, rgb) {
  const chunk = (type, body) => {
    const head = Buffer.alloc(8);
    head.writeUInt32BE(body.length, 0);
    head.write(type, 4, "latin1");
    const crc = Buffer.alloc(4);
    crc.writeUInt32BE(crc32(Buffer.concat([head.subarray(4), body])) >>> 0, 0);
    return Buffer.concat([head, body, crc]);
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(width, 0);
  ihdr.writeUInt32BE(height, 4);
  ihdr[8] = 8; // bit depth
  ihdr[9] = 2; // RGB
  const raw = Buffer.alloc(height * (3 * width + 1));
  for (let y = 0; y < height; y++)
    Buffer.from(rgb.buffer, rgb.byteOffset + y * 3 * width, 3 * width).copy(raw, y * (3 * width + 1) + 1);
  const signature = Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]);
  fs.writeFileSync(path, Buffer.concat([signature, chunk("IHDR", ihdr), chunk("IDAT", zlib.deflateSync(raw, { level: 9 })),
    chunk("IEND", Buffer.alloc(0))]));
}

// A binary little-endian PLY of float x, y, z, intensity (host::write_points_ply).
function readPly(path) {
  const b = fs.readFileSync(path);
  const end = b.indexOf("end_header\n") + "end_header\n".length;
  const count = Number(/element vertex (\d+)/.exec(b.toString("latin1", 0, end))[1]);
  return { count, bytes: new Uint8Array(b.subarray(end, end + 16 * count)) };
}

module.exports = { readIndexed, readStream, readNpy, readPng, writePng, readPly, crc32 };
