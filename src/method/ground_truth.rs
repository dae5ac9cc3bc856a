//! Ground truth (METHOD.md section 8): a cell label from the SemanticKITTI labels of
//! the points the method itself sees (the same integrated, gridded cloud).
//!
//! Input: [`CellPoints`] with labels. Output: one [`CellClass`] per cell.

use crate::config::{ClassRule, GroundTruthConfig};
use crate::method::grid::{CellClass, CellPoints};

/// Labels cells from per-point semantic classes.
#[derive(Clone, Debug)]
pub struct GroundTruth {
    pub config: GroundTruthConfig,
    /// The classes of `config` in force.
    classes: ClassRule,
}

impl GroundTruth {
    pub fn new(config: GroundTruthConfig) -> Self {
        Self {
            classes: config.classes(),
            config,
        }
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
            if self.classes.ignored.contains(&class) {
                continue;
            }
            voting += 1;
            if !self.classes.traversable.contains(&class) {
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
}
