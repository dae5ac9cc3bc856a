//! What a run says of the drives it scored, in words every front end uses (the
//! command line prints them, the Python module warns with them): how well they fit
//! the model, remission it could not use or of another sensor's scale, labels of
//! ids the label set does not define, and another rule than the model learnt.

use travmap_core::Config;
use travmap_core::config::{ForeignRemissionPolicy, LabelRule, LabelSet};
use travmap_method::classifier::SvmModel;

use super::evaluation::{EvaluationReport, Fit, POOR_FIT_UNSURE_SHARE, UNSURE_MARGIN};

/// `n noun` with the noun in the plural unless n is 1.
pub fn counted<N: Copy + std::fmt::Display + TryInto<u64>>(n: N, noun: &str) -> String {
    match n.try_into().ok() {
        Some(1) => format!("1 {noun}"),
        _ => format!("{n} {noun}s"),
    }
}

/// What a poor fit's notice may advise: only what the command and the drives
/// allow.
#[derive(Clone, Copy, Debug, Default)]
pub struct FitRemedies {
    /// The command adapts with `--adapt` (`eval`, `annotate`); elsewhere adapting
    /// is `travmap adapt`'s.
    pub adapt_flag: bool,
    /// The drives move (posed scans, more than one frame): a footprint to learn
    /// from. A single scan, or scans each alone, show none.
    pub drives_move: bool,
    /// How many of the scored frames the model was trained on (None: unknown).
    pub training_frames: Option<usize>,
}

impl FitRemedies {
    /// The remedies of a command over `drives` (`adapt_flag`: it has `--adapt`).
    pub fn of(
        drives: &[crate::DriveRun],
        adapt_flag: bool,
        training_frames: Option<usize>,
    ) -> Self {
        Self {
            adapt_flag,
            drives_move: drives.iter().any(crate::DriveRun::moves),
            training_frames,
        }
    }
}

/// What is said of the drives even when nothing else is (`-q`, `--json`): labels
/// of ids the label set does not define, remission that could not be used or is
/// of another sensor's scale, and a poor fit (each looks like a bad model otherwise).
pub fn drive_notices(
    report: &EvaluationReport,
    model: &SvmModel,
    config: &Config,
    remedies: FitRemedies,
) -> Vec<String> {
    (unknown_labels_said(report, config).into_iter())
        .chain(without_remission_said(report))
        .chain(foreign_remission_said(report, config))
        .chain(poor_fit_said(&report.fit, model, remedies))
        .collect()
}

/// How well the drives fit the model, in a line.
pub fn fit_said(fit: &Fit) -> String {
    format!(
        "fit: {}; over {:.0} % a drive fits the model poorly",
        unsure_share(fit),
        100.0 * POOR_FIT_UNSURE_SHARE
    )
}

fn unsure_share(fit: &Fit) -> String {
    format!(
        "{:.1} % of {} predicted cells within the model's margin (|margin| < {UNSURE_MARGIN})",
        100.0 * fit.unsure_share,
        fit.cells
    )
}

/// When the drives fit the model poorly: what that means, and what can be done
/// about it with this command and these drives.
pub fn poor_fit_said(fit: &Fit, model: &SvmModel, remedies: FitRemedies) -> Option<String> {
    if !fit.poor {
        return None;
    }
    let mut said = format!(
        "these drives fit the model poorly ({}, over {:.0} %: in docs/method.md's cross-dataset study every drive held out of training that scored below 60 mIoU was over it, and none that scored above 85)",
        unsure_share(fit),
        100.0 * POOR_FIT_UNSURE_SHARE
    );
    let trained_on = remedies.training_frames.filter(|&n| n > 0);
    if let Some(n) = trained_on {
        said += &format!(
            "; {n} of these frames {} among its training scans, so the model is unsure of this ground even where it was taught: more of the same teaching will not help, another rule of what is traversable may",
            if n == 1 { "was" } else { "were" }
        );
    }
    let mut remedies_said = Vec::new();
    let adapted = model.training.adaptation.as_ref();
    match adapted {
        Some(adaptation) if adaptation.check.as_ref().is_some_and(|c| !c.adapted) => {
            said += "; adaptation to these drives kept the model as it was";
        }
        Some(_) => said += "; the model is already adapted to drives",
        None if remedies.drives_move && trained_on.is_none() => {
            remedies_said.push(match remedies.adapt_flag {
                true => "adapt it to them (--adapt)".to_string(),
                false => "adapt it to them (travmap adapt INPUT -o adapted.json, then --model adapted.json)".to_string(),
            });
        }
        None => {}
    }
    let other = match model.config.ground_truth.rule {
        LabelRule::Road => {
            "the offroad model (--model offroad) if the robot may drive on grass, dirt or low vegetation: it calls them traversable, where this model's road rule does not"
        }
        LabelRule::Offroad => {
            "the road model (--model road) if only a car's road counts: it calls grass, dirt and low vegetation not traversable, where this model's rule does not"
        }
    };
    remedies_said.push(other.to_string());
    if trained_on.is_none() {
        remedies_said.push("train on labelled scans of this sensor (travmap train)".into());
    }
    said += &format!(": {}", or_list(&remedies_said));
    Some(said)
}

