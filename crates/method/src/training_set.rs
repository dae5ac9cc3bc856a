//! The training set: labelled cells with their raw features, world positions and
//! (where a camera saw them) appearance values; and the spatial folds that keep a
//! world block's cells, and their copies in other frames, in one fold.

use crate::features::feature_count;
use travmap_core::config::Config;
use travmap_core::random::SplitMix64;

/// Labelled cells: raw features and where each cell lies in the world.
#[derive(Clone, Debug, Default)]
pub struct TrainingSet {
    /// Row-major `len x dimension` raw features.
    pub features: Vec<f32>,
    pub dimension: usize,
    pub traversable: Vec<bool>,
    /// Each cell's weight on C (1 unless the cell counts more or less, as the
    /// prior's cells in adaptation).
    pub weight: Vec<f32>,
    /// World x, y of each cell's centre, metres.
    pub centre_in_world: Vec<[f64; 2]>,
    /// Where the cells came from, for the model's record.
    pub sources: Vec<String>,
    /// SHA-256 of each labelled scan the cells came from.
    pub frame_sha256: Vec<String>,
    /// Appearance values of the cells a camera has seen, `appearance_len` each.
    pub appearance: Vec<f32>,
    pub appearance_len: usize,
    /// Per cell, its row in `appearance` (seen cells: the hybrid model's cells).
    pub appearance_row: Vec<Option<usize>>,
    /// The rows each input (a drive, a dataset file) gave, in order; empty once the
    /// cells are a subset.
    pub input_rows: Vec<std::ops::Range<usize>>,
}

impl TrainingSet {
    /// An empty set of cells computed with `config`'s features.
    pub fn for_features(config: &Config) -> TrainingSet {
        TrainingSet {
            dimension: feature_count(&config.features.groups),
            ..Default::default()
        }
    }

    /// The same cells without the feature columns `columns`.
    pub fn without_columns(&self, columns: std::ops::Range<usize>) -> TrainingSet {
        let d = self.dimension;
        let mut out = TrainingSet {
            dimension: d - columns.len(),
            features: Vec::with_capacity(self.len() * (d - columns.len())),
            ..self.clone()
        };
        out.features.clear();
        for row in self.features.chunks_exact(d) {
            out.features.extend_from_slice(&row[..columns.start]);
            out.features.extend_from_slice(&row[columns.end..]);
        }
        out
    }

    pub fn len(&self) -> usize {
        self.traversable.len()
    }

    pub fn is_empty(&self) -> bool {
        self.traversable.is_empty()
    }

    pub fn push(
        &mut self,
        features: &[f32],
        appearance: Option<&[f32]>,
        traversable: bool,
        centre_in_world: [f64; 2],
    ) {
        self.push_weighted(features, appearance, traversable, centre_in_world, 1.0);
    }

    /// [`Self::push`] with a weight on C.
    pub fn push_weighted(
        &mut self,
        features: &[f32],
        appearance: Option<&[f32]>,
        traversable: bool,
        centre_in_world: [f64; 2],
        weight: f32,
    ) {
        self.features.extend_from_slice(features);
        self.traversable.push(traversable);
        self.weight.push(weight);
        self.centre_in_world.push(centre_in_world);
        let row = appearance.map(|values| {
            self.appearance_len = values.len();
            self.appearance.extend_from_slice(values);
            self.appearance.len() / values.len().max(1) - 1
        });
        self.appearance_row.push(row);
    }

    pub(crate) fn appearance_of(&self, i: usize) -> Option<&[f32]> {
        let n = self.appearance_len;
        self.appearance_row[i].map(|row| &self.appearance[row * n..(row + 1) * n])
    }

    /// The seen cells with geometric and appearance values side by side, for the
    /// hybrid model; None when no cell was seen.
    pub fn hybrid(&self) -> Option<TrainingSet> {
        let d = self.dimension;
        let mut out = TrainingSet {
            dimension: d + self.appearance_len,
            sources: self.sources.clone(),
            frame_sha256: self.frame_sha256.clone(),
            ..Default::default()
        };
        for i in 0..self.len() {
            if let Some(appearance) = self.appearance_of(i) {
                let mut row = self.features[i * d..(i + 1) * d].to_vec();
                row.extend_from_slice(appearance);
                out.push_weighted(
                    &row,
                    None,
                    self.traversable[i],
                    self.centre_in_world[i],
                    self.weight[i],
                );
            }
        }
        (!out.is_empty()).then_some(out)
    }

    /// The cells at `indices`, in that order.
    pub fn subset(&self, indices: &[usize]) -> TrainingSet {
        let d = self.dimension;
        let mut out = TrainingSet {
            dimension: d,
            sources: self.sources.clone(),
            frame_sha256: self.frame_sha256.clone(),
            appearance_len: self.appearance_len,
            ..Default::default()
        };
        for &i in indices {
            out.push_weighted(
                &self.features[i * d..(i + 1) * d],
                self.appearance_of(i),
                self.traversable[i],
                self.centre_in_world[i],
                self.weight[i],
            );
        }
        out
    }
}

/// Assigns every cell to one of `folds` folds by its world block: blocks are
/// shuffled with `seed` and dealt round-robin, so folds hold similar block counts.
pub fn spatial_folds(
    centres: &[[f64; 2]],
    block_size_m: f64,
    folds: usize,
    seed: u64,
) -> Vec<usize> {
    let block_of = |c: &[f64; 2]| {
        [
            (c[0] / block_size_m).floor() as i64,
            (c[1] / block_size_m).floor() as i64,
        ]
    };
    let mut blocks: Vec<[i64; 2]> = centres.iter().map(block_of).collect();
    blocks.sort_unstable();
    blocks.dedup();
    SplitMix64(seed).shuffle(&mut blocks);
    let fold_of_block: std::collections::HashMap<[i64; 2], usize> = blocks
        .iter()
        .enumerate()
        .map(|(i, b)| (*b, i % folds))
        .collect();
    centres
        .iter()
        .map(|c| fold_of_block[&block_of(c)])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spatial_folds_keep_blocks_whole_and_use_every_fold() {
        let centres: Vec<[f64; 2]> = (0..400)
            .map(|i| [(i % 20) as f64 * 0.4, (i / 20) as f64 * 0.4])
            .collect();
        let folds = spatial_folds(&centres, 2.0, 5, 1);
        for (a, fa) in centres.iter().zip(&folds) {
            for (b, fb) in centres.iter().zip(&folds) {
                if (a[0] / 2.0).floor() == (b[0] / 2.0).floor()
                    && (a[1] / 2.0).floor() == (b[1] / 2.0).floor()
                {
                    assert_eq!(fa, fb);
                }
            }
        }
        for f in 0..5 {
            assert!(folds.contains(&f));
        }
    }
}
