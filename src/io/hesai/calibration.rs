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

/// The factory angle table (nebula's `Pandar<model>.csv`).
fn builtin_table(model: HesaiModel) -> &'static str {
    match model {
        HesaiModel::PandarXt32 => XT32_CSV,
        HesaiModel::PandarXt16 => XT16_CSV,
        HesaiModel::Pandar40p => P40_CSV,
        HesaiModel::Pandar64 => P64_CSV,
        HesaiModel::PandarQt64 => QT64_CSV,
    }
}

/// nebula's `PandarXT32.csv` (Apache-2.0): channel, elevation, azimuth offset (degrees).
const XT32_CSV: &str = "Channel,Elevation,Azimuth
1,14.972363,0.082385
2,13.952372,0.076529
3,12.938632,0.078240
4,11.931141,0.076267
5,10.926151,0.064337
6,9.922410,0.059942
7,8.917419,0.049319
8,7.917429,0.044992
9,6.919938,0.034446
10,5.919947,0.027658
11,4.922456,0.020896
12,3.924965,0.014147
13,2.929974,0.008668
14,1.936233,-0.000548
15,0.944992,-0.007248
16,-0.047500,-0.015201
17,-1.039991,-0.025654
18,-2.036232,-0.031126
19,-3.028723,-0.037837
20,-4.024964,-0.045822
21,-5.019955,-0.061312
22,-6.016196,-0.065570
23,-7.013687,-0.068599
24,-8.013678,-0.076658
25,-9.011169,-0.088476
26,-10.011159,-0.091580
27,-11.006150,-0.098438
28,-12.003641,-0.092837
29,-12.996131,-0.102247
30,-13.997372,-0.104231
31,-15.004862,-0.118783
32,-16.023602,-0.129679
";

/// nebula's `PandarXT16.csv` (Apache-2.0).
const XT16_CSV: &str = "Channel,Elevation,Azimuth
1,15,0
2,13,0
3,11,0
4,9,0
5,7,0
6,5,0
7,3,0
8,1,0
9,-1,0
10,-3,0
11,-5,0
12,-7,0
13,-9,0
14,-11,0
15,-13,0
16,-15,0
";

/// nebula's `Pandar40P.csv` (Apache-2.0).
const P40_CSV: &str = "Laser id,Elevation,Azimuth
1,14.794,-1.042
2,10.944,-1.042
3,7.971,-1.042
4,4.969,-1.042
5,2.952,-1.042
6,1.94,-1.042
7,1.6,3.125
8,1.263,-5.208
9,0.925,-1.042
10,0.587,3.125
11,0.249,-5.208
12,-0.088,-1.042
13,-0.425,3.125
14,-0.763,-5.208
15,-1.101,-1.042
16,-1.439,3.125
17,-1.776,-5.208
18,-2.116,-1.042
19,-2.453,3.125
20,-2.788,-5.208
21,-3.128,-1.042
22,-3.463,3.125
23,-3.8,-5.208
24,-4.138,-1.042
25,-4.473,3.125
26,-4.808,-5.208
27,-5.145,-1.042
28,-5.479,3.125
29,-5.814,-5.208
30,-6.149,-1.042
31,-7.151,-1.042
32,-8.147,-1.042
33,-9.148,-1.042
34,-10.133,-1.042
35,-11.12,-1.042
36,-12.094,-1.042
37,-13.062,-1.042
38,-14.018,-1.042
39,-18.977,-1.042
40,-24.985,-1.042
";

/// nebula's `Pandar64.csv` (Apache-2.0).
const P64_CSV: &str = "Laser id,Elevation,Azimuth
1,14.9,-1.042
2,11.05,-1.042
3,8.077,-1.042
4,5.075,-1.042
5,3.058,-1.042
6,2.046,-1.042
7,1.878,1.042
8,1.706,3.125
9,1.54,5.208
10,1.369,-5.208
11,1.202,-3.125
12,1.031,-1.042
13,0.864,1.042
14,0.693,3.125
15,0.526,5.208
16,0.355,-5.208
17,0.187,-3.125
18,0.018,-1.042
19,-0.151,1.042
20,-0.319,3.125
21,-0.49,5.208
22,-0.657,-5.208
23,-0.827,-3.125
24,-0.995,-1.042
25,-1.166,1.042
26,-1.333,3.125
27,-1.504,5.208
28,-1.67,-5.208
29,-1.842,-3.125
30,-2.01,-1.042
31,-2.18,1.042
32,-2.347,3.125
33,-2.518,5.208
34,-2.682,-5.208
35,-2.855,-3.125
36,-3.022,-1.042
37,-3.192,1.042
38,-3.357,3.125
39,-3.53,5.208
40,-3.694,-5.208
41,-3.866,-3.125
42,-4.032,-1.042
43,-4.203,1.042
44,-4.367,3.125
45,-4.54,5.208
46,-4.702,-5.208
47,-4.874,-3.125
48,-5.039,-1.042
49,-5.211,1.042
50,-5.373,3.125
51,-5.547,5.208
52,-5.708,-5.208
53,-5.88,-3.125
54,-6.043,-1.042
55,-7.045,-1.042
56,-8.041,-1.042
57,-9.042,-1.042
58,-10.027,-1.042
59,-11.014,-1.042
60,-11.988,-1.042
61,-12.956,-1.042
62,-13.912,-1.042
63,-18.871,-1.042
64,-24.879,-1.042
";

/// nebula's `PandarQT64.csv` (Apache-2.0).
const QT64_CSV: &str = "Laser id,Elevation,Azimuth
1,-52.121,8.736
2,-49.785,8.314
3,-47.577,7.964
4,-45.477,7.669
5,-43.465,7.417
6,-41.528,7.198
7,-39.653,7.007
8,-37.831,6.838
9,-36.055,6.688
10,-34.320,6.554
11,-32.619,6.434
12,-30.950,6.326
13,-29.308,6.228
14,-27.690,6.140
15,-26.094,6.059
16,-24.517,5.987
17,-22.964,-5.270
18,-21.420,-5.216
19,-19.889,-5.167
20,-18.372,-5.123
21,-16.865,-5.083
22,-15.368,-5.047
23,-13.880,-5.016
24,-12.399,-4.988
25,-10.925,-4.963
26,-9.457,-4.942
27,-7.994,-4.924
28,-6.535,-4.910
29,-5.079,-4.898
30,-3.626,-4.889
31,-2.175,-4.884
32,-0.725,-4.881
33,0.725,5.493
34,2.175,5.496
35,3.626,5.502
36,5.079,5.512
37,6.534,5.525
38,7.993,5.541
39,9.456,5.561
40,10.923,5.584
41,12.397,5.611
42,13.877,5.642
43,15.365,5.676
44,16.861,5.716
45,18.368,5.759
46,19.885,5.808
47,21.415,5.862
48,22.959,5.921
49,24.524,-5.330
50,26.101,-5.396
51,27.697,-5.469
52,29.315,-5.550
53,30.957,-5.640
54,32.627,-5.740
55,34.328,-5.850
56,36.064,-5.974
57,37.840,-6.113
58,39.662,-6.269
59,41.537,-6.447
60,43.475,-6.651
61,45.487,-6.887
62,47.587,-7.163
63,49.795,-7.493
64,52.133,-7.892
";
