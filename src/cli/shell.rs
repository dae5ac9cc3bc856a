//! `travmap completions SHELL` and `travmap man`: what a shell and `man` need,
//! generated from the command line's own definition, so they never drift from it.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use clap_complete::Shell;
use travmap_outputs::atomic::Staged;

use super::Outcome;

/// Print a shell's completion script for travmap.
#[derive(Args)]
#[command(
    after_long_help = "Examples:\n  travmap completions bash > ~/.local/share/bash-completion/completions/travmap\n  travmap completions zsh > ~/.zfunc/_travmap\n  travmap completions fish > ~/.config/fish/completions/travmap.fish"
)]
pub struct CompletionsArgs {
    /// The shell to complete in.
    #[arg(value_enum)]
    shell: ShellArg,
}

#[derive(Clone, Copy, ValueEnum)]
enum ShellArg {
    Bash,
    Zsh,
    Fish,
    Elvish,
    Powershell,
}

/// Write travmap's man pages: travmap.1 and one per command (travmap-eval.1, ...).
#[derive(Args)]
#[command(
    after_long_help = "Examples:\n  travmap man -o ~/.local/share/man/man1 && man travmap-annotate"
)]
pub struct ManArgs {
    /// The folder to write the pages into (made if missing).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
}

pub fn completions(args: CompletionsArgs, mut command: clap::Command) -> Result<Outcome> {
    let shell = match args.shell {
        ShellArg::Bash => Shell::Bash,
        ShellArg::Zsh => Shell::Zsh,
        ShellArg::Fish => Shell::Fish,
        ShellArg::Elvish => Shell::Elvish,
        ShellArg::Powershell => Shell::PowerShell,
    };
    let name = command.get_name().to_string();
    let mut script = Vec::new();
    clap_complete::generate(shell, &mut command, name, &mut script);
    std::io::stdout().lock().write_all(&script)?;
    Ok(Outcome::Complete)
}

pub fn man(args: ManArgs, command: clap::Command) -> Result<Outcome> {
    let created = !args.output.exists();
    std::fs::create_dir_all(&args.output)
        .with_context(|| format!("cannot make {}", args.output.display()))?;
    // Every page staged, then all renamed into place: a full disk leaves none (nor
    // the folder, when this run made it).
    let written = write_pages(&args.output, &command);
    if written.is_err() && created {
        let _ = std::fs::remove_dir_all(&args.output);
    }
    let written = written?;
    for path in &written {
        println!("wrote {}", path.display());
    }
    Ok(Outcome::Complete)
}

/// The pages of `command` and each subcommand into `dir`, all or none.
fn write_pages(dir: &Path, command: &clap::Command) -> Result<Vec<PathBuf>> {
    let mut staged = Staged::default();
    let mut written = vec![page(&mut staged, dir, "travmap", command)?];
    for sub in command.get_subcommands() {
        // The page is travmap-eval(1), as git's are; its synopsis is the command
        // typed: `travmap eval`.
        let name = format!("travmap-{}", sub.get_name());
        let typed = format!("travmap {}", sub.get_name());
        let sub = sub.clone().display_name(&name).bin_name(typed);
        written.push(page(&mut staged, dir, &name, &sub)?);
    }
    staged.commit()?;
    Ok(written)
}

/// `command`'s page, `dir/name.1`, staged.
fn page(staged: &mut Staged, dir: &Path, name: &str, command: &clap::Command) -> Result<PathBuf> {
    let mut roff = Vec::new();
    clap_mangen::Man::new(command.clone())
        .title(name.to_uppercase())
        .render(&mut roff)?;
    let path = dir.join(format!("{name}.1"));
    staged.write(&path, &roff)?;
    Ok(path)
}
