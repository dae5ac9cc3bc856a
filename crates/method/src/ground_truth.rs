//! Ground truth (METHOD.md section 8): a cell label from the SemanticKITTI labels of
//! the points the method itself sees (the same integrated, gridded cloud).
//!
//! Input: [`CellPoints`] with labels. Output: one [`CellClass`] per cell.

use crate::grid::{CellClass, CellPoints};
use travmap_core::config::GroundTruthConfig;

/// Labels cells from per-point semantic classes.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    pub config: GroundTruthConfig,
    /// The classes of `config` in force: looked up for every labelled point, so as
    /// bits rather than lists.
    traversable: IdSet,
    ignored: IdSet,
    /// The ids the label set defines; None: any id is accepted.
    known: Option<IdSet>,
}

/// A set of label ids, one bit per id.
#[derive(Clone, Debug)]
struct IdSet(Box<[u64; 1024]>);

impl IdSet {
    fn of(ids: &[u16]) -> Self {
        let mut bits = Box::new([0u64; 1024]);
        for &id in ids {
            bits[id as usize / 64] |= 1 << (id % 64);
        }
        Self(bits)
    }

    #[inline]
    fn contains(&self, id: u16) -> bool {
        self.0[id as usize / 64] & (1 << (id % 64)) != 0
    }
}

/// Points of a scan whose label id the label set does not define: random ids, or
/// another dataset's labels read under the wrong set.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct UnknownLabels {
    pub points: usize,
    /// A few such ids, ascending.
    pub examples: Vec<u16>,
}

/// How many unknown ids a notice names.
const EXAMPLE_IDS: usize = 5;

impl UnknownLabels {
    /// Adds `other`'s points and ids.
    pub fn merge(&mut self, other: &UnknownLabels) {
        self.points += other.points;
        self.examples.extend(&other.examples);
        self.examples.sort_unstable();
        self.examples.dedup();
        self.examples.truncate(EXAMPLE_IDS);
    }
}

impl GroundTruth {
    pub fn new(config: GroundTruthConfig) -> Self {
        let classes = config.classes();
        Self {
            traversable: IdSet::of(&classes.traversable),
            ignored: IdSet::of(&classes.ignored),
            known: classes.known.as_deref().map(IdSet::of),
            config,
        }
    }

    /// The points of one scan's `labels` whose id the label set does not define.
    pub fn unknown_labels(&self, labels: &[u32]) -> UnknownLabels {
        let Some(known) = &self.known else {
            return UnknownLabels::default();
        };
        let mut unknown = UnknownLabels::default();
        for &label in labels {
            let id = (label & 0xFFFF) as u16;
            if !known.contains(id) {
                unknown.points += 1;
                if unknown.examples.len() < EXAMPLE_IDS && !unknown.examples.contains(&id) {
                    unknown.examples.push(id);
                }
            }
        }
        unknown.examples.sort_unstable();
        unknown
    }

    /// None when the points carry no labels.
    pub fn label(&self, cells: &CellPoints) -> Option<Vec<CellClass>> {
        let labels = cells.labels.as_ref()?;
        Some(
            (0..cells.layout.cell_count())
                .map(|cell| self.cell_class(&labels[cells.cell_range(cell)]))
                .collect(),
        )
    }

    /// Fewer than `min_points` voting points: unknown; at least
    /// `min_non_traversable_points` non-traversable points: non-traversable; else
    /// traversable. Ignored classes (unlabeled, outlier) do not vote (Decision).
    pub fn cell_class(&self, point_labels: &[u32]) -> CellClass {
        let (mut voting, mut non_traversable) = (0usize, 0usize);
        for &label in point_labels {
            let class = (label & 0xFFFF) as u16;
            if self.ignored.contains(class) {
                continue;
            }
            voting += 1;
            if !self.traversable.contains(class) {
                non_traversable += 1;
            }
        }
        if voting < self.config.min_points {
            CellClass::Unknown
        } else if non_traversable >= self.config.min_non_traversable_points {
            CellClass::NonTraversable
        } else {
            CellClass::Traversable
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gt() -> GroundTruth {
        GroundTruth::new(GroundTruthConfig::default())
    }

    #[test]
    fn id_sets_hold_exactly_their_ids_at_word_edges() {
        let set = IdSet::of(&[0, 63, 64, 65535]);
        for id in [0, 63, 64, 65535] {
            assert!(set.contains(id), "{id}");
        }
        for id in [1, 62, 65, 127, 128, 65534] {
            assert!(!set.contains(id), "{id}");
        }
    }

    #[test]
    fn cell_rules() {
        let g = gt();
        let road = 40;
        let car = 10;
        let with_instance = (7u32 << 16) | car;
        assert_eq!(g.cell_class(&[road]), CellClass::Unknown);
        assert_eq!(g.cell_class(&[road, 48]), CellClass::Traversable);
        // One non-traversable point among traversable ones does not flip the cell.
        assert_eq!(g.cell_class(&[road, road, car]), CellClass::Traversable);
        assert_eq!(
            g.cell_class(&[road, car, with_instance]),
            CellClass::NonTraversable
        );
        // Unlabeled (0) and outlier (1) do not vote.
        assert_eq!(g.cell_class(&[0, 1, road]), CellClass::Unknown);
        assert_eq!(g.cell_class(&[0, 0, 0, car, 70]), CellClass::NonTraversable);
        assert_eq!(g.cell_class(&[60, 44, 49]), CellClass::Traversable);
    }

    #[test]
    fn ids_the_label_set_does_not_define_are_counted() {
        let g = gt();
        let with_instance = (3u32 << 16) | 40;
        let unknown = g.unknown_labels(&[40, with_instance, 2, 4000, 2, 65535, 72]);
        assert_eq!(unknown.points, 4);
        assert_eq!(unknown.examples, [2, 4000, 65535]);
        // Explicit class lists accept any id.
        let listed = GroundTruth::new(GroundTruthConfig {
            traversable_classes: Some(vec![7]),
            ..GroundTruthConfig::default()
        });
        assert_eq!(listed.unknown_labels(&[4000]), UnknownLabels::default());
    }
}
