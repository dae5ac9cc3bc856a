//! `travmap config`: the effective configuration as TOML (or JSON).

use anyhow::Result;
use clap::Args;

use super::{Outcome, Output, Settings, print_json_summary};

/// Print the effective configuration (TOML; JSON with --json).
#[derive(Args)]
#[command(
    after_long_help = "Examples (SEQ: a KITTI sequence folder, e.g. ../shared/data/semantickitti-00/sequences/00):\n  travmap config > travmap.toml\n  travmap config --set integration.poses=tf -q\n  travmap config --json"
)]
pub struct ConfigArgs {
    #[command(flatten)]
    settings: Settings,
    #[command(flatten)]
    output: Output,
}

pub fn config(args: ConfigArgs) -> Result<Outcome> {
    let config = args.settings.load()?;
    // The configuration is the answer: `--quiet` (nothing else to hide) prints it too.
    if args.output.json {
        print_json_summary("config", &[], serde_json::json!({ "config": config }))?;
    } else {
        print!("{}", toml::to_string(&config)?);
    }
    Ok(Outcome::Complete)
}
