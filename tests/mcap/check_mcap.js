// The ROS 2 bag (`vksonar render --out run.mcap`) read back with the MCAP reader (@mcap/core) and every
// message decoded with Foxglove's ROS 2 CDR deserializer (@foxglove/rosmsg2-serialization), the way
// Foxglove reads it. Run by ctest (mcap_ros2) through run_check.sh:
//     node check_mcap.js path/to/vksonar WORKDIR
// Checks, each of which can fail:
//   - header profile ros2; schema names, ros2msg encoding and the dependency blocks rosbag2 writes;
//     cdr channels with offered_qos_profiles; message counts per topic; the rosbag2 metadata record;
//   - every frame's ProjectedSonarImage equals polar.npy and meta.json of the same frame rendered into
//     folders (ranges, beam directions and angles, beamwidths, frequency, intensities bit for bit),
//     the fan image fan.png, the polar image polar_u16.npy, the cloud cloud.ply, /tf the pose;
//   - time stamps (header, log and publish time) from the time column, else frame ordinal / --rate;
//   - CRCs: summary (checked on open), chunks (checked on read), data section (recomputed here);
//   - --compress (zstd chunks) decodes to the same messages; --ros-sonar-dtype uint16 = polar_u16.npy;
//   - a run killed half way (its temporary .~NAME.writing-PID; nothing at OUT), and a file cut in the
//     middle of a chunk, read record by record up to the
//     last whole chunk, equal to the same frames of a whole run;
//   - 3 shard bags (--shard i/3): each its block with the unsharded run's stamps and a vksonar_shard
//     Metadata record; `vksonar merge` of them equals the unsharded bag, message for message and byte
//     for byte;
//   - bad input (an unwritable path, a bad time column, ...) gets one line and exit 2, and no file.
"use strict";
const fs = require("fs");
const path = require("path");
const { spawn, spawnSync } = require("child_process");
const { readIndexed, readStream, readNpy, readPng, readPly, crc32 } = require("./lib.js");

const [CLI, WORK] = process.argv.slice(2);
const SMALL = ["--backend", "cpu", "--set", "bins=64", "--set", "beams=32", "--set", "range_min=6", "--seed", "5"];
const failures = [];
function check(condition, what) {
  if (!condition) {
    failures.push(what);
    console.log("FAIL:", what);
  }
}
function render(args, expect = 0) {
  const run = spawnSync(CLI, ["render", ...args], { encoding: "utf8" });
  check(run.status === expect, `exit ${run.status} (expected ${expect}) for ${args.join(" ")}: ${run.stderr}`);
  return run;
}
const bytesEqual = (a, b) => a.length === b.length && Buffer.compare(Buffer.from(a), Buffer.from(b)) === 0;
const f32Bytes = (a) => new Uint8Array(a.buffer, a.byteOffset, a.byteLength);
const file = (...p) => path.join(WORK, ...p);
const TOPICS = {
  "/vksonar/sonar_image": "marine_acoustic_msgs/msg/ProjectedSonarImage",
  "/vksonar/fan": "sensor_msgs/msg/Image",
  "/vksonar/polar": "sensor_msgs/msg/Image",
  "/vksonar/points": "sensor_msgs/msg/PointCloud2",
  "/tf": "tf2_msgs/msg/TFMessage",
  "/tf_static": "tf2_msgs/msg/TFMessage",
};

// R = Rz(yaw) Ry(pitch) Rx(roll) applied to v, and a quaternion applied to v, independently.
function rotateEuler(rollDeg, pitchDeg, yawDeg, v) {
  const [r, p, y] = [rollDeg, pitchDeg, yawDeg].map((d) => (d * Math.PI) / 180);
  const rx = [v[0], Math.cos(r) * v[1] - Math.sin(r) * v[2], Math.sin(r) * v[1] + Math.cos(r) * v[2]];
  const ry = [Math.cos(p) * rx[0] + Math.sin(p) * rx[2], rx[1], -Math.sin(p) * rx[0] + Math.cos(p) * rx[2]];
  return [Math.cos(y) * ry[0] - Math.sin(y) * ry[1], Math.sin(y) * ry[0] + Math.cos(y) * ry[1], ry[2]];
}
function rotateQuaternion(q, v) {
  const { x, y, z, w } = q;
  const t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])];
  return [v[0] + w * t[0] + (y * t[2] - z * t[1]), v[1] + w * t[1] + (z * t[0] - x * t[2]),
    v[2] + w * t[2] + (x * t[1] - y * t[0])];
}
const near = (a, b, tol = 1e-9) => a.every((v, i) => Math.abs(v - b[i]) <= tol);
const stampNs = (h) => BigInt(h.stamp.sec) * 1000000000n + BigInt(h.stamp.nanosec);

