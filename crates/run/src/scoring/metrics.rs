//! Metrics (METHOD.md section 9): the confusion of a predicted grid against its
//! ground truth and the paper's table columns. Positive class = traversable.

use serde::Serialize;

use travmap_method::grid::CellClass;

/// Counts of cells with a ground-truth label, by outcome.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Confusion {
    pub tp: u64,
    pub tn: u64,
    pub fp: u64,
    pub r#fn: u64,
    /// Cells with ground truth that the method left unpredictable.
    pub unknown: u64,
}

/// The paper's table columns, as fractions in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Scores {
    pub accuracy: f64,
    pub miou: f64,
    pub iou_traversable: f64,
    pub iou_non_traversable: f64,
    pub f1: f64,
    pub fpr: f64,
    pub tpr: f64,
    pub fnr: f64,
    pub tnr: f64,
}

impl Confusion {
    /// Compares two grids cell by cell; cells without ground truth do not count.
    pub fn of_grids(predicted: &[CellClass], truth: &[CellClass]) -> Self {
        let mut c = Confusion::default();
        for (&p, &t) in predicted.iter().zip(truth) {
            c.add(p, t);
        }
        c
    }

    pub fn add(&mut self, predicted: CellClass, truth: CellClass) {
        use CellClass::{NonTraversable as N, Traversable as T, Unknown as U};
        match (predicted, truth) {
            (_, U) => {}
            (U, _) => self.unknown += 1,
            (T, T) => self.tp += 1,
            (N, N) => self.tn += 1,
            (T, N) => self.fp += 1,
            (N, T) => self.r#fn += 1,
        }
    }

    /// A fused drive map against its fused ground truth, each world cell once.
    pub fn of_drive_map(cells: &[travmap_method::fusion::FusedCell]) -> Self {
        let mut confusion = Confusion::default();
        for cell in cells
            .iter()
            .filter(|c| c.ground_truth != CellClass::Unknown)
        {
            confusion.add(cell.class, cell.ground_truth);
        }
        confusion
    }

    pub fn merge(&mut self, other: &Confusion) {
        self.tp += other.tp;
        self.tn += other.tn;
        self.fp += other.fp;
        self.r#fn += other.r#fn;
        self.unknown += other.unknown;
    }

    /// Cells with ground truth: TP + TN + FP + FN + UNK.
    pub fn total(&self) -> u64 {
        self.tp + self.tn + self.fp + self.r#fn + self.unknown
    }

    /// Cells both predicted and with ground truth: TP + TN + FP + FN.
    pub fn predicted(&self) -> u64 {
        self.tp + self.tn + self.fp + self.r#fn
    }

    /// [`Self::scores`], when some cell was predicted.
    pub fn scores_if_predicted(&self) -> Option<Scores> {
        (self.predicted() > 0).then(|| self.scores())
    }

    /// Rates are conditional (TPR = TP / (TP + FN)), as in the paper's table; an
    /// empty denominator gives 0.
    pub fn scores(&self) -> Scores {
        let ratio = |num: u64, den: u64| {
            if den == 0 {
                0.0
            } else {
                num as f64 / den as f64
            }
        };
        let (tp, tn, fp, fn_) = (self.tp, self.tn, self.fp, self.r#fn);
        let iou_traversable = ratio(tp, tp + fp + fn_);
        let iou_non_traversable = ratio(tn, tn + fn_ + fp);
        Scores {
            accuracy: ratio(tp + tn, self.total()),
            miou: (iou_traversable + iou_non_traversable) / 2.0,
            iou_traversable,
            iou_non_traversable,
            f1: ratio(2 * tp, 2 * tp + fp + fn_),
            fpr: ratio(fp, fp + tn),
            tpr: ratio(tp, tp + fn_),
            fnr: ratio(fn_, tp + fn_),
            tnr: ratio(tn, tn + fp),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use CellClass::{NonTraversable as N, Traversable as T, Unknown as U};

    #[test]
    fn hand_counted_grid() {
        let predicted = [T, T, T, N, N, U, T, U];
        let truth = [T, T, N, N, T, T, U, U];
        let c = Confusion::of_grids(&predicted, &truth);
        assert_eq!(
            c,
            Confusion {
                tp: 2,
                tn: 1,
                fp: 1,
                r#fn: 1,
                unknown: 1
            }
        );
        let s = c.scores();
        assert_eq!(s.accuracy, 3.0 / 6.0);
        assert_eq!(s.iou_traversable, 2.0 / 4.0);
        assert_eq!(s.iou_non_traversable, 1.0 / 3.0);
        assert_eq!(s.miou, (0.5 + 1.0 / 3.0) / 2.0);
        assert_eq!(s.f1, 4.0 / 6.0);
        assert_eq!(s.tpr, 2.0 / 3.0);
        assert_eq!(s.fnr, 1.0 / 3.0);
        assert_eq!(s.fpr, 0.5);
        assert_eq!(s.tnr, 0.5);
    }

    #[test]
    fn empty_confusion_scores_zero_not_nan() {
        let s = Confusion::default().scores();
        assert_eq!(s.accuracy, 0.0);
        assert_eq!(s.f1, 0.0);
    }
}
