//! Which cells to ask a person about (`travmap label`): the cells the model is least
//! sure of, spread over the drive's frames and places. A cell with a small margin is
//! worth 3-4 random ones to the model retrained on it (`../shared/notes/
//! asking-unsure-cells.md`); spreading keeps one confusing patch of ground from
//! taking the whole budget.
//!
//! Input: candidate cells with their margin and world position. Output: the indices
//! of the chosen ones, least sure first.

use std::collections::HashSet;

use travmap_core::random::SplitMix64;

/// A predictable cell of some frame the model could be asked about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The frame's position among the frames considered.
    pub frame: usize,
    pub cell: usize,
    /// The model's margin (decision value minus threshold; positive: traversable).
    pub margin: f32,
    pub centre_in_world: [f64; 2],
}

/// How the cells to ask are ranked before they are spread.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AskBy {
    /// Least sure first: the smallest |margin|.
    Margin,
    /// In a seeded random order (the baseline asking by margin is measured against).
    Random { seed: u64 },
}

/// How asked cells are spread: no two within `spacing_m` of each other in the world,
/// and no frame holding more than its share.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    pub spacing_m: f64,
    /// A frame holds at most `frame_share` times the budget over the frames (and at
    /// least one cell).
    pub frame_share: f64,
}

impl Default for Spread {
    fn default() -> Self {
        // 2 m: five cells of 0.4 m, wider than a feature's neighbourhood, so that two
        // answers say two things; twice a frame's even share, so that a frame that
        // shows much unsure ground gets more, not all.
        Self {
            spacing_m: 2.0,
            frame_share: 2.0,
        }
    }
}

/// Up to `budget` of `candidates` to ask about, ranked as `by` says and spread as
/// `spread` says; indices into `candidates`, in the order they were chosen.
pub fn choose(candidates: &[Candidate], budget: usize, by: AskBy, spread: Spread) -> Vec<usize> {
    let mut order: Vec<usize> = (0..candidates.len()).collect();
    match by {
        AskBy::Margin => order.sort_by(|&a, &b| {
            let (a, b) = (&candidates[a], &candidates[b]);
            (a.margin.abs().total_cmp(&b.margin.abs()))
                .then(a.frame.cmp(&b.frame))
                .then(a.cell.cmp(&b.cell))
        }),
        AskBy::Random { seed } => SplitMix64(seed).shuffle(&mut order),
    }
    let frames = candidates.iter().map(|c| c.frame + 1).max().unwrap_or(0);
    let per_frame = match frames {
        0 => 0,
        n => ((spread.frame_share * budget as f64 / n as f64).ceil() as usize).max(1),
    };
    let mut taken_in_frame = vec![0usize; frames];
    // Occupied blocks of `spacing_m`: a new cell is checked against its own block
    // and the eight around it.
    let block = |p: [f64; 2]| p.map(|v| (v / spread.spacing_m).floor() as i64);
    let mut occupied: std::collections::HashMap<[i64; 2], Vec<[f64; 2]>> = Default::default();
    let mut chosen = Vec::with_capacity(budget);
    let mut chosen_cells = HashSet::new();
    for index in order {
        if chosen.len() == budget {
            break;
        }
        let candidate = &candidates[index];
        if !candidate.margin.is_finite()
            || taken_in_frame[candidate.frame] >= per_frame
            || !chosen_cells.insert((candidate.frame, candidate.cell))
        {
            continue;
        }
        let [bx, by] = block(candidate.centre_in_world);
        let p = candidate.centre_in_world;
        let too_close = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                occupied.get(&[bx + dx, by + dy]).is_some_and(|points| {
                    points.iter().any(|q| {
                        (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) < spread.spacing_m.powi(2)
                    })
                })
            })
        });
        if too_close {
            chosen_cells.remove(&(candidate.frame, candidate.cell));
            continue;
        }
        occupied.entry([bx, by]).or_default().push(p);
        taken_in_frame[candidate.frame] += 1;
        chosen.push(index);
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(frame: usize, cell: usize, margin: f32, x: f64, y: f64) -> Candidate {
        Candidate {
            frame,
            cell,
            margin,
            centre_in_world: [x, y],
        }
    }

    #[test]
    fn the_least_sure_come_first_and_no_two_lie_close() {
        let candidates = [
            candidate(0, 0, 2.0, 0.0, 0.0),
            candidate(0, 1, -0.1, 10.0, 0.0),
            // Closer than 2 m to the cell above: passed over for the next.
            candidate(0, 2, 0.2, 11.0, 0.0),
            candidate(0, 3, 0.5, 20.0, 0.0),
            candidate(0, 4, f32::NAN, 30.0, 0.0),
        ];
        let chosen = choose(&candidates, 3, AskBy::Margin, Spread::default());
        assert_eq!(chosen, [1, 3, 0]);
    }

    #[test]
    fn no_frame_takes_more_than_its_share() {
        // Frame 0's cells are all less sure than frame 1's.
        let candidates: Vec<Candidate> = (0..20)
            .map(|i| candidate(0, i, 0.01 * i as f32, 3.0 * i as f64, 0.0))
            .chain((0..20).map(|i| candidate(1, i, 0.5, 3.0 * i as f64, 100.0)))
            .collect();
        let spread = Spread {
            spacing_m: 2.0,
            frame_share: 1.5,
        };
        let chosen = choose(&candidates, 10, AskBy::Margin, spread);
        let in_frame_0 = chosen.iter().filter(|&&i| candidates[i].frame == 0).count();
        assert_eq!((chosen.len(), in_frame_0), (10, 8));
    }

    #[test]
    fn random_asking_is_seeded() {
        let candidates: Vec<Candidate> = (0..50)
            .map(|i| candidate(0, i, 1.0, 5.0 * i as f64, 0.0))
            .collect();
        let by = AskBy::Random { seed: 7 };
        let first = choose(&candidates, 10, by, Spread::default());
        assert_eq!(first, choose(&candidates, 10, by, Spread::default()));
        assert_ne!(first, (0..10).collect::<Vec<_>>());
    }
}
