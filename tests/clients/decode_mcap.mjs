// Decodes every message of an MCAP written by travmap with the libraries Foxglove
// itself uses (@mcap/core, @foxglove/rosmsg, @foxglove/rosmsg2-serialization) and
// prints the same JSON summary per message as decode_mcap.py.
// Usage: node decode_mcap.mjs FILE.mcap
import { readFileSync } from "node:fs";
import { McapStreamReader } from "@mcap/core";
import { parse } from "@foxglove/rosmsg";
import { MessageReader } from "@foxglove/rosmsg2-serialization";
import { decompress as zstdDecompress } from "fzstd";
import lz4 from "lz4js";

const bytes = readFileSync(process.argv[2]);
const reader = new McapStreamReader({
  decompressHandlers: {
    zstd: (data, size) => zstdDecompress(data, new Uint8Array(Number(size))),
    lz4: (data, size) => {
      const out = new Uint8Array(Number(size));
      lz4.decompressBlock(data, out, 0, data.length, 0);
      return out;
    },
  },
});
reader.append(bytes);

const schemas = new Map();
const channels = new Map();
const readers = new Map();
const out = [];

const stampOf = (msg) =>
  msg.header ? Number(BigInt(msg.header.stamp.sec) * 1000000000n + BigInt(msg.header.stamp.nanosec)) : null;

function summarise(topic, schema, msg, logTime) {
  const entry = { topic, schema, log_time: Number(logTime), stamp: stampOf(msg) };
  if (schema === "sensor_msgs/msg/PointCloud2") {
    const view = new DataView(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
    // x, y, z by their fields: FLOAT32 (7), or FLOAT64 (8) as travmap's annotated cloud.
    const xyz = ["x", "y", "z"].map((axis) => msg.fields.find((f) => f.name === axis));
    const read = (f, offset) =>
      f.datatype === 8 ? view.getFloat64(offset + f.offset, true) : view.getFloat32(offset + f.offset, true);
    const at = (offset) => xyz.map((f) => read(f, offset));
    entry.points = msg.width * msg.height;
    entry.fields = msg.fields.map((f) => f.name);
    entry.first = msg.data.length ? at(0) : null;
    entry.last = msg.data.length ? at(msg.data.length - msg.point_step) : null;
  } else if (schema === "nav_msgs/msg/OccupancyGrid") {
    entry.width = msg.info.width;
    entry.height = msg.info.height;
    entry.resolution = msg.info.resolution;
    entry.origin = [msg.info.origin.position.x, msg.info.origin.position.y];
    entry.cells = Array.from(msg.data);
  } else if (schema === "grid_map_msgs/msg/GridMap") {
    const pose = msg.info.pose.position;
    entry.resolution = msg.info.resolution;
    entry.length = [msg.info.length_x, msg.info.length_y];
    entry.centre = [pose.x, pose.y, pose.z];
    entry.basic_layers = msg.basic_layers;
    entry.layers = Object.fromEntries(msg.layers.map((name, i) => [name, {
      dims: msg.data[i].layout.dim.map((d) => [d.label, d.size, d.stride]),
      values: Array.from(msg.data[i].data, (v) => (Number.isNaN(v) ? null : v)),
    }]));
  } else if (schema === "foxglove_msgs/msg/Grid") {
    const view = new DataView(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
    const cells = msg.data.byteLength / msg.cell_stride;
    entry.column_count = msg.column_count;
    entry.cell_size = [msg.cell_size.x, msg.cell_size.y];
    entry.row_stride = msg.row_stride;
    entry.origin = [msg.pose.position.x, msg.pose.position.y];
    entry.layers = Object.fromEntries(msg.fields.map((f) => [f.name, Array.from({ length: cells }, (_, i) => {
      const v = view.getFloat32(i * msg.cell_stride + f.offset, true);
      return Number.isNaN(v) ? null : v;
    })]));
  } else if (schema === "tf2_msgs/msg/TFMessage") {
    entry.transforms = msg.transforms.map((t) => [
      t.header.frame_id, t.child_frame_id,
      t.transform.translation.x, t.transform.translation.y, t.transform.translation.z,
    ]);
  } else if (schema === "travmap_msgs/msg/FrameMetrics") {
    entry.frame_index = msg.frame_index;
    entry.accuracy = Number.isNaN(msg.accuracy) ? null : msg.accuracy;
  }
  return entry;
}

for (let record; (record = reader.nextRecord()) !== undefined; ) {
  if (record.type === "Schema") {
    schemas.set(record.id, record);
  } else if (record.type === "Channel") {
    channels.set(record.id, record);
    const schema = schemas.get(record.schemaId);
    const text = new TextDecoder().decode(schema.data);
    readers.set(record.id, { name: schema.name, reader: new MessageReader(parse(text, { ros2: true })) });
  } else if (record.type === "Message") {
    const channel = channels.get(record.channelId);
    const { name, reader: messageReader } = readers.get(record.channelId);
    const msg = messageReader.readMessage(record.data);
    out.push(summarise(channel.topic, name, msg, record.logTime));
  }
}
if (!reader.done()) {
  console.error("the MCAP ended early (truncated file)");
  process.exit(1);
}
console.log(JSON.stringify(out));
