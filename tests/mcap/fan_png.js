// The fan image of one frame of a bag, decoded back from its sensor_msgs/Image message and written as
// a PNG: node fan_png.js run.mcap out.png [frame (default 0)] [topic (default /vksonar/fan)].
// (How docs/images/mcap_fan.png was made.) Needs NODE_PATH with the packages of package.json.
"use strict";
const { readIndexed, writePng } = require("./lib.js");

async function main() {
  const [path, out, frame = "0", topic = "/vksonar/fan"] = process.argv.slice(2);
  if (!path || !out) throw new Error("usage: node fan_png.js run.mcap out.png [frame] [topic]");
  const { messages } = await readIndexed(path);
  const fans = messages.filter((m) => m.topic === topic);
  const m = fans[Number(frame)];
  if (!m) throw new Error(`${path}: no frame ${frame} on ${topic} (${fans.length} frames)`);
  const image = m.decoded;
  if (image.encoding !== "rgb8") throw new Error(`${topic}: encoding ${image.encoding}, not rgb8`);
  writePng(out, image.width, image.height, image.data);
  console.log(`${out}: ${image.width}x${image.height} rgb8, stamp ${image.header.stamp.sec}.` +
    `${String(image.header.stamp.nanosec).padStart(9, "0")} s, frame_id ${image.header.frame_id}`);
}

main().catch((e) => {
  console.error(`fan_png: ${e.message}`);
  process.exit(1);
});
