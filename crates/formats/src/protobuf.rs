//! Protocol Buffers' wire format, as far as reading messages of known schemas needs:
//! each field's number and value in the order written, unknown fields stepped over,
//! every length checked against what is left.

/// A field's value as the wire carries it; what it means is the schema's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'a> {
    Varint(u64),
    Fixed64(u64),
    Fixed32(u32),
    /// Strings, bytes, nested messages and packed repeated numbers.
    Bytes(&'a [u8]),
}

impl<'a> Value<'a> {
    fn kind(&self) -> &'static str {
        match self {
            Value::Varint(_) => "a varint",
            Value::Fixed64(_) => "a 64-bit value",
            Value::Fixed32(_) => "a 32-bit value",
            Value::Bytes(_) => "bytes",
        }
    }

    fn expected(&self, field: u32, what: &str) -> String {
        format!("field {field}: expected {what}, found {}", self.kind())
    }

    pub fn varint(self, field: u32) -> Result<u64, String> {
        match self {
            Value::Varint(v) => Ok(v),
            other => Err(other.expected(field, "a varint")),
        }
    }

    pub fn fixed32(self, field: u32) -> Result<u32, String> {
        match self {
            Value::Fixed32(v) => Ok(v),
            other => Err(other.expected(field, "a fixed32")),
        }
    }

    pub fn double(self, field: u32) -> Result<f64, String> {
        match self {
            Value::Fixed64(bits) => Ok(f64::from_bits(bits)),
            other => Err(other.expected(field, "a double")),
        }
    }

    pub fn bytes(self, field: u32) -> Result<&'a [u8], String> {
        match self {
            Value::Bytes(bytes) => Ok(bytes),
            other => Err(other.expected(field, "bytes")),
        }
    }

    pub fn string(self, field: u32) -> Result<String, String> {
        let bytes = self.bytes(field)?;
        String::from_utf8(bytes.to_vec()).map_err(|_| format!("field {field}: not UTF-8"))
    }

    /// One or more values of a `repeated double`: packed (proto3's way) or one
    /// per field, both of which a reader must take.
    pub fn doubles(self, field: u32, into: &mut Vec<f64>) -> Result<(), String> {
        match self {
            Value::Bytes(packed) if packed.len() % 8 == 0 => {
                let values = packed.chunks_exact(8);
                into.extend(values.map(|b| f64::from_le_bytes(b.try_into().unwrap())));
                Ok(())
            }
            Value::Bytes(packed) => Err(format!(
                "field {field}: {} bytes of packed doubles",
                packed.len()
            )),
            other => {
                into.push(other.double(field)?);
                Ok(())
            }
        }
    }
}

/// The fields of one message, in the order written.
pub struct Fields<'a> {
    rest: &'a [u8],
}

/// The fields of `message`.
pub fn fields(message: &[u8]) -> Fields<'_> {
    Fields { rest: message }
}

impl<'a> Fields<'a> {
    fn varint(&mut self) -> Result<u64, String> {
        let mut value = 0u64;
        for shift in (0..64).step_by(7) {
            let (&byte, rest) = self
                .rest
                .split_first()
                .ok_or("a varint runs past the end")?;
            self.rest = rest;
            value |= u64::from(byte & 0x7f) << shift;
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err("a varint longer than 10 bytes".into())
    }

    fn take(&mut self, n: usize, field: u32) -> Result<&'a [u8], String> {
        if n > self.rest.len() {
            return Err(format!(
                "field {field}: {n} bytes, {} left in the message",
                self.rest.len()
            ));
        }
        let (taken, rest) = self.rest.split_at(n);
        self.rest = rest;
        Ok(taken)
    }

    fn field(&mut self) -> Result<(u32, Value<'a>), String> {
        let key = self.varint()?;
        let field = u32::try_from(key >> 3).map_err(|_| format!("field number {}", key >> 3))?;
        if field == 0 {
            return Err("field number 0".into());
        }
        let value = match key & 7 {
            0 => Value::Varint(self.varint()?),
            1 => Value::Fixed64(u64::from_le_bytes(self.take(8, field)?.try_into().unwrap())),
            2 => {
                let n = usize::try_from(self.varint()?).unwrap_or(usize::MAX);
                Value::Bytes(self.take(n, field)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(self.take(4, field)?.try_into().unwrap())),
            wire => {
                return Err(format!(
                    "field {field}: wire type {wire} (groups are not read)"
                ));
            }
        };
        Ok((field, value))
    }
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<(u32, Value<'a>), String>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.rest.is_empty() {
            return None;
        }
        let field = self.field();
        if field.is_err() {
            // Nothing after a field that does not read can be trusted.
            self.rest = &[];
        }
        Some(field)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(message: &[u8]) -> Result<Vec<(u32, Value<'_>)>, String> {
        fields(message).collect()
    }

    #[test]
    fn every_wire_type_reads_as_written() {
        // Field 1 varint 300, field 2 string "hi", field 3 double 1.5, field 4 fixed32 7.
        let mut message = vec![0x08, 0xac, 0x02, 0x12, 2, b'h', b'i', 0x19];
        message.extend(1.5f64.to_le_bytes());
        message.extend([0x25, 7, 0, 0, 0]);
        let read = read(&message).unwrap();
        assert_eq!(read[0], (1, Value::Varint(300)));
        assert_eq!(read[1].1.string(2).unwrap(), "hi");
        assert_eq!(read[2].1.double(3).unwrap(), 1.5);
        assert_eq!(read[3].1.fixed32(4).unwrap(), 7);
    }

    #[test]
    fn repeated_doubles_read_packed_or_one_by_one() {
        let (mut packed, mut single) = (vec![0x2a, 16], Vec::new());
        for v in [1.0f64, -2.0] {
            packed.extend(v.to_le_bytes());
            single.push(0x29);
            single.extend(v.to_le_bytes());
        }
        for message in [packed, single] {
            let mut values = Vec::new();
            for field in fields(&message) {
                field.unwrap().1.doubles(5, &mut values).unwrap();
            }
            assert_eq!(values, [1.0, -2.0]);
        }
    }

    #[test]
    fn cut_or_malformed_messages_are_errors_not_panics() {
        assert!(
            read(&[0x12, 5, b'a'])
                .unwrap_err()
                .contains("field 2: 5 bytes, 1 left")
        );
        assert!(
            read(&[0x08, 0x80])
                .unwrap_err()
                .contains("runs past the end")
        );
        assert!(read(&[0x0b]).unwrap_err().contains("wire type 3"));
        assert!(read(&[0x00, 1]).unwrap_err().contains("field number 0"));
        assert!(
            read(&[
                0x08, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01
            ])
            .is_err()
        );
        let huge_length = [0x12, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x7f];
        assert!(read(&huge_length).is_err());
        let mismatch = Value::Varint(1).bytes(6).unwrap_err();
        assert_eq!(mismatch, "field 6: expected bytes, found a varint");
    }
}
