//! RoboSense angle tables: nebula's generic one per model (Apache-2.0), a CSV given
//! with `--lidar-calibration`, or the unit's own from its DIFOP packets.

use super::model::RobosenseModel;

/// Per laser: elevation and horizontal offset, 0.01 degree, as the decoder works in
/// them.
#[derive(Clone, Debug, PartialEq)]
pub struct RobosenseCalibration {
    pub vertical_centideg: Vec<i32>,
    pub horizontal_centideg: Vec<i32>,
    /// The generic table, which the unit's own (in its DIFOP) replaces once read; a
    /// table given as a file is kept.
    pub generic: bool,
}

impl RobosenseCalibration {
    /// The model's generic table.
    pub fn builtin(model: RobosenseModel) -> Self {
        let text = match model {
            RobosenseModel::Helios16p => include_str!("tables/RobosenseHelios16P.csv"),
        };
        Self {
            generic: true,
            ..Self::from_csv(text).expect("the built-in tables parse")
        }
    }

    /// RoboSense's angle CSV: a line per laser, `elevation,horizontal offset` in
    /// degrees (the offset may be missing: 0). Taken to 0.01 degree as nebula takes
    /// them (truncated).
    pub fn from_csv(text: &str) -> Result<Self, String> {
        let mut calibration = Self {
            vertical_centideg: Vec::new(),
            horizontal_centideg: Vec::new(),
            generic: false,
        };
        for (number, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let mut fields = line.split(',').map(str::trim);
            let angle = |field: Option<&str>| -> Result<i32, String> {
                let field = field.unwrap_or("0");
                let degrees: f32 = field.parse().map_err(|_| {
                    format!(
                        "line {}: `{field}` is not an angle (RoboSense's table: elevation,horizontal offset in degrees)",
                        number + 1
                    )
                })?;
                Ok((degrees * 100.0) as i32)
            };
            let vertical = angle(fields.next())?;
            let horizontal = angle(fields.next())?;
            calibration.vertical_centideg.push(vertical);
            calibration.horizontal_centideg.push(horizontal);
        }
        if calibration.vertical_centideg.is_empty() {
            return Err("an empty RoboSense angle table".into());
        }
        Ok(calibration)
    }

    /// The unit's own table in a DIFOP's 32 {sign, value u16} pairs of elevations
    /// then of horizontal offsets: its first `lasers`; None where a value is unset
    /// (sign 0xFF) or beyond +-90 degrees, as nebula checks it.
    pub(super) fn from_difop(vertical: &[u8], horizontal: &[u8], lasers: usize) -> Option<Self> {
        let angles = |bytes: &[u8]| -> Option<Vec<i32>> {
            (bytes.chunks_exact(3).take(lasers))
                .map(|pair| {
                    let value = i32::from(u16::from_be_bytes([pair[1], pair[2]]));
                    let value = if pair[0] == 0 { value } else { -value };
                    (pair[0] != 0xFF && (-9000..9000).contains(&value)).then_some(value)
                })
                .collect()
        };
        Some(Self {
            vertical_centideg: angles(vertical)?,
            horizontal_centideg: angles(horizontal)?,
            generic: false,
        })
    }

    /// Each laser's ring: its rank by elevation, lowest 0.
    pub(super) fn rings(&self) -> Vec<u16> {
        let vertical = &self.vertical_centideg;
        vertical
            .iter()
            .map(|&v| vertical.iter().filter(|&&other| other < v).count() as u16)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_reads_as_nebula_reads_it_and_rings_rank_the_elevations() {
        let table = RobosenseCalibration::from_csv("8.90,-4.05\n-1.5\n\n2,0.5\n").unwrap();
        // 8.90 is 8.8999996 in f32: nebula's truncation makes it 889.
        assert_eq!(table.vertical_centideg, [889, -150, 200]);
        assert_eq!(table.horizontal_centideg, [-405, 0, 50]);
        assert_eq!(table.rings(), [2, 0, 1]);
        let error = RobosenseCalibration::from_csv("1.0,x\n").unwrap_err();
        assert!(error.contains("line 1: `x` is not an angle"), "{error}");
        assert!(RobosenseCalibration::from_csv("\n").is_err());
        let builtin = RobosenseCalibration::builtin(RobosenseModel::Helios16p);
        assert_eq!(
            (builtin.vertical_centideg.len(), builtin.generic),
            (16, true)
        );
    }

    #[test]
    fn the_difop_table_is_refused_where_a_value_is_unset_or_beyond_a_right_angle() {
        let pair = |sign: u8, value: u16| [&[sign][..], &value.to_be_bytes()].concat();
        let vertical = [pair(0, 1494), pair(1, 801)].concat();
        let horizontal = [pair(1, 405), pair(0, 361)].concat();
        let table = RobosenseCalibration::from_difop(&vertical, &horizontal, 2).unwrap();
        assert_eq!(table.vertical_centideg, [1494, -801]);
        assert_eq!(table.horizontal_centideg, [-405, 361]);
        let unset = [pair(0xFF, 0), pair(0, 0)].concat();
        assert!(RobosenseCalibration::from_difop(&unset, &horizontal, 2).is_none());
        let beyond = [pair(0, 9_000), pair(0, 0)].concat();
        assert!(RobosenseCalibration::from_difop(&beyond, &horizontal, 2).is_none());
    }
}
