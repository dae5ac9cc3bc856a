//! MCAP records as bytes: the little-endian fields, strings, maps and length
//! prefixes of the MCAP specification, written in one pass without copies.

use std::collections::BTreeMap;

use mcap::records::op;

pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Writes `opcode`, then the body `fields` put after it, then patches the length
/// in: one pass, no copy of the body.
pub fn put_record(out: &mut Vec<u8>, opcode: u8, fields: impl FnOnce(&mut Vec<u8>)) {
    out.push(opcode);
    let length_at = out.len();
    out.extend_from_slice(&[0; 8]);
    fields(out);
    let length = (out.len() - length_at - 8) as u64;
    out[length_at..length_at + 8].copy_from_slice(&length.to_le_bytes());
}

pub fn put_u16(out: &mut Vec<u8>, value: u16) {
    out.extend_from_slice(&value.to_le_bytes());
}

pub fn put_u32(out: &mut Vec<u8>, value: u32) {
    out.extend_from_slice(&value.to_le_bytes());
}

pub fn put_u64(out: &mut Vec<u8>, value: u64) {
    out.extend_from_slice(&value.to_le_bytes());
}

/// A string or byte array: u32 length, then the bytes.
pub fn put_bytes(out: &mut Vec<u8>, bytes: &[u8]) {
    put_u32(out, bytes.len() as u32);
    out.extend_from_slice(bytes);
}

/// A map or array: u32 byte length, then the entries `entries` puts.
pub fn put_sized(out: &mut Vec<u8>, entries: impl FnOnce(&mut Vec<u8>)) {
    let length_at = out.len();
    put_u32(out, 0);
    entries(out);
    let length = (out.len() - length_at - 4) as u32;
    out[length_at..length_at + 4].copy_from_slice(&length.to_le_bytes());
}

pub fn put_string_map(out: &mut Vec<u8>, map: &BTreeMap<String, String>) {
    put_sized(out, |out| {
        for (key, value) in map {
            put_bytes(out, key.as_bytes());
            put_bytes(out, value.as_bytes());
        }
    });
}

/// A schema record, as written in chunks and in the summary.
pub fn schema_record(id: u16, name: &str, encoding: &str, data: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(data.len() + name.len() + 32);
    put_record(&mut out, op::SCHEMA, |out| {
        put_u16(out, id);
        put_bytes(out, name.as_bytes());
        put_bytes(out, encoding.as_bytes());
        put_bytes(out, data);
    });
    out
}

/// A channel record, as written in chunks and in the summary.
pub fn channel_record(channel: &mcap::records::Channel) -> Vec<u8> {
    let mut out = Vec::new();
    put_record(&mut out, op::CHANNEL, |out| {
        put_u16(out, channel.id);
        put_u16(out, channel.schema_id);
        put_bytes(out, channel.topic.as_bytes());
        put_bytes(out, channel.message_encoding.as_bytes());
        put_string_map(out, &channel.metadata);
    });
    out
}
