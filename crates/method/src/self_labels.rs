//! Stage 6b (adaptation only), self-labels: what a drive says of its own cells,
//! without any annotation. Traversable: footprint cells the vehicle can have driven
//! over (height range within its clearance; a footprint cell over it, say a car
//! that stood there before the vehicle passed, is left out, not flipped). Not
//! traversable: cells the prior model rejects with a confident margin, and cells
//! over the clearance; never a footprint cell. Everything else is unknown.
//!
//! Input: a frame's [`FeatureGrid`], its footprint and the prior's margins. Output:
//! per cell `Some(true)`, `Some(false)` or `None`.

use crate::features::{FEATURE_NAMES, FeatureGrid};
use travmap_core::config::{AdaptConfig, VehicleConfig};

/// Where the height range of a cell (`zeta_difference`) is among its features.
const HEIGHT_RANGE: usize = 16;
const _: () = assert!(matches!(
    FEATURE_NAMES[HEIGHT_RANGE].as_bytes(),
    b"zeta_difference"
));

/// Whether a cell's height range (its features, `cell`) is over the vehicle's
/// clearance: an obstacle by geometry alone.
pub fn over_clearance(cell: &[f32], vehicle: &VehicleConfig) -> bool {
    cell[HEIGHT_RANGE] > vehicle.clearance_m as f32
}

/// The rules of the self-labels.
#[derive(Clone, Debug)]
pub struct SelfLabeller {
    pub vehicle: VehicleConfig,
    pub adapt: AdaptConfig,
}

impl SelfLabeller {
    /// The self-label of every cell: footprint and clear: traversable; a confident
    /// rejection by the prior (`margins`, when there is a prior) or over the
    /// clearance: not; else (and unpredictable cells) none.
    pub fn label(
        &self,
        features: &FeatureGrid,
        footprint: &[bool],
        margins: Option<&[f32]>,
    ) -> Vec<Option<bool>> {
        let confident = -(self.adapt.negative_margin as f32);
        (0..features.predictable.len())
            .map(|cell| {
                if !features.predictable[cell] {
                    return None;
                }
                let blocked = over_clearance(features.cell(cell), &self.vehicle);
                if footprint[cell] {
                    return (!blocked).then_some(true);
                }
                let rejected = margins.is_some_and(|m| m[cell] <= confident);
                (rejected || (blocked && self.adapt.geometric_negatives)).then_some(false)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use travmap_core::config::FeatureGroup;

    /// Four predictable cells and one that is not; cell 1 and 3 are over the
    /// clearance.
    fn grid() -> FeatureGrid {
        let dimension = FEATURE_NAMES.len();
        let mut values = vec![0.0f32; 5 * dimension];
        values[dimension + HEIGHT_RANGE] = 0.5;
        values[3 * dimension + HEIGHT_RANGE] = 1.2;
        FeatureGrid {
            values,
            dimension,
            groups: Vec::<FeatureGroup>::new(),
            predictable: vec![true, true, true, true, false],
            appearance: Default::default(),
        }
    }

    fn labeller() -> SelfLabeller {
        SelfLabeller {
            vehicle: VehicleConfig::default(),
            adapt: AdaptConfig::default(),
        }
    }

    #[test]
    fn footprint_is_traversable_unless_blocked_and_never_negative() {
        let footprint = [true, true, false, false, true];
        // The prior rejects every cell: a footprint cell stays a positive (cell 0),
        // a blocked one is left out (cell 1), others are negatives.
        let margins = [-5.0f32, -5.0, -5.0, 0.5, f32::NAN];
        let labels = labeller().label(&grid(), &footprint, Some(&margins));
        assert_eq!(
            labels,
            vec![Some(true), None, Some(false), Some(false), None]
        );
    }

    #[test]
    fn negatives_need_a_confident_margin_or_a_height_over_the_clearance() {
        let footprint = [false; 5];
        let margins = [-0.5f32, 2.0, -2.0, 2.0, f32::NAN];
        let labels = labeller().label(&grid(), &footprint, Some(&margins));
        assert_eq!(
            labels,
            vec![None, Some(false), Some(false), Some(false), None]
        );
        let mut only_prior = labeller();
        only_prior.adapt.geometric_negatives = false;
        let labels = only_prior.label(&grid(), &footprint, Some(&margins));
        assert_eq!(labels, vec![None, None, Some(false), None, None]);
        // Without a prior, only geometry says no.
        let labels = labeller().label(&grid(), &footprint, None);
        assert_eq!(labels, vec![None, Some(false), None, Some(false), None]);
    }
}