/// How a taught model fits the drives its cells were labelled on, beside its prior,
/// in a line.
pub fn taught_fit_said(taught: &Fit, prior: &Fit) -> String {
    format!(
        "fit on the labelled drives: {:.1} % of {} predicted cells within the taught model's margin, {:.1} % within the prior's ({})",
        100.0 * taught.unsure_share,
        taught.cells,
        100.0 * prior.unsure_share,
        match taught.unsure_share < prior.unsure_share {
            true => "the taught model fits them better",
            false => "the taught model fits them no better",
        }
    )
}

/// `a; b; or c` (the items hold commas of their own).
fn or_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{}; or {last}", rest.join("; ")),
    }
}

/// What is said when the scores count another rule of what is traversable than the
/// model learnt (the off-road model scored by the road rule looks like a bad model).
pub fn other_rule_said(model: &SvmModel, config: &Config) -> Option<String> {
    let (learnt, scored) = (model.config.ground_truth.rule, config.ground_truth.rule);
    let by_preset = |c: &Config| {
        c.ground_truth.label_map.is_none() && c.ground_truth.traversable_classes.is_none()
    };
    (learnt != scored && by_preset(&model.config) && by_preset(config)).then(|| {
        format!(
            "the model learnt the {} rule of what is traversable, these scores count the {} rule (--set ground_truth.rule=\"{}\" scores it by its own)",
            learnt.name(),
            scored.name(),
            learnt.name()
        )
    })
}

/// What is said when frames had no usable remission, and why when some of it was
/// NaN or infinite (a frame that looks fine but lost its remission features).
pub fn without_remission_said(report: &EvaluationReport) -> Option<String> {
    if report.frames_without_remission == 0 {
        return None;
    }
    let why = match report.non_finite_remission_points {
        0 => String::new(),
        points => format!("; {points} points' remission was NaN or infinite"),
    };
    Some(format!(
        "{} had no usable remission (intensity{why}): the model's fallback without remission features classified them",
        counted(report.frames_without_remission, "frame")
    ))
}

/// What is said of frames whose remission lay far outside the model's training
/// range (another sensor's scale), when there were some.
pub fn foreign_remission_said(report: &EvaluationReport, config: &Config) -> Option<String> {
    let foreign = report.foreign_remission?;
    Some(format!(
        "{} had remission far outside the model's training range (median cell {:.4}, the model learnt {:.2} +- {:.2}: another sensor's scale?): {}",
        counted(report.frames_foreign_remission, "frame"),
        foreign.median,
        foreign.trained_mean,
        foreign.trained_std,
        match config.classifier.foreign_remission {
            ForeignRemissionPolicy::Notice => {
                "classified as read (--set classifier.foreign_remission=\"fallback\" classifies them without remission)"
            }
            ForeignRemissionPolicy::Fallback => {
                "the model's fallback without remission classified them"
            }
        }
    ))
}

/// What is said when labels carried ids the label set does not define: a run
/// scored against another dataset's labels looks like a bad model.
pub fn unknown_labels_said(report: &EvaluationReport, config: &Config) -> Option<String> {
    let unknown = &report.unknown_labels;
    if unknown.points == 0 {
        return None;
    }
    let ids: Vec<String> = unknown.examples.iter().map(u16::to_string).collect();
    let truth = &config.ground_truth;
    let label_set = match &truth.label_map {
        Some(path) => format!("label map {}", path.display()),
        None => format!("{} label set", truth.labels.name()),
    };
    // The presets that define every id seen (the unknown ones among them).
    let fitting: Vec<&str> = (LabelSet::ALL.iter())
        .filter(|set| truth.label_map.is_some() || **set != truth.labels)
        .filter(|set| unknown.examples.iter().all(|&id| set.defines(id)))
        .map(|set| set.name())
        .collect();
    let which = match fitting.as_slice() {
        [] => "--set ground_truth.labels=..., or a label_map".to_string(),
        [one] => format!("they fit the {one} label set: --set ground_truth.labels={one}"),
        several => format!(
            "they fit the {} label sets: --set ground_truth.labels=...",
            several.join(" and ")
        ),
    };
    Some(format!(
        "{} labelled points in {} carry ids the {label_set} does not define (e.g. {}): they count as not traversable; are these another dataset's labels ({which})?",
        unknown.points,
        counted(report.frames_with_unknown_labels, "frame"),
        ids.join(", ")
    ))
}
