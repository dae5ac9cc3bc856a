//! What every vendor's packets become: points, gathered into scans.

/// One decoded return, of any vendor's packets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PacketPoint {
    /// x, y, z in the sensor frame, metres.
    pub xyz_m: [f32; 3],
    pub intensity: u8,
    pub ring: u16,
    /// Azimuth after correction, 0.01 degree clockwise from +x.
    pub azimuth_centideg: u16,
    /// Time of the firing: the packet's stamp plus the firing's offset, ns.
    pub time_ns: u64,
}

/// A complete scan.
#[derive(Clone, Debug)]
pub struct PacketScan {
    pub stamp_ns: u64,
    pub points: Vec<PacketPoint>,
}

impl PacketScan {
    /// The scan, its stamp and its points' times moved by `shift_ns` (from the
    /// sensor's clock to the log's).
    pub fn shifted(mut self, shift_ns: i64) -> Self {
        self.stamp_ns = self.stamp_ns.saturating_add_signed(shift_ns);
        for point in &mut self.points {
            point.time_ns = point.time_ns.saturating_add_signed(shift_ns);
        }
        self
    }
}

/// What moves a packet's time in the sensor's clock (`sensor_ns`) to the log's, by
/// the stamp it was recorded with (0: unknown, the sensor's clock is the log's).
pub fn to_log_clock_ns(stamp_ns: u64, sensor_ns: u64) -> i64 {
    match stamp_ns {
        0 => 0,
        stamp_ns => (i128::from(stamp_ns) - i128::from(sensor_ns)) as i64,
    }
}