async function main() {
  fs.mkdirSync(WORK, { recursive: true });
  // A trajectory with a time column; the same frames into folders and into bags.
  const poses = [];
  for (let i = 0; i < 5; i++) poses.push([0.25 * i, 0.1 * i, -0.05 * i, 2 * i, 10 + i, 4 * i]);
  // Epoch times to the nanosecond: a double holds them to about 0.2 us only, so the stamps must come
  // from the text (1700000000.923456789 came out 235 ns off through a double); the expected stamps are
  // worked out here from the same text, in BigInt.
  const times = ["1700000000", "1700000000.1", "1700000000.25", "1700000000.923456789", "1700000001.5"];
  const textNs = (t) => {
    const [whole, fraction = ""] = t.split(".");
    return BigInt(whole) * 1000000000n + BigInt((fraction + "000000000").slice(0, 9));
  };
  fs.writeFileSync(file("timed.csv"),
    "time,x,y,z,roll,pitch,yaw\n" + poses.map((p, i) => [times[i], ...p].join(",")).join("\n") + "\n");
  render(["--trajectory", file("timed.csv"), "--out", file("frames"), "--save", "polar,polar_u16,fan,cloud", ...SMALL]);
  render(["--trajectory", file("timed.csv"), "--out", file("run.mcap"), "--save", "default,cloud", ...SMALL]);
  render(["--trajectory", file("timed.csv"), "--out", file("zstd.mcap"), "--save", "default,cloud", "--compress", ...SMALL]);

  const { bytes, reader, messages } = await readIndexed(file("run.mcap"));
  check(reader.header.profile === "ros2", `profile ${reader.header.profile}`);
  // Schemas and channels.
  const byTopic = new Map();
  for (const channel of reader.channelsById.values()) {
    const schema = reader.schemasById.get(channel.schemaId);
    byTopic.set(channel.topic, { channel, schema });
    check(TOPICS[channel.topic] === schema.name, `${channel.topic}: schema ${schema.name}`);
    check(channel.messageEncoding === "cdr", `${channel.topic}: message encoding ${channel.messageEncoding}`);
    check(schema.encoding === "ros2msg", `${channel.topic}: schema encoding ${schema.encoding}`);
    const qos = channel.metadata.get("offered_qos_profiles") || "";
    check(/^- history: 1\n  depth: \d+\n  reliability: 1\n  durability: [12]\n/.test(qos), `${channel.topic}: qos ${qos}`);
  }
  check(byTopic.size === 6, `topics: ${[...byTopic.keys()]}`);
  check(byTopic.get("/tf_static").channel.metadata.get("offered_qos_profiles").includes("durability: 1\n"),
    "/tf_static is transient_local");
  // The dependency blocks of ProjectedSonarImage, in rosbag2's order (depth first, sorted).
  const sonarSchema = new TextDecoder().decode(byTopic.get("/vksonar/sonar_image").schema.data);
  const blocks = [...sonarSchema.matchAll(/\n={80}\nMSG: (\S+)\n/g)].map((m) => m[1]);
  check(JSON.stringify(blocks) === JSON.stringify(["geometry_msgs/Vector3", "marine_acoustic_msgs/PingInfo",
    "marine_acoustic_msgs/SonarImageData", "std_msgs/Header", "builtin_interfaces/Time"]), `blocks ${blocks}`);
  check(sonarSchema.startsWith("# Single scan from an imaging sonar"), "the schema starts with the root .msg");
  check(sonarSchema.includes("uint32  DTYPE_FLOAT32 = 8"), "SonarImageData's constants are in the schema");

  // Counts and statistics.
  const counts = {};
  for (const m of messages) counts[m.topic] = (counts[m.topic] || 0) + 1;
  for (const t of Object.keys(TOPICS))
    check(counts[t] === (t === "/tf_static" ? 1 : 5), `${t}: ${counts[t]} messages`);
  check(reader.statistics.messageCount === BigInt(messages.length), `statistics ${reader.statistics.messageCount}`);
  for (const [id, n] of reader.statistics.channelMessageCounts)
    check(n === BigInt(counts[reader.channelsById.get(id).topic]), `statistics of channel ${id}`);
  check(reader.chunkIndexes.length >= 2, `${reader.chunkIndexes.length} chunks`);
  // CRCs: the summary was checked by Initialize, the chunks by readMessages; the data section here.
  check(reader.dataSectionCrc !== undefined, "a data section CRC is written");
  check(reader.dataSectionCrc === crc32(bytes.subarray(0, Number(reader.dataEndOffset))) >>> 0,
    "data section CRC = CRC-32 of the file up to Data End");
  // rosbag2's metadata record.
  const metadata = [];
  for await (const m of reader.readMetadata({ name: "rosbag2" })) metadata.push(m);
  const yaml = metadata.length === 1 ? metadata[0].metadata.get("serialized_metadata") : "";
  check(/storage_identifier: mcap\n/.test(yaml) && yaml.includes(`message_count: ${messages.length}\n`),
    `rosbag2 metadata: ${yaml}`);

  // Each frame against its folder.
  for (let i = 0; i < 5; i++) {
    const dir = file("frames", `frame_${String(i + 2).padStart(6, "0")}`);
    const meta = JSON.parse(fs.readFileSync(path.join(dir, "meta.json"), "utf8"));
    const polar = readNpy(path.join(dir, "polar.npy")), u16 = readNpy(path.join(dir, "polar_u16.npy"));
    const at = (topic) => messages.filter((m) => m.topic === topic)[i];
    const expectNs = textNs(times[i]);
    for (const topic of ["/vksonar/sonar_image", "/vksonar/fan", "/vksonar/polar", "/vksonar/points", "/tf"]) {
      const m = at(topic);
      const header = topic === "/tf" ? m.decoded.transforms[0].header : m.decoded.header;
      check(m.logTime === expectNs && m.publishTime === expectNs && stampNs(header) === expectNs,
        `frame ${i} ${topic}: times ${m.logTime} ${m.publishTime} ${stampNs(header)}, expected ${expectNs}`);
    }
    const s = at("/vksonar/sonar_image").decoded;
    check(s.header.frame_id === "sonar_acoustic", `frame_id ${s.header.frame_id}`);
    check(s.image.dtype === 8 && s.image.is_bigendian === false && s.image.beam_count === meta.beams,
      `image dtype ${s.image.dtype} beam_count ${s.image.beam_count}`);
    check(polar.shape[0] === meta.bins && polar.shape[1] === meta.beams, `polar.npy shape ${polar.shape}`);
    check(bytesEqual(s.image.data, polar.bytes), `frame ${i}: sonar image data = polar.npy`);
    check(s.ranges.length === meta.bins && s.ranges.every((r, k) => r === Math.fround(meta.ranges_m[k])),
      `frame ${i}: ranges = meta.json ranges_m`);
    check(s.beam_directions.length === meta.beams && s.beam_directions.every((d, j) =>
      d.x === meta.beam_directions[j].x && d.y === meta.beam_directions[j].y && d.z === meta.beam_directions[j].z &&
      Math.abs(Math.atan2(-d.y, d.z) - meta.beam_angles_rad[j]) < 1e-12), `frame ${i}: beam directions`);
    const pi = s.ping_info;
    check(pi.frequency === Math.fround(meta.frequency_hz) && pi.sound_speed === Math.fround(meta.sound_speed_mps),
      `ping info ${pi.frequency} ${pi.sound_speed}`);
    check(pi.tx_beamwidths.every((w, j) => w === Math.fround(meta.tx_beamwidths_rad[j])) &&
      pi.rx_beamwidths.every((w, j) => w === Math.fround(meta.rx_beamwidths_rad[j])) &&
      pi.tx_beamwidths.length === meta.beams && pi.rx_beamwidths.length === meta.beams, "beamwidths");

    const fan = at("/vksonar/fan").decoded, png = readPng(path.join(dir, "fan.png"));
    check(fan.encoding === "rgb8" && fan.width === png.width && fan.height === png.height &&
      fan.step === 3 * fan.width && png.channels === 3 && bytesEqual(fan.data, png.data), `frame ${i}: fan = fan.png`);
    const p = at("/vksonar/polar").decoded;
    const flipped = new Uint16Array(meta.bins * meta.beams);
    for (let k = 0; k < meta.bins; k++)
      flipped.set(u16.array.subarray((meta.bins - 1 - k) * meta.beams, (meta.bins - k) * meta.beams), k * meta.beams);
    check(p.encoding === "mono16" && p.height === meta.bins && p.width === meta.beams && p.step === 2 * meta.beams &&
      bytesEqual(p.data, f32Bytes(flipped)), `frame ${i}: polar image = polar_u16.npy, far range first`);
    const cloud = at("/vksonar/points").decoded, ply = readPly(path.join(dir, "cloud.ply"));
    check(cloud.fields.map((f) => `${f.name}:${f.offset}:${f.datatype}:${f.count}`).join(",") ===
      "x:0:7:1,y:4:7:1,z:8:7:1,intensity:12:7:1", "cloud fields");
    check(cloud.width === ply.count && cloud.height === 1 && cloud.point_step === 16 && ply.count > 0 &&
      bytesEqual(cloud.data, ply.bytes), `frame ${i}: cloud = cloud.ply (${cloud.width} vs ${ply.count} points)`);
    const tf = at("/tf").decoded.transforms;
    const pose = meta.pose;
    check(tf.length === 1 && tf[0].header.frame_id === "world" && tf[0].child_frame_id === "sonar", "tf frames");
    const t = tf[0].transform;
    check(near([t.translation.x, t.translation.y, t.translation.z], [pose.x_m, pose.y_m, pose.z_m], 0), "tf translation");
    for (const v of [[1, 0, 0], [0, 1, 0], [0, 0, 1]])
      check(near(rotateQuaternion(t.rotation, v), rotateEuler(pose.roll_deg, pose.pitch_deg, pose.yaw_deg, v), 1e-12),
        `frame ${i}: tf rotation of ${v}`);
  }
  const st = messages.find((m) => m.topic === "/tf_static").decoded.transforms[0];
  check(st.header.frame_id === "sonar" && st.child_frame_id === "sonar_acoustic", "tf_static frames");
  check(near(rotateQuaternion(st.transform.rotation, [0, 0, 1]), [1, 0, 0], 1e-15) &&
    near(rotateQuaternion(st.transform.rotation, [1, 0, 0]), [0, 0, 1], 1e-15), "sonar_acoustic: Z forward, X up");

  // zstd: the same messages, smaller.
  const packed = await readIndexed(file("zstd.mcap"));
  check(packed.reader.chunkIndexes.every((c) => c.compression === "zstd"), "zstd chunks");
  check(packed.messages.length === messages.length &&
    packed.messages.every((m, k) => bytesEqual(m.data, messages[k].data)), "zstd: the same messages");
  const [plainSize, packedSize] = [fs.statSync(file("run.mcap")).size, fs.statSync(file("zstd.mcap")).size];
  check(packedSize < plainSize, `zstd ${packedSize} < ${plainSize} bytes`);
  console.log(`sizes: ${plainSize} bytes plain, ${packedSize} zstd (${(100 * packedSize / plainSize).toFixed(0)} %)`);

  // No time column: frame ordinal / --rate; uint16 sonar data; another prefix and frame.
  fs.writeFileSync(file("plain.csv"), "x,y,z,roll,pitch,yaw\n" + poses.map((p) => p.join(",")).join("\n") + "\n");
  render(["--trajectory", file("plain.csv"), "--out", file("rate.mcap"), "--rate", "4", "--ros-sonar-dtype", "uint16",
    "--ros-prefix", "/auv/sonar/", "--ros-frame", "fls", "--save", "polar", ...SMALL]);
  const rated = await readIndexed(file("rate.mcap"));
  const sonars = rated.messages.filter((m) => m.topic === "/auv/sonar/sonar_image");
  check(sonars.length === 5 && sonars.every((m, k) => m.logTime === BigInt(k) * 250000000n), "stamps = ordinal / rate");
  check(JSON.stringify([...new Set(rated.messages.map((m) => m.topic))].sort()) ===
    JSON.stringify(["/auv/sonar/sonar_image", "/tf", "/tf_static"]), "--save polar: the sonar image and tf only");
  sonars.forEach((m, k) => {
    const u16 = readNpy(file("frames", `frame_${String(k + 2).padStart(6, "0")}`, "polar_u16.npy"));
    check(m.decoded.image.dtype === 2 && bytesEqual(m.decoded.image.data, f32Bytes(u16.array)),
      `uint16 sonar image ${k} = polar_u16.npy`);
    check(m.decoded.header.frame_id === "fls_acoustic", `frame id ${m.decoded.header.frame_id}`);
  });
  // A single --pose: one frame at time 0.
  render(["--pose", "0,0,0,0,10,0", "--out", file("one.mcap"), ...SMALL]);
  const one = await readIndexed(file("one.mcap"));
  check(one.messages.length === 5 && one.messages.every((m) => m.logTime === 0n), `--pose: ${one.messages.length}`);

  // A file cut in the middle of its last chunk: the whole chunks before it are read, then an error.
  const cutAt = Number(reader.chunkIndexes[reader.chunkIndexes.length - 1].chunkStartOffset) + 100;
  const cut = readStream(bytes.subarray(0, cutAt));
  const wholeChunks = reader.chunkIndexes.length - 1;
  const before = messages.filter((m) => m.logTime <= reader.chunkIndexes[wholeChunks - 1].messageEndTime);
  check(cut.chunks === wholeChunks && !cut.done, `cut file: ${cut.chunks} whole chunks of ${reader.chunkIndexes.length}`);
  check(cut.messages.length === before.length && cut.messages.every((m, k) => bytesEqual(m.data, before[k].data)),
    `cut file: ${cut.messages.length} messages, expected ${before.length}`);

  // Killed half way: the chunks on disk are whole and equal a whole run's frames.
  const long = [];
  for (let i = 0; i < 3000; i++) long.push(`${0.001 * i},0,0,0,10,${0.01 * i}`);
  fs.writeFileSync(file("long.csv"), long.join("\n") + "\n");
  // An unsharded run writes a temporary beside OUT and renames it onto OUT only when it is complete.
  const child = spawn(CLI, ["render", "--trajectory", file("long.csv"), "--out", file("killed.mcap"), ...SMALL], { stdio: "ignore" });
  const killedPath = file(`.~killed.mcap.writing-${child.pid}`);
  let exited = false;
  child.on("exit", () => (exited = true));
  const deadline = Date.now() + 60000;
  while (Date.now() < deadline && !exited && !(fs.existsSync(killedPath) && fs.statSync(killedPath).size > 8e6))
    await new Promise((r) => setTimeout(r, 20));
  check(!exited, "the long run ended before it could be killed (make it longer)");
  child.kill("SIGKILL");
  await new Promise((r) => (exited ? r() : child.on("exit", r)));
  check(!fs.existsSync(file("killed.mcap")), "a killed unsharded run leaves nothing at OUT");
  const killed = readStream(fs.readFileSync(killedPath));
  const killedSonar = killed.messages.filter((m) => m.topic === "/vksonar/sonar_image");
  const frames = killedSonar.length;
  check(killed.chunks > 0 && frames > 0 && frames < 3000, `killed run: ${killed.chunks} chunks, ${frames} frames`);
  check(killed.messages.filter((m) => m.topic === "/vksonar/fan").length === frames &&
    killed.messages.filter((m) => m.topic === "/tf").length === frames, "killed run: whole frames only");
  fs.writeFileSync(file("head.csv"), long.slice(0, frames).join("\n") + "\n");
  render(["--trajectory", file("head.csv"), "--out", file("head.mcap"), ...SMALL]);
  const head = await readIndexed(file("head.mcap"));
  const headSonar = head.messages.filter((m) => m.topic === "/vksonar/sonar_image");
  check(headSonar.length === frames && killedSonar.every((m, k) => bytesEqual(m.data, headSonar[k].data)),
    `killed run: the ${frames} frames equal a whole run's`);
  console.log(`killed run: ${frames} whole frames in ${killed.chunks} chunks (${killed.error ? "ends in a partial record" : "ends at a record boundary"})`);

  // Sharded bags, read by @mcap/core (summary and chunk CRCs): each of 3 shards holds its block with
  // the unsharded run's stamps (no time column: global ordinal / --rate) and a vksonar_shard Metadata
  // record; `vksonar merge` gives the unsharded bag, message for message and byte for byte.
  fs.writeFileSync(file("untimed.csv"), "x,y,z,roll,pitch,yaw\n" +
    poses.concat(poses).map((p) => p.join(",")).join("\n") + "\n"); // 10 frames: 0..2, 3..5, 6..9
  fs.mkdirSync(file("sharded"), { recursive: true });
  fs.mkdirSync(file("merged"), { recursive: true });
  render(["--trajectory", file("untimed.csv"), "--out", file("sharded", "run.mcap"), "--rate", "4", ...SMALL]);
  const whole = await readIndexed(file("sharded", "run.mcap"));
  const parts = [];
  for (let i = 0; i < 3; i++) {
    parts.push(file("sharded", `part${i}.mcap`));
    render(["--trajectory", file("untimed.csv"), "--out", parts[i], "--rate", "4", "--shard", `${i}/3`, ...SMALL]);
    const part = await readIndexed(parts[i]);
    const records = [];
    for await (const m of part.reader.readMetadata({ name: "vksonar_shard" })) records.push(m.metadata);
    const [first, end] = [[0, 3], [3, 6], [6, 10]][i];
    check(records.length === 1 && records[0].get("index") === `${i}` && records[0].get("count") === "3" &&
      records[0].get("first") === `${first}` && records[0].get("end") === `${end}` && records[0].get("identity.rate") === "4",
      `shard ${i}/3: vksonar_shard record ${records.length ? [...records[0].entries()].join(" ") : "missing"}`);
    const stamps = part.messages.filter((m) => m.topic === "/tf").map((m) => m.logTime);
    const want = whole.messages.filter((m) => m.topic === "/tf").slice(first, end).map((m) => m.logTime);
    check(stamps.length === end - first && stamps.every((t, k) => t === want[k] && t === BigInt(first + k) * 250000000n),
      `shard ${i}/3: /tf stamps ${stamps} vs ${want}`);
  }
  const merge = spawnSync(CLI, ["merge", file("merged", "run.mcap"), ...parts], { encoding: "utf8" });
  check(merge.status === 0, `merge of 3 bag shards: ${merge.stderr}`);
  const merged = await readIndexed(file("merged", "run.mcap"));
  const key = (m) => `${m.topic} ${m.sequence} ${m.logTime} ${m.publishTime}`;
  check(merged.messages.length === whole.messages.length &&
    merged.messages.every((m, k) => key(m) === key(whole.messages[k]) && bytesEqual(m.data, whole.messages[k].data)),
    "merged shards: the unsharded bag's messages (topic, sequence, stamps, data)");
  check(bytesEqual(merged.bytes, whole.bytes), "merged shards: the unsharded bag byte for byte");
  // The run record: what the bag's messages depend on, in the unsharded bag and (being the same bytes)
  // the merged one; none in a shard's bag (its vksonar_shard record holds the same as identity.*).
  const runRecords = async (bag) => {
    const records = [];
    for await (const m of bag.reader.readMetadata({ name: "vksonar_run" })) records.push(m.metadata);
    return records;
  };
  let fnv = 0xcbf29ce484222325n; // FNV-1a 64 of the trajectory file's bytes
  for (const b of fs.readFileSync(file("untimed.csv"))) fnv = ((fnv ^ BigInt(b)) * 0x100000001b3n) & 0xffffffffffffffffn;
  const version = spawnSync(CLI, ["--version"], { encoding: "utf8" }).stdout.trim().split(/\s+/).pop();
  for (const [name, bag] of [["unsharded", whole], ["merged", merged]]) {
    const records = await runRecords(bag);
    const r = records.length === 1 ? records[0] : new Map();
    let config = {};
    try { config = JSON.parse(r.get("config") || "{}"); } catch (e) { config = {}; }
    check(records.length === 1 && r.get("seed") === "5" && r.get("backend") === "cpu" && r.get("frames") === "10" &&
      r.get("trajectory") === fnv.toString(16).padStart(16, "0") && /^[0-9a-f]{16}$/.test(r.get("scene_fnv1a64") || "") &&
      r.get("rate") === "4" && r.get("ros_prefix") === "/vksonar" && config.bins === 64 && config.beams === 32 &&
      r.get("vksonar_version") === version,
      `${name} bag: vksonar_run record ${records.length ? [...r.entries()].map(([k, v]) => `${k}=${v.slice(0, 40)}`).join(" ") : "missing"}`);
  }
  for (const part of parts) check((await runRecords(await readIndexed(part))).length === 0, `${part}: a run record in a shard's bag`);
  // One --pose: its --frame-index keys the noise, so the run record that renders the bag again holds it
  // (an audit's: it was missing); a rate reads back as written (29.97, not 29.969999999999999).
  render(["--pose", "1,0,0,0,10,3", "--frame-index", "7", "--rate", "29.97", "--out", file("single.mcap"),
    "--save", "polar", ...SMALL]);
  const single = await runRecords(await readIndexed(file("single.mcap")));
  check(single.length === 1 && single[0].get("frame_index") === "7" && single[0].get("rate") === "29.97",
    `single pose bag: vksonar_run ${single.length ? [...single[0].entries()].map(([k, v]) => `${k}=${v.slice(0, 30)}`).join(" ") : "missing"}`);
  console.log(`shards: 3 bags merged into ${merged.messages.length} messages, ${merged.bytes.length} bytes, ` +
    `identical to the unsharded bag: ${bytesEqual(merged.bytes, whole.bytes)}`);

  // Bad input: one line, exit 2, no file.
  const bad = (args, expect, what) => {
    const run = render(args, 2);
    check(run.stderr.trim().split("\n").length === 1 && expect.every((e) => run.stderr.includes(e)), `${what}: ${run.stderr}`);
  };
  bad(["--out", file("no_such_folder", "x.mcap"), ...SMALL], ["no_such_folder"], "missing folder");
  fs.mkdirSync(file("dir.mcap"), { recursive: true });
  bad(["--out", file("dir.mcap"), ...SMALL], ["dir.mcap", "directory"], "a directory in the way");
  fs.writeFileSync(file("badtime.csv"), "t,x,y,z,roll,pitch,yaw\n0,0,0,0,0,10,0\nabc,0,0,0,0,10,0\n");
  bad(["--trajectory", file("badtime.csv"), "--out", file("badtime.mcap"), ...SMALL], ["badtime.csv:3", "time", "abc"],
    "bad time value");
  fs.writeFileSync(file("negative.csv"), "time_s,x,y,z,roll,pitch,yaw\n-1,0,0,0,0,10,0\n");
  bad(["--trajectory", file("negative.csv"), "--out", file("negative.mcap"), ...SMALL], ["negative.csv:2", "time -1"],
    "negative time");
  bad(["--trajectory", file("timed.csv"), "--out", file("rate2.mcap"), "--rate", "5", ...SMALL], ["--rate", "time column"],
    "--rate with a time column");
  bad(["--out", file("depth.mcap"), "--save", "depth", ...SMALL], ["--save depth"], "--save depth");
  bad(["--out", file("prefix.mcap"), "--ros-prefix", "no slash", ...SMALL], ["--ros-prefix"], "bad prefix");
  // ROS 2 refuses a name token that starts with a digit (ros2 bag play could not publish it); tf2 takes a
  // frame id that does, but not the world frame as the sonar's (a world -> world transform); a sonar dtype
  // with no sonar_image topic to set means nothing.
  bad(["--out", file("digit.mcap"), "--ros-prefix", "/auv/1st", ...SMALL], ["--ros-prefix", "digit"], "digit prefix");
  bad(["--out", file("world.mcap"), "--ros-frame", "world", ...SMALL], ["--ros-frame", "world frame"], "world frame");
  bad(["--out", file("dtype.mcap"), "--save", "fan", "--ros-sonar-dtype", "uint16", ...SMALL], ["--ros-sonar-dtype"],
    "dtype without polar");
  render(["--out", file("digit_frame.mcap"), "--ros-frame", "2nd_sonar", "--save", "polar", ...SMALL]);
  for (const f of ["badtime.mcap", "negative.mcap", "rate2.mcap", "depth.mcap", "prefix.mcap"])
    check(!fs.existsSync(file(f)), `no file left after a refusal: ${f}`);

  if (failures.length) {
    console.log(`${failures.length} check(s) failed`);
    process.exit(1);
  }
  console.log(`mcap: all checks passed (${messages.length} messages decoded in the main bag)`);
}

main().catch((e) => {
  console.log("FAIL:", e.stack || e);
  process.exit(1);
});
