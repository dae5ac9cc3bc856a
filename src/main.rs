//! The `travmap` binary: parses the command line and calls one subcommand, each a
//! function in `cli/` over library types; then maps how it ended to an exit code.
//!
//! Exit codes: 0 complete, 1 error (no output written), 2 usage error, 3 completed
//! with skipped frames (`--keep-going`), 129 / 130 / 143 hung up / interrupted /
//! terminated (no output written), 141 stdout closed early (`| head`).

mod cli;

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

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
    Adapt(cli::adapt::AdaptArgs),
    Label(cli::label::LabelArgs),
    Dataset(cli::dataset::DatasetArgs),
    Crossval(cli::crossval::CrossvalArgs),
    Convert(cli::convert::ConvertArgs),
    Annotate(cli::annotate::AnnotateArgs),
    Render(cli::render::RenderArgs),
    Bench(cli::bench::BenchArgs),
    Odometry(cli::odometry::OdometryArgs),
    Map(cli::map::MapArgs),
    Config(cli::config::ConfigArgs),
    Completions(cli::shell::CompletionsArgs),
    Man(cli::shell::ManArgs),
}

fn main() -> ExitCode {
    keep_freed_scans_for_reuse();
    remove_outputs_on_signals();
    // `--json` anywhere: errors too are JSON (on stderr), usage errors included.
    let json = std::env::args_os().any(|a| a == "--json");
    let command = match Cli::try_parse() {
        Ok(cli) => cli.command,
        Err(usage) if json && usage.use_stderr() => {
            cli::print_json_error(&usage.render().to_string(), None, usage.exit_code());
            return ExitCode::from(usage.exit_code() as u8);
        }
        Err(usage) => usage.exit(),
    };
    let outcome = match command {
        Command::Run(args) => cli::run::run(args),
        Command::Eval(args) => cli::eval::eval(args),
        Command::Train(args) => cli::train::train(args),
        Command::Adapt(args) => cli::adapt::adapt(args),
        Command::Label(args) => cli::label::label(args),
        Command::Dataset(args) => cli::dataset::dataset(args),
        Command::Crossval(args) => cli::crossval::crossval(args),
        Command::Convert(args) => cli::convert::convert(args),
        Command::Annotate(args) => cli::annotate::annotate(args),
        Command::Render(args) => cli::render::render(args),
        Command::Bench(args) => cli::bench::bench(args),
        Command::Odometry(args) => cli::odometry::odometry(args),
        Command::Map(args) => cli::map::map(args),
        Command::Config(args) => cli::config::config(args),
        Command::Completions(args) => cli::shell::completions(args, Cli::command()),
        Command::Man(args) => cli::shell::man(args, Cli::command()),
    };
    match outcome {
        Ok(Outcome::Complete) => ExitCode::SUCCESS,
        Ok(Outcome::Incomplete { skipped, lost }) => {
            if !json {
                let what = [(skipped, "skipped frame"), (lost, "lost part of an input")]
                    .into_iter()
                    .filter(|(n, _)| *n > 0)
                    .map(|(n, noun)| cli::counted(n, noun))
                    .collect::<Vec<_>>();
                eprintln!("completed with {}", what.join(" and "));
            }
            ExitCode::from(3)
        }
        Err(_) if travmap_core::temporaries::cleaning_up() => {
            // A tool the signal's handler stopped: the handler says so and exits with
            // the signal's status.
            loop {
                std::thread::park();
            }
        }
        Err(error) => {
            let code = if error.downcast_ref::<cli::UsageError>().is_some() {
                2
            } else {
                1
            };
            if json {
                let file = error
                    .chain()
                    .find_map(|e| e.downcast_ref::<travmap_core::Error>()?.path());
                cli::print_json_error(&format!("{error:#}"), file, code);
            } else {
                eprintln!("error: {error:#}");
            }
            ExitCode::from(code as u8)
        }
    }
}

/// Every frame allocates and frees buffers of a scan's size (1-5 MB). glibc's
/// thresholds, left to adjust themselves, can settle so that each such buffer is
/// mapped afresh or the heap trimmed under it, and every frame faults its pages in
/// again (integration took 40 % longer so on a 120,000-point scan). Fixed thresholds
/// above a scan's size keep freed buffers for the next frame; higher ones held
/// 25 MB more at the peak for no more speed (docs/speed.md).
fn keep_freed_scans_for_reuse() {
    #[cfg(target_env = "gnu")]
    {
        const MMAP_THRESHOLD_BYTES: libc::c_int = 8 << 20;
        const TRIM_THRESHOLD_BYTES: libc::c_int = 16 << 20;
        // SAFETY: mallopt only sets the allocator's parameters, before any other
        // thread exists. A refusal leaves glibc's defaults: correct, only slower.
        unsafe {
            libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES);
            libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES);
        }
    }
}

/// SIGINT, SIGTERM and SIGHUP (Ctrl-C; Docker, systemd, Ray and SLURM stopping a
/// job; a closed terminal) stop the child processes, remove the temporary outputs
/// and exit with 128 + the signal, as shells expect. A closed stdout (`travmap eval | head`) ends the
/// process quietly with SIGPIPE's status, as Unix tools do, instead of an error;
/// outputs are committed before anything is printed, so none is left half-written.
fn remove_outputs_on_signals() {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    // SAFETY: restores the default disposition before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    if let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) {
        std::thread::spawn(move || {
            if let Some(signal) = signals.forever().next() {
                travmap_core::temporaries::clean_up();
                let name = match signal {
                    SIGINT => "SIGINT",
                    SIGTERM => "SIGTERM",
                    _ => "SIGHUP",
                };
                eprintln!("interrupted by {name}: unfinished outputs removed");
                std::process::exit(128 + signal);
            }
        });
    }
}
