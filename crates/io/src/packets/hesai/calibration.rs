//! Hesai angle tables: the factory ones (nebula's CSVs, Apache-2.0) and the
//! angle-correction CSV a sensor ships with.

use super::model::HesaiModel;

/// Per laser: elevation and azimuth offset, degrees.
#[derive(Clone, Debug, PartialEq)]
pub struct HesaiCalibration {
    pub elevation_deg: Vec<f32>,
    pub azimuth_offset_deg: Vec<f32>,
}

impl HesaiCalibration {
    /// The model's factory table.
    pub fn builtin(model: HesaiModel) -> Self {
        Self::from_csv(builtin_table(model)).expect("the built-in tables parse")
    }

    /// Hesai's angle-correction CSV: `Channel,Elevation,Azimuth`, channels from 1.
    pub fn from_csv(text: &str) -> Result<Self, String> {
        let mut rows = Vec::new();
        for (number, line) in text.lines().enumerate() {
            let fields: Vec<&str> = line
                .split(',')
                .map(str::trim)
                .filter(|f| !f.is_empty())
                .collect();
            let [channel, elevation, azimuth] = fields[..] else {
                continue;
            };
            // The header line is not a row.
            let Ok(channel) = channel.parse::<usize>() else {
                continue;
            };
            let angle = |v: &str| {
                v.parse::<f32>()
                    .map_err(|_| format!("line {}: `{v}` is not an angle", number + 1))
            };
            rows.push((channel, angle(elevation)?, angle(azimuth)?));
        }
        let lasers = rows.len();
        let mut calibration = Self {
            elevation_deg: vec![f32::NAN; lasers],
            azimuth_offset_deg: vec![f32::NAN; lasers],
        };
        for (channel, elevation, azimuth) in rows {
            let at = channel
                .checked_sub(1)
                .filter(|&at| at < lasers)
                .ok_or_else(|| format!("channel {channel} in a table of {lasers} channels"))?;
            calibration.elevation_deg[at] = elevation;
            calibration.azimuth_offset_deg[at] = azimuth;
        }
        if lasers == 0 || calibration.elevation_deg.iter().any(|e| e.is_nan()) {
            return Err("not a Hesai angle table (Channel,Elevation,Azimuth rows, each channel once from 1)".into());
        }
        Ok(calibration)
    }
}

/// The factory angle table: nebula's `calibration/Pandar<model>.csv` (Apache-2.0),
/// unchanged, in `tables/`: channel, elevation, azimuth offset (degrees).
fn builtin_table(model: HesaiModel) -> &'static str {
    match model {
        HesaiModel::PandarXt32 => include_str!("tables/PandarXT32.csv"),
        HesaiModel::PandarXt16 => include_str!("tables/PandarXT16.csv"),
        HesaiModel::PandarXt32m => include_str!("tables/PandarXT32M.csv"),
        HesaiModel::Pandar40p => include_str!("tables/Pandar40P.csv"),
        HesaiModel::Pandar64 => include_str!("tables/Pandar64.csv"),
        HesaiModel::PandarQt64 => include_str!("tables/PandarQT64.csv"),
        HesaiModel::PandarQt128 => include_str!("tables/PandarQT128.csv"),
    }
}
