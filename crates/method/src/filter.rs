//! Stage 5, outlier filter (METHOD.md section 7): a weighted majority vote of each
//! predicted cell with its predicted 8-neighbours.
//!
//! Input: the classified grid. Output: the filtered grid. One pass over the labels
//! before filtering; unknown cells neither vote nor change.

use crate::grid::CellClass;
use travmap_core::config::FilterConfig;

/// The neighbourhood vote.
#[derive(Clone, Debug)]
pub struct OutlierFilter {
    pub config: FilterConfig,
}

impl OutlierFilter {
    /// Filters a row-major square grid of `cells_per_side` cells.
    pub fn apply(&self, predicted: &[CellClass], cells_per_side: usize) -> Vec<CellClass> {
        if !self.config.enabled {
            return predicted.to_vec();
        }
        let l = cells_per_side as isize;
        let mut filtered = predicted.to_vec();
        for (cell, out) in filtered.iter_mut().enumerate() {
            let own = predicted[cell];
            if own == CellClass::Unknown {
                continue;
            }
            let (col, row) = (
                (cell % cells_per_side) as isize,
                (cell / cells_per_side) as isize,
            );
            let (mut agree, mut disagree) = (self.config.self_weight, 0u32);
            for dr in -1..=1 {
                for dc in -1..=1 {
                    let (c, r) = (col + dc, row + dr);
                    if (dr, dc) == (0, 0) || c < 0 || r < 0 || c >= l || r >= l {
                        continue;
                    }
                    match predicted[(r * l + c) as usize] {
                        CellClass::Unknown => {}
                        n if n == own => agree += 1,
                        _ => disagree += 1,
                    }
                }
            }
            // A tie keeps the cell's own label.
            if disagree > agree {
                *out = match own {
                    CellClass::Traversable => CellClass::NonTraversable,
                    _ => CellClass::Traversable,
                };
            }
        }
        filtered
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use CellClass::{NonTraversable as N, Traversable as T, Unknown as U};

    fn filter() -> OutlierFilter {
        OutlierFilter {
            config: FilterConfig::default(),
        }
    }

    #[test]
    fn an_isolated_cell_flips_only_with_more_than_three_opposing_neighbours() {
        // Surrounded by 8 opposite labels: 8 > 3, flips.
        let grid = vec![T, T, T, T, N, T, T, T, T];
        assert_eq!(filter().apply(&grid, 3)[4], T);
        // Four opposing, one agreeing neighbour, the rest unknown: 4 > 3 + 1 is false.
        let grid = vec![T, T, N, T, N, U, T, U, U];
        assert_eq!(filter().apply(&grid, 3)[4], N);
        // Four opposing, no agreeing: 4 > 3 flips.
        let grid = vec![T, T, U, T, N, U, T, U, U];
        assert_eq!(filter().apply(&grid, 3)[4], T);
        // Exactly three opposing: a tie keeps the own label.
        let grid = vec![T, T, U, T, N, U, U, U, U];
        assert_eq!(filter().apply(&grid, 3)[4], N);
    }

    #[test]
    fn unknown_cells_stay_unknown_and_votes_use_the_unfiltered_labels() {
        let grid = vec![U; 9];
        assert_eq!(filter().apply(&grid, 3), grid);
        // Corner cell (0) has neighbours 1, 3, 4 only (3 opposing: a tie keeps it).
        let grid = vec![N, T, T, T, T, T, T, T, T];
        assert_eq!(filter().apply(&grid, 3)[0], N);
        // A 4x4 checkerboard: every interior cell has 4 agreeing and 4 opposing
        // neighbours, so nothing changes; a second pass would see the same labels.
        let board: Vec<CellClass> = (0..16)
            .map(|i| if (i / 4 + i % 4) % 2 == 0 { T } else { N })
            .collect();
        assert_eq!(filter().apply(&board, 4), board);
    }

    #[test]
    fn disabled_filter_is_the_identity() {
        let f = OutlierFilter {
            config: FilterConfig {
                enabled: false,
                self_weight: 3,
            },
        };
        let grid = vec![T, T, T, T, N, T, T, T, T];
        assert_eq!(f.apply(&grid, 3), grid);
    }
}
