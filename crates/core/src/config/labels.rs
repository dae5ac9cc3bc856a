//! Which label ids are traversable: presets for the datasets travmap reads
//! (SemanticKITTI, RELLIS-3D, nuScenes-lidarseg), each with a road rule (the seed paper's: a road
//! car's ground) and an off-road rule (also terrain, grass, dirt, mud, puddles), and
//! label maps for any other ontology.

use serde::{Deserialize, Serialize};

/// Whose label ids the per-point labels are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelSet {
    /// SemanticKITTI's ids (lower 16 bits; the upper 16 are the instance).
    #[default]
    Semantickitti,
    /// RELLIS-3D's ids.
    Rellis3d,
    /// nuScenes-lidarseg's ids (0-31), and 32-39 for moving objects as some
    /// conversions of it mark them.
    Nuscenes,
}

/// Which ground counts as traversable.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LabelRule {
    /// A road car's: road, parking, sidewalk, other ground, lane marking
    /// (SemanticKITTI); asphalt and concrete (RELLIS-3D).
    #[default]
    Road,
    /// An off-road vehicle's: the road rule's and terrain (SemanticKITTI); dirt,
    /// grass, puddles and mud too (RELLIS-3D).
    Offroad,
}

impl LabelRule {
    pub const ALL: [LabelRule; 2] = [LabelRule::Road, LabelRule::Offroad];

    /// Its name in settings (`ground_truth.rule`, `classifier.model`).
    pub fn name(self) -> &'static str {
        match self {
            LabelRule::Road => "road",
            LabelRule::Offroad => "offroad",
        }
    }
}

/// The classes of a label set under a rule: which are traversable, which do not
/// vote, and every id the set defines (others are unknown to it).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClassRule {
    pub traversable: Vec<u16>,
    pub ignored: Vec<u16>,
    /// Ids the label set defines; None: any id is accepted.
    pub known: Option<Vec<u16>>,
}

/// SemanticKITTI's ids (semantic-kitti.yaml).
const SEMANTICKITTI_IDS: &[u16] = &[
    0, 1, 10, 11, 13, 15, 16, 18, 20, 30, 31, 32, 40, 44, 48, 49, 50, 51, 52, 60, 70, 71, 72, 80,
    81, 99, 252, 253, 254, 255, 256, 257, 258, 259,
];
/// RELLIS-3D's ids (its ontology, shared/data PROVENANCE section 7).
const RELLIS3D_IDS: &[u16] = &[
    0, 1, 3, 4, 5, 6, 7, 8, 9, 10, 12, 15, 17, 18, 19, 23, 27, 31, 33, 34,
];
/// nuScenes-lidarseg's ids 0-31 (shared/data PROVENANCE section 10), and 32-39:
/// moving objects, as SegNet4D's conversion (scene 1072's labels) marks them.
const NUSCENES_IDS: &[u16] = &[
    0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25,
    26, 27, 28, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39,
];

impl LabelSet {
    pub const ALL: [LabelSet; 3] = [
        LabelSet::Semantickitti,
        LabelSet::Rellis3d,
        LabelSet::Nuscenes,
    ];

    /// Whether the set defines `id` (a SemanticKITTI label's lower 16 bits).
    pub fn defines(self, id: u16) -> bool {
        let ids = match self {
            LabelSet::Semantickitti => SEMANTICKITTI_IDS,
            LabelSet::Rellis3d => RELLIS3D_IDS,
            LabelSet::Nuscenes => NUSCENES_IDS,
        };
        ids.contains(&id)
    }

