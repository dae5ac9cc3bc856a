//! The questions `travmap label` asks a person: the drives run by a model on the
//! training grid (the cells `dataset` and `train` use), the cells it is least sure of
//! chosen over every frame (`travmap_method::asking`), and the frames that hold them
//! kept whole, with their camera images, for the page to show and for the answers'
//! features.
//!
//! Two passes over the drives: the first ranks every predictable cell by the model's
//! margin and keeps only the candidates the budget could use; the second keeps the
//! results of the frames asked about. Memory stays that of the asked frames however
//! long the drives.

use std::collections::{BTreeMap, BinaryHeap};

use travmap_core::Config;
use travmap_core::error::{Error, Result};
use travmap_core::frame::CameraImage;
use travmap_core::random::SplitMix64;
use travmap_method::asking::{AskBy, Candidate, Spread, choose};
use travmap_method::classifier::SvmModel;
use travmap_method::pipeline::FrameResult;

use crate::{DriveRun, RunEvent};

/// How many cells to ask about, and how they are chosen.
#[derive(Clone, Copy, Debug)]
pub struct AskOptions {
    pub budget: usize,
    pub by: AskBy,
    pub spread: Spread,
}

/// A frame some asked cell lies in: its result on the training grid (features,
/// the model's classes and margins, ground truth when the drive has labels) and the
/// camera image read with it.
pub struct AskedFrame {
    /// Which of the drives, and the drive's path as the labels file records it.
    pub drive: usize,
    pub source: String,
    pub result: FrameResult,
    pub camera: Option<CameraImage>,
}

/// A cell asked about: its frame (in [`Questions::frames`]), its cell of that frame's
/// grid and the model's margin of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AskedCell {
    pub frame: usize,
    pub cell: usize,
    pub margin: f32,
}

/// What a person is asked: the frames in drive and frame order, the cells in the
/// order they were chosen (least sure first when asking by margin).
pub struct Questions {
    pub frames: Vec<AskedFrame>,
    pub cells: Vec<AskedCell>,
    /// Predictable cells the model classified over every frame.
    pub candidates: usize,
}

/// Candidates kept from the first pass per cell of the budget: spreading passes
/// over many (near neighbours of cells already chosen), so that many are kept.
const CANDIDATES_PER_ASKED_CELL: usize = 200;

/// A candidate in the first pass, ordered by how early it would be chosen.
#[derive(Clone, Copy, Debug)]
struct Ranked {
    key: f32,
    drive: usize,
    frame_index: usize,
    candidate: Candidate,
}

impl PartialEq for Ranked {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == std::cmp::Ordering::Equal
    }
}

impl Eq for Ranked {}

impl PartialOrd for Ranked {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ranked {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (self.key.total_cmp(&other.key))
            .then(self.drive.cmp(&other.drive))
            .then(self.frame_index.cmp(&other.frame_index))
            .then(self.candidate.cell.cmp(&other.candidate.cell))
    }
}

/// The questions about `drives` that `model` makes under `config` (the training
/// grid's: [`Config::for_training_cells`]); `on_frame` is called after each frame
/// of either pass.
pub fn ask(
    drives: &[DriveRun],
    config: &Config,
    model: &SvmModel,
    options: AskOptions,
    on_frame: &mut dyn FnMut(),
) -> Result<Questions> {
    // 1. Every predictable cell, ranked; the first `keep` of the ranking kept.
    let keep = (options.budget * CANDIDATES_PER_ASKED_CELL).max(1);
    let mut random = SplitMix64(match options.by {
        AskBy::Random { seed } => seed,
        AskBy::Margin => 0,
    });
    let mut ranked: BinaryHeap<Ranked> = BinaryHeap::with_capacity(keep + 1);
    let mut candidates = 0;
    let mut frame_numbers: Vec<(usize, usize)> = Vec::new();
    for (drive, run) in drives.iter().enumerate() {
        run.run::<Error>(config, Some(model), |result| {
            on_frame();
            let Some(margins) = &result.margins else {
                return Ok(());
            };
            let frame = frame_numbers.len();
            frame_numbers.push((drive, result.index));
            for (cell, &margin) in margins.iter().enumerate() {
                if !margin.is_finite() {
                    continue;
                }
                candidates += 1;
                let key = match options.by {
                    AskBy::Margin => margin.abs(),
                    // A uniform random rank keeps a uniform sample of `keep`.
                    AskBy::Random { .. } => (random.next_u64() >> 40) as f32,
                };
                ranked.push(Ranked {
                    key,
                    drive,
                    frame_index: result.index,
                    candidate: Candidate {
                        frame,
                        cell,
                        margin,
                        centre_in_world: result.layout.cell_centre_in_world(cell),
                    },
                });
                if ranked.len() > keep {
                    ranked.pop();
                }
            }
            Ok(())
        })?;
    }
    let pool: Vec<Candidate> = (ranked.into_sorted_vec().into_iter())
        .map(|r| r.candidate)
        .collect();
    let chosen: Vec<Candidate> = choose(&pool, options.budget, options.by, options.spread)
        .into_iter()
        .map(|i| pool[i])
        .collect();

    // 2. The frames of the chosen cells, kept whole with their camera images.
    let wanted: BTreeMap<(usize, usize), usize> = {
        let mut frames: Vec<(usize, usize)> =
            chosen.iter().map(|c| frame_numbers[c.frame]).collect();
        frames.sort_unstable();
        frames.dedup();
        frames
            .into_iter()
            .enumerate()
            .map(|(i, f)| (f, i))
            .collect()
    };
    let mut frames: Vec<Option<AskedFrame>> = (0..wanted.len()).map(|_| None).collect();
    for (drive, run) in drives.iter().enumerate() {
        if !wanted.keys().any(|&(d, _)| d == drive) {
            continue;
        }
        let source = run.source.path().display().to_string();
        let mut cameras: BTreeMap<usize, Option<CameraImage>> = BTreeMap::new();
        let camera_of =
            |frame: &travmap_core::frame::Frame| -> Result<(usize, Option<CameraImage>)> {
                let asked = wanted.contains_key(&(drive, frame.index));
                Ok((frame.index, asked.then(|| frame.camera.clone()).flatten()))
            };
        run.run_mapped_beside::<Error, _>(config, Some(model), &camera_of, |event| {
            match event {
                RunEvent::Read((index, camera)) => {
                    cameras.insert(index, camera);
                }
                RunEvent::Result(result, _) => {
                    on_frame();
                    if let Some(&slot) = wanted.get(&(drive, result.index)) {
                        frames[slot] = Some(AskedFrame {
                            drive,
                            source: source.clone(),
                            camera: cameras.remove(&result.index).flatten(),
                            result: *result,
                        });
                    }
                }
            }
            Ok(())
        })?;
    }
    // A frame the second pass did not hand on (skipped with --keep-going after the
    // first read it) asks nothing.
    let mut position = Vec::with_capacity(frames.len());
    let mut kept = 0;
    for frame in &frames {
        position.push(frame.as_ref().map(|_| kept));
        kept += usize::from(frame.is_some());
    }
    let frames: Vec<AskedFrame> = frames.into_iter().flatten().collect();
    let cells = chosen
        .iter()
        .filter_map(|c| {
            let frame = position[*wanted.get(&frame_numbers[c.frame])?]?;
            Some(AskedCell {
                frame,
                cell: c.cell,
                margin: c.margin,
            })
        })
        .collect();
    Ok(Questions {
        frames,
        cells,
        candidates,
    })
}
