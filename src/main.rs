//! The `travmap` binary: parses the command line and calls one subcommand, each a
//! function in `cli/` over library types; then maps how it ended to an exit code.
//!
//! Exit codes: 0 complete, 1 error (no output written), 2 usage error, 3 completed
//! with skipped frames (`--keep-going`), 130 interrupted (no output written).

mod cli;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use cli::Outcome;

#[derive(Parser)]
#[command(
    name = "travmap",
    version,
    about = "Traversability maps from recorded drives (LiDAR + SVM, CPU only)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    Run(cli::run::RunArgs),
    Eval(cli::eval::EvalArgs),
    Train(cli::train::TrainArgs),
    Dataset(cli::dataset::DatasetArgs),
    Crossval(cli::crossval::CrossvalArgs),
    Convert(cli::convert::ConvertArgs),
    Annotate(cli::annotate::AnnotateArgs),
    Render(cli::render::RenderArgs),
    Bench(cli::bench::BenchArgs),
    Config(cli::config::ConfigArgs),
}

fn main() -> ExitCode {
    // Interrupted: remove partial outputs, exit as shells expect after SIGINT.
    let _ = ctrlc::set_handler(|| {
        travmap::outputs::writing::remove_temporary_files();
        std::process::exit(130);
    });
    let outcome = match Cli::parse().command {
        Command::Run(args) => cli::run::run(args),
        Command::Eval(args) => cli::eval::eval(args),
        Command::Train(args) => cli::train::train(args),
        Command::Dataset(args) => cli::dataset::dataset(args),
        Command::Crossval(args) => cli::crossval::crossval(args),
        Command::Convert(args) => cli::convert::convert(args),
        Command::Annotate(args) => cli::annotate::annotate(args),
        Command::Render(args) => cli::render::render(args),
        Command::Bench(args) => cli::bench::bench(args),
        Command::Config(args) => cli::config::config(args),
    };
    match outcome {
        Ok(Outcome::Complete) => ExitCode::SUCCESS,
        Ok(Outcome::Skipped(frames)) => {
            eprintln!("completed with {frames} skipped frame(s)");
            ExitCode::from(3)
        }
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
