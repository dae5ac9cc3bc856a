//! `travmap config`: the effective configuration as TOML (or JSON).

use anyhow::Result;
use clap::Args;

use super::{Outcome, Settings, print_json_summary};

/// Print the effective configuration (TOML; JSON with --json).
#[derive(Args)]
pub struct ConfigArgs {
    #[command(flatten)]
    settings: Settings,
    #[arg(long)]
    json: bool,
}

pub fn config(args: ConfigArgs) -> Result<Outcome> {
    let config = args.settings.load()?;
    if args.json {
        print_json_summary("config", &[], serde_json::json!({ "config": config }))?;
    } else {
        print!("{}", toml::to_string(&config)?);
    }
    Ok(Outcome::Complete)
}