    /// The preset: `rule`'s traversable classes, the classes that do not vote.
    pub fn classes(self, rule: LabelRule) -> ClassRule {
        let (traversable, ignored, known): (&[u16], &[u16], &[u16]) = match (self, rule) {
            // road 40, parking 44, sidewalk 48, other-ground 49, lane-marking 60;
            // unlabeled 0 and outlier 1 do not vote (METHOD.md section 8).
            (LabelSet::Semantickitti, LabelRule::Road) => {
                (&[40, 44, 48, 49, 60], &[0, 1], SEMANTICKITTI_IDS)
            }
            // ... and terrain 72 (grass, soil).
            (LabelSet::Semantickitti, LabelRule::Offroad) => {
                (&[40, 44, 48, 49, 60, 72], &[0, 1], SEMANTICKITTI_IDS)
            }
            // asphalt 10, concrete 23; void 0 and sky 7 do not vote.
            (LabelSet::Rellis3d, LabelRule::Road) => (&[10, 23], &[0, 7], RELLIS3D_IDS),
            // ... and dirt 1, grass 3, puddle 31, mud 33.
            (LabelSet::Rellis3d, LabelRule::Offroad) => {
                (&[1, 3, 10, 23, 31, 33], &[0, 7], RELLIS3D_IDS)
            }
            // flat.driveable_surface 24, flat.other 25, flat.sidewalk 26; noise 0 and
            // vehicle.ego 31 (the recording car's own body) do not vote.
            (LabelSet::Nuscenes, LabelRule::Road) => (&[24, 25, 26], &[0, 31], NUSCENES_IDS),
            // ... and flat.terrain 27 (grass, soil, gravel).
            (LabelSet::Nuscenes, LabelRule::Offroad) => (&[24, 25, 26, 27], &[0, 31], NUSCENES_IDS),
        };
        ClassRule {
            traversable: traversable.to_vec(),
            ignored: ignored.to_vec(),
            known: Some(known.to_vec()),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            LabelSet::Semantickitti => "semantickitti",
            LabelSet::Rellis3d => "rellis3d",
            LabelSet::Nuscenes => "nuscenes",
        }
    }
}

/// What a label map file says of one id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
enum MappedClass {
    Traversable,
    NotTraversable,
    Ignored,
}

/// A label map (`ground_truth.label_map`): a TOML table `[ids]` of id =
/// "traversable" | "not_traversable" | "ignored"; ids it does not name are unknown.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LabelMapFile {
    ids: std::collections::BTreeMap<String, MappedClass>,
}

/// The classes a label map's text gives, or what is wrong with it.
pub fn parse_label_map(text: &str) -> Result<ClassRule, String> {
    let file: LabelMapFile = toml::from_str(text).map_err(|e| e.to_string())?;
    let mut rule = ClassRule {
        traversable: Vec::new(),
        ignored: Vec::new(),
        known: Some(Vec::new()),
    };
    for (id, class) in file.ids {
        let id: u16 = id
            .parse()
            .map_err(|_| format!("`{id}` is not a label id (0..=65535)"))?;
        match class {
            MappedClass::Traversable => rule.traversable.push(id),
            MappedClass::Ignored => rule.ignored.push(id),
            MappedClass::NotTraversable => {}
        }
        if let Some(known) = &mut rule.known {
            known.push(id);
        }
    }
    if rule.traversable.is_empty() {
        return Err("it names no traversable id".into());
    }
    Ok(rule)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_hold_what_the_rules_say() {
        let road = LabelSet::Semantickitti.classes(LabelRule::Road);
        assert_eq!(road.traversable, vec![40, 44, 48, 49, 60]);
        let offroad = LabelSet::Semantickitti.classes(LabelRule::Offroad);
        assert!(offroad.traversable.contains(&72));
        let rellis = LabelSet::Rellis3d.classes(LabelRule::Offroad);
        assert_eq!(rellis.traversable, vec![1, 3, 10, 23, 31, 33]);
        assert_eq!(rellis.ignored, vec![0, 7]);
        let nuscenes = LabelSet::Nuscenes.classes(LabelRule::Road);
        assert_eq!(nuscenes.traversable, vec![24, 25, 26]);
        assert_eq!(nuscenes.ignored, vec![0, 31]);
        assert!(
            !nuscenes.traversable.contains(&32),
            "a moving car is no road"
        );
        for set in [
            LabelSet::Semantickitti,
            LabelSet::Rellis3d,
            LabelSet::Nuscenes,
        ] {
            for rule in [LabelRule::Road, LabelRule::Offroad] {
                let classes = set.classes(rule);
                let known = classes.known.unwrap();
                assert!(classes.traversable.iter().all(|id| known.contains(id)));
                assert!(classes.ignored.iter().all(|id| known.contains(id)));
            }
        }
    }

    #[test]
    fn a_label_map_names_ids_and_refuses_what_it_cannot_read() {
        let rule = parse_label_map(
            "[ids]\n7 = \"traversable\"\n8 = \"not_traversable\"\n0 = \"ignored\"\n",
        )
        .unwrap();
        assert_eq!(rule.traversable, vec![7]);
        assert_eq!(rule.ignored, vec![0]);
        assert_eq!(rule.known, Some(vec![0, 7, 8]));
        assert!(parse_label_map("[ids]\nx = \"traversable\"\n").is_err());
        assert!(parse_label_map("[ids]\n1 = \"maybe\"\n").is_err());
        assert!(parse_label_map("[ids]\n1 = \"ignored\"\n").is_err());
    }
}
